//! The VLAD backend: OpenCV local features aggregated into one global vector.
//!
//! VLAD (vector of locally aggregated descriptors, Jégou et al. 2010) describes an image by
//! where its local descriptors fall relative to a small visual vocabulary:
//!
//! 1. [`LocalExtractor`] resizes the image to [`VladOptions::input_size`], converts it to grey
//!    and runs ORB or SIFT, giving at most [`VladOptions::max_features`] descriptors
//!    ([`LocalFeatures`]). ORB's binary descriptors are unpacked to 0/1 floats so that every
//!    later step (k-means, nearest centre) can use the Euclidean distance, which on 0/1 vectors
//!    is the square root of the Hamming distance.
//! 2. [`Codebook::train`] learns `clusters` centres with k-means over descriptors sampled from
//!    the map's own images (the describer does the sampling).
//! 3. [`Codebook::vlad`] assigns every descriptor to its nearest centre, sums the residuals
//!    (descriptor minus centre) per centre, and normalises: signed square root, L2 per centre
//!    block ("intra-normalisation", Arandjelović & Zisserman 2013), then global L2.
//!
//! Every option in [`VladOptions`] changes the descriptor space, so all of them are part of
//! the map's descriptor identity. PCA whitening of the VLAD vectors is done by the caller.

use super::mlf::l2_normalize;
use crate::bounds::Bounds;
use crate::errors::VisionError;
use crate::image::ImageView;
use opencv::core::{KeyPoint, Mat, Ptr, Size, TermCriteria, Vector, CV_32F, CV_8U};
use opencv::features2d::{ORB_ScoreType, ORB, SIFT};
use opencv::prelude::*;

/// Which local feature VLAD aggregates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LocalFeature {
    /// ORB (oriented FAST keypoints, rotated BRIEF): 256 binary tests, fast. The default.
    Orb,
    /// SIFT: 128 gradient-histogram values, slower but more distinctive.
    Sift,
}

impl LocalFeature {
    /// Length of one descriptor as [`LocalExtractor`] returns it (ORB bits unpacked).
    pub fn dim(self) -> usize {
        match self {
            LocalFeature::Orb => ORB_BYTES * 8,
            LocalFeature::Sift => SIFT_DIM,
        }
    }
}

/// Bytes of one ORB descriptor (256 bits, with OpenCV's default `WTA_K = 2`).
const ORB_BYTES: usize = 32;
/// Floats of one SIFT descriptor.
const SIFT_DIM: usize = 128;

/// VLAD options (all part of the descriptor identity).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VladOptions {
    /// Local feature aggregated; default ORB.
    pub feature: LocalFeature,
    /// Number of codebook centres (k-means clusters); the raw VLAD vector has
    /// `clusters x feature dim` values. Default 64, accepted 2..=1024.
    pub clusters: usize,
    /// Most keypoints kept per image (the strongest) when they are detected (not with `dense`).
    /// Default 1000, accepted 10..=20000.
    pub max_features: usize,
    /// Images are resized to this (width, height) before detection, so that feature scales do
    /// not depend on the camera resolution. Default (320, 240), accepted 32..=2048 per side.
    pub input_size: (u32, u32),
    /// Describe a regular grid of keypoints (every [`DENSE_STEP`] pixels, size
    /// [`DENSE_SIZE`]) instead of detected ones (dense VLAD): every image gets the same number
    /// of features wherever they lie, which helps on blurred, low-resolution or snowy images
    /// where detectors find few stable corners. Default true: better single-frame R@1 than
    /// detected keypoints on Gardens Point and Nordland at the same cost (BENCHMARKS.md,
    /// "Real images").
    #[serde(default)]
    pub dense: bool,
}

/// Grid step of dense keypoints, in pixels of the resized image.
pub const DENSE_STEP: i32 = 8;
/// Diameter of dense keypoints, in pixels of the resized image.
pub const DENSE_SIZE: f32 = 16.0;
/// Distance kept from the image border by dense keypoints: ORB drops keypoints closer than its
/// edge threshold (31 pixels).
const DENSE_BORDER: i32 = 32;

impl Default for VladOptions {
    fn default() -> Self {
        Self {
            feature: LocalFeature::Orb,
            clusters: 64,
            max_features: 1000,
            input_size: (320, 240),
            dense: true,
        }
    }
}

impl VladOptions {
    /// Accepted values of [`Self::clusters`].
    pub const CLUSTERS_RANGE: Bounds = Bounds::whole(2, 1024);
    /// Accepted values of [`Self::max_features`].
    pub const MAX_FEATURES_RANGE: Bounds = Bounds::whole(10, 20_000);

