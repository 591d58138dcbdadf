//! Procedural surface textures: deterministic square tiles with real high-frequency content.
//!
//! A [`Material`] names a [`TextureFamily`] (bricks, tiles, wood, wallpaper, posters, ...), two
//! colours and a seed; [`Texture::generate`] turns it into an RGB tile (256x256 texels, 128x128
//! for posters, signs and lamps) plus its mip levels, once per world. The renderer samples the
//! tile in world-space face coordinates ([`face_uv`]) at [`Material::texels_per_metre`]
//! (128 texels/m by default: a brick is 0.25 m x 0.125 m, a floor tile 0.5 m), so texture density
//! on screen does not depend on the voxel size. Tiles wrap seamlessly (every pattern period
//! divides the tile side). Landmarks (posters, signs) and lamps are not tiled: their
//! [`Placement`] maps the tile once onto their rectangle.
//!
//! Texel values are albedo (reflectance) in 8 bits per channel; lighting and the output gamma
//! are the renderer's business. Patterns use only integer hashes and [`crate::rng::SimRng`],
//! so a material gives the same texels on every platform.

use crate::rng::{hash3, hash_unit, SimRng};
use serde::{Deserialize, Serialize};
use std::f32::consts::TAU;

/// The kinds of surface patterns. Styles draw their surfaces from disjoint subsets (the
/// training style never shows the test style's families).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TextureFamily {
    /// Running-bond bricks with mortar joints (walls).
    Brick,
    /// Painted plaster: low-contrast mottling and speckles (walls, ceilings); nearly texture-less.
    Plaster,
    /// Vertical two-colour stripes with a small diamond motif (walls).
    StripeWallpaper,
    /// Vertical wooden boards with grain and seams (walls).
    WoodPanel,
    /// Large concrete blocks with pores and joints (walls).
    ConcreteBlock,
    /// Checkered square floor tiles (0.5 m) with grout.
    FloorTiles,
    /// Staggered wooden floor planks with grain.
    WoodFloor,
    /// Carpet: fine pile noise and a small grid.
    Carpet,
    /// Suspended ceiling: 0.6 m acoustic tiles with pinholes in a metal grid.
    CeilingTiles,
    /// Argyle diamonds with outlines (walls; test style).
    DiamondWallpaper,
    /// Hexagonal tiles with grout (walls, floors; test style).
    HexTiles,
    /// Veined marble (walls, floors; test style).
    Marble,
    /// Riveted metal panels (walls, ceilings; test style).
    MetalPanels,
    /// Basket-weave parquet (floors; test style).
    Parquet,
    /// Terrazzo: coloured chips in a binder (floors; test style).
    Terrazzo,
    /// Wood with grain (furniture).
    Wood,
    /// Painted metal sheet with seams, vents and handles (lockers, cabinets).
    Metal,
    /// Woven fabric (sofas, beds).
    Fabric,
    /// A unique poster: shapes and blocks of "text" on a coloured ground (landmark).
    Poster,
    /// A unique sign: a coloured plate with large "text" blocks and an arrow (landmark).
    Sign,
    /// A ceiling lamp's diffuser (emissive while the lamps are on).
    Lamp,
    /// Door frames, slab edges and other structural trim: plain paint.
    Trim,
}

impl TextureFamily {
    /// Every family.
    pub const ALL: [TextureFamily; 22] = [
        Self::Brick,
        Self::Plaster,
        Self::StripeWallpaper,
        Self::WoodPanel,
        Self::ConcreteBlock,
        Self::FloorTiles,
        Self::WoodFloor,
        Self::Carpet,
        Self::CeilingTiles,
        Self::DiamondWallpaper,
        Self::HexTiles,
        Self::Marble,
        Self::MetalPanels,
        Self::Parquet,
        Self::Terrazzo,
        Self::Wood,
        Self::Metal,
        Self::Fabric,
        Self::Poster,
        Self::Sign,
        Self::Lamp,
        Self::Trim,
    ];

    /// Tile side in texels (a power of two).
    pub fn tile_side(self) -> usize {
        match self {
            Self::Poster | Self::Sign | Self::Lamp => 128,
            _ => 256,
        }
    }

    /// Texels per metre of a tiled material of this family (128; 106.7 for ceiling tiles so
    /// that their grid is 0.6 m).
    pub fn default_texels_per_metre(self) -> f64 {
        match self {
            Self::CeilingTiles => 64.0 / 0.6,
            _ => 128.0,
        }
    }
}

/// Where a non-tiled texture lies on its face: the rectangle `origin .. origin + size` in the
/// face coordinates of [`face_uv`] (metres).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    /// Lower corner (u, v), metres.
    pub origin: [f64; 2],
    /// Extent along u and v, metres (positive).
    pub size: [f64; 2],
}

