//! Procedural indoor worlds: storeys of rooms and corridors joined by doors, as a voxel grid.
//!
//! [`World::generate`] is deterministic from [`WorldParams`] (a seed, a [`Style`] and layout
//! numbers). The building plan is shared by its storeys (so vertical openings line up), the rooms
//! of each storey are drawn anew:
//!
//! ```text
//!  y ^   outer wall
//!    |  +----+--------+--------+--------+----+
//!    |  |    |room    |room    |room    |    |   band above corridor 1
//!    |  | W  +--door--+--------+--------+ E  |
//!    |  | e   corridor 1 (along x)        a  |
//!    |  | s  +--------+--------+--------+ s  |
//!    |  | t  |room    |room    |room    | t  |   band below corridor 1
//!    |  |    +--------+--------+--------+    |
//!    |  | c  |room    |room    |room    | c  |   band above corridor 0
//!    |  | o  +--------+--------+--------+ o  |
//!    |  | r   corridor 0 (along x)        r  |
//!    |  |[S] +--------+--------+--------+ r  |   [S] shaft to the next storey
//!    |  |    |room    |room    |room    |    |   band below corridor 0
//!    |  +----+--------+--------+--------+----+ -> x
//! ```
//! One corridor along x with a band of rooms on each side, two when a storey has eight rooms or
//! more; a west corridor joins the corridors' ends, and with two corridors an east one closes a
//! loop (probability 0.6). Each band is cut along x into rooms whose widths are drawn from
//! `room_size` (then stretched so the band is filled); a room's depth is 75-100 % of its band's.
//! Every room has a door to its corridor, and a door to its neighbour in the band with
//! probability 0.3 (more loops). Storeys are joined by a shaft: an opening through the slab in
//! the west corridor, at least 1.2 m square, so a 3D path can fly from one storey to the next.
//! Walls are 0.2 m thick (at least two voxels, so each side carries its own material), slabs
//! 0.3 m (at least two voxels); the outside of the building is solid.
//!
//! Materials: every voxel has a material id (`u16`, 0 = air) in the grid's layout. Room walls,
//! floors and ceilings draw from small per-world pools of materials (`style.wall_materials`
//! walls, about half as many floors and ceilings), so many rooms look alike: perceptual
//! aliasing, the seed's main difficulty. Landmarks break it: with `landmark_probability` a room
//! wall holds a poster and a 6 m stretch of corridor wall a sign, each with a unique pattern. Door
//! jambs and slab edges are trim; ceiling lamps are emissive patches. Furniture (kinds from the
//! style, `furniture_density` items per 10 m^2) stands against walls or free with clearance, kept
//! away from doors and posters, so free space stays connected ([`World::free_components`]).
//!
//! Frames: world metres, z up; the ground floor's surface is at z = 0 and the grid's origin at
//! `(0, 0, -slab)`. [`World::flight_band`] gives the heights a MAV flies at on each storey.

mod build;

use crate::rng::SimRng;
use crate::style::{FurnitureKind, Split, Style};
use crate::texture::Material;
use nalgebra::Point3;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use topoloc::skeleton::SkeletonError;
use topoloc::skeleton::{OccupancyGrid, Voxel};

/// Voxel size of worlds made by [`WorldParams::from_style`], metres.
pub const DEFAULT_VOXEL_SIZE: f64 = 0.1;

/// Most voxels a world may have (2^26): about 400 MB with the renderer's tables.
pub const MAX_WORLD_VOXELS: usize = 1 << 26;

/// Region id of voxels outside every room and corridor in [`World::region_map`].
pub const NO_REGION: u16 = u16::MAX;

/// Errors of world generation.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// A parameter is out of range; `field` names it as in [`WorldParams`].
    #[error("world parameter `{field}`: {message}")]
    InvalidParam {
        /// The field, e.g. `room_size` or `style.palette`.
        field: &'static str,
        /// What is wrong and the accepted range.
        message: String,
    },
    /// The voxel grid could not be built.
    #[error(transparent)]
    Grid(#[from] SkeletonError),
}

fn invalid(field: &'static str, message: String) -> WorldError {
    WorldError::InvalidParam { field, message }
}