    /// Checks every option against its accepted range ([`VisionError::InvalidArgument`]).
    pub fn validate(&self) -> Result<(), VisionError> {
        Self::CLUSTERS_RANGE
            .check("VLAD clusters", self.clusters)
            .and_then(|()| Self::MAX_FEATURES_RANGE.check("VLAD max_features", self.max_features))
            .map_err(VisionError::InvalidArgument)?;
        super::limits::check_input_size([self.input_size.0, self.input_size.1], "VLAD")
    }
}

/// Local descriptors of one image, row-major `count x dim` floats.
///
/// ORB's 256 binary bits are unpacked to 0/1 floats (dim 256), so that k-means in L2 equals
/// Hamming clustering; SIFT gives dim 128 (OpenCV's values, integers in 0..=255).
#[derive(Clone, Debug, PartialEq)]
pub struct LocalFeatures {
    /// Length of one descriptor.
    pub dim: usize,
    /// `count x dim` values, one descriptor after the other.
    pub values: Vec<f32>,
}

impl LocalFeatures {
    /// Number of descriptors.
    pub fn count(&self) -> usize {
        self.values.len().checked_div(self.dim).unwrap_or(0)
    }
}

/// The OpenCV detector, by feature type (each has its own `Ptr` type).
enum Detector {
    Orb(Ptr<ORB>),
    Sift(Ptr<SIFT>),
}

/// A reusable extractor (holds the OpenCV detector; not Sync, one per thread).
pub struct LocalExtractor {
    detector: Detector,
    dense: bool,
    feature: LocalFeature,
    max_features: usize,
    size: Size,
}

impl LocalExtractor {
    /// Validates the options and creates the OpenCV detector.
    pub fn new(options: &VladOptions) -> Result<Self, VisionError> {
        options.validate()?;
        // validate() bounds max_features to 20000, so the cast cannot overflow.
        let n = options.max_features as i32;
        let detector = match options.feature {
            // OpenCV's defaults except the feature count: scale 1.2 over 8 levels, edge and
            // patch 31 pixels, 2-point BRIEF tests (256 bits), Harris ranking, FAST threshold 20.
            LocalFeature::Orb => Detector::Orb(ORB::create(
                n,
                1.2,
                8,
                31,
                0,
                2,
                ORB_ScoreType::HARRIS_SCORE,
                31,
                20,
            )?),
            // OpenCV's defaults except the feature count: 3 layers per octave, contrast
            // threshold 0.04, edge threshold 10, sigma 1.6.
            LocalFeature::Sift => Detector::Sift(SIFT::create(n, 3, 0.04, 10.0, 1.6)?),
        };
        Ok(Self {
            detector,
            dense: options.dense,
            feature: options.feature,
            max_features: options.max_features,
            size: Size::new(options.input_size.0 as i32, options.input_size.1 as i32),
        })
    }

    /// Validates, converts to grey at input_size, detects and describes.
    ///
    /// An image without any keypoint (blank, constant, too blurred) gives zero descriptors,
    /// not an error; the caller decides what that means.
    pub fn extract(&mut self, image: &ImageView<'_>) -> Result<LocalFeatures, VisionError> {
        let rgb = image.to_rgb_resized(self.size)?;
        let mut grey = Mat::default();
        opencv::imgproc::cvt_color_def(&rgb, &mut grey, opencv::imgproc::COLOR_RGB2GRAY)?;

        let mut keypoints = if self.dense {
            dense_grid(self.size)?
        } else {
            Vector::<KeyPoint>::new()
        };
        let mut descriptors = Mat::default();
        let mask = opencv::core::no_array();
        let given = self.dense;
        match &mut self.detector {
            Detector::Orb(d) => {
                d.detect_and_compute(&grey, &mask, &mut keypoints, &mut descriptors, given)?
            }
            Detector::Sift(d) => {
                d.detect_and_compute(&grey, &mask, &mut keypoints, &mut descriptors, given)?
            }
        }

        let dim = self.feature.dim();
        if descriptors.empty() {
            return Ok(LocalFeatures {
                dim,
                values: Vec::new(),
            });
        }
        // Detectors may keep a few more than asked when responses tie; their output is sorted
        // strongest first only for some of them, so simply keep the first max_features rows.
        // A dense grid is kept whole (it is fixed by the input size).
        let rows = descriptors.rows().max(0) as usize;
        let rows = if self.dense {
            rows
        } else {
            rows.min(self.max_features)
        };
        let values = match self.feature {
            LocalFeature::Orb => {
                let bytes = descriptor_rows::<u8>(&descriptors, CV_8U, ORB_BYTES, "ORB")?;
                unpack_bits(&bytes[..rows * ORB_BYTES])
            }
            LocalFeature::Sift => {
                let floats = descriptor_rows::<f32>(&descriptors, CV_32F, SIFT_DIM, "SIFT")?;
                floats[..rows * SIFT_DIM].to_vec()
            }
        };
        Ok(LocalFeatures { dim, values })
    }