/// A surface material: what a voxel looks like.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    /// Pattern family.
    pub family: TextureFamily,
    /// Main colour (sRGB-ish 8-bit albedo).
    pub colour: [u8; 3],
    /// Second colour (mortar, grout, stripes, veins, ...).
    pub accent: [u8; 3],
    /// Seed of the pattern's random details.
    pub seed: u64,
    /// Texel density of the tile on the surface, texels per metre (ignored with a placement).
    pub texels_per_metre: f64,
    /// For landmarks and lamps: the rectangle the tile covers once; `None` tiles the face.
    pub placement: Option<Placement>,
}

impl Material {
    /// A tiled material with the family's default texel density.
    pub fn new(family: TextureFamily, colour: [u8; 3], accent: [u8; 3], seed: u64) -> Self {
        Self {
            family,
            colour,
            accent,
            seed,
            texels_per_metre: family.default_texels_per_metre(),
            placement: None,
        }
    }

    /// Whether the material emits light while the lamps are on (lamp diffusers).
    pub fn is_emissive(&self) -> bool {
        self.family == TextureFamily::Lamp
    }
}

/// Face coordinates (metres) of world point `p` lying on a voxel face whose normal is along
/// `axis` (0 = x, 1 = y, 2 = z), pointing to + when `positive`.
///
/// On walls u runs to the right of a viewer facing the wall and v upward from `floor_z` (the
/// floor surface of the storey), so patterns and posters are never mirrored and wall patterns
/// start at the floor; on floors and ceilings `(u, v) = (x, y)`.
pub fn face_uv(axis: usize, positive: bool, p: [f64; 3], floor_z: f64) -> [f64; 2] {
    let up = p[2] - floor_z;
    match (axis, positive) {
        (0, true) => [p[1], up],
        (0, false) => [-p[1], up],
        (1, true) => [-p[0], up],
        (1, false) => [p[0], up],
        _ => [p[0], p[1]],
    }
}

/// A square texture tile and its mip levels; texels packed as `r | g << 8 | b << 16`, the
/// levels one after the other in one buffer (level `l` starts at [`level_offset`]).
#[derive(Clone, Debug)]
pub struct Texture {
    side_log2: u32,
    level_count: u32,
    texels: Vec<u32>,
}

/// Where mip level `level` starts in the buffer of a texture of side `2^side_log2`: the sizes
/// of the levels before it, `n^2 + n^2/4 + ...`.
#[inline]
pub fn level_offset(side_log2: u32, level: u32) -> usize {
    let n2 = 1usize << (2 * side_log2);
    4 * (n2 - (n2 >> (2 * level))) / 3
}

impl Texture {
    /// Generates the tile of `material` (deterministic) and its box-filtered mip levels down to
    /// 4x4. Costs a few milliseconds per material in release builds.
    pub fn generate(material: &Material) -> Self {
        let n = material.family.tile_side();
        let mut canvas = Canvas::new(n, material);
        canvas.paint();
        let mut level: Vec<[f32; 3]> = canvas.px;
        let mut texels = pack(&level);
        let mut side = n;
        let mut level_count = 1;
        while side > 4 {
            let half = side / 2;
            let mut next = vec![[0.0f32; 3]; half * half];
            for t in 0..half {
                for s in 0..half {
                    let mut acc = [0.0f32; 3];
                    for (ds, dt) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let p = level[(2 * t + dt) * side + 2 * s + ds];
                        for c in 0..3 {
                            acc[c] += 0.25 * p[c];
                        }
                    }
                    next[t * half + s] = acc;
                }
            }
            texels.extend(pack(&next));
            level = next;
            side = half;
            level_count += 1;
        }
        Self {
            side_log2: n.trailing_zeros(),
            level_count,
            texels,
        }
    }

    /// Side of level 0, texels.
    pub fn side(&self) -> usize {
        1 << self.side_log2
    }

    /// log2 of the side of level 0.
    pub fn side_log2(&self) -> u32 {
        self.side_log2
    }

    /// Number of mip levels (level `l` has side `side() >> l`).
    pub fn level_count(&self) -> usize {
        self.level_count as usize
    }

    /// Every level's texels, level 0 first (see [`level_offset`]).
    pub fn texels(&self) -> &[u32] {
        &self.texels
    }

    /// The packed texel of mip `level` (clamped to the coarsest level) covering the level-0
    /// texel `(s, t)` (column, row; wrapping).
    #[inline]
    pub fn fetch(&self, level: usize, s: i32, t: i32) -> u32 {
        fetch(
            &self.texels,
            self.side_log2,
            self.level_count,
            level as u32,
            s,
            t,
        )
    }

    /// The RGB albedo at `(s, t)` of level 0 (wrapping).
    pub fn texel(&self, s: i32, t: i32) -> [u8; 3] {
        let p = self.fetch(0, s, t);
        [p as u8, (p >> 8) as u8, (p >> 16) as u8]
    }
}

