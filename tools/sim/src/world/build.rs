//! The generator behind [`World::generate`]: plan, carve, paint, open doors and shafts, light,
//! decorate and furnish (see the module documentation of [`crate::world`]).

use super::{
    invalid, Door, Furniture, Lamp, Landmark, LandmarkKind, Region, RegionKind, World, WorldError,
    WorldParams, MAX_WORLD_VOXELS, NO_REGION,
};
use crate::rng::SimRng;
use crate::style::FurnitureKind;
use crate::texture::{face_uv, Material, Placement, TextureFamily};
use nalgebra::Point3;
use std::collections::HashMap;
use topoloc::skeleton::OccupancyGrid;

/// Irradiance a lamp gives 1 m away under a 2.7 m ceiling (scaled with the ceiling height
/// squared), chosen so that a lit office wall gets about 0.3-0.6 on top of the ambient term.
const LAMP_INTENSITY: f64 = 1.4;

/// Colours of sign plates (green exit, blue information, red fire, dark, yellow warning).
const SIGN_COLOURS: [[u8; 3]; 5] = [
    [30, 140, 70],
    [40, 80, 170],
    [180, 40, 40],
    [60, 60, 70],
    [220, 170, 30],
];

/// Material id of structural trim (door jambs, slab edges, the outside).
const TRIM: u16 = 1;

/// A box of voxels `lo..hi` (half-open); z is ignored by the `_xy` methods.
#[derive(Clone, Copy, Debug, PartialEq)]
struct VBox {
    lo: [usize; 3],
    hi: [usize; 3],
}

impl VBox {
    fn new(lo: [usize; 3], hi: [usize; 3]) -> Self {
        Self { lo, hi }
    }

    fn overlaps_xy(&self, o: &VBox) -> bool {
        (0..2).all(|k| self.lo[k] < o.hi[k] && o.lo[k] < self.hi[k])
    }

    fn grow_xy(&self, m: usize) -> VBox {
        VBox::new(
            [
                self.lo[0].saturating_sub(m),
                self.lo[1].saturating_sub(m),
                self.lo[2],
            ],
            [self.hi[0] + m, self.hi[1] + m, self.hi[2]],
        )
    }

    fn len(&self, k: usize) -> usize {
        self.hi[k] - self.lo[k]
    }
}

/// One wall of a region box: the voxel layer just outside it on `axis` (0 = x, 1 = y), whose
/// face looks into the region along +axis when `positive`.
#[derive(Clone, Copy, Debug)]
struct Side {
    axis: usize,
    layer: usize,
    positive: bool,
    along: [usize; 2],
}

impl Side {
    fn of(b: &VBox) -> [Side; 4] {
        let side = |axis: usize, layer, positive| Side {
            axis,
            layer,
            positive,
            along: [b.lo[1 - axis], b.hi[1 - axis]],
        };
        [
            side(0, b.lo[0] - 1, true),
            side(0, b.hi[0], false),
            side(1, b.lo[1] - 1, true),
            side(1, b.hi[1], false),
        ]
    }

    fn voxel(&self, a: usize, z: usize) -> [usize; 3] {
        if self.axis == 0 {
            [self.layer, a, z]
        } else {
            [a, self.layer, z]
        }
    }

    /// The box spanning `c` on the wall's axis, `a` along the wall and `z` vertically.
    fn span(&self, c: [usize; 2], a: [usize; 2], z: [usize; 2]) -> VBox {
        if self.axis == 0 {
            VBox::new([c[0], a[0], z[0]], [c[1], a[1], z[1]])
        } else {
            VBox::new([a[0], c[0], z[0]], [a[1], c[1], z[1]])
        }
    }

    /// The wall layer itself over the height `z`.
    fn wall(&self, z: [usize; 2]) -> VBox {
        self.span([self.layer, self.layer + 1], self.along, z)
    }

    /// The footprint `depth` voxels deep in front of the wall, over `a0..a1` along it.
    fn front(&self, a0: usize, a1: usize, depth: usize, z: [usize; 2]) -> VBox {
        let c = if self.positive {
            [self.layer + 1, self.layer + 1 + depth]
        } else {
            [self.layer - depth, self.layer]
        };
        self.span(c, [a0, a1], z)
    }

    /// Unit normal into the region.
    fn normal(&self) -> [f64; 3] {
        let mut n = [0.0; 3];
        n[self.axis] = if self.positive { 1.0 } else { -1.0 };
        n
    }
}

/// A band of rooms along a corridor.
#[derive(Clone, Copy, Debug)]
struct Band {
    y: [usize; 2],
    /// Whether the band lies below (smaller y than) its corridor.
    below: bool,
}

