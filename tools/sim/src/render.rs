//! A CPU ray caster for [`World`]s: textured voxels, ceiling lamps, a head light, and camera
//! conditions (exposure, white balance, sensor noise, motion blur).
//!
//! [`Renderer::new`] precomputes, once per world: the texture tiles of every material (shared
//! between materials that differ only in placement), a Chebyshev distance field over the voxels
//! (for empty-space skipping), and the lamps that light each region. [`Renderer::render`] then
//! casts one ray per pixel through the pixel centre ([`Intrinsics::ray`]):
//!
//! - Traversal: from the current voxel, whose distance field value `d` says that every voxel
//!   within Chebyshev distance `d - 1` is free, the ray jumps straight to the exit of that free
//!   cube (a plain Amanatides-Woo step when `d = 1`), until it enters an occupied voxel. The
//!   entry face gives the normal.
//! - Texture: the hit point's face coordinates ([`face_uv`]) at the material's texel density,
//!   nearest texel of the mip level matching the pixel footprint (distance / focal length,
//!   widened at grazing angles), so far walls do not alias.
//! - Light: `albedo * (ambient * face factor + lamps + head light)`. Lamps are point lights
//!   with inverse-square falloff and a cosine term, smoothly cut off at 8 m; a surface is lit by
//!   the lamps of the region in front of it (a room's own lamps; for corridors, every corridor
//!   lamp of the storey in range), so light does not leak through walls, and no shadows are
//!   cast. The head light is a cone from the camera along its optical axis (night). Lamp
//!   diffusers glow while the lamps are on. Faces get a fixed factor per orientation (floor 1.0,
//!   x walls 0.9, y walls 0.85, ceiling 0.8) so corners read even under flat ambient light.
//! - Camera: optional horizontal box blur over `motion_blur_px` pixels (linear light), gain and
//!   per-channel white balance, a 1/2.2 gamma to 8 bits, then additive approximately Gaussian
//!   noise of `noise_sigma` grey levels drawn from the frame's seed.
//!
//! A render is single-threaded and deterministic given the world, pose, intrinsics, condition
//! and seed; callers parallelise across frames (the renderer is `Sync`). Its time per frame:
//! `cargo bench -p topoloc-sim --bench render` (about half traversal, half shading).

use crate::camera::{Intrinsics, Pose};
use crate::rng::SimRng;
use crate::texture::{face_uv, fetch, Material, Texture, TextureFamily};
use crate::world::{RegionKind, World, NO_REGION};
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::Path;

/// Lamps stop lighting at this distance, metres (smooth window, see the module docs).
pub const LAMP_RANGE: f32 = 8.0;

/// Radiance scale of a lamp diffuser while the lamps are on (saturates to white at gain 1).
const EMISSIVE_GAIN: f32 = 1.6;

/// Most traversal steps per ray (never reached in a closed world).
const MAX_STEPS: usize = 4096;

/// Errors of rendering and image output.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A condition knob is out of range; `field` names it as in [`Condition`].
    #[error("condition `{field}`: {message}")]
    InvalidCondition {
        /// The knob, e.g. `noise_sigma`.
        field: &'static str,
        /// What is wrong and the accepted range.
        message: String,
    },
    /// The intrinsics are invalid (the message names the field).
    #[error("{0}")]
    InvalidIntrinsics(String),
    /// The image could not be converted or written.
    #[error("image output: {0}")]
    Image(#[from] opencv::Error),
    /// The image could not be written to `path`.
    #[error("could not write {path}")]
    Write {
        /// Where.
        path: String,
    },
}

/// A packed 8-bit RGB image, rows top to bottom, no padding.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `width * height * 3` bytes, R G B per pixel.
    pub rgb: Vec<u8>,
}

impl Image {
    /// A black image.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            rgb: vec![0; width as usize * height as usize * 3],
        }
    }

    /// The pixel at column `x`, row `y` (panics outside the image).
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    /// Sets the pixel at column `x`, row `y` (panics outside the image).
    pub fn set_pixel(&mut self, x: u32, y: u32, c: [u8; 3]) {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        self.rgb[i..i + 3].copy_from_slice(&c);
    }

    /// Grey levels (ITU-R BT.601 luma), one byte per pixel.
    pub fn to_gray(&self) -> Vec<u8> {
        self.rgb
            .chunks_exact(3)
            .map(|p| {
                ((299 * p[0] as u32 + 587 * p[1] as u32 + 114 * p[2] as u32 + 500) / 1000) as u8
            })
            .collect()
    }

    /// An owned OpenCV matrix, 8-bit BGR (OpenCV's channel order).
    pub fn to_bgr_mat(&self) -> Result<opencv::core::Mat, RenderError> {
        use opencv::core::{Mat, CV_8UC3};
        use opencv::prelude::*;
        let mut bgr = self.rgb.clone();
        for p in bgr.chunks_exact_mut(3) {
            p.swap(0, 2);
        }
        let mut mat = Mat::new_rows_cols_with_default(
            self.height as i32,
            self.width as i32,
            CV_8UC3,
            opencv::core::Scalar::all(0.0),
        )?;
        mat.data_bytes_mut()?.copy_from_slice(&bgr);
        Ok(mat)
    }

    /// Writes the image as PNG (or any format OpenCV infers from the extension).
    pub fn write_png(&self, path: &Path) -> Result<(), RenderError> {
        let mat = self.to_bgr_mat()?;
        let name = path.to_string_lossy().into_owned();
        let params = opencv::core::Vector::<i32>::new();
        if opencv::imgcodecs::imwrite(&name, &mat, &params)? {
            Ok(())
        } else {
            Err(RenderError::Write { path: name })
        }
    }
}

