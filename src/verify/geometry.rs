//! Two-view check: mutual nearest-neighbour matches (ORB by Hamming distance, XFeat by cosine),
//! then a fundamental matrix fitted with RANSAC; the inliers are the matches consistent with
//! one rigid scene seen from two poses.

use super::keypoints::{Descriptor, DescriptorsRef, KeypointsRef, DESCRIPTOR_BYTES};
use crate::bounds::Bounds;
use crate::errors::VisionError;
use crate::profile::{measure, Stage};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat as FaerMat, MatRef, Par};
use opencv::boxed_ref::BoxedRef;
use opencv::calib3d;
use opencv::core::{DMatch, Mat, Point2f, Vector, NORM_HAMMING};
use opencv::features2d::BFMatcher;
use opencv::prelude::*;

/// The [`PairOptions::min_cosine`] that keeps every mutual match of learned descriptors.
pub(crate) const ANY_COSINE: f32 = -1.0;

/// Fewest matches a fundamental matrix is fitted to (the 8-point algorithm's minimum).
pub const MIN_MATCHES: usize = 8;

/// Accepted values of a RANSAC threshold (epipolar distance or reprojection error), pixels.
pub const RANSAC_THRESHOLD_PX_RANGE: Bounds = Bounds::above(0.0);
/// Accepted values of a RANSAC iteration budget.
pub const RANSAC_ITERATIONS_RANGE: Bounds = Bounds::whole(1, 100_000);
/// Accepted values of the fewest inliers of a fundamental matrix or relative pose.
pub const PAIR_MIN_INLIERS_RANGE: Bounds = Bounds::whole(MIN_MATCHES as u64, 10_000);

/// The robust estimator that fits the fundamental matrix.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FundamentalEstimator {
    /// OpenCV's classic RANSAC (`FM_RANSAC`).
    #[default]
    Ransac,
    /// OpenCV's USAC with MAGSAC++ scoring (`USAC_MAGSAC`): steadier inlier counts at low
    /// inlier ratios, at a higher cost per fit.
    Magsac,
    /// OpenCV's USAC in its fast settings (`USAC_FAST`: SPRT drops a bad model after a few
    /// points instead of scoring every match, local optimisation refines the best): a fraction
    /// of RANSAC's time on pairs that do not match, which are most of a loop detector's checks.
    /// Deterministic (USAC's fixed seed).
    UsacFast,
}

/// Options of [`check_pair`].
#[derive(Clone, Debug, PartialEq)]
pub struct PairOptions {
    /// The robust estimator. Default RANSAC.
    pub estimator: FundamentalEstimator,
    /// Largest Hamming distance (of 256 bits) of a kept ORB match. Default 64.
    pub max_hamming: u32,
    /// Smallest cosine of a kept match of learned descriptors (XFeat, dense cells), in -1..=1;
    /// -1 keeps every mutual match (XFeat's own matcher without its threshold). Default -1.
    pub min_cosine: f32,
    /// RANSAC inlier threshold: distance to the epipolar line, pixels. Default 1.5.
    pub ransac_threshold_px: f64,
    /// RANSAC confidence. Default 0.99.
    pub confidence: f64,
    /// RANSAC iterations at most. Default 200.
    pub max_iterations: u32,
}

impl Default for PairOptions {
    fn default() -> Self {
        Self {
            estimator: FundamentalEstimator::Ransac,
            max_hamming: 64,
            min_cosine: ANY_COSINE,
            ransac_threshold_px: 1.5,
            confidence: 0.99,
            max_iterations: 200,
        }
    }
}

impl PairOptions {
    /// The fit for dense cells: MAGSAC++ at 1.5 px with 1,000 iterations (it re-ranked Gardens
    /// Point best; RANSAC 200 lost recall there, BENCHMARKS.md).
    pub fn cells_default() -> Self {
        Self {
            estimator: FundamentalEstimator::Magsac,
            max_iterations: 1000,
            ..Self::default()
        }
    }

    /// Fails with a message naming the field out of range.
    pub fn validate(&self) -> Result<(), String> {
        Self::MAX_HAMMING_RANGE.check("max_hamming", self.max_hamming)?;
        Self::MIN_COSINE_RANGE.check("min_cosine", self.min_cosine)?;
        RANSAC_THRESHOLD_PX_RANGE.check("ransac_threshold_px", self.ransac_threshold_px)?;
        Self::CONFIDENCE_RANGE.check("confidence", self.confidence)?;
        RANSAC_ITERATIONS_RANGE.check("max_iterations", self.max_iterations)
    }