    /// Length of the descriptors this extractor returns (256 for ORB, 128 for SIFT).
    pub fn dim(&self) -> usize {
        self.feature.dim()
    }
}

/// Keypoints on a regular grid over an image of `size`, [`DENSE_BORDER`] pixels from its edges.
fn dense_grid(size: Size) -> Result<Vector<KeyPoint>, VisionError> {
    let mut grid = Vector::<KeyPoint>::new();
    for y in (DENSE_BORDER..size.height - DENSE_BORDER).step_by(DENSE_STEP as usize) {
        for x in (DENSE_BORDER..size.width - DENSE_BORDER).step_by(DENSE_STEP as usize) {
            grid.push(KeyPoint::new_coords(
                x as f32, y as f32, DENSE_SIZE, 0.0, 0.0, 0, -1,
            )?);
        }
    }
    Ok(grid)
}

/// The descriptor matrix as a flat slice, after checking the element type and row length that
/// the rest of this module relies on.
fn descriptor_rows<'m, T: opencv::core::DataType>(
    descriptors: &'m Mat,
    depth: i32,
    cols: usize,
    name: &str,
) -> Result<&'m [T], VisionError> {
    if descriptors.depth() != depth
        || descriptors.channels() != 1
        || descriptors.cols() as usize != cols
    {
        return Err(VisionError::Model(format!(
            "{name} returned descriptors of type {} with {} columns, expected {cols} columns",
            descriptors.typ(),
            descriptors.cols()
        )));
    }
    Ok(descriptors.data_typed::<T>()?)
}

/// Unpacks binary descriptors to one 0.0/1.0 float per bit, least significant bit first (the
/// bit order is irrelevant to distances, it only has to be fixed).
fn unpack_bits(bytes: &[u8]) -> Vec<f32> {
    let mut out = Vec::with_capacity(bytes.len() * 8);
    for &byte in bytes {
        out.extend((0..8).map(|bit| f32::from((byte >> bit) & 1)));
    }
    out
}

/// k-means attempts from different k-means++ seedings; the most compact one is kept.
const KMEANS_ATTEMPTS: i32 = 3;
/// k-means stops after this many iterations per attempt...
const KMEANS_MAX_ITERATIONS: i32 = 30;
/// ...or when no centre moves by more than this (Euclidean distance).
const KMEANS_EPSILON: f64 = 1e-3;
/// Seed of OpenCV's thread-local random generator before k-means, so that training is
/// reproducible (the same samples always give the same codebook).
const KMEANS_SEED: i32 = 0x5eed;

/// The visual vocabulary: `clusters x dim` centres.
#[derive(Clone, Debug, PartialEq)]
pub struct Codebook {
    /// Number of centres.
    pub clusters: usize,
    /// Length of one centre (the local descriptor length).
    pub dim: usize,
    /// `clusters x dim` values, one centre after the other.
    pub centres: Vec<f32>,
}