/// The named presets of [`Condition`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConditionKind {
    /// Lamps on, well exposed, little noise.
    Bright,
    /// Lamps at 30 %, weak ambient light, gain 2 (auto exposure), more noise.
    Dim,
    /// Lamps off, a 40-degree head light cone from the camera, noise.
    Night,
    /// Bright, with a warm white balance (tungsten-like).
    ColourShift,
    /// Bright, with strong sensor noise.
    Noise,
    /// Bright, with horizontal motion blur over 3 pixels.
    MotionBlur,
}

impl ConditionKind {
    /// Every preset.
    pub const ALL: [ConditionKind; 6] = [
        Self::Bright,
        Self::Dim,
        Self::Night,
        Self::ColourShift,
        Self::Noise,
        Self::MotionBlur,
    ];

    /// Its name: `bright`, `dim`, `night`, `colour_shift`, `noise`, `motion_blur`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Bright => "bright",
            Self::Dim => "dim",
            Self::Night => "night",
            Self::ColourShift => "colour_shift",
            Self::Noise => "noise",
            Self::MotionBlur => "motion_blur",
        }
    }

    /// The preset called `name` (as [`ConditionKind::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// Lighting and camera knobs of a render. Light values are irradiance on an albedo scale (a
/// white surface under light 1 at gain 1 is white).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Condition {
    /// Uniform ambient light, 0..=4.
    pub ambient: f32,
    /// Scale of the ceiling lamps (0 = off), 0..=4.
    pub lamps: f32,
    /// Head light intensity: irradiance 1 m ahead on the axis (0 = off), 0..=16.
    pub headlight: f32,
    /// Half-angle of the head light cone, degrees, 1..=89.
    pub headlight_half_angle_deg: f32,
    /// Exposure gain, 0..=16.
    pub gain: f32,
    /// Per-channel gains (R, G, B), each 0..=4.
    pub white_balance: [f32; 3],
    /// Standard deviation of additive sensor noise, 8-bit grey levels, 0..=64.
    pub noise_sigma: f32,
    /// Length of the horizontal box blur, pixels (0 or 1 = none), 0..=64.
    pub motion_blur_px: u32,
}

impl Default for Condition {
    /// [`ConditionKind::Bright`].
    fn default() -> Self {
        Self::preset(ConditionKind::Bright)
    }
}

impl Condition {
    /// The knobs of a named preset.
    pub fn preset(kind: ConditionKind) -> Self {
        let bright = Self {
            ambient: 0.32,
            lamps: 1.0,
            headlight: 0.0,
            headlight_half_angle_deg: 30.0,
            gain: 1.0,
            white_balance: [1.0; 3],
            noise_sigma: 1.0,
            motion_blur_px: 0,
        };
        match kind {
            ConditionKind::Bright => bright,
            ConditionKind::Dim => Self {
                ambient: 0.08,
                lamps: 0.3,
                gain: 2.0,
                noise_sigma: 4.0,
                ..bright
            },
            ConditionKind::Night => Self {
                ambient: 0.01,
                lamps: 0.0,
                headlight: 2.0,
                headlight_half_angle_deg: 40.0,
                noise_sigma: 3.0,
                ..bright
            },
            ConditionKind::ColourShift => Self {
                white_balance: [1.3, 1.0, 0.62],
                gain: 0.95,
                ..bright
            },
            ConditionKind::Noise => Self {
                noise_sigma: 12.0,
                ..bright
            },
            ConditionKind::MotionBlur => Self {
                motion_blur_px: 3,
                ..bright
            },
        }
    }

    /// Checks every knob against its documented range; the error names the first bad one.
    pub fn validate(&self) -> Result<(), RenderError> {
        let check = |field: &'static str, x: f32, hi: f32| {
            if x.is_finite() && (0.0..=hi).contains(&x) {
                Ok(())
            } else {
                Err(RenderError::InvalidCondition {
                    field,
                    message: format!("{x} is outside 0..={hi}"),
                })
            }
        };
        check("ambient", self.ambient, 4.0)?;
        check("lamps", self.lamps, 4.0)?;
        check("headlight", self.headlight, 16.0)?;
        check("gain", self.gain, 16.0)?;
        for c in self.white_balance {
            check("white_balance", c, 4.0)?;
        }
        check("noise_sigma", self.noise_sigma, 64.0)?;
        let angle = self.headlight_half_angle_deg;
        if !(angle.is_finite() && (1.0..=89.0).contains(&angle)) {
            return Err(RenderError::InvalidCondition {
                field: "headlight_half_angle_deg",
                message: format!("{angle} is outside 1..=89"),
            });
        }
        if self.motion_blur_px > 64 {
            return Err(RenderError::InvalidCondition {
                field: "motion_blur_px",
                message: format!("{} is outside 0..=64", self.motion_blur_px),
            });
        }
        Ok(())
    }
}