/// Parameters of a world. Lengths in metres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WorldParams {
    /// Seed of every random choice.
    pub seed: u64,
    /// Look (texture families, palette, furniture kinds, aliasing).
    pub style: Style,
    /// Storeys, 1..=3.
    pub floors: u32,
    /// Rooms per storey, 1..=32.
    pub rooms_per_floor: u32,
    /// Range of room side lengths `[min, max]`, 2.5 <= min <= max <= 20.
    pub room_size: [f64; 2],
    /// Corridor width, 1.2..=5.
    pub corridor_width: f64,
    /// Door width, 0.7..=2.5, and at most `room_size[0] - 0.6`.
    pub door_width: f64,
    /// Door height, 1.8..=3, and at most `ceiling_height - 0.2`.
    pub door_height: f64,
    /// Floor-to-ceiling height, 2.2..=6.
    pub ceiling_height: f64,
    /// Voxel edge, 0.05..=0.25, and at most a third of the door width.
    pub voxel_size: f64,
    /// Furniture items per 10 m^2 of room floor, 0..=5.
    pub furniture_density: f64,
    /// Probability that a room wall holds a poster, and that a 6 m stretch of corridor wall
    /// holds a sign, 0..=1.
    pub landmark_probability: f64,
}

impl Default for WorldParams {
    /// [`WorldParams::from_style`] with seed 0 and the office style.
    fn default() -> Self {
        Self::from_style(0, Style::office())
    }
}

impl WorldParams {
    /// Parameters with the layout drawn from `style.layout` (deterministic in `seed`), door
    /// height 2.1 m and [`DEFAULT_VOXEL_SIZE`].
    pub fn from_style(seed: u64, style: Style) -> Self {
        let mut rng = SimRng::new(seed).fork(0x5041_5241);
        let l = &style.layout;
        let floors = rng.between(l.floors[0] as usize, l.floors[1] as usize) as u32;
        let rooms = rng.between(l.rooms_per_floor[0] as usize, l.rooms_per_floor[1] as usize);
        let corridor_width = rng.range(l.corridor_width[0], l.corridor_width[1]);
        let ceiling_height = rng.range(l.ceiling_height[0], l.ceiling_height[1]);
        Self {
            seed,
            floors,
            rooms_per_floor: rooms as u32,
            room_size: l.room_size,
            corridor_width,
            door_width: l.door_width,
            door_height: 2.1f64.min(ceiling_height - 0.3),
            ceiling_height,
            voxel_size: DEFAULT_VOXEL_SIZE,
            furniture_density: l.furniture_density,
            landmark_probability: l.landmark_probability,
            style,
        }
    }

    /// Checks every field against its documented range; the error names the first bad field.
    pub fn validate(&self) -> Result<(), WorldError> {
        let range = |field: &'static str, x: f64, lo: f64, hi: f64| {
            if x.is_finite() && (lo..=hi).contains(&x) {
                Ok(())
            } else {
                Err(invalid(field, format!("{x} is outside {lo}..={hi}")))
            }
        };
        if !(1..=3).contains(&self.floors) {
            return Err(invalid(
                "floors",
                format!("{} is outside 1..=3", self.floors),
            ));
        }
        if !(1..=32).contains(&self.rooms_per_floor) {
            return Err(invalid(
                "rooms_per_floor",
                format!("{} is outside 1..=32", self.rooms_per_floor),
            ));
        }
        let [lo, hi] = self.room_size;
        if !(lo.is_finite() && hi.is_finite() && 2.5 <= lo && lo <= hi && hi <= 20.0) {
            return Err(invalid(
                "room_size",
                format!("[{lo}, {hi}] must satisfy 2.5 <= min <= max <= 20"),
            ));
        }
        range("corridor_width", self.corridor_width, 1.2, 5.0)?;
        range("door_width", self.door_width, 0.7, 2.5)?;
        if self.door_width > lo - 0.6 {
            return Err(invalid(
                "door_width",
                format!(
                    "{} leaves no wall beside the door in the smallest room ({lo}): at most {}",
                    self.door_width,
                    lo - 0.6
                ),
            ));
        }
        range("ceiling_height", self.ceiling_height, 2.2, 6.0)?;
        range("door_height", self.door_height, 1.8, 3.0)?;
        if self.door_height > self.ceiling_height - 0.2 {
            return Err(invalid(
                "door_height",
                format!(
                    "{} must be at most ceiling_height - 0.2 = {}",
                    self.door_height,
                    self.ceiling_height - 0.2
                ),
            ));
        }
        range("voxel_size", self.voxel_size, 0.05, 0.25)?;
        if self.voxel_size > self.door_width / 3.0 {
            return Err(invalid(
                "voxel_size",
                format!(
                    "{} is more than a third of door_width {}: doors would be under 3 voxels",
                    self.voxel_size, self.door_width
                ),
            ));
        }
        range("furniture_density", self.furniture_density, 0.0, 5.0)?;
        range("landmark_probability", self.landmark_probability, 0.0, 1.0)?;
        let s = &self.style;
        for (field, empty) in [
            ("style.wall_families", s.wall_families.is_empty()),
            ("style.floor_families", s.floor_families.is_empty()),
            ("style.ceiling_families", s.ceiling_families.is_empty()),
        ] {
            if empty {
                return Err(invalid(field, "must list at least one family".into()));
            }
        }
        if s.palette.len() < 2 {
            return Err(invalid(
                "style.palette",
                format!("holds {} colours, needs at least 2", s.palette.len()),
            ));
        }
        if !(1..=16).contains(&s.wall_materials) {
            return Err(invalid(
                "style.wall_materials",
                format!("{} is outside 1..=16", s.wall_materials),
            ));
        }
        Ok(())
    }
}