    /// Accepted values of [`Self::max_hamming`].
    pub const MAX_HAMMING_RANGE: Bounds = Bounds::whole(1, 256);
    /// Accepted values of [`Self::min_cosine`].
    pub const MIN_COSINE_RANGE: Bounds = Bounds::closed(-1.0, 1.0);
    /// Accepted values of [`Self::confidence`].
    pub const CONFIDENCE_RANGE: Bounds = Bounds::open(0.0, 1.0);
}

/// Outcome of [`check_pair`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PairCheck {
    /// Mutual nearest-neighbour matches within `max_hamming`.
    pub matches: u32,
    /// Matches consistent with the fitted fundamental matrix (0 with fewer than
    /// [`MIN_MATCHES`] matches).
    pub inliers: u32,
}

/// The mutual matches of a pair and which of them the fitted fundamental matrix keeps: what
/// [`check_pair`] counts, kept for a pose fit on the same matches
/// ([`super::relative_pose_from_fit`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PairFit {
    /// Mutual matches: `[query index, view index]`.
    pub matches: Vec<[u32; 2]>,
    /// Whether each match is a fundamental-matrix inlier (none with fewer than
    /// [`MIN_MATCHES`] matches).
    pub inliers: Vec<bool>,
}

impl PairFit {
    /// The counts of the fit.
    pub fn check(&self) -> PairCheck {
        PairCheck {
            matches: self.matches.len() as u32,
            inliers: self.inliers.iter().filter(|&&i| i).count() as u32,
        }
    }
}

/// ORB descriptors as an OpenCV matrix borrowing them (one row of 32 bytes each).
fn descriptor_mat(descriptors: &[Descriptor]) -> opencv::Result<BoxedRef<'_, Mat>> {
    Mat::new_rows_cols_with_data(
        descriptors.len() as i32,
        DESCRIPTOR_BYTES as i32,
        descriptors.as_flattened(),
    )
}

/// Mutual nearest-neighbour matches of `query` to `view` (`query_idx` indexes the query,
/// `train_idx` the view): ORB within `max_hamming` bits, XFeat and cells by cosine, at least
/// `min_cosine` (XFeat's own matcher; `distance` is 1 - cosine). Features of two kinds are an
/// invalid argument.
pub(crate) fn mutual_matches(
    query: KeypointsRef<'_>,
    view: KeypointsRef<'_>,
    max_hamming: u32,
    min_cosine: f32,
) -> Result<Vec<DMatch>, VisionError> {
    if query.points.is_empty() || view.points.is_empty() {
        return Ok(Vec::new());
    }
    let above = |matches: Vec<DMatch>| -> Vec<DMatch> {
        matches
            .into_iter()
            .filter(|m| 1.0 - m.distance >= min_cosine)
            .collect()
    };
    match (query.descriptors, view.descriptors) {
        (DescriptorsRef::Orb(q), DescriptorsRef::Orb(v)) => orb_matches(q, v, max_hamming),
        (DescriptorsRef::XFeat(q), DescriptorsRef::XFeat(v)) => Ok(above(cosine_matches(q, v))),
        (DescriptorsRef::Cells(q), DescriptorsRef::Cells(v)) => Ok(above(cosine_matches(q, v))),
        (q, v) => Err(VisionError::InvalidArgument(format!(
            "query keypoints are {} but the view's are {}: a map is verified with the features it stores",
            q.kind().name(),
            v.kind().name()
        ))),
    }
}