/// What makes two materials' textures identical: family, colours, seed.
type TextureKey = (TextureFamily, [u8; 3], [u8; 3], u64);

/// How a material is drawn.
#[derive(Clone, Copy, Debug)]
struct Look {
    /// Start of its texture in the renderer's texel buffer.
    base: u32,
    side_log2: u32,
    level_count: u32,
    /// Texels per metre along u and v.
    density: [f32; 2],
    /// Placement origin (u, v), metres; zero for tiled materials.
    origin: [f32; 2],
    placed: bool,
    emissive: bool,
}

#[derive(Clone, Copy, Debug)]
struct PointLight {
    position: [f32; 3],
    intensity: f32,
}

/// The first occupied voxel along a ray.
#[derive(Clone, Copy, Debug)]
struct Hit {
    voxel: [i32; 3],
    index: usize,
    /// Axis of the entered face.
    axis: usize,
    /// Distance along the unit ray, voxels.
    t: f32,
}

/// A ray caster for one world (see the module documentation). Owns everything it needs; build
/// it once per world (about 0.2 s at 0.1 m) and share it across threads.
pub struct Renderer {
    dims: [i32; 3],
    /// Index steps along y and z (x is 1).
    stride: [usize; 3],
    voxel_size: f32,
    origin: [f32; 3],
    distance: Vec<u8>,
    materials: Vec<u16>,
    looks: Vec<Look>,
    texels: Vec<u32>,
    storey_of_z: Vec<u8>,
    floor_z: Vec<f64>,
    region_map: Vec<u16>,
    light_start: Vec<u32>,
    lights: Vec<PointLight>,
    gamma: Vec<u8>,
}

impl Renderer {
    /// Precomputes textures, the distance field and light lists of `world`.
    pub fn new(world: &World) -> Self {
        let grid = world.grid();
        let [nx, ny, nz] = grid.dims();
        let vs = grid.voxel_size();
        let o = grid.origin();

        // Every texture's levels in one buffer; materials differing only in placement share.
        let mut texels = Vec::new();
        // (family, colour, accent, seed) -> (start, side_log2, level_count)
        let mut cache: HashMap<TextureKey, (u32, u32, u32)> = HashMap::new();
        let looks = world
            .material_table()
            .iter()
            .map(|m: &Material| {
                let key = (m.family, m.colour, m.accent, m.seed);
                let (base, side_log2, level_count) = *cache.entry(key).or_insert_with(|| {
                    let texture = Texture::generate(m);
                    let base = texels.len() as u32;
                    texels.extend_from_slice(texture.texels());
                    (base, texture.side_log2(), texture.level_count() as u32)
                });
                let side = (1u32 << side_log2) as f32;
                let (density, origin) = match m.placement {
                    Some(p) => (
                        [side / p.size[0] as f32, side / p.size[1] as f32],
                        [p.origin[0] as f32, p.origin[1] as f32],
                    ),
                    None => ([m.texels_per_metre as f32; 2], [0.0; 2]),
                };
                Look {
                    base,
                    side_log2,
                    level_count,
                    density,
                    origin,
                    placed: m.placement.is_some(),
                    emissive: m.is_emissive(),
                }
            })
            .collect();

        let storey_of_z = (0..nz)
            .map(|z| {
                let centre = o.z + (z as f64 + 0.5) * vs;
                world.floor_at(centre).unwrap_or(0) as u8
            })
            .collect();
        let floor_z = (0..world.floor_count())
            .map(|f| world.floor_range(f)[0])
            .collect();
        let region_map = (0..world.floor_count())
            .flat_map(|f| world.region_map(f).iter().copied())
            .collect();

        // Lamps per region: a room's own; for a corridor every corridor lamp of its storey
        // within LAMP_RANGE of its footprint (corridors meet without walls).
        let regions = world.regions();
        let mut light_start = vec![0u32];
        let mut lights = Vec::new();
        for (r, region) in regions.iter().enumerate() {
            for lamp in world.lamps() {
                let owner = &regions[lamp.region];
                let lit = match region.kind {
                    RegionKind::Room => lamp.region == r,
                    RegionKind::Corridor => {
                        owner.kind == RegionKind::Corridor
                            && owner.floor == region.floor
                            && (0..2).all(|k| {
                                let p = lamp.position[k];
                                p > region.min[k] - LAMP_RANGE as f64
                                    && p < region.max[k] + LAMP_RANGE as f64
                            })
                    }
                    RegionKind::Shaft => false,
                };
                if lit {
                    lights.push(PointLight {
                        position: lamp.position.map(|c| c as f32),
                        intensity: lamp.intensity as f32,
                    });
                }
            }
            light_start.push(lights.len() as u32);
        }

        let gamma = (0..4096)
            .map(|i| ((i as f32 / 4095.0).powf(1.0 / 2.2) * 255.0 + 0.5) as u8)
            .collect();

        Self {
            dims: [nx as i32, ny as i32, nz as i32],
            stride: [1, nx, nx * ny],
            voxel_size: vs as f32,
            origin: [o.x as f32, o.y as f32, o.z as f32],
            distance: chebyshev_distance(grid.cells(), [nx, ny, nz]),
            materials: world.materials().to_vec(),
            looks,
            texels,
            storey_of_z,
            floor_z,
            region_map,
            light_start,
            lights,
            gamma,
        }
    }