/// [`Texture::fetch`] on a texture's buffer `texels` (all levels, see [`level_offset`]).
#[inline(always)]
pub fn fetch(texels: &[u32], side_log2: u32, level_count: u32, level: u32, s: i32, t: i32) -> u32 {
    let level = level.min(level_count - 1);
    let log = side_log2 - level;
    let mask = (1i32 << log) - 1;
    let (s, t) = (s >> level, t >> level);
    texels[level_offset(side_log2, level) + (((t & mask) << log) | (s & mask)) as usize]
}

fn pack(px: &[[f32; 3]]) -> Vec<u32> {
    px.iter()
        .map(|p| {
            let q = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u32;
            q(p[0]) | q(p[1]) << 8 | q(p[2]) << 16
        })
        .collect()
}

type Rgb = [f32; 3];

fn rgb(c: [u8; 3]) -> Rgb {
    [
        c[0] as f32 / 255.0,
        c[1] as f32 / 255.0,
        c[2] as f32 / 255.0,
    ]
}

fn scale(c: Rgb, k: f32) -> Rgb {
    [c[0] * k, c[1] * k, c[2] * k]
}

fn mix(a: Rgb, b: Rgb, t: f32) -> Rgb {
    [
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
    ]
}

/// A colour from hue (turns), saturation and value.
fn hsv(h: f32, s: f32, v: f32) -> Rgb {
    let h6 = h.rem_euclid(1.0) * 6.0;
    let f = |n: f32| {
        let k = (n + h6) % 6.0;
        v - v * s * k.min(4.0 - k).clamp(0.0, 1.0)
    };
    [f(5.0), f(3.0), f(1.0)]
}

/// Periodic value noise: a lattice of `cells x cells` random values over the tile, smoothly
/// interpolated; wraps with the tile.
struct Noise {
    cells: usize,
    values: Vec<f32>,
    per_texel: f32,
}

impl Noise {
    fn new(seed: u64, cells: usize, side: usize) -> Self {
        let values = (0..cells * cells)
            .map(|i| hash_unit(seed, (i % cells) as i64, (i / cells) as i64, cells as i64) as f32)
            .collect();
        Self {
            cells,
            values,
            per_texel: cells as f32 / side as f32,
        }
    }

    /// In [0, 1].
    fn at(&self, s: usize, t: usize) -> f32 {
        let x = s as f32 * self.per_texel;
        let y = t as f32 * self.per_texel;
        let (ix, iy) = (x.floor(), y.floor());
        let smooth = |f: f32| f * f * (3.0 - 2.0 * f);
        let (fx, fy) = (smooth(x - ix), smooth(y - iy));
        let n = self.cells;
        let (x0, y0) = (ix as usize % n, iy as usize % n);
        let (x1, y1) = ((x0 + 1) % n, (y0 + 1) % n);
        let v = |x: usize, y: usize| self.values[y * n + x];
        let top = v(x0, y0) + (v(x1, y0) - v(x0, y0)) * fx;
        let bottom = v(x0, y1) + (v(x1, y1) - v(x0, y1)) * fx;
        top + (bottom - top) * fy
    }
}

/// Fractal sum of [`Noise`] octaves (cells doubling), normalised to about [0, 1].
struct Fbm {
    octaves: Vec<Noise>,
}

impl Fbm {
    fn new(seed: u64, cells: usize, octaves: usize, side: usize) -> Self {
        Self {
            octaves: (0..octaves)
                .map(|o| Noise::new(seed.wrapping_add(o as u64 * 7919), cells << o, side))
                .collect(),
        }
    }

    fn at(&self, s: usize, t: usize) -> f32 {
        let (mut sum, mut norm, mut amp) = (0.0, 0.0, 1.0);
        for octave in &self.octaves {
            sum += amp * octave.at(s, t);
            norm += amp;
            amp *= 0.5;
        }
        sum / norm
    }
}

/// The tile being painted, in linear albedo.
struct Canvas {
    n: usize,
    px: Vec<Rgb>,
    seed: u64,
    base: Rgb,
    accent: Rgb,
    family: TextureFamily,
}

impl Canvas {
    fn new(n: usize, m: &Material) -> Self {
        Self {
            n,
            px: vec![[0.0; 3]; n * n],
            seed: m.seed,
            base: rgb(m.colour),
            accent: rgb(m.accent),
            family: m.family,
        }
    }

    /// Per-texel white noise in [0, 1).
    fn grain(&self, s: usize, t: usize, salt: i64) -> f32 {
        hash_unit(self.seed, s as i64, t as i64, salt) as f32
    }

