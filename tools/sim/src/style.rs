//! World styles and the dataset splits they define.
//!
//! A [`Style`] is everything about a world that a seed does not pick at random: the texture
//! families its walls, floors and ceilings are drawn from, its colour palette, its furniture
//! kinds, how few distinct surface materials a world reuses (perceptual aliasing), and the
//! ranges its layout parameters are drawn from ([`LayoutRanges`]).
//!
//! Two styles exist. [`Style::office`] (training): bricks, plaster, striped wallpaper, wood
//! panels and concrete blocks over tiles, wooden floors and carpet, acoustic ceilings, warm
//! colours, tables, cabinets, shelves, sofas and crates, 2.7 m ceilings, 1.8-2.4 m corridors.
//! [`Style::lab`] (test): none of those surfaces, but argyle wallpaper, hexagonal tiles, marble and
//! metal panels over parquet and terrazzo, cool saturated colours, lockers, beds, pillars and
//! crates, 3.2 m ceilings, wider corridors and larger rooms.
//!
//! The splits of the seed (§4.4.3) follow from them ([`Split`]): `Train` worlds; `TrT`, the same
//! worlds as `Train` flown along new trajectories; `TrA`, new worlds (new seeds) of the training
//! style; `Test`, worlds of the unseen style.

use crate::rng::mix64;
use crate::texture::TextureFamily;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Kinds of furniture and objects a world may hold (sizes in [`FurnitureKind::size`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FurnitureKind {
    /// A free-standing table on four legs (0.75 m).
    Table,
    /// A solid cabinet against a wall.
    Cabinet,
    /// An open shelf against a wall: back, sides and boards, open front.
    Shelf,
    /// A free-standing crate or box, sometimes stacked.
    Crate,
    /// A sofa against a wall: seat and back.
    Sofa,
    /// A free-standing square pillar from floor to ceiling.
    Pillar,
    /// A bed along a wall, with a headboard.
    Bed,
    /// A row of metal lockers against a wall.
    Locker,
}

impl FurnitureKind {
    /// Every kind.
    pub const ALL: [FurnitureKind; 8] = [
        Self::Table,
        Self::Cabinet,
        Self::Shelf,
        Self::Crate,
        Self::Sofa,
        Self::Pillar,
        Self::Bed,
        Self::Locker,
    ];

    /// Size ranges in metres: `[[width lo, hi], [depth lo, hi], [height lo, hi]]`, width along
    /// the wall for items placed against one (a pillar's height is the room's).
    pub fn size(self) -> [[f64; 2]; 3] {
        match self {
            Self::Table => [[1.0, 1.6], [0.6, 0.9], [0.75, 0.75]],
            Self::Cabinet => [[0.8, 1.2], [0.4, 0.6], [1.0, 1.9]],
            Self::Shelf => [[0.8, 1.6], [0.3, 0.4], [1.8, 2.1]],
            Self::Crate => [[0.4, 0.8], [0.4, 0.8], [0.4, 0.8]],
            Self::Sofa => [[1.6, 2.2], [0.8, 0.9], [0.85, 0.85]],
            Self::Pillar => [[0.3, 0.5], [0.3, 0.5], [0.0, 0.0]],
            Self::Bed => [[1.9, 2.1], [0.9, 1.0], [0.5, 0.5]],
            Self::Locker => [[0.9, 2.0], [0.5, 0.5], [1.8, 1.8]],
        }
    }

    /// Whether the item stands against a wall (else free-standing, away from walls).
    pub fn against_wall(self) -> bool {
        !matches!(self, Self::Table | Self::Crate | Self::Pillar)
    }

    /// The texture family of its surface.
    pub fn family(self) -> TextureFamily {
        match self {
            Self::Table | Self::Cabinet | Self::Shelf | Self::Crate => TextureFamily::Wood,
            Self::Sofa | Self::Bed => TextureFamily::Fabric,
            Self::Locker => TextureFamily::Metal,
            Self::Pillar => TextureFamily::Trim,
        }
    }
}

/// Ranges a world's layout parameters are drawn from (see [`WorldParams::from_style`](crate::world::WorldParams::from_style)).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LayoutRanges {
    /// Storeys, inclusive range.
    pub floors: [u32; 2],
    /// Rooms per storey, inclusive range.
    pub rooms_per_floor: [u32; 2],
    /// Room side lengths, metres: `[min, max]` (copied into the world's parameters).
    pub room_size: [f64; 2],
    /// Corridor width, metres, range.
    pub corridor_width: [f64; 2],
    /// Floor-to-ceiling height, metres, range.
    pub ceiling_height: [f64; 2],
    /// Door width, metres.
    pub door_width: f64,
    /// Furniture items per 10 m^2 of room floor.
    pub furniture_density: f64,
    /// Probability that a room wall (or a 6 m stretch of corridor wall) holds a landmark.
    pub landmark_probability: f64,
}

/// The look and layout family of a world (see the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Style {
    /// Short name (`office`, `lab`, or a user's).
    pub name: String,
    /// Families room and corridor walls are drawn from.
    pub wall_families: Vec<TextureFamily>,
    /// Families floors are drawn from.
    pub floor_families: Vec<TextureFamily>,
    /// Families ceilings are drawn from.
    pub ceiling_families: Vec<TextureFamily>,
    /// Base colours of surfaces and furniture (sRGB-ish 8-bit albedo); at least two.
    pub palette: Vec<[u8; 3]>,
    /// Furniture kinds rooms are furnished with (may be empty: bare rooms).
    pub furniture: Vec<FurnitureKind>,
    /// Distinct wall materials per world, shared by all its rooms: the lower, the more rooms
    /// look alike (perceptual aliasing). Floors and ceilings get about half as many.
    pub wall_materials: u32,
    /// Ranges the layout parameters are drawn from.
    pub layout: LayoutRanges,
}