    /// Renders the view from `pose` (`world_T_camera`, see [`crate::camera`]) under
    /// `condition`; `seed` drives the sensor noise.
    ///
    /// # Panics
    /// When the intrinsics or the condition are invalid; [`Renderer::try_render`] returns the
    /// error instead.
    pub fn render(&self, pose: &Pose, k: &Intrinsics, condition: &Condition, seed: u64) -> Image {
        self.try_render(pose, k, condition, seed)
            .unwrap_or_else(|e| panic!("render: {e}"))
    }

    /// [`Renderer::render`], with invalid intrinsics or conditions reported as errors naming
    /// the field. A camera outside the world's grid sees black.
    pub fn try_render(
        &self,
        pose: &Pose,
        k: &Intrinsics,
        condition: &Condition,
        seed: u64,
    ) -> Result<Image, RenderError> {
        k.validate().map_err(RenderError::InvalidIntrinsics)?;
        condition.validate()?;
        let (w, h) = (k.width as usize, k.height as usize);
        let mut linear = vec![[0.0f32; 3]; w * h];
        let forward = (pose.rotation * Vector3::x()).map(|c| c as f32).into();
        let start = self.voxel_position(pose);
        let cone_outer = condition.headlight_half_angle_deg.to_radians().cos();
        let cone_inner = (0.7 * condition.headlight_half_angle_deg)
            .to_radians()
            .cos();
        let shade = Shade {
            renderer: self,
            condition,
            forward,
            cone: [cone_outer, cone_inner],
            focal: k.fx as f32,
        };
        self.trace_pixels(pose, k, |pixel, dir, hit| {
            linear[pixel] = shade.at(start, dir, hit);
        });

        if condition.motion_blur_px > 1 {
            box_blur_rows(&mut linear, w, condition.motion_blur_px as usize);
        }
        let mut image = Image::new(k.width, k.height);
        let mut rng = SimRng::new(seed);
        let gains = condition.white_balance.map(|c| c * condition.gain);
        let sigma = condition.noise_sigma;
        let mut noise = [0.0f32; 3];
        for (p, out) in linear.iter().zip(image.rgb.chunks_exact_mut(3)) {
            if sigma > 0.0 {
                let [a, b, c] = rng.normal_triple();
                noise = [a * sigma, b * sigma, c * sigma];
            }
            for ch in 0..3 {
                let x = (p[ch] * gains[ch]).clamp(0.0, 1.0);
                let level = self.gamma[(x * 4095.0) as usize] as f32 + noise[ch];
                out[ch] = (level.clamp(0.0, 255.0) + 0.5) as u8;
            }
        }
        Ok(image)
    }

    /// The depth image from `pose`: per pixel (rows of `k.width`), the distance in metres
    /// along the camera's forward axis to the surface its centre sees (the z of an optical
    /// camera frame, as depth cameras report it); NaN where the ray leaves the grid.
    pub fn try_render_depth(&self, pose: &Pose, k: &Intrinsics) -> Result<Vec<f32>, RenderError> {
        k.validate().map_err(RenderError::InvalidIntrinsics)?;
        let mut depth = vec![f32::NAN; k.width as usize * k.height as usize];
        let forward: [f32; 3] = (pose.rotation * Vector3::x()).map(|c| c as f32).into();
        self.trace_pixels(pose, k, |pixel, dir, hit| {
            let along = dir[0] * forward[0] + dir[1] * forward[1] + dir[2] * forward[2];
            depth[pixel] = hit.t * self.voxel_size * along;
        });
        Ok(depth)
    }

    /// The camera position in voxel units from the grid origin.
    fn voxel_position(&self, pose: &Pose) -> [f32; 3] {
        let t = pose.translation.vector;
        let eye = [t.x as f32, t.y as f32, t.z as f32];
        [0, 1, 2].map(|i| (eye[i] - self.origin[i]) / self.voxel_size)
    }

    /// Casts one ray through the centre of every pixel of `k` from `pose` (valid intrinsics)
    /// and calls `visit(pixel index, unit world direction, hit)` for each that hits.
    fn trace_pixels(
        &self,
        pose: &Pose,
        k: &Intrinsics,
        mut visit: impl FnMut(usize, [f32; 3], &Hit),
    ) {
        let (w, h) = (k.width as usize, k.height as usize);
        let r = pose.rotation.to_rotation_matrix();
        let col = |v: Vector3<f64>| -> [f32; 3] { (r * v).map(|c| c as f32).into() };
        // world direction of pixel (u, v) = forward * fx - right_step * (u - cx) - down * ...
        let axis_x = col(Vector3::x() * k.fx);
        let step_u = col(-Vector3::y());
        let step_v = col(-Vector3::z() * (k.fx / k.fy));
        let start = self.voxel_position(pose);
        let mut dirs = [[0.0f32; 3]; PACKET];
        let mut hits: [Option<Hit>; PACKET] = Default::default();
        for row in 0..h {
            let dv = row as f32 + 0.5 - k.cy as f32;
            for c0 in (0..w).step_by(PACKET) {
                for (lane, dir) in dirs.iter_mut().enumerate() {
                    // Lanes past the right edge repeat the last pixel; their result is dropped.
                    let du = (c0 + lane).min(w - 1) as f32 + 0.5 - k.cx as f32;
                    let d = [
                        axis_x[0] + du * step_u[0] + dv * step_v[0],
                        axis_x[1] + du * step_u[1] + dv * step_v[1],
                        axis_x[2] + du * step_u[2] + dv * step_v[2],
                    ];
                    let inv_norm = 1.0 / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                    *dir = [d[0] * inv_norm, d[1] * inv_norm, d[2] * inv_norm];
                }
                self.trace_packet(start, &dirs, &mut hits);
                for (lane, hit) in hits.iter().enumerate().take(w - c0) {
                    if let Some(hit) = hit {
                        visit(row * w + c0 + lane, dirs[lane], hit);
                    }
                }
            }
        }
    }