    /// Sets every texel `(s, t)` from `f(self, s, t)`.
    fn fill(&mut self, f: impl Fn(&Canvas, usize, usize) -> Rgb) {
        let n = self.n;
        let px = (0..n * n).map(|i| f(self, i % n, i / n)).collect();
        self.px = px;
    }

    fn paint(&mut self) {
        use TextureFamily as F;
        match self.family {
            F::Brick => self.blocks(32, 16, 2, 0.5, 0.04),
            F::ConcreteBlock => self.blocks(64, 32, 2, 0.4, 0.03),
            F::Plaster => self.plaster(),
            F::StripeWallpaper => self.stripes(),
            F::WoodPanel => self.boards(32, true, true),
            F::Wood => self.boards(64, false, false),
            F::FloorTiles => self.tiles(),
            F::WoodFloor => self.planks(),
            F::Carpet => self.carpet(),
            F::CeilingTiles => self.ceiling_tiles(),
            F::DiamondWallpaper => self.diamonds(),
            F::HexTiles => self.hexagons(),
            F::Marble => self.marble(),
            F::MetalPanels => self.metal_panels(),
            F::Parquet => self.parquet(),
            F::Terrazzo => self.terrazzo(),
            F::Metal => self.sheet_metal(),
            F::Fabric => self.fabric(),
            F::Poster => self.poster(),
            F::Sign => self.sign(),
            F::Lamp => self.lamp(),
            F::Trim => self.trim(),
        }
    }

    /// Running-bond blocks `w x h` texels with `joint`-wide joints in the accent colour;
    /// `jitter` is the per-block brightness spread, `pores` the density of dark pits.
    fn blocks(&mut self, w: usize, h: usize, joint: usize, jitter: f32, pores: f32) {
        let (base, accent, seed) = (self.base, self.accent, self.seed);
        let fbm = Fbm::new(seed, 16, 3, self.n);
        let n = self.n;
        self.fill(|this, s, t| {
            let row = t / h;
            let ss = (s + (row % 2) * w / 2) % n;
            let col = ss / w;
            let (ls, lt) = (ss % w, t % h);
            let noise = fbm.at(s, t);
            if ls < joint || lt < joint {
                return scale(accent, 0.8 + 0.3 * noise);
            }
            let k = 1.0 - jitter / 2.0 + jitter * hash_unit(seed, row as i64, col as i64, 1) as f32;
            let tint = [
                0.92 + 0.16 * hash_unit(seed, row as i64, col as i64, 2) as f32,
                1.0,
                0.92 + 0.16 * hash_unit(seed, row as i64, col as i64, 3) as f32,
            ];
            let edge = if ls == joint || lt == joint { 0.8 } else { 1.0 };
            let pit = if this.grain(s, t, 4) < pores {
                0.55
            } else {
                1.0
            };
            let fine = 0.9 + 0.2 * this.grain(s, t, 5);
            let k = k * edge * pit * fine * (0.8 + 0.4 * noise);
            [
                base[0] * k * tint[0],
                base[1] * k * tint[1],
                base[2] * k * tint[2],
            ]
        });
    }

    fn plaster(&mut self) {
        let fbm = Fbm::new(self.seed, 8, 4, self.n);
        self.fill(|this, s, t| {
            let speck = if this.grain(s, t, 1) < 0.012 {
                0.7
            } else {
                1.0
            };
            scale(
                this.base,
                (0.8 + 0.3 * fbm.at(s, t)) * (0.95 + 0.06 * this.grain(s, t, 2)) * speck,
            )
        });
    }

    fn stripes(&mut self) {
        let fbm = Fbm::new(self.seed, 8, 3, self.n);
        self.fill(|this, s, t| {
            let (ls, lt) = (s % 32, t % 32);
            let mut c = if ls < 20 { this.base } else { this.accent };
            if ls == 0 || ls == 20 {
                c = scale(c, 0.6);
            } else if ls < 20 {
                let d = (ls as i32 - 10).abs() + (lt as i32 - 16).abs();
                if d < 5 {
                    c = scale(this.accent, 0.85);
                } else if d == 5 {
                    c = scale(this.base, 0.7);
                }
            }
            scale(
                c,
                (0.9 + 0.15 * fbm.at(s, t)) * (0.96 + 0.06 * this.grain(s, t, 1)),
            )
        });
    }