/// What a region is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RegionKind {
    /// A room.
    Room,
    /// A corridor.
    Corridor,
    /// An opening through the slab between storey `floor` and the next.
    Shaft,
}

/// A box of free space: a room, a corridor or a shaft. Boxes in metres, `min` inclusive corner
/// to `max` (walls excluded).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Region {
    /// Room, corridor or shaft.
    pub kind: RegionKind,
    /// Storey (for a shaft: the storey below it).
    pub floor: usize,
    /// Lower corner (x, y, z), metres.
    pub min: [f64; 3],
    /// Upper corner, metres.
    pub max: [f64; 3],
    /// Material id of its walls (0 for a shaft).
    pub wall_material: u16,
    /// Material id of its floor (0 for a shaft).
    pub floor_material: u16,
    /// Material id of its ceiling (0 for a shaft).
    pub ceiling_material: u16,
}

/// A door: an opening through a wall between two regions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Door {
    /// Storey.
    pub floor: usize,
    /// Lower corner of the opening, metres.
    pub min: [f64; 3],
    /// Upper corner of the opening, metres.
    pub max: [f64; 3],
    /// The regions it joins (a room first).
    pub regions: [usize; 2],
}

/// A ceiling lamp: a point light (inverse-square falloff) just under its diffuser.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Lamp {
    /// Position, metres.
    pub position: [f64; 3],
    /// Irradiance it gives a surface facing it 1 m away (albedo-relative units).
    pub intensity: f64,
    /// The region it lights.
    pub region: usize,
}

/// Kinds of landmarks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LandmarkKind {
    /// A poster on a room wall.
    Poster,
    /// A sign on a corridor wall.
    Sign,
}

/// A unique landmark painted on a wall.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Landmark {
    /// Poster or sign.
    pub kind: LandmarkKind,
    /// The region it faces.
    pub region: usize,
    /// Centre of its face, metres.
    pub centre: [f64; 3],
    /// Unit normal of the wall, pointing into the region.
    pub normal: [f64; 3],
    /// Width and height, metres.
    pub size: [f64; 2],
    /// Its material id (unique to it).
    pub material: u16,
}

/// A piece of furniture.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Furniture {
    /// What it is.
    pub kind: FurnitureKind,
    /// The room it stands in.
    pub region: usize,
    /// Lower corner of its bounding box, metres.
    pub min: [f64; 3],
    /// Upper corner of its bounding box, metres.
    pub max: [f64; 3],
    /// Its material id.
    pub material: u16,
}

/// A generated world (see the module documentation). Immutable; share it across threads.
#[derive(Clone, Debug)]
pub struct World {
    params: WorldParams,
    grid: OccupancyGrid,
    materials: Vec<u16>,
    material_table: Vec<Material>,
    floor_z: Vec<[f64; 2]>,
    regions: Vec<Region>,
    doors: Vec<Door>,
    lamps: Vec<Lamp>,
    landmarks: Vec<Landmark>,
    furniture: Vec<Furniture>,
    region_map: Vec<u16>,
}