    /// The surface point seen from `pose` through image position `(u, v)` (pixels, the centre
    /// of the top-left pixel at `(0.5, 0.5)`, see [`Intrinsics`]), in world coordinates: the
    /// entry point of the ray into its first occupied voxel. `None` when the ray leaves the
    /// grid.
    pub fn surface_point(
        &self,
        pose: &Pose,
        k: &Intrinsics,
        u: f64,
        v: f64,
    ) -> Option<Point3<f64>> {
        let body = Vector3::new(k.fx, -(u - k.cx), -(v - k.cy) * k.fx / k.fy);
        let d = (pose.rotation * body).normalize().map(|c| c as f32);
        let t = pose.translation.vector;
        let eye = [t.x as f32, t.y as f32, t.z as f32];
        let o = [0, 1, 2].map(|i| (eye[i] - self.origin[i]) / self.voxel_size);
        let mut ray = Ray::new(self, o, [d[0], d[1], d[2]]);
        for _ in 0..MAX_STEPS {
            if ray.state != RayState::Running {
                break;
            }
            ray.step(self, o);
        }
        (ray.state == RayState::Hit).then(|| {
            Point3::from([0, 1, 2].map(|i| {
                f64::from(self.origin[i])
                    + f64::from(o[i] + ray.t * d[i]) * f64::from(self.voxel_size)
            }))
        })
    }

    /// Walks the rays from `o` (voxel units from the grid origin) along the unit directions
    /// `dirs` to their first occupied voxels (see the module documentation). The rays advance
    /// in lockstep: each step is a chain of dependent loads and conversions, and interleaving
    /// independent rays lets the processor overlap them (about twice as fast as one at a time).
    #[inline]
    fn trace_packet(
        &self,
        o: [f32; 3],
        dirs: &[[f32; 3]; PACKET],
        hits: &mut [Option<Hit>; PACKET],
    ) {
        let mut rays = [Ray::new(self, o, dirs[0]); PACKET];
        for (ray, &d) in rays.iter_mut().zip(dirs).skip(1) {
            *ray = Ray::new(self, o, d);
        }
        for _ in 0..MAX_STEPS {
            let mut running = false;
            for ray in rays.iter_mut() {
                if ray.state == RayState::Running {
                    ray.step(self, o);
                    running = true;
                }
            }
            if !running {
                break;
            }
        }
        for (hit, ray) in hits.iter_mut().zip(&rays) {
            *hit = (ray.state == RayState::Hit).then_some(Hit {
                voxel: ray.v,
                index: ray.index,
                axis: ray.axis,
                t: ray.t,
            });
        }
    }
}

/// Rays traced together (see [`Renderer::trace_packet`]).
const PACKET: usize = 8;

#[derive(Clone, Copy, Debug, PartialEq)]
enum RayState {
    Running,
    Hit,
    Missed,
}

/// One ray's traversal state.
#[derive(Clone, Copy, Debug)]
struct Ray {
    d: [f32; 3],
    inv: [f32; 3],
    /// +1 or -1: the direction of travel along each axis.
    sign: [i32; 3],
    /// 0 when travelling towards +, 1 towards - (the exit face of a cube `v +- (r - 1)` is at
    /// `v + sign * r + back`).
    back: [i32; 3],
    v: [i32; 3],
    index: usize,
    axis: usize,
    t: f32,
    state: RayState,
}

impl Ray {
    #[inline(always)]
    fn new(rd: &Renderer, o: [f32; 3], d: [f32; 3]) -> Self {
        let v = [floor_i32(o[0]), floor_i32(o[1]), floor_i32(o[2])];
        let inv_of = |c: f32| {
            1.0 / if c.abs() < 1e-12 {
                1e-12f32.copysign(c)
            } else {
                c
            }
        };
        let (ax, ay, az) = (d[0].abs(), d[1].abs(), d[2].abs());
        let axis = if ax >= ay && ax >= az {
            0
        } else if ay >= az {
            1
        } else {
            2
        };
        let sign_of = |c: f32| if c > 0.0 { 1 } else { -1 };
        let inside = rd.contains(v);
        Self {
            d,
            inv: [inv_of(d[0]), inv_of(d[1]), inv_of(d[2])],
            sign: [sign_of(d[0]), sign_of(d[1]), sign_of(d[2])],
            back: [
                i32::from(d[0] <= 0.0),
                i32::from(d[1] <= 0.0),
                i32::from(d[2] <= 0.0),
            ],
            v,
            index: if inside { rd.index(v) } else { 0 },
            axis,
            t: 0.0,
            state: if inside {
                RayState::Running
            } else {
                RayState::Missed
            },
        }
    }