impl Codebook {
    /// Trains with cv::kmeans (KMEANS_PP_CENTERS, a few attempts, fixed RNG seed via
    /// opencv::core::set_rng_seed so the result is deterministic) on `samples` (row-major,
    /// n x dim). Error if n < clusters or values non-finite.
    ///
    /// Side effect: reseeds OpenCV's random generator of the calling thread.
    pub fn train(samples: &[f32], dim: usize, clusters: usize) -> Result<Self, VisionError> {
        let bad = |m: String| Err(VisionError::InvalidArgument(m));
        if dim == 0 || clusters == 0 {
            return bad(format!(
                "codebook needs positive dimensions, got {clusters} clusters of {dim} values"
            ));
        }
        if !samples.len().is_multiple_of(dim) {
            return bad(format!(
                "{} sample values are not a whole number of {dim}-value descriptors",
                samples.len()
            ));
        }
        let n = samples.len() / dim;
        if n < clusters {
            return bad(format!(
                "{n} local features are too few to train {clusters} clusters"
            ));
        }
        if !samples.iter().all(|x| x.is_finite()) {
            return bad("codebook samples hold NaN or infinite values".into());
        }
        let (rows, cols, k) = match (
            i32::try_from(n),
            i32::try_from(dim),
            i32::try_from(clusters),
        ) {
            (Ok(r), Ok(c), Ok(k)) => (r, c, k),
            _ => return bad(format!("{n}x{dim} samples are too many for OpenCV")),
        };

        let data = Mat::new_rows_cols_with_data(rows, cols, samples)?;
        let mut labels = Mat::default();
        let mut centres = Mat::default();
        let criteria = TermCriteria::new(
            opencv::core::TermCriteria_COUNT + opencv::core::TermCriteria_EPS,
            KMEANS_MAX_ITERATIONS,
            KMEANS_EPSILON,
        )?;
        // k-means++ seeding draws from the calling thread's cv::theRNG(); the rest of
        // cv::kmeans is deterministic (its parallel loops write disjoint outputs).
        opencv::core::set_rng_seed(KMEANS_SEED)?;
        opencv::core::kmeans(
            &data,
            k,
            &mut labels,
            criteria,
            KMEANS_ATTEMPTS,
            opencv::core::KMEANS_PP_CENTERS,
            &mut centres,
        )?;
        if centres.rows() != k || centres.cols() != cols || centres.typ() != CV_32F {
            return Err(VisionError::Model(format!(
                "k-means returned {}x{} centres of type {}, expected {clusters}x{dim} floats",
                centres.rows(),
                centres.cols(),
                centres.typ()
            )));
        }
        let centres = centres.data_typed::<f32>()?.to_vec();
        Self::from_parts(clusters, dim, centres)
    }

    /// Validates a stored codebook (shape, finite values), for maps loaded from files.
    pub fn from_parts(clusters: usize, dim: usize, centres: Vec<f32>) -> Result<Self, VisionError> {
        let bad = |m: String| Err(VisionError::InvalidArgument(m));
        if clusters == 0 || dim == 0 {
            return bad(format!(
                "codebook needs positive dimensions, got {clusters} clusters of {dim} values"
            ));
        }
        if clusters.checked_mul(dim) != Some(centres.len()) {
            return bad(format!(
                "codebook holds {} values, {clusters} clusters of {dim} need {}",
                centres.len(),
                clusters.saturating_mul(dim)
            ));
        }
        if !centres.iter().all(|x| x.is_finite()) {
            return bad("codebook holds NaN or infinite values".into());
        }
        Ok(Self {
            clusters,
            dim,
            centres,
        })
    }

    /// VLAD: sum of residuals to the nearest centre per cluster, signed square root (power
    /// normalisation), then intra-normalisation (L2 per cluster), then global L2. Length
    /// clusters*dim. An image without features gives all zeros (the caller turns that into a
    /// typed error).
    ///
    /// # Panics
    /// If `features.dim` differs from the codebook's `dim` (features from another extractor).
    pub fn vlad(&self, features: &LocalFeatures) -> Vec<f32> {
        assert_eq!(
            features.dim, self.dim,
            "VLAD: {}-value local features against a codebook of {}-value centres",
            features.dim, self.dim
        );
        let dim = self.dim;
        let mut out = vec![0.0f32; self.clusters * dim];
        if features.count() == 0 {
            return out;
        }
        // ||x - c||^2 = ||x||^2 - 2 x.c + ||c||^2; ||x||^2 is the same for every centre, so the
        // nearest centre minimises ||c||^2 - 2 x.c. Norms are recomputed per call (clusters x
        // dim operations, negligible) because the fields are public and could have changed.
        let half_norms: Vec<f32> = self
            .centres
            .chunks_exact(dim)
            .map(|c| 0.5 * dot(c, c))
            .collect();
        for x in features.values.chunks_exact(dim) {
            let k = self.nearest(x, &half_norms);
            let centre = &self.centres[k * dim..(k + 1) * dim];
            let sum = &mut out[k * dim..(k + 1) * dim];
            for ((s, &xi), &ci) in sum.iter_mut().zip(x).zip(centre) {
                *s += xi - ci;
            }
        }
        // Power normalisation damps bursty components (repeated texture), then each cluster
        // block gets unit norm so that no single visual word dominates, then the whole vector.
        for v in &mut out {
            *v = v.abs().sqrt().copysign(*v);
        }
        for block in out.chunks_exact_mut(dim) {
            l2_normalize(block);
        }
        l2_normalize(&mut out);
        out
    }