/// The building plan shared by all storeys, in voxels.
struct Plan {
    tw: usize,
    ts: usize,
    hv: usize,
    dw: usize,
    dh: usize,
    dims: [usize; 3],
    bands: Vec<Band>,
    /// Corridor footprints: west, then one per band pair, then east if any.
    corridors: Vec<VBox>,
    x_rooms: [usize; 2],
    shaft: VBox,
}

impl Plan {
    fn new(p: &WorldParams, rng: &mut SimRng) -> Result<Self, WorldError> {
        let vs = p.voxel_size;
        let vox = |m: f64| vox(m, vs);
        let tw = vox(0.2).max(2);
        let ts = vox(0.3).max(2);
        let cw = vox(p.corridor_width);
        let hv = vox(p.ceiling_height);
        let dw = vox(p.door_width);
        let dh = vox(p.door_height).min(hv - 1);
        let [rmin, rmax] = p.room_size;
        let n_corr = if p.rooms_per_floor >= 8 { 2 } else { 1 };
        let mut y = tw;
        let mut bands = Vec::new();
        let mut corridor_y = Vec::new();
        for _ in 0..n_corr {
            let depth = vox(rng.range(rmin, rmax));
            bands.push(Band {
                y: [y, y + depth],
                below: true,
            });
            y += depth + tw;
            corridor_y.push([y, y + cw]);
            y += cw + tw;
            let depth = vox(rng.range(rmin, rmax));
            bands.push(Band {
                y: [y, y + depth],
                below: false,
            });
            y += depth + tw;
        }
        let ny = y;
        let per_band = (p.rooms_per_floor as usize).div_ceil(bands.len());
        let mean = vox(0.5 * (rmin + rmax));
        let x0 = tw + cw + tw;
        let x1 = x0 + per_band * mean + (per_band - 1) * tw;
        let east = n_corr == 2 && rng.chance(0.6);
        let x_end = if east { x1 + tw + cw } else { x1 };
        let nx = x_end + tw;
        let nz = ts + p.floors as usize * (hv + ts);
        let count = nx * ny * nz;
        if count > MAX_WORLD_VOXELS {
            return Err(invalid(
                "voxel_size",
                format!(
                    "{vs} m makes a {nx} x {ny} x {nz} grid ({count} voxels), more than \
                     {MAX_WORLD_VOXELS}: use larger voxels or fewer, smaller rooms"
                ),
            ));
        }
        let full = |x: [usize; 2], y: [usize; 2]| VBox::new([x[0], y[0], 0], [x[1], y[1], 0]);
        let mut corridors = vec![full([tw, tw + cw], [tw, ny - tw])];
        corridors.extend(corridor_y.iter().map(|&cy| full([tw, x_end], cy)));
        if east {
            corridors.push(full([x1 + tw, x_end], [tw, ny - tw]));
        }
        // The shaft: in the west corridor, beside the band above corridor 0 (away from the
        // junction), at least 1.2 m long and as wide as the corridor.
        let b = bands[1].y;
        let len = vox(2.0).min(b[1] - b[0] - 2).max(vox(1.2));
        let ys = (b[0] + b[1] - len) / 2;
        let shaft = full([tw, tw + cw], [ys, ys + len]);
        Ok(Self {
            tw,
            ts,
            hv,
            dw,
            dh,
            dims: [nx, ny, nz],
            bands,
            corridors,
            x_rooms: [x0, x1],
            shaft,
        })
    }

    /// Voxel z range `[floor, ceiling)` of the free space of storey `f`.
    fn z(&self, f: usize) -> [usize; 2] {
        let z0 = self.ts + f * (self.hv + self.ts);
        [z0, z0 + self.hv]
    }
}

/// Material ids a world's surfaces draw from.
struct Pools {
    walls: Vec<u16>,
    floors: Vec<u16>,
    ceilings: Vec<u16>,
    furniture: HashMap<FurnitureKind, u16>,
    lamp_seed: u64,
}

struct Builder<'a> {
    p: &'a WorldParams,
    plan: Plan,
    vs: f64,
    mats: Vec<u16>,
    table: Vec<Material>,
    regions: Vec<Region>,
    boxes: Vec<VBox>,
    reserved: Vec<Vec<VBox>>,
    doors: Vec<Door>,
    lamps: Vec<Lamp>,
    landmarks: Vec<Landmark>,
    furniture: Vec<Furniture>,
    region_map: Vec<u16>,
}