    /// Boards `width` texels wide; grain lines run along t when `vertical` (else along s);
    /// `seams` draws dark joints between boards.
    fn boards(&mut self, width: usize, vertical: bool, seams: bool) {
        let noise = Fbm::new(self.seed, 8, 3, self.n);
        self.fill(|this, s, t| {
            let (across, along) = if vertical { (s, t) } else { (t, s) };
            let board = across / width;
            let local = across % width;
            if seams && local < 2 {
                return scale(this.base, 0.35);
            }
            let phase = hash_unit(this.seed, board as i64, 0, 7) as f32;
            let warp = 3.0 * noise.at(s, t) + 0.02 * along as f32 * phase;
            let g = (TAU * (local as f32 * 0.16 + warp + phase)).sin();
            let tint = 0.85 + 0.3 * hash_unit(this.seed, board as i64, 0, 8) as f32;
            let k = tint * (0.62 + 0.38 * (0.5 + 0.5 * g)) * (0.94 + 0.1 * this.grain(s, t, 1));
            let knot = if this.grain(s / 4, t / 4, 2) < 0.004 {
                0.6
            } else {
                1.0
            };
            scale(
                mix(this.base, this.accent, 0.25 * (0.5 - 0.5 * g)),
                k * knot,
            )
        });
    }

    fn tiles(&mut self) {
        let fbm = Fbm::new(self.seed, 8, 3, self.n);
        self.fill(|this, s, t| {
            let (ls, lt) = (s % 64, t % 64);
            if ls < 3 || lt < 3 {
                return scale(this.accent, 0.85 + 0.2 * this.grain(s, t, 1));
            }
            let (ts, tt) = ((s / 64) as i64, (t / 64) as i64);
            let c = if (ts + tt) % 2 == 0 {
                this.base
            } else {
                scale(this.base, 0.62)
            };
            let k = 0.93 + 0.14 * hash_unit(this.seed, ts, tt, 2) as f32;
            let speck = if this.grain(s, t, 3) < 0.02 { 0.7 } else { 1.0 };
            scale(c, k * speck * (0.9 + 0.15 * fbm.at(s, t)))
        });
    }

    fn planks(&mut self) {
        let noise = Fbm::new(self.seed, 16, 2, self.n);
        self.fill(|this, s, t| {
            let row = t / 16;
            let offset = (hash_unit(this.seed, row as i64, 0, 1) * 128.0) as usize;
            let ss = (s + offset) % this.n;
            let plank = ss / 128;
            if t % 16 == 0 || ss.is_multiple_of(128) {
                return scale(this.base, 0.3);
            }
            let phase = hash_unit(this.seed, row as i64, plank as i64, 2) as f32;
            let g = (TAU * ((t % 16) as f32 * 0.22 + 2.5 * noise.at(s, t) + phase)).sin();
            let tint = 0.8 + 0.35 * hash_unit(this.seed, row as i64, plank as i64, 3) as f32;
            scale(
                mix(this.base, this.accent, 0.3 * (0.5 + 0.5 * g)),
                tint * (0.92 + 0.1 * this.grain(s, t, 4)),
            )
        });
    }

    fn carpet(&mut self) {
        let fbm = Fbm::new(self.seed, 16, 3, self.n);
        self.fill(|this, s, t| {
            let pile = 0.65 + 0.45 * this.grain(s, t, 1);
            let grid = s % 16 < 2 || t % 16 < 2;
            let c = if grid { this.accent } else { this.base };
            scale(c, pile * (0.8 + 0.3 * fbm.at(s, t)))
        });
    }

    fn ceiling_tiles(&mut self) {
        let fbm = Fbm::new(self.seed, 8, 2, self.n);
        self.fill(|this, s, t| {
            let (ls, lt) = (s % 64, t % 64);
            if ls < 2 || lt < 2 {
                return this.accent;
            }
            if ls == 2 || lt == 2 {
                return scale(this.base, 0.7);
            }
            let hole = if this.grain(s, t, 1) < 0.05 {
                0.55
            } else {
                1.0
            };
            scale(this.base, hole * (0.88 + 0.15 * fbm.at(s, t)))
        });
    }

    fn diamonds(&mut self) {
        let fbm = Fbm::new(self.seed, 8, 2, self.n);
        self.fill(|this, s, t| {
            let ds = ((s % 32) as f32 - 16.0).abs() / 16.0;
            let dt = ((t % 64) as f32 - 32.0).abs() / 32.0;
            let d = ds + dt;
            let c = if d < 0.82 {
                let inner = if d < 0.35 { 0.75 } else { 1.0 };
                scale(this.base, inner)
            } else if d < 0.95 {
                scale(this.accent, 0.35)
            } else {
                this.accent
            };
            scale(c, 0.9 + 0.15 * fbm.at(s, t))
        });
    }