    /// One step: stop in an occupied voxel, else jump to the exit of the free cube around the
    /// current voxel (`v +- (r - 1)`, `r` its distance value).
    #[inline(always)]
    fn step(&mut self, rd: &Renderer, o: [f32; 3]) {
        let r = rd.distance[self.index] as i32;
        if r == 0 {
            self.state = RayState::Hit;
            return;
        }
        let [vx, vy, vz] = self.v;
        let [sx, sy, sz] = self.sign;
        let tx = ((vx + sx * r + self.back[0]) as f32 - o[0]) * self.inv[0];
        let ty = ((vy + sy * r + self.back[1]) as f32 - o[1]) * self.inv[1];
        let tz = ((vz + sz * r + self.back[2]) as f32 - o[2]) * self.inv[2];
        // The other coordinates at the exit, kept inside the cube (inside the grid they are
        // non-negative, so truncation is floor; a rounding error below 0 is clamped away).
        let within = |c: f32, v: i32| (c as i32).clamp(v - r + 1, v + r - 1);
        let [dx, dy, dz] = self.d;
        let (next, t, axis) = if tx <= ty && tx <= tz {
            let next = [
                vx + sx * r,
                within(o[1] + tx * dy, vy),
                within(o[2] + tx * dz, vz),
            ];
            (next, tx, 0)
        } else if ty <= tz {
            let next = [
                within(o[0] + ty * dx, vx),
                vy + sy * r,
                within(o[2] + ty * dz, vz),
            ];
            (next, ty, 1)
        } else {
            let next = [
                within(o[0] + tz * dx, vx),
                within(o[1] + tz * dy, vy),
                vz + sz * r,
            ];
            (next, tz, 2)
        };
        self.v = next;
        self.t = t;
        self.axis = axis;
        if rd.contains(next) {
            self.index = rd.index(next);
        } else {
            self.state = RayState::Missed;
        }
    }
}

impl Renderer {
    #[inline(always)]
    fn contains(&self, v: [i32; 3]) -> bool {
        (v[0] as u32) < self.dims[0] as u32
            && (v[1] as u32) < self.dims[1] as u32
            && (v[2] as u32) < self.dims[2] as u32
    }

    #[inline(always)]
    fn index(&self, v: [i32; 3]) -> usize {
        v[0] as usize + self.stride[1] * v[1] as usize + self.stride[2] * v[2] as usize
    }
}

/// Per-frame shading state.
struct Shade<'a> {
    renderer: &'a Renderer,
    condition: &'a Condition,
    forward: [f32; 3],
    /// Cosines of the head light's outer and inner cone angles.
    cone: [f32; 2],
    focal: f32,
}

impl Shade<'_> {
    /// Linear RGB seen along unit `d` from `o` (voxel units) at `hit`.
    #[inline]
    fn at(&self, o: [f32; 3], d: [f32; 3], hit: &Hit) -> [f32; 3] {
        let rd = self.renderer;
        let vs = rd.voxel_size;
        let k = hit.axis;
        let normal_positive = d[k] < 0.0;
        let at = |i: usize| rd.origin[i] + (o[i] + hit.t * d[i]) * vs;
        let p = [at(0), at(1), at(2)];
        // The free voxel in front of the face: its storey and region.
        let mut front = hit.voxel;
        front[k] += if normal_positive { 1 } else { -1 };
        let fz = front[2].clamp(0, rd.dims[2] - 1) as usize;
        let storey = rd.storey_of_z[fz] as usize;
        let look = rd.looks[rd.materials[hit.index] as usize];
        let p64 = [p[0] as f64, p[1] as f64, p[2] as f64];
        let uv = face_uv(k, normal_positive, p64, rd.floor_z[storey]);
        let s = (uv[0] as f32 - look.origin[0]) * look.density[0];
        let tv = (uv[1] as f32 - look.origin[1]) * look.density[1];
        let row = if look.placed {
            let side = (1u32 << look.side_log2) as f32;
            side - 1.0 - tv
        } else {
            -tv
        };
        let distance = hit.t * vs;
        let cos_incidence = d[k].abs();
        let footprint =
            distance * look.density[0].max(look.density[1]) / (self.focal * cos_incidence.max(0.3));
        // floor(log2(footprint)) from the float's exponent.
        let level = if footprint > 1.0 {
            ((footprint.to_bits() >> 23) as usize).saturating_sub(127)
        } else {
            0
        };
        let texel = fetch(
            &rd.texels[look.base as usize..],
            look.side_log2,
            look.level_count,
            level as u32,
            floor_i32(s),
            floor_i32(row),
        );
        let albedo = [
            (texel & 0xff) as f32 / 255.0,
            ((texel >> 8) & 0xff) as f32 / 255.0,
            ((texel >> 16) & 0xff) as f32 / 255.0,
        ];

        let c = self.condition;
        if look.emissive && c.lamps > 0.0 {
            return albedo.map(|a| a * EMISSIVE_GAIN * c.lamps);
        }
        let face = match (k, normal_positive) {
            (2, true) => 1.0,
            (2, false) => 0.8,
            (0, _) => 0.9,
            _ => 0.85,
        };
        let mut light = c.ambient * face;
        if c.lamps > 0.0 {
            let [fx, fy] = [front[0], front[1]];
            if fx >= 0 && fy >= 0 && fx < rd.dims[0] && fy < rd.dims[1] {
                let plane = (rd.dims[0] * rd.dims[1]) as usize;
                let region = rd.region_map[storey * plane + (fy * rd.dims[0] + fx) as usize];
                if region != NO_REGION {
                    let sign = if normal_positive { 1.0 } else { -1.0 };
                    let range2 = LAMP_RANGE * LAMP_RANGE;
                    let (a, b) = (
                        rd.light_start[region as usize] as usize,
                        rd.light_start[region as usize + 1] as usize,
                    );
                    let mut sum = 0.0;
                    for lamp in &rd.lights[a..b] {
                        let l = [
                            lamp.position[0] - p[0],
                            lamp.position[1] - p[1],
                            lamp.position[2] - p[2],
                        ];
                        let ndotl = sign * l[k];
                        let d2 = l[0] * l[0] + l[1] * l[1] + l[2] * l[2];
                        if ndotl > 0.0 && d2 < range2 {
                            let window = 1.0 - d2 / range2;
                            let d2 = d2.max(0.01);
                            sum += lamp.intensity * window * window * ndotl / (d2 * d2.sqrt());
                        }
                    }
                    light += c.lamps * sum;
                }
            }
        }
        if c.headlight > 0.0 {
            let along = d[0] * self.forward[0] + d[1] * self.forward[1] + d[2] * self.forward[2];
            let x = ((along - self.cone[0]) / (self.cone[1] - self.cone[0])).clamp(0.0, 1.0);
            let spot = x * x * (3.0 - 2.0 * x);
            light += c.headlight * spot * cos_incidence / (distance * distance).max(0.04);
        }
        albedo.map(|a| a * light)
    }
}