impl World {
    /// Generates the world of `params` (validated first; errors name the bad field).
    pub fn generate(params: &WorldParams) -> Result<Self, WorldError> {
        params.validate()?;
        build::generate(params)
    }

    /// The parameters it was generated from.
    pub fn params(&self) -> &WorldParams {
        &self.params
    }

    /// Occupancy: walls, slabs, furniture and the outside are occupied.
    pub fn grid(&self) -> &OccupancyGrid {
        &self.grid
    }

    /// Material id per voxel (0 = air), in the grid's layout (x fastest).
    pub fn materials(&self) -> &[u16] {
        &self.materials
    }

    /// Material id of voxel `v` (0 = air), `None` outside the grid.
    pub fn material_at(&self, v: Voxel) -> Option<u16> {
        self.grid.index(v).map(|i| self.materials[i])
    }

    /// Materials by id; entry 0 (air) is a placeholder never drawn.
    pub fn material_table(&self) -> &[Material] {
        &self.material_table
    }

    /// Number of storeys.
    pub fn floor_count(&self) -> usize {
        self.floor_z.len()
    }

    /// `[floor surface z, ceiling z]` of storey `floor`, metres. Panics for a storey that does
    /// not exist.
    pub fn floor_range(&self, floor: usize) -> [f64; 2] {
        self.floor_z[floor]
    }

    /// The heights a MAV flies at on storey `floor`: from 0.8 m above the floor to
    /// `min(2.0, ceiling_height - 0.5)` m above it (under the door lintels), metres.
    pub fn flight_band(&self, floor: usize) -> [f64; 2] {
        let [z0, z1] = self.floor_z[floor];
        let top = (z0 + 2.0)
            .min(z1 - 0.5)
            .min(z0 + self.params.door_height - 0.1);
        [z0 + 0.8, top]
    }

    /// The storey whose floor-to-ceiling range holds `z` (slabs count as the storey below).
    pub fn floor_at(&self, z: f64) -> Option<usize> {
        let first = self.floor_z.first()?;
        if z < first[0] {
            return None;
        }
        let slab = self.slab_thickness();
        self.floor_z.iter().position(|&[_, top]| z < top + slab)
    }

    /// Rooms, corridors and shafts; indices are the region ids used elsewhere.
    pub fn regions(&self) -> &[Region] {
        &self.regions
    }

    /// Doors.
    pub fn doors(&self) -> &[Door] {
        &self.doors
    }

    /// Ceiling lamps.
    pub fn lamps(&self) -> &[Lamp] {
        &self.lamps
    }

    /// Posters and signs.
    pub fn landmarks(&self) -> &[Landmark] {
        &self.landmarks
    }

    /// Furniture and objects.
    pub fn furniture(&self) -> &[Furniture] {
        &self.furniture
    }

    /// Region id (or [`NO_REGION`]) of each column `(x, y)` of storey `floor`, x fastest
    /// (`nx * ny` entries). Doorways belong to their room.
    pub fn region_map(&self, floor: usize) -> &[u16] {
        let [nx, ny, _] = self.grid.dims();
        &self.region_map[floor * nx * ny..(floor + 1) * nx * ny]
    }

    /// The region holding world point `p` (by its storey and column), if any.
    pub fn region_at(&self, p: &Point3<f64>) -> Option<usize> {
        let floor = self.floor_at(p.z)?;
        let z = self.floor_z[floor][0] + 0.5 * self.grid.voxel_size();
        let v = self.grid.voxel_at(&Point3::new(p.x, p.y, z))?;
        let [nx, _, _] = self.grid.dims();
        let id = self.region_map(floor)[v[0] + nx * v[1]];
        (id != NO_REGION).then_some(id as usize)
    }

    /// Slab thickness, metres.
    pub fn slab_thickness(&self) -> f64 {
        -self.grid.origin().z
    }