    fn hexagons(&mut self) {
        // Voronoi cells of an offset lattice (32 x 32 texels, odd rows shifted by 16): hexagons.
        let fbm = Fbm::new(self.seed, 8, 2, self.n);
        let (n, cell) = (self.n as i64, 32i64);
        let cells = n / cell;
        self.fill(|this, s, t| {
            let (s, t) = (s as i64, t as i64);
            let (cx, cy) = (s / cell, t / cell);
            let mut best = (f32::MAX, 0i64, 0i64);
            let mut second = f32::MAX;
            for gy in cy - 1..=cy + 1 {
                for gx in cx - 1..=cx + 1 {
                    let px =
                        gx * cell + cell / 2 + if gy.rem_euclid(2) == 1 { cell / 2 } else { 0 };
                    let py = gy * cell + cell / 2;
                    let d = (((s - px) * (s - px) + (t - py) * (t - py)) as f32).sqrt();
                    if d < best.0 {
                        second = best.0;
                        best = (d, gx.rem_euclid(cells), gy.rem_euclid(cells));
                    } else if d < second {
                        second = d;
                    }
                }
            }
            if second - best.0 < 2.5 {
                return scale(
                    this.accent,
                    0.8 + 0.2 * this.grain(s as usize, t as usize, 1),
                );
            }
            let pick = hash_unit(this.seed, best.1, best.2, 2) as f32;
            let c = if pick < 0.3 {
                scale(this.base, 0.55)
            } else {
                this.base
            };
            scale(
                c,
                (0.75 + 0.5 * pick) * (0.92 + 0.12 * fbm.at(s as usize, t as usize)),
            )
        });
    }

    fn marble(&mut self) {
        let turbulence = Fbm::new(self.seed, 4, 5, self.n);
        let n = self.n as f32;
        self.fill(|this, s, t| {
            let (x, y) = (s as f32 / n, t as f32 / n);
            let vein = (TAU * (2.0 * x + y + 2.5 * turbulence.at(s, t)))
                .sin()
                .abs();
            let v = vein.powf(0.3);
            scale(
                mix(this.accent, this.base, v),
                0.95 + 0.08 * this.grain(s, t, 1),
            )
        });
    }

    fn metal_panels(&mut self) {
        self.fill(|this, s, t| {
            let (ls, lt) = (s % 64, t % 64);
            if ls < 2 || lt < 2 {
                return scale(this.base, 0.35);
            }
            for (rx, ry) in [(7, 7), (57, 7), (7, 57), (57, 57), (32, 7), (32, 57)] {
                let d2 = (ls as i32 - rx).pow(2) + (lt as i32 - ry).pow(2);
                if d2 <= 4 {
                    return scale(this.accent, 1.2);
                }
                if d2 <= 9 {
                    return scale(this.base, 0.45);
                }
            }
            let brushed = 0.9 + 0.12 * hash_unit(this.seed, t as i64, (s / 32) as i64, 1) as f32;
            scale(this.base, brushed * (0.95 + 0.06 * this.grain(s, t, 2)))
        });
    }

    fn parquet(&mut self) {
        let noise = Fbm::new(self.seed, 16, 2, self.n);
        self.fill(|this, s, t| {
            let (bx, by) = (s / 32, t / 32);
            let (ls, lt) = (s % 32, t % 32);
            let flip = (bx + by) % 2 == 1;
            let (across, along) = if flip { (lt, ls) } else { (ls, lt) };
            let plank = across / 8;
            if across % 8 == 0 || along == 0 {
                return scale(this.base, 0.35);
            }
            let id = (bx * 4 + plank) as i64;
            let tint = 0.8 + 0.35 * hash_unit(this.seed, id, by as i64, 1) as f32;
            let g = (TAU * ((across % 8) as f32 * 0.3 + 2.0 * noise.at(s, t))).sin();
            scale(mix(this.base, this.accent, 0.3 * (0.5 + 0.5 * g)), tint)
        });
    }

    fn terrazzo(&mut self) {
        // Chips: one jittered point per 8x8 cell, a disc of random radius and colour.
        let (n, cell) = (self.n as i64, 8i64);
        let cells = n / cell;
        let fbm = Fbm::new(self.seed, 8, 2, self.n);
        self.fill(|this, s, t| {
            let (si, ti) = (s as i64, t as i64);
            for gy in ti / cell - 1..=ti / cell + 1 {
                for gx in si / cell - 1..=si / cell + 1 {
                    let (kx, ky) = (gx.rem_euclid(cells), gy.rem_euclid(cells));
                    let h = hash3(this.seed, kx, ky, 1);
                    let px = gx * cell + (h & 7) as i64;
                    let py = gy * cell + ((h >> 3) & 7) as i64;
                    let r = 1.5 + ((h >> 6) & 7) as f32 * 0.35;
                    let d2 = ((si - px).pow(2) + (ti - py).pow(2)) as f32;
                    if d2 <= r * r {
                        return match (h >> 9) % 4 {
                            0 => this.accent,
                            1 => [0.12, 0.12, 0.13],
                            2 => [0.92, 0.92, 0.9],
                            _ => scale(this.base, 0.55),
                        };
                    }
                }
            }
            scale(this.base, 0.9 + 0.15 * fbm.at(s, t))
        });
    }