/// `x.floor() as i32` without a libm call (the baseline x86-64 target has no SSE4.1 `roundss`).
#[inline(always)]
fn floor_i32(x: f32) -> i32 {
    let i = x as i32;
    i - i32::from((i as f32) > x)
}

/// Centred horizontal box blur over `len` pixels of each row (edges clamped), by running sums.
fn box_blur_rows(px: &mut [[f32; 3]], width: usize, len: usize) {
    let before = len as isize / 2;
    let after = len as isize - 1 - before;
    let at = |row: &[[f32; 3]], x: isize| row[x.clamp(0, width as isize - 1) as usize];
    let mut row = vec![[0.0f32; 3]; width];
    let scale = 1.0 / len as f32;
    for line in px.chunks_exact_mut(width) {
        row.copy_from_slice(line);
        let mut acc = [0.0f32; 3];
        for dx in -before..=after {
            let p = at(&row, dx);
            for c in 0..3 {
                acc[c] += p[c];
            }
        }
        for x in 0..width as isize {
            line[x as usize] = acc.map(|a| a * scale);
            let (enter, leave) = (at(&row, x + after + 1), at(&row, x - before));
            for c in 0..3 {
                acc[c] += enter[c] - leave[c];
            }
        }
    }
}

// The world's plan is drawn here, where images are: the world module does not import the renderer.
impl World {
    /// A plan of storey `floor` at the middle of its flight band, one pixel per voxel column,
    /// north (+y) up: walls dark, rooms light with a tint per wall material, corridors grey,
    /// furniture brown, landmarks red, doorways green, shaft openings (above and below) blue.
    pub fn top_view(&self, floor: usize) -> Image {
        use TextureFamily as F;
        let [nx, ny, _] = self.grid().dims();
        let vs = self.grid().voxel_size();
        let [lo, hi] = self.flight_band(floor);
        let z = ((0.5 * (lo + hi) - self.grid().origin().z) / vs) as usize;
        let furniture: Vec<u16> = self.furniture().iter().map(|f| f.material).collect();
        let map = self.region_map(floor);
        let mut image = Image::new(nx as u32, ny as u32);
        let mut put = |x: usize, y: usize, c| image.set_pixel(x as u32, (ny - 1 - y) as u32, c);
        for y in 0..ny {
            for x in 0..nx {
                let m = self.materials()[x + nx * (y + ny * z)];
                let colour = if m != 0 {
                    match self.material_table()[m as usize].family {
                        F::Poster | F::Sign => [220, 30, 30],
                        _ if furniture.contains(&m) => [140, 90, 40],
                        _ => [40, 40, 40],
                    }
                } else {
                    match self.regions().get(map[x + nx * y] as usize) {
                        Some(r) if r.kind == RegionKind::Room => {
                            let tint = r.wall_material as u32 * 67;
                            [
                                (180 + tint % 60) as u8,
                                (180 + (tint / 3) % 60) as u8,
                                (200 + (tint / 7) % 50) as u8,
                            ]
                        }
                        Some(_) => [160, 160, 160],
                        None => [60, 170, 60],
                    }
                };
                put(x, y, colour);
            }
        }
        let shafts = self
            .regions()
            .iter()
            .filter(|r| r.kind == RegionKind::Shaft && (r.floor == floor || r.floor + 1 == floor));
        for r in shafts {
            for y in (r.min[1] / vs).round() as usize..(r.max[1] / vs).round() as usize {
                for x in (r.min[0] / vs).round() as usize..(r.max[0] / vs).round() as usize {
                    put(x, y, [60, 90, 220]);
                }
            }
        }
        image
    }
}