    /// Index of the centre nearest to `x`, given each centre's `||c||^2 / 2` (ties: the lowest
    /// index). Minimises `||c||^2 / 2 - x.c`, i.e. the squared distance up to constants.
    fn nearest(&self, x: &[f32], half_norms: &[f32]) -> usize {
        let mut best = (0, f32::INFINITY);
        for (k, (c, &h)) in self
            .centres
            .chunks_exact(self.dim)
            .zip(half_norms)
            .enumerate()
        {
            let score = h - dot(x, c);
            if score < best.1 {
                best = (k, score);
            }
        }
        best.0
    }
}

/// Dot product with eight independent accumulators, so that the compiler can vectorise it
/// (floating-point addition is not reassociated on its own). The hot loop of [`Codebook::vlad`].
#[inline]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    const LANES: usize = 8;
    let mut acc = [0.0f32; LANES];
    let (a_chunks, b_chunks) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: f32 = a_chunks
        .remainder()
        .iter()
        .zip(b_chunks.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in a_chunks.zip(b_chunks) {
        for i in 0..LANES {
            acc[i] += x[i] * y[i];
        }
    }
    acc.iter().sum::<f32>() + tail
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::PixelFormat;
    use opencv::core::{Point, Rect, Scalar, CV_8UC1};

    /// A deterministic grey test scene: random filled rectangles and circles of random shades
    /// on mid-grey, `width x height` packed bytes.
    fn textured(width: i32, height: i32, seed: u64) -> Vec<u8> {
        let mut state = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut next = move |n: i32| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 33) % n as u64) as i32
        };
        let mut mat =
            Mat::new_rows_cols_with_default(height, width, CV_8UC1, Scalar::all(128.0)).unwrap();
        for i in 0..150 {
            let shade = Scalar::all(next(256) as f64);
            let (x, y) = (next(width), next(height));
            if i % 2 == 0 {
                let rect = Rect::new(x, y, 6 + next(40), 6 + next(40));
                opencv::imgproc::rectangle(&mut mat, rect, shade, -1, opencv::imgproc::LINE_8, 0)
                    .unwrap();
            } else {
                let radius = 4 + next(20);
                opencv::imgproc::circle(
                    &mut mat,
                    Point::new(x, y),
                    radius,
                    shade,
                    -1,
                    opencv::imgproc::LINE_8,
                    0,
                )
                .unwrap();
            }
        }
        mat.data_bytes().unwrap().to_vec()
    }

    fn extract(options: &VladOptions, width: u32, height: u32, data: &[u8]) -> LocalFeatures {
        let mut extractor = LocalExtractor::new(options).unwrap();
        extractor
            .extract(&ImageView::packed(width, height, PixelFormat::Gray8, data))
            .unwrap()
    }

    /// ORB features of a few textured 320x240 scenes, concatenated.
    fn orb_samples(images: u64) -> Vec<f32> {
        let options = VladOptions::default();
        let mut extractor = LocalExtractor::new(&options).unwrap();
        let mut samples = Vec::new();
        for seed in 0..images {
            let data = textured(320, 240, seed);
            let f = extractor
                .extract(&ImageView::packed(320, 240, PixelFormat::Gray8, &data))
                .unwrap();
            samples.extend_from_slice(&f.values);
        }
        samples
    }

    fn norm(v: &[f32]) -> f32 {
        v.iter().map(|x| x * x).sum::<f32>().sqrt()
    }

    #[test]
    fn orb_gives_hundreds_of_unpacked_binary_descriptors() {
        let data = textured(320, 240, 1);
        let options = VladOptions::default();
        let f = extract(&options, 320, 240, &data);
        assert_eq!(f.dim, 256);
        assert_eq!(f.values.len(), f.count() * 256);
        assert!(
            (300..=options.max_features).contains(&f.count()),
            "{} features",
            f.count()
        );
        assert!(f.values.iter().all(|&v| v == 0.0 || v == 1.0));
        let ones = f.values.iter().filter(|&&v| v == 1.0).count() as f32;
        let share = ones / f.values.len() as f32;
        assert!((0.2..0.8).contains(&share), "share of set bits {share}");
        // The same image at another resolution and format is resized to the same input.
        let mut rgb = Vec::with_capacity(data.len() * 3);
        data.iter().for_each(|&g| rgb.extend([g, g, g]));
        let mut extractor = LocalExtractor::new(&options).unwrap();
        let again = extractor
            .extract(&ImageView::packed(320, 240, PixelFormat::Rgb8, &rgb))
            .unwrap();
        assert_eq!(
            again, f,
            "grey and equal-channel RGB give the same features"
        );
    }

    #[test]
    fn sift_gives_128_value_descriptors_and_honours_max_features() {
        let data = textured(320, 240, 2);
        let options = VladOptions {
            feature: LocalFeature::Sift,
            dense: false,
            ..Default::default()
        };
        let f = extract(&options, 320, 240, &data);
        assert_eq!(f.dim, 128);
        assert!(f.count() >= 50, "{} features", f.count());
        assert!(f.values.iter().all(|v| v.is_finite() && *v >= 0.0));
        let few = VladOptions {
            max_features: 20,
            ..options
        };
        assert!(extract(&few, 320, 240, &data).count() <= 20);
        let orb_few = VladOptions {
            max_features: 20,
            dense: false,
            ..Default::default()
        };
        assert!(extract(&orb_few, 320, 240, &data).count() <= 20);
    }

    #[test]
    fn constant_images_give_no_detected_features_and_a_zero_vlad() {
        let blank = vec![77u8; 200 * 150];
        for feature in [LocalFeature::Orb, LocalFeature::Sift] {
            let options = VladOptions {
                feature,
                dense: false,
                ..Default::default()
            };
            let f = extract(&options, 200, 150, &blank);
            assert_eq!(f.count(), 0, "{feature:?}");
            assert_eq!(f.dim, feature.dim());
            let codebook =
                Codebook::from_parts(4, f.dim, (0..4 * f.dim).map(|i| i as f32).collect()).unwrap();
            let v = codebook.vlad(&f);
            assert_eq!(v.len(), 4 * f.dim);
            assert!(v.iter().all(|&x| x == 0.0));
        }
    }

    #[test]
    fn dense_keypoints_cover_a_fixed_grid_whatever_the_content() {
        let grid = |size: i32, step: i32| ((size - 2 * DENSE_BORDER) + step - 1) / step;
        let expected = (grid(320, DENSE_STEP) * grid(240, DENSE_STEP)) as usize;
        let textured = textured(320, 240, 5);
        let blank = vec![77u8; 320 * 240];
        for feature in [LocalFeature::Orb, LocalFeature::Sift] {
            let options = VladOptions {
                feature,
                dense: true,
                max_features: 10,
                ..Default::default()
            };
            for data in [&textured, &blank] {
                let f = extract(&options, 320, 240, data);
                assert_eq!(
                    f.count(),
                    expected,
                    "{feature:?}: max_features does not apply"
                );
            }
        }
    }

    #[test]
    fn bad_images_are_refused() {
        let mut extractor = LocalExtractor::new(&VladOptions::default()).unwrap();
        let data = vec![0u8; 10];
        let image = ImageView::packed(32, 32, PixelFormat::Gray8, &data);
        assert!(matches!(
            extractor.extract(&image),
            Err(VisionError::InvalidImage(_))
        ));
    }

    /// Three well separated blobs in 4-D with small deterministic noise.
    fn blobs() -> (Vec<f32>, [[f32; 4]; 3]) {
        let means = [
            [0.0f32, 0.0, 0.0, 0.0],
            [10.0, 0.0, 5.0, 0.0],
            [0.0, -8.0, 0.0, 6.0],
        ];
        let mut state = 12345u64;
        let mut noise = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 0.4
        };
        let mut samples = Vec::new();
        for i in 0..300 {
            // Interleave the blobs so that no ordering helps.
            let mean = means[i % 3];
            samples.extend(mean.iter().map(|m| m + noise()));
        }
        (samples, means)
    }

    #[test]
    fn kmeans_finds_separated_blobs_deterministically() {
        let (samples, means) = blobs();
        let codebook = Codebook::train(&samples, 4, 3).unwrap();
        assert_eq!((codebook.clusters, codebook.dim), (3, 4));
        assert_eq!(codebook.centres.len(), 12);
        for mean in means {
            let closest = codebook
                .centres
                .chunks_exact(4)
                .map(|c| norm(&c.iter().zip(&mean).map(|(a, b)| a - b).collect::<Vec<_>>()))
                .fold(f32::INFINITY, f32::min);
            assert!(closest < 0.05, "no centre near {mean:?}: {closest}");
        }
        assert_eq!(Codebook::train(&samples, 4, 3).unwrap(), codebook);
    }

    #[test]
    fn kmeans_on_orb_features_is_deterministic() {
        let samples = orb_samples(3);
        let a = Codebook::train(&samples, 256, 16).unwrap();
        // Disturb the thread's OpenCV generator in between: training reseeds it.
        opencv::core::set_rng_seed(99).unwrap();
        let b = Codebook::train(&samples, 256, 16).unwrap();
        assert_eq!(a, b);
        assert!(a.centres.iter().all(|c| (0.0..=1.0).contains(c)));
    }

    #[test]
    fn vlad_is_normalised_per_cluster_and_globally() {
        let samples = orb_samples(4);
        let clusters = 16;
        let codebook = Codebook::train(&samples, 256, clusters).unwrap();
        let data = textured(320, 240, 10);
        let f = extract(&VladOptions::default(), 320, 240, &data);
        let v = codebook.vlad(&f);
        assert_eq!(v.len(), clusters * 256);
        assert!((norm(&v) - 1.0).abs() < 1e-5, "global norm {}", norm(&v));

        // Count the clusters that received features, by brute-force assignment.
        let mut used = vec![false; clusters];
        for x in f.values.chunks_exact(256) {
            let distances: Vec<f32> = codebook
                .centres
                .chunks_exact(256)
                .map(|c| x.iter().zip(c).map(|(a, b)| (a - b) * (a - b)).sum())
                .collect();
            let mut order: Vec<usize> = (0..clusters).collect();
            order.sort_by(|&i, &j| distances[i].total_cmp(&distances[j]));
            used[order[0]] = true;
            // Where the choice is clear-cut, the fast assignment agrees with brute force.
            if distances[order[1]] - distances[order[0]] > 1e-2 {
                let half: Vec<f32> = codebook
                    .centres
                    .chunks_exact(256)
                    .map(|c| 0.5 * dot(c, c))
                    .collect();
                assert_eq!(codebook.nearest(x, &half), order[0]);
            }
        }
        let nonempty = used.iter().filter(|&&u| u).count();
        assert!(nonempty >= clusters / 2, "{nonempty} clusters used");
        // Every non-empty block had unit norm before the global scaling, which divided
        // everything by sqrt(number of non-empty blocks).
        let expected = 1.0 / (nonempty as f32).sqrt();
        for (k, block) in v.chunks_exact(256).enumerate() {
            let n = norm(block);
            if used[k] {
                assert!((n - expected).abs() < 1e-5, "block {k}: {n} vs {expected}");
            } else {
                assert_eq!(n, 0.0, "block {k} has no feature");
            }
        }
        // Same features, same vector; another image, another vector.
        assert_eq!(codebook.vlad(&f), v);
        let other = extract(&VladOptions::default(), 320, 240, &textured(320, 240, 11));
        let similarity: f32 = codebook
            .vlad(&other)
            .iter()
            .zip(&v)
            .map(|(a, b)| a * b)
            .sum();
        assert!(
            similarity < 0.9,
            "different scenes, similarity {similarity}"
        );
    }

    #[test]
    fn vlad_matches_a_hand_computation() {
        // Two 2-D centres; features (1, 0) and (3, 4) go to centre 0 at (0, 0); (10, 9) to
        // centre 1 at (10, 10).
        let codebook = Codebook::from_parts(2, 2, vec![0.0, 0.0, 10.0, 10.0]).unwrap();
        let f = LocalFeatures {
            dim: 2,
            values: vec![1.0, 0.0, 3.0, 4.0, 10.0, 9.0],
        };
        let v = codebook.vlad(&f);
        // Residual sums (4, 4) and (0, -1); signed sqrt (2, 2) and (0, -1); per block
        // (1/sqrt2, 1/sqrt2) and (0, -1); global scaling by 1/sqrt2.
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let expected = [h * h, h * h, 0.0, -h];
        for (a, b) in v.iter().zip(expected) {
            assert!((a - b).abs() < 1e-6, "{v:?} vs {expected:?}");
        }
    }

    #[test]
    fn dot_handles_lengths_that_are_not_multiples_of_eight() {
        for n in [0usize, 1, 7, 8, 9, 128, 131] {
            let a: Vec<f32> = (0..n).map(|i| i as f32).collect();
            let b: Vec<f32> = (0..n).map(|i| 1.0 - i as f32 * 0.5).collect();
            let naive: f32 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
            assert!(
                (dot(&a, &b) - naive).abs() <= 1e-3 * naive.abs().max(1.0),
                "{n}"
            );
        }
    }

    #[test]
    fn bad_options_are_invalid_arguments() {
        let ok = VladOptions::default();
        assert!(ok.validate().is_ok());
        let cases = [
            VladOptions {
                clusters: 1,
                ..ok.clone()
            },
            VladOptions {
                clusters: 1025,
                ..ok.clone()
            },
            VladOptions {
                max_features: 9,
                ..ok.clone()
            },
            VladOptions {
                max_features: 20_001,
                ..ok.clone()
            },
            VladOptions {
                input_size: (31, 240),
                ..ok.clone()
            },
            VladOptions {
                input_size: (320, 2049),
                ..ok.clone()
            },
        ];
        for options in cases {
            assert!(
                matches!(options.validate(), Err(VisionError::InvalidArgument(_))),
                "{options:?}"
            );
            assert!(matches!(
                LocalExtractor::new(&options),
                Err(VisionError::InvalidArgument(_))
            ));
        }
    }

    #[test]
    fn options_serialise_with_lowercase_feature_names() {
        let options = VladOptions {
            feature: LocalFeature::Sift,
            ..Default::default()
        };
        let json = serde_json::to_string(&options).unwrap();
        assert!(json.contains("\"sift\""), "{json}");
        let back: VladOptions = serde_json::from_str(&json).unwrap();
        assert_eq!(back, options);
    }

    #[test]
    fn training_refuses_unusable_samples() {
        let (samples, _) = blobs();
        let invalid =
            |r: Result<Codebook, VisionError>| matches!(r, Err(VisionError::InvalidArgument(_)));
        assert!(
            invalid(Codebook::train(&samples[..8], 4, 3)),
            "2 samples, 3 clusters"
        );
        assert!(
            invalid(Codebook::train(&samples[..10], 4, 2)),
            "partial descriptor"
        );
        assert!(invalid(Codebook::train(&samples, 0, 3)));
        assert!(invalid(Codebook::train(&samples, 4, 0)));
        let mut nan = samples.clone();
        nan[17] = f32::NAN;
        assert!(invalid(Codebook::train(&nan, 4, 3)));
        nan[17] = f32::INFINITY;
        assert!(invalid(Codebook::train(&nan, 4, 3)));
    }

    #[test]
    fn stored_codebooks_are_checked() {
        let invalid =
            |r: Result<Codebook, VisionError>| matches!(r, Err(VisionError::InvalidArgument(_)));
        assert!(invalid(Codebook::from_parts(2, 3, vec![0.0; 5])));
        assert!(invalid(Codebook::from_parts(2, 3, vec![0.0; 7])));
        assert!(invalid(Codebook::from_parts(0, 3, vec![])));
        assert!(invalid(Codebook::from_parts(2, 0, vec![])));
        assert!(invalid(Codebook::from_parts(usize::MAX, 2, vec![0.0; 2])));
        assert!(invalid(Codebook::from_parts(
            2,
            2,
            vec![0.0, f32::NAN, 0.0, 0.0]
        )));
        let ok = Codebook::from_parts(2, 3, vec![1.0; 6]).unwrap();
        assert_eq!((ok.clusters, ok.dim, ok.centres.len()), (2, 3, 6));
    }

    /// Timing of the per-query work, for the record: run with
    /// `cargo test --release --lib describe::vlad -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn time_extract_and_vlad() {
        let codebook = Codebook::train(&orb_samples(8), 256, 64).unwrap();
        let data = textured(320, 240, 42);
        let image = ImageView::packed(320, 240, PixelFormat::Gray8, &data);
        let mut extractor = LocalExtractor::new(&VladOptions::default()).unwrap();
        let default_threads = opencv::core::get_num_threads().unwrap();
        for threads in [1, default_threads] {
            opencv::core::set_num_threads(threads).unwrap();
            let mut extract_ms = Vec::new();
            let mut vlad_ms = Vec::new();
            let mut count = 0;
            for _ in 0..60 {
                let start = std::time::Instant::now();
                let f = extractor.extract(&image).unwrap();
                let middle = std::time::Instant::now();
                let v = codebook.vlad(&f);
                let end = std::time::Instant::now();
                assert_eq!(v.len(), 64 * 256);
                count = f.count();
                extract_ms.push((middle - start).as_secs_f64() * 1e3);
                vlad_ms.push((end - middle).as_secs_f64() * 1e3);
            }
            let median = |v: &mut Vec<f64>| {
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            };
            let total: Vec<f64> = extract_ms
                .iter()
                .zip(&vlad_ms)
                .map(|(a, b)| a + b)
                .collect();
            println!(
                "OpenCV threads {threads}: {count} ORB features, extract {:.2} ms + vlad {:.2} ms, \
                 median total {:.2} ms",
                median(&mut extract_ms),
                median(&mut vlad_ms),
                median(&mut total.clone())
            );
        }
        opencv::core::set_num_threads(default_threads).unwrap();
    }
}