/// Mutual nearest neighbours of quantised unit descriptors (XFeat, cells): one faer product
/// gives every (scaled) cosine, then one pass over it, column by column as faer stores it,
/// finds each query row's best view column and each column's best row; a pair is kept when
/// each is the other's best (the first on ties).
fn cosine_matches<const DIM: usize>(query: &[[i8; DIM]], view: &[[i8; DIM]]) -> Vec<DMatch> {
    // Unscaled: the products are 127^2 times the cosines, which keeps the ranking.
    let to_f32 = |rows: &[[i8; DIM]]| -> Vec<f32> {
        rows.as_flattened().iter().map(|&v| f32::from(v)).collect()
    };
    let (q, v) = (to_f32(query), to_f32(view));
    let lhs = MatRef::from_row_major_slice(&q, query.len(), DIM);
    let rhs = MatRef::from_row_major_slice(&v, view.len(), DIM);
    let mut sim = FaerMat::<f32>::zeros(query.len(), view.len());
    matmul(
        sim.as_mut(),
        Accum::Replace,
        lhs,
        rhs.transpose(),
        1.0f32,
        Par::Seq,
    );
    let mut best_of_row = vec![(0usize, f32::NEG_INFINITY); query.len()];
    let best_of_col: Vec<usize> = (0..view.len())
        .map(|j| {
            let column = sim.col(j);
            let mut best = (0, f32::NEG_INFINITY);
            for (i, &x) in column.iter().enumerate() {
                if x > best.1 {
                    best = (i, x);
                }
                if x > best_of_row[i].1 {
                    best_of_row[i] = (j, x);
                }
            }
            best.0
        })
        .collect();
    let scale = 1.0 / (127.0f32 * 127.0);
    best_of_row
        .iter()
        .enumerate()
        .filter(|&(i, &(j, _))| best_of_col[j] == i)
        .map(|(i, &(j, x))| DMatch::new(i as i32, j as i32, 1.0 - x * scale).expect("plain struct"))
        .collect()
}

/// Mutual nearest ORB neighbours (OpenCV's brute-force cross-check) within `max_hamming` bits.
fn orb_matches(
    query: &[Descriptor],
    view: &[Descriptor],
    max_hamming: u32,
) -> Result<Vec<DMatch>, VisionError> {
    let query_mat = descriptor_mat(query)?;
    let view_mat = descriptor_mat(view)?;
    let matcher = BFMatcher::create(NORM_HAMMING, true)?;
    let mut matches = Vector::<DMatch>::new();
    matcher.train_match(
        &query_mat,
        &view_mat,
        &mut matches,
        &opencv::core::no_array(),
    )?;
    Ok(matches
        .iter()
        .filter(|m| m.distance <= max_hamming as f32)
        .collect())
}

/// Matches `query` to `view` and counts the geometric inliers: the fundamental matrix's, or
/// the matches that did not move when they are more (the camera back where the view was
/// taken). Deterministic (OpenCV's RANSAC uses a fixed seed). Options are assumed valid
/// ([`PairOptions::validate`]).
pub fn check_pair(
    query: KeypointsRef<'_>,
    view: KeypointsRef<'_>,
    options: &PairOptions,
) -> Result<PairCheck, VisionError> {
    fit_pair(query, view, options).map(|fit| fit.check())
}

/// [`check_pair`] keeping the matches and the fit's inlier mask.
pub fn fit_pair(
    query: KeypointsRef<'_>,
    view: KeypointsRef<'_>,
    options: &PairOptions,
) -> Result<PairFit, VisionError> {
    fit_pair_reaching(query, view, options, 0)
}

/// [`fit_pair`] for a caller that accepts only pairs with at least `needed` inliers: with fewer
/// matches than that (or than [`MIN_MATCHES`]) no fit is tried and no match is an inlier, so a
/// pair that cannot pass costs only its matching.
pub fn fit_pair_reaching(
    query: KeypointsRef<'_>,
    view: KeypointsRef<'_>,
    options: &PairOptions,
    needed: u32,
) -> Result<PairFit, VisionError> {
    if query.points.len() < MIN_MATCHES || view.points.len() < MIN_MATCHES {
        return Ok(PairFit::default());
    }
    let kept = measure(Stage::Matching, || {
        mutual_matches(query, view, options.max_hamming, options.min_cosine)
    })?;
    let matches: Vec<[u32; 2]> = kept
        .iter()
        .map(|m| [m.query_idx as u32, m.train_idx as u32])
        .collect();
    if kept.len() < MIN_MATCHES.max(needed as usize) {
        let inliers = vec![false; matches.len()];
        return Ok(PairFit { matches, inliers });
    }
    let inliers = measure(Stage::Fit, || fit_matches(query, view, &kept, options))?;
    Ok(PairFit { matches, inliers })
}