/// Chebyshev (L-infinity) distance in voxels from each voxel to the nearest occupied one,
/// saturated at 255; voxels outside the grid count as occupied. Exact: two raster passes over
/// the 26-neighbourhood with unit weights. Not the library's Euclidean
/// [`topoloc::skeleton::squared_distance_transform`]: the traversal needs the free cube around a
/// voxel, and a Euclidean distance `d` only guarantees a cube of half-side `d / sqrt(3)`.
fn chebyshev_distance(occupied: &[bool], dims: [usize; 3]) -> Vec<u8> {
    let [nx, ny, nz] = dims;
    let mut d: Vec<u8> = occupied.iter().map(|&o| if o { 0 } else { 255 }).collect();
    let at = |d: &[u8], x: isize, y: isize, z: isize| -> u8 {
        if x < 0 || y < 0 || z < 0 || x >= nx as isize || y >= ny as isize || z >= nz as isize {
            0
        } else {
            d[x as usize + nx * (y as usize + ny * z as usize)]
        }
    };
    // The 13 neighbours before a voxel in raster order (x fastest); the backward pass mirrors.
    let mut before = Vec::new();
    for dz in -1isize..=1 {
        for dy in -1isize..=1 {
            for dx in -1isize..=1 {
                if (dz, dy, dx) < (0, 0, 0) {
                    before.push((dx, dy, dz));
                }
            }
        }
    }
    let mut pass = |forward: bool| {
        for zi in 0..nz {
            let z = if forward { zi } else { nz - 1 - zi } as isize;
            for yi in 0..ny {
                let y = if forward { yi } else { ny - 1 - yi } as isize;
                for xi in 0..nx {
                    let x = if forward { xi } else { nx - 1 - xi } as isize;
                    let i = x as usize + nx * (y as usize + ny * z as usize);
                    if d[i] == 0 {
                        continue;
                    }
                    let sign = if forward { 1 } else { -1 };
                    let mut best = d[i];
                    for &(dx, dy, dz) in &before {
                        let n = at(&d, x + sign * dx, y + sign * dy, z + sign * dz);
                        best = best.min(n.saturating_add(1));
                    }
                    d[i] = best;
                }
            }
        }
    };
    pass(true);
    pass(false);
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_field_is_exact_chebyshev() {
        let dims = [9usize, 7, 6];
        let mut rng = SimRng::new(5);
        let occupied: Vec<bool> = (0..dims.iter().product())
            .map(|_| rng.chance(0.04))
            .collect();
        let d = chebyshev_distance(&occupied, dims);
        let [nx, ny, nz] = dims.map(|n| n as isize);
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    // Outside the grid counts as occupied: distance to the border + 1.
                    let mut best = [x + 1, y + 1, z + 1, nx - x, ny - y, nz - z]
                        .into_iter()
                        .min()
                        .unwrap();
                    for (j, &o) in occupied.iter().enumerate() {
                        if o {
                            let j = j as isize;
                            let (ox, oy, oz) = (j % nx, (j / nx) % ny, j / (nx * ny));
                            best = best.min((x - ox).abs().max((y - oy).abs()).max((z - oz).abs()));
                        }
                    }
                    let i = (x + nx * (y + ny * z)) as usize;
                    assert_eq!(d[i] as isize, best, "at {x} {y} {z}");
                }
            }
        }
    }

    #[test]
    fn conditions_validate_and_name_the_field() {
        for kind in ConditionKind::ALL {
            assert!(Condition::preset(kind).validate().is_ok());
            assert_eq!(ConditionKind::from_name(kind.name()), Some(kind));
        }
        let base = Condition::default();
        for (bad, field) in [
            (
                Condition {
                    noise_sigma: -1.0,
                    ..base.clone()
                },
                "noise_sigma",
            ),
            (
                Condition {
                    motion_blur_px: 1000,
                    ..base.clone()
                },
                "motion_blur_px",
            ),
            (
                Condition {
                    white_balance: [1.0, f32::NAN, 1.0],
                    ..base.clone()
                },
                "white_balance",
            ),
            (
                Condition {
                    headlight_half_angle_deg: 0.0,
                    ..base
                },
                "headlight_half_angle_deg",
            ),
        ] {
            let message = bad.validate().unwrap_err().to_string();
            assert!(message.contains(field), "{message}");
        }
    }

    #[test]
    fn box_blur_keeps_constants_and_spreads_edges() {
        let mut px = vec![[0.0f32; 3]; 8];
        px[4] = [1.0; 3];
        box_blur_rows(&mut px, 8, 4);
        let total: f32 = px.iter().map(|p| p[0]).sum();
        assert!((total - 1.0).abs() < 1e-6);
        assert!(px[3][0] > 0.0 && px[5][0] > 0.0);
        let mut flat = vec![[0.5f32; 3]; 8];
        box_blur_rows(&mut flat, 8, 5);
        assert!(flat.iter().all(|p| (p[1] - 0.5).abs() < 1e-6));
    }
}