impl Style {
    /// The training style: an office building (see the module documentation).
    pub fn office() -> Self {
        use TextureFamily as F;
        Self {
            name: "office".into(),
            wall_families: vec![
                F::Brick,
                F::Plaster,
                F::StripeWallpaper,
                F::WoodPanel,
                F::ConcreteBlock,
            ],
            floor_families: vec![F::FloorTiles, F::WoodFloor, F::Carpet],
            ceiling_families: vec![F::CeilingTiles, F::Plaster],
            palette: vec![
                [196, 160, 120],
                [170, 92, 70],
                [222, 208, 180],
                [150, 120, 90],
                [200, 190, 160],
                [120, 130, 100],
                [180, 150, 130],
                [235, 225, 205],
            ],
            furniture: vec![
                FurnitureKind::Table,
                FurnitureKind::Cabinet,
                FurnitureKind::Shelf,
                FurnitureKind::Sofa,
                FurnitureKind::Crate,
            ],
            wall_materials: 4,
            layout: LayoutRanges {
                floors: [1, 2],
                rooms_per_floor: [5, 10],
                room_size: [3.5, 7.0],
                corridor_width: [1.8, 2.4],
                ceiling_height: [2.7, 2.7],
                door_width: 1.0,
                furniture_density: 1.0,
                landmark_probability: 0.5,
            },
        }
    }

    /// The test style: a laboratory / hospital building with unseen surfaces, colours,
    /// furniture and proportions (see the module documentation).
    pub fn lab() -> Self {
        use TextureFamily as F;
        Self {
            name: "lab".into(),
            wall_families: vec![F::DiamondWallpaper, F::HexTiles, F::Marble, F::MetalPanels],
            floor_families: vec![F::Parquet, F::Terrazzo, F::HexTiles],
            ceiling_families: vec![F::MetalPanels, F::Marble],
            palette: vec![
                [90, 150, 190],
                [200, 220, 230],
                [80, 170, 140],
                [230, 230, 240],
                [150, 110, 180],
                [60, 90, 130],
                [210, 190, 90],
            ],
            furniture: vec![
                FurnitureKind::Locker,
                FurnitureKind::Bed,
                FurnitureKind::Pillar,
                FurnitureKind::Crate,
                FurnitureKind::Table,
            ],
            wall_materials: 3,
            layout: LayoutRanges {
                floors: [1, 2],
                rooms_per_floor: [4, 8],
                room_size: [4.5, 9.0],
                corridor_width: [2.6, 3.2],
                ceiling_height: [3.2, 3.2],
                door_width: 1.4,
                furniture_density: 0.8,
                landmark_probability: 0.5,
            },
        }
    }