pub(super) fn generate(p: &WorldParams) -> Result<World, WorldError> {
    let root = SimRng::new(p.seed);
    let plan = Plan::new(p, &mut root.fork(1))?;
    let [nx, ny, nz] = plan.dims;
    let floors = p.floors as usize;
    let mut b = Builder {
        p,
        vs: p.voxel_size,
        mats: vec![TRIM; nx * ny * nz],
        table: Vec::new(),
        regions: Vec::new(),
        boxes: Vec::new(),
        reserved: Vec::new(),
        doors: Vec::new(),
        lamps: Vec::new(),
        landmarks: Vec::new(),
        furniture: Vec::new(),
        region_map: vec![NO_REGION; floors * nx * ny],
        plan,
    };
    let pools = b.pools(&mut root.fork(2));
    for f in 0..floors {
        b.storey(f, &pools, &mut root.fork(100 + f as u64));
    }
    for f in 0..floors.saturating_sub(1) {
        b.shaft(f);
    }
    let mut decor = root.fork(3);
    for r in 0..b.regions.len() {
        b.light(r, &pools);
        b.decorate(r, &mut decor);
    }
    let mut furnish = root.fork(4);
    for r in 0..b.regions.len() {
        b.furnish(r, &pools, &mut furnish);
    }
    b.finish()
}