/// The inlier mask of `kept` matches of `query` to `view`: the fundamental matrix's, or the
/// matches that did not move when they are more ([`fit_pair_reaching`]).
fn fit_matches(
    query: KeypointsRef<'_>,
    view: KeypointsRef<'_>,
    kept: &[DMatch],
    options: &PairOptions,
) -> Result<Vec<bool>, VisionError> {
    let point = |p: [f32; 2]| Point2f::new(p[0], p[1]);
    let from: Vector<Point2f> = kept
        .iter()
        .map(|m| point(query.points[m.query_idx as usize]))
        .collect();
    let to: Vector<Point2f> = kept
        .iter()
        .map(|m| point(view.points[m.train_idx as usize]))
        .collect();
    let mut mask = Mat::default();
    let fundamental = calib3d::find_fundamental_mat(
        &from,
        &to,
        match options.estimator {
            FundamentalEstimator::Ransac => calib3d::FM_RANSAC,
            FundamentalEstimator::Magsac => calib3d::USAC_MAGSAC,
            FundamentalEstimator::UsacFast => calib3d::USAC_FAST,
        },
        options.ransac_threshold_px,
        options.confidence,
        options.max_iterations as i32,
        &mut mask,
    )?;
    let inliers: Vec<bool> = if fundamental.empty() || mask.total() != kept.len() {
        vec![false; kept.len()]
    } else {
        mask.data_bytes()?.iter().map(|&m| m != 0).collect()
    };
    // The no-motion model beside the fundamental matrix: a camera back where the view was taken
    // sees its points where they were, which no fundamental matrix describes (MAGSAC++ then
    // finds none, and dense cells, on a 16 px grid, do not move for a shift of a few pixels).
    let still: Vec<bool> = kept
        .iter()
        .map(|m| {
            let (a, b) = (
                query.points[m.query_idx as usize],
                view.points[m.train_idx as usize],
            );
            (a[0] - b[0]).hypot(a[1] - b[1]) <= options.ransac_threshold_px as f32
        })
        .collect();
    let count = |mask: &[bool]| mask.iter().filter(|&&m| m).count();
    Ok(match count(&still) > count(&inliers) {
        true => still,
        false => inliers,
    })
}

/// Outcome of [`spatial_check`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpatialCheck {
    /// Mutual nearest-neighbour matches.
    pub matches: u32,
    /// The seed's s-GC: how well the matches agree on one image-plane shift, summed over them
    /// (each in 0..=1, 1 for a match displaced exactly by the mean shift), per query keypoint.
    pub score: f32,
}

/// The seed's sampling-free spatial score (s-GC, after Patch-NetVLAD's rapid spatial scoring):
/// the mutual matches' displacements (view minus query pixel) are compared with their mean;
/// a match whose residual is `(rx, ry)` in an image of extent `(w, h)` (the larger of the two
/// keypoint sets' largest coordinates) scores `((w - |rx|)^2 + (h - |ry|)^2) / (w^2 + h^2)`,
/// residuals clamped to the extent, so the sum grows with the number of matches and their
/// agreement on one shift. The sum is divided by the query's keypoints. No sampling, so it is
/// deterministic and costs one pass over the matches besides matching.
pub fn spatial_check(
    query: KeypointsRef<'_>,
    view: KeypointsRef<'_>,
    max_hamming: u32,
) -> Result<SpatialCheck, VisionError> {
    let matches = mutual_matches(query, view, max_hamming, ANY_COSINE)?;
    if matches.is_empty() {
        return Ok(SpatialCheck::default());
    }
    let shift = |m: &DMatch| {
        let (q, v) = (
            query.points[m.query_idx as usize],
            view.points[m.train_idx as usize],
        );
        [v[0] - q[0], v[1] - q[1]]
    };
    let n = matches.len() as f32;
    let mean = matches
        .iter()
        .map(shift)
        .fold([0.0f32; 2], |a, d| [a[0] + d[0] / n, a[1] + d[1] / n]);
    let extent = |axis: usize| {
        query
            .points
            .iter()
            .chain(view.points)
            .map(|p| p[axis])
            .fold(1.0f32, f32::max)
    };
    let (w, h) = (extent(0), extent(1));
    let total: f32 = matches
        .iter()
        .map(|m| {
            let d = shift(m);
            let rx = (d[0] - mean[0]).abs().min(w);
            let ry = (d[1] - mean[1]).abs().min(h);
            ((w - rx).powi(2) + (h - ry).powi(2)) / (w * w + h * h)
        })
        .sum();
    Ok(SpatialCheck {
        matches: matches.len() as u32,
        score: total / query.points.len() as f32,
    })
}