    fn sheet_metal(&mut self) {
        self.fill(|this, s, t| {
            let (ls, lt) = (s % 64, t % 128);
            if ls < 2 {
                return scale(this.base, 0.3);
            }
            let vent = (8..40).contains(&ls) && lt % 8 < 3 && (12..40).contains(&lt);
            let handle = (52..56).contains(&ls) && (60..76).contains(&lt);
            if vent || handle {
                return scale(this.accent, 0.4);
            }
            let brushed = 0.9 + 0.1 * hash_unit(this.seed, t as i64, 0, 1) as f32;
            scale(this.base, brushed * (0.95 + 0.06 * this.grain(s, t, 2)))
        });
    }

    fn fabric(&mut self) {
        let fbm = Fbm::new(self.seed, 8, 3, self.n);
        self.fill(|this, s, t| {
            let weave = if (s / 2 + t / 2) % 2 == 0 { 0.88 } else { 1.05 };
            let stripe = s % 48 < 6;
            let c = if stripe { this.accent } else { this.base };
            scale(c, weave * (0.8 + 0.3 * fbm.at(s, t)))
        });
    }

    fn trim(&mut self) {
        let fbm = Fbm::new(self.seed, 8, 2, self.n);
        self.fill(|this, s, t| {
            scale(
                this.base,
                (0.9 + 0.12 * fbm.at(s, t)) * (0.96 + 0.06 * this.grain(s, t, 1)),
            )
        });
    }

    fn lamp(&mut self) {
        let n = self.n;
        let accent = self.accent;
        self.fill(|_, s, t| {
            let edge = s.min(t).min(n - 1 - s).min(n - 1 - t);
            if edge < 10 {
                accent
            } else if s % 24 < 2 || t % 24 < 2 {
                [0.85, 0.84, 0.8]
            } else {
                [1.0, 0.97, 0.9]
            }
        });
    }

    /// Fills the axis-aligned rectangle `[s0, s1) x [t0, t1)` (clipped to the tile).
    fn rect(&mut self, s0: i64, t0: i64, s1: i64, t1: i64, c: Rgb) {
        let n = self.n as i64;
        for t in t0.max(0)..t1.min(n) {
            for s in s0.max(0)..s1.min(n) {
                self.px[(t * n + s) as usize] = c;
            }
        }
    }

    /// Fills the texels where `inside(s, t)` within the bounding box `[s0, s1) x [t0, t1)`.
    fn shape(&mut self, bbox: [i64; 4], c: Rgb, inside: impl Fn(f32, f32) -> bool) {
        let n = self.n as i64;
        for t in bbox[1].max(0)..bbox[3].min(n) {
            for s in bbox[0].max(0)..bbox[2].min(n) {
                if inside(s as f32 + 0.5, t as f32 + 0.5) {
                    self.px[(t * n + s) as usize] = c;
                }
            }
        }
    }

    /// Rows of "words" (blocks of random widths) between `s0` and `s1`, starting at row `t0`,
    /// `height` texels high, `rows` lines.
    #[allow(clippy::too_many_arguments)]
    fn text(
        &mut self,
        rng: &mut SimRng,
        s0: i64,
        s1: i64,
        t0: i64,
        height: i64,
        rows: usize,
        c: Rgb,
    ) {
        let gap = (height / 2).max(2);
        for row in 0..rows as i64 {
            let t = t0 + row * (height + gap);
            let mut s = s0 + if row > 0 { 0 } else { rng.below(4) as i64 };
            let end = s1 - rng.below(((s1 - s0) / 3).max(1) as usize) as i64;
            while s < end {
                let w = (height as f64 * rng.range(0.8, 3.5)) as i64;
                self.rect(s, t, (s + w).min(end), t + height, c);
                s += w + gap;
            }
        }
    }