    /// Number of 6-connected components of free voxels (1 for every generated world).
    pub fn free_components(&self) -> usize {
        let [nx, ny, nz] = self.grid.dims();
        let cells = self.grid.cells();
        let mut seen = vec![false; cells.len()];
        let mut queue = VecDeque::new();
        let mut components = 0;
        for start in 0..cells.len() {
            if cells[start] || seen[start] {
                continue;
            }
            components += 1;
            seen[start] = true;
            queue.push_back(start);
            while let Some(i) = queue.pop_front() {
                let (x, y, z) = (i % nx, (i / nx) % ny, i / (nx * ny));
                let mut visit = |j: usize| {
                    if !cells[j] && !seen[j] {
                        seen[j] = true;
                        queue.push_back(j);
                    }
                };
                if x > 0 {
                    visit(i - 1);
                }
                if x + 1 < nx {
                    visit(i + 1);
                }
                if y > 0 {
                    visit(i - nx);
                }
                if y + 1 < ny {
                    visit(i + nx);
                }
                if z > 0 {
                    visit(i - nx * ny);
                }
                if z + 1 < nz {
                    visit(i + nx * ny);
                }
            }
        }
        components
    }
}

impl Split {
    /// The parameters of world `k` of the split: its seed and style, layout drawn from the
    /// style's ranges. (Defined here, beside [`WorldParams::from_style`], so that the style
    /// module does not import this one.)
    pub fn world_params(self, k: u32) -> WorldParams {
        WorldParams::from_style(self.world_seed(k), self.style())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small(seed: u64) -> WorldParams {
        WorldParams {
            voxel_size: 0.2,
            ..WorldParams::from_style(seed, Style::office())
        }
    }

    #[test]
    fn bad_parameters_name_the_field() {
        let ok = small(1);
        assert!(ok.validate().is_ok());
        let field = |p: WorldParams| match p.validate() {
            Err(WorldError::InvalidParam { field, .. }) => field,
            other => panic!("expected an invalid parameter, got {other:?}"),
        };
        assert_eq!(
            field(WorldParams {
                floors: 0,
                ..ok.clone()
            }),
            "floors"
        );
        assert_eq!(
            field(WorldParams {
                floors: 4,
                ..ok.clone()
            }),
            "floors"
        );
        assert_eq!(
            field(WorldParams {
                rooms_per_floor: 0,
                ..ok.clone()
            }),
            "rooms_per_floor"
        );
        assert_eq!(
            field(WorldParams {
                room_size: [5.0, 4.0],
                ..ok.clone()
            }),
            "room_size"
        );
        assert_eq!(
            field(WorldParams {
                room_size: [1.0, 4.0],
                ..ok.clone()
            }),
            "room_size"
        );
        assert_eq!(
            field(WorldParams {
                corridor_width: f64::NAN,
                ..ok.clone()
            }),
            "corridor_width"
        );
        assert_eq!(
            field(WorldParams {
                door_width: 3.4,
                ..ok.clone()
            }),
            "door_width"
        );
        assert_eq!(
            field(WorldParams {
                door_height: 2.65,
                ..ok.clone()
            }),
            "door_height"
        );
        assert_eq!(
            field(WorldParams {
                ceiling_height: 9.0,
                ..ok.clone()
            }),
            "ceiling_height"
        );
        assert_eq!(
            field(WorldParams {
                voxel_size: 0.01,
                ..ok.clone()
            }),
            "voxel_size"
        );
        assert_eq!(
            field(WorldParams {
                voxel_size: 0.25,
                door_width: 0.7,
                ..ok.clone()
            }),
            "voxel_size"
        );
        assert_eq!(
            field(WorldParams {
                furniture_density: -1.0,
                ..ok.clone()
            }),
            "furniture_density"
        );
        assert_eq!(
            field(WorldParams {
                landmark_probability: 1.5,
                ..ok.clone()
            }),
            "landmark_probability"
        );
        let mut style = ok.style.clone();
        style.palette.truncate(1);
        assert_eq!(
            field(WorldParams {
                style,
                ..ok.clone()
            }),
            "style.palette"
        );
        let mut style = ok.style.clone();
        style.wall_families.clear();
        assert_eq!(
            field(WorldParams {
                style,
                ..ok.clone()
            }),
            "style.wall_families"
        );
        let message = World::generate(&WorldParams { floors: 7, ..ok })
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("floors") && message.contains("1..=3"),
            "{message}"
        );
    }
}