impl Builder<'_> {
    fn index(&self, v: [usize; 3]) -> usize {
        let [nx, ny, _] = self.plan.dims;
        v[0] + nx * (v[1] + ny * v[2])
    }

    fn add_material(&mut self, m: Material) -> u16 {
        self.table.push(m);
        (self.table.len() - 1) as u16
    }

    fn metres(&self, v: [usize; 3]) -> [f64; 3] {
        let vs = self.vs;
        [
            v[0] as f64 * vs,
            v[1] as f64 * vs,
            (v[2] as f64 - self.plan.ts as f64) * vs,
        ]
    }

    fn floor_z(&self, f: usize) -> f64 {
        self.metres([0, 0, self.plan.z(f)[0]])[2]
    }

    fn fill(&mut self, b: &VBox, material: u16) {
        for z in b.lo[2]..b.hi[2] {
            for y in b.lo[1]..b.hi[1] {
                let start = self.index([b.lo[0], y, z]);
                self.mats[start..start + b.len(0)].fill(material);
            }
        }
    }

    /// Sets `material` on the occupied voxels of `b`.
    fn paint(&mut self, b: &VBox, material: u16) {
        for z in b.lo[2]..b.hi[2] {
            for y in b.lo[1]..b.hi[1] {
                for x in b.lo[0]..b.hi[0] {
                    let i = self.index([x, y, z]);
                    if self.mats[i] != 0 {
                        self.mats[i] = material;
                    }
                }
            }
        }
    }

    fn pools(&mut self, rng: &mut SimRng) -> Pools {
        let style = &self.p.style;
        self.table
            .push(Material::new(TextureFamily::Trim, [0; 3], [0; 3], 0)); // air
        let trim = self.add_material(Material::new(
            TextureFamily::Trim,
            [225, 222, 215],
            [200, 200, 200],
            rng.next_u64(),
        ));
        debug_assert_eq!(trim, TRIM);
        let palette = style.palette.clone();
        let mut draw = |families: &[TextureFamily], count: usize, this: &mut Self| {
            let mut order = families.to_vec();
            rng.shuffle(&mut order);
            (0..count)
                .map(|i| {
                    let family = order[i % order.len()];
                    let c = rng.below(palette.len());
                    let jointed = matches!(
                        family,
                        TextureFamily::Brick
                            | TextureFamily::ConcreteBlock
                            | TextureFamily::FloorTiles
                            | TextureFamily::HexTiles
                            | TextureFamily::CeilingTiles
                    );
                    let accent = if jointed {
                        // Joints contrast with the blocks: dark between light ones and light
                        // between dark ones.
                        let [r, g, b] = palette[c].map(f64::from);
                        let light = 0.3 * r + 0.59 * g + 0.11 * b > 120.0;
                        let (lo, hi) = if light { (70.0, 120.0) } else { (180.0, 230.0) };
                        let g = rng.range(lo, hi) as u8;
                        [g, g, g.saturating_sub(8)]
                    } else {
                        palette[(c + 1 + rng.below(palette.len() - 1)) % palette.len()]
                    };
                    this.add_material(Material::new(family, palette[c], accent, rng.next_u64()))
                })
                .collect::<Vec<u16>>()
        };
        let k = style.wall_materials as usize;
        let walls = draw(&style.wall_families, k, self);
        let floors = draw(&style.floor_families, k.div_ceil(2), self);
        let ceilings = draw(&style.ceiling_families, (k / 2).max(1), self);
        let mut furniture = HashMap::new();
        for &kind in &style.furniture {
            let ids = draw(&[kind.family()], 1, self);
            furniture.insert(kind, ids[0]);
        }
        Pools {
            walls,
            floors,
            ceilings,
            furniture,
            lamp_seed: rng.next_u64(),
        }
    }

    /// Adds a region: carves it, paints its walls, floor and ceiling, maps its columns.
    fn add_region(&mut self, kind: RegionKind, floor: usize, b: VBox, mats: [u16; 3]) -> usize {
        let id = self.regions.len();
        self.fill(&b, 0);
        let [nx, ny, _] = self.plan.dims;
        for y in b.lo[1]..b.hi[1] {
            let row = floor * nx * ny + y * nx;
            self.region_map[row + b.lo[0]..row + b.hi[0]].fill(id as u16);
        }
        self.regions.push(Region {
            kind,
            floor,
            min: self.metres(b.lo),
            max: self.metres(b.hi),
            wall_material: mats[0],
            floor_material: mats[1],
            ceiling_material: mats[2],
        });
        self.boxes.push(b);
        self.reserved.push(Vec::new());
        id
    }

    fn paint_surfaces(&mut self, r: usize) {
        let b = self.boxes[r];
        let Region {
            wall_material,
            floor_material,
            ceiling_material,
            ..
        } = self.regions[r];
        let z = [b.lo[2], b.hi[2]];
        for side in Side::of(&b) {
            self.paint(&side.wall(z), wall_material);
        }
        let mut floor = b;
        floor.lo[2] = b.lo[2] - 1;
        floor.hi[2] = b.lo[2];
        self.paint(&floor, floor_material);
        let mut ceiling = b;
        ceiling.lo[2] = b.hi[2];
        ceiling.hi[2] = b.hi[2] + 1;
        self.paint(&ceiling, ceiling_material);
    }

    /// Carves and paints storey `f`: corridors, rooms, doors.
    fn storey(&mut self, f: usize, pools: &Pools, rng: &mut SimRng) {
        let z = self.plan.z(f);
        let corridor_mats = [
            *rng.pick(&pools.walls).expect("pool"),
            *rng.pick(&pools.floors).expect("pool"),
            *rng.pick(&pools.ceilings).expect("pool"),
        ];
        let corridors: Vec<usize> = self
            .plan
            .corridors
            .clone()
            .into_iter()
            .map(|c| {
                let b = VBox::new([c.lo[0], c.lo[1], z[0]], [c.hi[0], c.hi[1], z[1]]);
                self.add_region(RegionKind::Corridor, f, b, corridor_mats)
            })
            .collect();
        for &c in &corridors {
            self.paint_surfaces(c);
        }
        // Rooms per band: as even as possible, the extra ones in random bands.
        let bands = self.plan.bands.clone();
        let rooms = self.p.rooms_per_floor as usize;
        let mut order: Vec<usize> = (0..bands.len()).collect();
        rng.shuffle(&mut order);
        let mut counts = vec![rooms / bands.len(); bands.len()];
        for &b in order.iter().take(rooms % bands.len()) {
            counts[b] += 1;
        }
        let (tw, vs) = (self.plan.tw, self.vs);
        let [rmin, rmax] = self.p.room_size.map(|m| m / vs);
        for (bi, band) in bands.iter().enumerate() {
            let n = counts[bi];
            if n == 0 {
                continue;
            }
            let corridor = corridors[1 + bi / 2];
            // Widths drawn from room_size, stretched so the rooms fill the band.
            let [x0, x1] = self.plan.x_rooms;
            let free = (x1 - x0 - (n - 1) * tw) as f64;
            let raw: Vec<f64> = (0..n).map(|_| rng.range(rmin, rmax)).collect();
            let extra: f64 = raw.iter().map(|w| w - rmin).sum();
            let k = if extra > 1e-9 {
                (free - n as f64 * rmin) / extra
            } else {
                0.0
            };
            let mut edges = vec![0.0];
            for w in &raw {
                let w = if extra > 1e-9 {
                    rmin + (w - rmin) * k
                } else {
                    free / n as f64
                };
                edges.push(edges.last().unwrap() + w);
            }
            let mut previous: Option<usize> = None;
            for i in 0..n {
                let xa = x0 + edges[i].round() as usize + i * tw;
                let xb = x0 + edges[i + 1].round() as usize + i * tw;
                let band_depth = band.y[1] - band.y[0];
                let depth = ((band_depth as f64 * rng.range(0.75, 1.0)).round() as usize)
                    .clamp(rmin.round() as usize, band_depth);
                let y = if band.below {
                    [band.y[1] - depth, band.y[1]]
                } else {
                    [band.y[0], band.y[0] + depth]
                };
                let mats = [
                    *rng.pick(&pools.walls).expect("pool"),
                    *rng.pick(&pools.floors).expect("pool"),
                    *rng.pick(&pools.ceilings).expect("pool"),
                ];
                let b = VBox::new([xa, y[0], z[0]], [xb, y[1], z[1]]);
                let room = self.add_region(RegionKind::Room, f, b, mats);
                self.paint_surfaces(room);
                // The door to the corridor, through the wall between them.
                let wall = if band.below {
                    [y[1], y[1] + tw]
                } else {
                    [y[0] - tw, y[0]]
                };
                if let Some(along) = self.door_span(rng, [xa, xb]) {
                    self.cut_door(f, along, wall, 1, [room, corridor]);
                }
                // A door to the previous room of the band, sometimes.
                if let Some(prev) = previous.filter(|_| rng.chance(0.3)) {
                    let pb = self.boxes[prev];
                    let overlap = [pb.lo[1].max(b.lo[1]), pb.hi[1].min(b.hi[1])];
                    let span = self.door_span(rng, overlap);
                    if let Some(along) = span.filter(|s| s[1] - s[0] == self.plan.dw) {
                        self.cut_door(f, along, [pb.hi[0], xa], 0, [room, prev]);
                    }
                }
                previous = Some(room);
            }
        }
    }

    /// Where a door may open along a wall spanning `span`: `door_width` wide with 0.3 m of wall
    /// each side, narrower on a wall too short for that (keeping one voxel of wall each side);
    /// `None` only when the wall is under three voxels long.
    fn door_span(&self, rng: &mut SimRng, span: [usize; 2]) -> Option<[usize; 2]> {
        let len = span[1].checked_sub(span[0])?;
        let width = self.plan.dw.min(len.checked_sub(2)?);
        if width == 0 {
            return None;
        }
        let margin = vox(0.3, self.vs).min((len - width) / 2);
        let a = rng.between(span[0] + margin, span[1] - margin - width);
        Some([a, a + width])
    }

    /// Opens a door `along` (on the axis other than `through`) across the wall `wall` (on axis
    /// `through`), from the storey's floor to the door height.
    fn cut_door(
        &mut self,
        f: usize,
        along: [usize; 2],
        wall: [usize; 2],
        through: usize,
        joins: [usize; 2],
    ) {
        let z0 = self.plan.z(f)[0];
        let (x, y) = if through == 0 {
            (wall, along)
        } else {
            (along, wall)
        };
        let b = VBox::new([x[0], y[0], z0], [x[1], y[1], z0 + self.plan.dh]);
        self.fill(&b, 0);
        let [nx, ny, _] = self.plan.dims;
        for yy in y[0]..y[1] {
            let row = f * nx * ny + yy * nx;
            self.region_map[row + x[0]..row + x[1]].fill(joins[0] as u16);
        }
        let clearance = b.grow_xy(vox(1.0, self.vs));
        for r in joins {
            self.reserved[r].push(clearance);
        }
        self.doors.push(Door {
            floor: f,
            min: self.metres(b.lo),
            max: self.metres(b.hi),
            regions: joins,
        });
    }

    /// Opens the slab above storey `f` at the shaft's footprint.
    fn shaft(&mut self, f: usize) {
        let s = self.plan.shaft;
        let b = VBox::new(
            [s.lo[0], s.lo[1], self.plan.z(f)[1]],
            [s.hi[0], s.hi[1], self.plan.z(f + 1)[0]],
        );
        self.fill(&b, 0);
        self.regions.push(Region {
            kind: RegionKind::Shaft,
            floor: f,
            min: self.metres(b.lo),
            max: self.metres(b.hi),
            wall_material: 0,
            floor_material: 0,
            ceiling_material: 0,
        });
        self.boxes.push(b);
        self.reserved.push(Vec::new());
    }

    /// Ceiling lamps of region `r`: a grid about 3 m apart in rooms, a row 4 m apart in
    /// corridors; each an emissive patch on the ceiling (skipped where the ceiling is open).
    fn light(&mut self, r: usize, pools: &Pools) {
        let region = self.regions[r].clone();
        let b = self.boxes[r];
        let vs = self.vs;
        let (lx, ly) = (b.len(0) as f64 * vs, b.len(1) as f64 * vs);
        let (counts, patch) = match region.kind {
            RegionKind::Shaft => return,
            RegionKind::Room => (
                [(lx / 3.0).round().max(1.0), (ly / 3.0).round().max(1.0)],
                [0.6, 0.6],
            ),
            RegionKind::Corridor if lx >= ly => ([(lx / 4.0).round().max(1.0), 1.0], [1.2, 0.3]),
            RegionKind::Corridor => ([1.0, (ly / 4.0).round().max(1.0)], [0.3, 1.2]),
        };
        let height = self.p.ceiling_height;
        let intensity = LAMP_INTENSITY * (height / 2.7).powi(2);
        for i in 0..counts[0] as usize {
            for j in 0..counts[1] as usize {
                let cx = region.min[0] + lx * (i as f64 + 0.5) / counts[0];
                let cy = region.min[1] + ly * (j as f64 + 0.5) / counts[1];
                let half = [patch[0] / 2.0, patch[1] / 2.0];
                let to_voxel = |m: f64| (m / vs).round() as usize;
                let lo = [to_voxel(cx - half[0]), to_voxel(cy - half[1]), b.hi[2]];
                let hi = [
                    to_voxel(cx + half[0]).max(lo[0] + 1),
                    to_voxel(cy + half[1]).max(lo[1] + 1),
                    b.hi[2] + 1,
                ];
                let patch_box = VBox::new(lo, hi);
                if !self.all_voxels(&patch_box, region.ceiling_material) {
                    continue;
                }
                let (min, max) = (self.metres(lo), self.metres(hi));
                let mut m = Material::new(
                    TextureFamily::Lamp,
                    [255, 250, 235],
                    [150, 150, 155],
                    pools.lamp_seed,
                );
                m.placement = Some(Placement {
                    origin: [min[0], min[1]],
                    size: [max[0] - min[0], max[1] - min[1]],
                });
                let id = self.add_material(m);
                self.fill(&patch_box, id);
                self.lamps.push(Lamp {
                    position: [cx, cy, region.max[2] - 0.1],
                    intensity,
                    region: r,
                });
            }
        }
    }

    fn all_voxels(&self, b: &VBox, material: u16) -> bool {
        (b.lo[2]..b.hi[2]).all(|z| {
            (b.lo[1]..b.hi[1])
                .all(|y| (b.lo[0]..b.hi[0]).all(|x| self.mats[self.index([x, y, z])] == material))
        })
    }

    /// Landmarks of region `r`: a poster on each wall of a room, a sign on each 6 m stretch of
    /// corridor, each with probability `landmark_probability`.
    fn decorate(&mut self, r: usize, rng: &mut SimRng) {
        let p = self.p.landmark_probability;
        let b = self.boxes[r];
        match self.regions[r].kind {
            RegionKind::Shaft => {}
            RegionKind::Room => {
                for side in Side::of(&b) {
                    if !rng.chance(p) {
                        continue;
                    }
                    let w = rng.range(0.5, 0.9);
                    let h = (w * rng.range(1.2, 1.45)).min(self.p.ceiling_height - 1.4);
                    let colour = *rng.pick(&self.p.style.palette).expect("palette");
                    let bottom = rng.range(1.0, 1.2);
                    for _ in 0..4 {
                        if self.place_landmark(
                            r,
                            side,
                            LandmarkKind::Poster,
                            [w, h],
                            bottom,
                            colour,
                            rng,
                        ) {
                            break;
                        }
                    }
                }
            }
            RegionKind::Corridor => {
                let long = if b.len(0) >= b.len(1) { 0 } else { 1 };
                let stretches = (b.len(long) as f64 * self.vs / 6.0).floor() as usize;
                let sides = Side::of(&b);
                for s in 0..stretches {
                    if !rng.chance(p) {
                        continue;
                    }
                    let mut side = sides[2 * (1 - long) + rng.below(2)];
                    let span = b.len(long) / stretches.max(1);
                    side.along = [b.lo[long] + s * span, b.lo[long] + (s + 1) * span];
                    let colour = *rng.pick(&SIGN_COLOURS).expect("colours");
                    let top = self.p.ceiling_height - 0.15;
                    let bottom = rng.range(1.7, 1.9).min(top - 0.3);
                    for _ in 0..4 {
                        if self.place_landmark(
                            r,
                            side,
                            LandmarkKind::Sign,
                            [0.9, 0.3],
                            bottom,
                            colour,
                            rng,
                        ) {
                            break;
                        }
                    }
                }
            }
        }
    }

    /// Paints a landmark of `size` (metres) on `side` of region `r`, `bottom` metres above the
    /// floor, where the wall is plain; false when the chosen spot is not.
    #[allow(clippy::too_many_arguments)]
    fn place_landmark(
        &mut self,
        r: usize,
        side: Side,
        kind: LandmarkKind,
        size: [f64; 2],
        bottom: f64,
        colour: [u8; 3],
        rng: &mut SimRng,
    ) -> bool {
        let vs = self.vs;
        let vox = |m: f64| vox(m, vs);
        let (w, h) = (vox(size[0]), vox(size[1]));
        let margin = vox(0.2);
        let Some(last) = side.along[1].checked_sub(w + margin) else {
            return false;
        };
        if last < side.along[0] + margin {
            return false;
        }
        let a0 = rng.between(side.along[0] + margin, last);
        let z0 = self.plan.z(self.regions[r].floor)[0] + vox(bottom);
        let wall = self.regions[r].wall_material;
        let ok = (z0..z0 + h)
            .all(|z| (a0..a0 + w).all(|a| self.mats[self.index(side.voxel(a, z))] == wall));
        if !ok {
            return false;
        }
        let floor_z = self.floor_z(self.regions[r].floor);
        // Corners of the face in metres (the face plane's coordinate does not matter to uv).
        let corner = |a: usize, z: usize| {
            let v = side.voxel(a, z);
            face_uv(side.axis, side.positive, self.metres(v), floor_z)
        };
        let (c0, c1) = (corner(a0, z0), corner(a0 + w, z0 + h));
        let family = match kind {
            LandmarkKind::Poster => TextureFamily::Poster,
            LandmarkKind::Sign => TextureFamily::Sign,
        };
        let mut m = Material::new(family, colour, [20, 20, 25], rng.next_u64());
        m.placement = Some(Placement {
            origin: [c0[0].min(c1[0]), c0[1].min(c1[1])],
            size: [(c1[0] - c0[0]).abs(), (c1[1] - c0[1]).abs()],
        });
        let id = self.add_material(m);
        for z in z0..z0 + h {
            for a in a0..a0 + w {
                let i = self.index(side.voxel(a, z));
                self.mats[i] = id;
            }
        }
        let front = side.front(a0, a0 + w, vox(0.8), [z0, z0 + h]);
        self.reserved[r].push(front);
        let mut centre = self.metres(side.voxel(a0, z0));
        let far = self.metres(side.voxel(a0 + w, z0 + h));
        for k in 0..3 {
            centre[k] = 0.5 * (centre[k] + far[k]);
        }
        // On the face plane: the wall layer's face towards the region.
        centre[side.axis] = (side.layer + usize::from(side.positive)) as f64 * vs;
        self.landmarks.push(Landmark {
            kind,
            region: r,
            centre,
            normal: side.normal(),
            size: [w as f64 * vs, h as f64 * vs],
            material: id,
        });
        true
    }

    /// Furniture of room `r`: `furniture_density` items per 10 m^2 (randomly rounded), each
    /// against a wall or free-standing with clearance, away from doors, posters and each other.
    fn furnish(&mut self, r: usize, pools: &Pools, rng: &mut SimRng) {
        if self.regions[r].kind != RegionKind::Room || pools.furniture.is_empty() {
            return;
        }
        let b = self.boxes[r];
        let vs = self.vs;
        let vox = |m: f64| vox(m, vs);
        let area = b.len(0) as f64 * b.len(1) as f64 * vs * vs;
        let expected = self.p.furniture_density * area / 10.0;
        let count = expected.floor() as usize + usize::from(rng.chance(expected.fract()));
        let kinds = &self.p.style.furniture;
        for _ in 0..count {
            let kind = *rng.pick(kinds).expect("kinds");
            let [sw, sd, sh] = kind.size();
            let (w, d) = (vox(rng.range(sw[0], sw[1])), vox(rng.range(sd[0], sd[1])));
            let h = if kind == FurnitureKind::Pillar {
                b.len(2)
            } else {
                vox(rng.range(sh[0], sh[1]))
            };
            for _ in 0..25 {
                let placed = if kind.against_wall() {
                    let side = Side::of(&b)[rng.below(4)];
                    if side.along[1] < side.along[0] + w + 2 {
                        continue;
                    }
                    let a0 = rng.between(side.along[0], side.along[1] - w);
                    let foot = side.front(a0, a0 + w, d, [b.lo[2], b.lo[2] + h]);
                    (foot.hi[0] <= b.hi[0]
                        && foot.hi[1] <= b.hi[1]
                        && foot.lo[0] >= b.lo[0]
                        && foot.lo[1] >= b.lo[1])
                        .then_some((foot, Some(side), vox(0.4)))
                } else {
                    let c = vox(0.7);
                    let (w, d) = if rng.chance(0.5) { (w, d) } else { (d, w) };
                    let (Some(xs), Some(ys)) =
                        (b.hi[0].checked_sub(c + w), b.hi[1].checked_sub(c + d))
                    else {
                        continue;
                    };
                    if xs < b.lo[0] + c || ys < b.lo[1] + c {
                        continue;
                    }
                    let (x, y) = (rng.between(b.lo[0] + c, xs), rng.between(b.lo[1] + c, ys));
                    Some((
                        VBox::new([x, y, b.lo[2]], [x + w, y + d, b.lo[2] + h]),
                        None,
                        vox(0.6),
                    ))
                };
                let Some((foot, side, margin)) = placed else {
                    continue;
                };
                let grown = foot.grow_xy(margin);
                if self.reserved[r].iter().any(|o| o.overlaps_xy(&grown)) {
                    continue;
                }
                let material = pools.furniture[&kind];
                self.build_item(kind, &foot, side, material, rng);
                self.reserved[r].push(foot);
                let (min, max) = (self.metres(foot.lo), self.metres(foot.hi));
                self.furniture.push(Furniture {
                    kind,
                    region: r,
                    min,
                    max,
                    material,
                });
                break;
            }
        }
    }

    /// Rasterises one item into the footprint box `f` (z from the floor to its height).
    fn build_item(
        &mut self,
        kind: FurnitureKind,
        f: &VBox,
        side: Option<Side>,
        material: u16,
        rng: &mut SimRng,
    ) {
        let vs = self.vs;
        let vox = |m: f64| vox(m, vs);
        let with_z = |b: &VBox, z0: usize, z1: usize| {
            VBox::new([b.lo[0], b.lo[1], z0], [b.hi[0], b.hi[1], z1])
        };
        let (z0, z1) = (f.lo[2], f.hi[2]);
        // The layer of the footprint against the wall, and the two ends along the wall.
        let back = |thick: usize| -> VBox {
            let s = side.expect("against a wall");
            let mut b = *f;
            let k = s.axis;
            if s.positive {
                b.hi[k] = b.lo[k] + thick;
            } else {
                b.lo[k] = b.hi[k] - thick;
            }
            b
        };
        match kind {
            FurnitureKind::Table => {
                let top = (z1 - 1).max(z0 + 1);
                self.fill(&with_z(f, top, top + 1), material);
                for (x, y) in [
                    (f.lo[0], f.lo[1]),
                    (f.hi[0] - 1, f.lo[1]),
                    (f.lo[0], f.hi[1] - 1),
                    (f.hi[0] - 1, f.hi[1] - 1),
                ] {
                    self.fill(&VBox::new([x, y, z0], [x + 1, y + 1, top]), material);
                }
            }
            FurnitureKind::Cabinet | FurnitureKind::Locker | FurnitureKind::Pillar => {
                self.fill(f, material)
            }
            FurnitureKind::Crate => {
                self.fill(f, material);
                if rng.chance(0.35) && f.len(0) >= 3 && f.len(1) >= 3 {
                    let top = VBox::new(
                        [f.lo[0] + 1, f.lo[1] + 1, z1],
                        [f.hi[0] - 1, f.hi[1] - 1, z1 + f.len(2) * 2 / 3],
                    );
                    self.fill(&top, material);
                }
            }
            FurnitureKind::Shelf => {
                self.fill(&back(1), material);
                let s = side.expect("shelf against a wall");
                let a = 1 - s.axis;
                for end in [f.lo[a], f.hi[a] - 1] {
                    let mut e = *f;
                    e.lo[a] = end;
                    e.hi[a] = end + 1;
                    self.fill(&e, material);
                }
                let step = vox(0.4);
                let mut z = z0;
                while z < z1 {
                    self.fill(&with_z(f, z, z + 1), material);
                    z += step;
                }
                self.fill(&with_z(f, z1 - 1, z1), material);
            }
            FurnitureKind::Sofa => {
                self.fill(&with_z(f, z0, z0 + vox(0.45)), material);
                let b = back(vox(0.2));
                self.fill(&with_z(&b, z0, z1), material);
            }
            FurnitureKind::Bed => {
                self.fill(&with_z(f, z0, z0 + vox(0.5)), material);
                let s = side.expect("bed against a wall");
                let a = 1 - s.axis;
                let mut head = *f;
                head.hi[a] = head.lo[a] + 1;
                self.fill(&with_z(&head, z0, z0 + vox(1.0)), material);
            }
        }
    }

    fn finish(self) -> Result<World, WorldError> {
        let vs = self.vs;
        let origin = Point3::new(0.0, 0.0, -(self.plan.ts as f64) * vs);
        let occupied = self.mats.iter().map(|&m| m != 0).collect();
        let grid = OccupancyGrid::new(self.plan.dims, vs, origin, occupied)?;
        let floor_z = (0..self.p.floors as usize)
            .map(|f| {
                let [z0, z1] = self.plan.z(f);
                [self.metres([0, 0, z0])[2], self.metres([0, 0, z1])[2]]
            })
            .collect();
        Ok(World {
            params: self.p.clone(),
            grid,
            materials: self.mats,
            material_table: self.table,
            floor_z,
            regions: self.regions,
            doors: self.doors,
            lamps: self.lamps,
            landmarks: self.landmarks,
            furniture: self.furniture,
            region_map: self.region_map,
        })
    }
}

/// `m` metres in voxels of `vs` metres, rounded, at least one.
fn vox(m: f64, vs: f64) -> usize {
    ((m / vs).round() as usize).max(1)
}