    fn poster(&mut self) {
        let mut rng = SimRng::new(self.seed);
        let n = self.n as i64;
        let hue = rng.unit() as f32;
        let ground = mix(hsv(hue, 0.5, 0.9), [1.0; 3], rng.range(0.1, 0.6) as f32);
        let ink = if rng.chance(0.7) {
            [0.08, 0.08, 0.1]
        } else {
            hsv(hue + 0.5, 0.8, 0.35)
        };
        self.fill(|_, _, _| ground);
        self.rect(0, 0, n, n, scale(ground, 0.3));
        self.rect(4, 4, n - 4, n - 4, ground);
        let shapes = rng.between(3, 7);
        for _ in 0..shapes {
            let c = hsv(
                rng.unit() as f32,
                rng.range(0.5, 1.0) as f32,
                rng.range(0.3, 0.95) as f32,
            );
            let (cx, cy) = (rng.range(20.0, 108.0) as f32, rng.range(32.0, 96.0) as f32);
            let r = rng.range(6.0, 26.0) as f32;
            let bbox = [
                (cx - r) as i64,
                (cy - r) as i64,
                (cx + r + 1.0) as i64,
                (cy + r + 1.0) as i64,
            ];
            match rng.below(3) {
                0 => self.shape(bbox, c, |s, t| (s - cx).powi(2) + (t - cy).powi(2) <= r * r),
                1 => {
                    let a = rng.range(0.4, 1.0) as f32;
                    self.shape(bbox, c, |s, t| {
                        (s - cx).abs() <= r && (t - cy).abs() <= r * a
                    })
                }
                _ => self.shape(bbox, c, |s, t| {
                    let dy = (t - (cy - r)) / (2.0 * r);
                    (0.0..=1.0).contains(&dy) && (s - cx).abs() <= r * dy
                }),
            }
        }
        let title = rng.between(1, 2);
        self.text(&mut rng, 10, n - 10, 10, 7, title, ink);
        let body = rng.between(2, 5);
        self.text(&mut rng, 10, n - 10, n - 12 - body as i64 * 5, 3, body, ink);
    }

    fn sign(&mut self) {
        let mut rng = SimRng::new(self.seed);
        let n = self.n as i64;
        let plate = scale(self.base, rng.range(0.6, 1.0) as f32);
        let ink = [0.95, 0.95, 0.92];
        self.fill(|_, _, _| ink);
        self.rect(4, 8, n - 4, n - 8, plate);
        let arrow_left = rng.chance(0.5);
        // The tile covers a wide, short plate, so shapes are drawn tall (the tile is squashed).
        let (ax0, ax1) = if arrow_left {
            (10, 34)
        } else {
            (n - 34, n - 10)
        };
        let (tip, back) = if arrow_left {
            (ax0 as f32, ax1 as f32)
        } else {
            (ax1 as f32, ax0 as f32)
        };
        self.shape([ax0, 24, ax1, 104], ink, move |s, t| {
            let along = (s - tip) / (back - tip);
            let head = along < 0.5 && (t - 64.0).abs() <= 80.0 * along;
            let shaft = along >= 0.5 && (t - 64.0).abs() <= 10.0;
            head || shaft
        });
        let (s0, s1) = if arrow_left {
            (42, n - 10)
        } else {
            (10, n - 42)
        };
        let rows = rng.between(1, 2);
        self.text(&mut rng, s0, s1, 28, 26, rows, ink);
        let pictogram = rng.below(3);
        let (cx, cy) = (if arrow_left { n - 22 } else { 22 } as f32, 96.0);
        if pictogram == 0 {
            self.shape([0, 80, n, 112], ink, |s, t| {
                ((s - cx) / 8.0).powi(2) + ((t - cy) / 14.0).powi(2) <= 1.0
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn contrast(tex: &Texture) -> f64 {
        let n = tex.side() as i32;
        let lum = |s, t| {
            let p = tex.texel(s, t);
            p[0] as f64 + p[1] as f64 + p[2] as f64
        };
        let mut sum = 0.0;
        for t in 0..n {
            for s in 0..n {
                sum += (lum(s, t) - lum(s + 1, t)).abs();
            }
        }
        sum / (n * n) as f64
    }

    #[test]
    fn every_family_has_texture_and_is_deterministic() {
        for (i, family) in TextureFamily::ALL.into_iter().enumerate() {
            let m = Material::new(family, [170, 120, 90], [220, 215, 200], i as u64);
            let a = Texture::generate(&m);
            let b = Texture::generate(&m);
            assert_eq!(a.texels, b.texels, "{family:?} deterministic");
            assert_eq!(a.side(), family.tile_side());
            assert_eq!(a.side() >> (a.level_count() - 1), 4);
            let c = contrast(&a);
            assert!(c > 2.0, "{family:?}: mean neighbour difference {c}");
            let other = Texture::generate(&Material { seed: 99, ..m });
            if matches!(family, TextureFamily::Poster | TextureFamily::Sign) {
                assert_ne!(a.texels, other.texels, "{family:?} unique per seed");
            }
        }
    }

    #[test]
    fn face_coordinates_run_to_the_viewers_right() {
        let p = [1.0, 2.0, 3.5];
        assert_eq!(face_uv(0, true, p, 1.0), [2.0, 2.5]);
        assert_eq!(face_uv(0, false, p, 1.0), [-2.0, 2.5]);
        assert_eq!(face_uv(1, true, p, 0.0), [-1.0, 3.5]);
        assert_eq!(face_uv(1, false, p, 0.0), [1.0, 3.5]);
        assert_eq!(face_uv(2, true, p, 0.0), [1.0, 2.0]);
    }
}