    /// The style called `name` (`office` or `lab`).
    pub fn by_name(name: &str) -> Option<Self> {
        match name {
            "office" => Some(Self::office()),
            "lab" => Some(Self::lab()),
            _ => None,
        }
    }
}

/// A split of the dataset (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Split {
    /// Training worlds and trajectories.
    Train,
    /// The training worlds, new trajectories.
    TrT,
    /// New worlds of the training style.
    TrA,
    /// Worlds of the unseen test style.
    Test,
}

impl Split {
    /// Every split.
    pub const ALL: [Split; 4] = [Self::Train, Self::TrT, Self::TrA, Self::Test];

    /// Its name: `train`, `tr-t`, `tr-a`, `test`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Train => "train",
            Self::TrT => "tr-t",
            Self::TrA => "tr-a",
            Self::Test => "test",
        }
    }

    /// The style of its worlds: [`Style::office`] except for `Test` ([`Style::lab`]).
    pub fn style(self) -> Style {
        match self {
            Self::Test => Style::lab(),
            _ => Style::office(),
        }
    }

    /// The seed of world `k`: `Train` and `TrT` share their worlds; `TrA` and `Test` draw from
    /// their own seed ranges (`(1 | 2 | 3) << 32 | k`), which never overlap.
    pub fn world_seed(self, k: u32) -> u64 {
        let range: u64 = match self {
            Self::Train | Self::TrT => 1,
            Self::TrA => 2,
            Self::Test => 3,
        };
        range << 32 | k as u64
    }

    /// A seed for trajectory `i` in world `k`, different for every split (so `TrT` flies new
    /// paths through the `Train` worlds).
    pub fn trajectory_seed(self, k: u32, i: u32) -> u64 {
        let tag = self as u64 + 1;
        mix64(mix64(self.world_seed(k) ^ tag << 56) ^ i as u64)
    }
}

impl fmt::Display for Split {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Split {
    type Err = String;

    /// Parses a split name (case-insensitive; `trt`/`tra` and `_` for `-` accepted).
    fn from_str(s: &str) -> Result<Self, String> {
        let key = s.to_ascii_lowercase().replace('_', "-");
        match key.as_str() {
            "train" => Ok(Self::Train),
            "tr-t" | "trt" => Ok(Self::TrT),
            "tr-a" | "tra" => Ok(Self::TrA),
            "test" => Ok(Self::Test),
            _ => Err(format!(
                "split `{s}` is unknown: expected train, tr-t, tr-a or test"
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_give_the_documented_styles_and_seeds() {
        assert_eq!(Split::Train.world_params(3), Split::TrT.world_params(3));
        assert_ne!(Split::Train.world_seed(3), Split::TrA.world_seed(3));
        assert_eq!(Split::TrA.style(), Style::office());
        assert_eq!(Split::Test.style(), Style::lab());
        assert_ne!(
            Split::Train.trajectory_seed(3, 0),
            Split::TrT.trajectory_seed(3, 0)
        );
        let train = Style::office();
        let test = Style::lab();
        for f in test
            .wall_families
            .iter()
            .chain(&test.floor_families)
            .chain(&test.ceiling_families)
        {
            assert!(
                !train.wall_families.contains(f)
                    && !train.floor_families.contains(f)
                    && !train.ceiling_families.contains(f),
                "{f:?} seen in training"
            );
        }
        assert!(test.palette.iter().all(|c| !train.palette.contains(c)));
        for split in Split::ALL {
            assert_eq!(split.name().parse::<Split>(), Ok(split));
            assert!(split.world_params(0).validate().is_ok());
        }
        assert!("nope".parse::<Split>().unwrap_err().contains("nope"));
    }
}
