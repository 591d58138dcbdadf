//! Two-view check: mutual nearest-neighbour ORB matches, then a fundamental matrix fitted with
//! RANSAC; the inliers are the matches consistent with one rigid scene seen from two poses.

use super::keypoints::{Descriptor, KeypointsRef, DESCRIPTOR_BYTES};
use crate::errors::VisionError;
use opencv::boxed_ref::BoxedRef;
use opencv::calib3d;
use opencv::core::{DMatch, Mat, Point2f, Vector, NORM_HAMMING};
use opencv::features2d::BFMatcher;
use opencv::prelude::*;

/// Fewest matches a fundamental matrix is fitted to (the 8-point algorithm's minimum).
pub const MIN_MATCHES: usize = 8;

/// Options of [`check_pair`].
#[derive(Clone, Debug, PartialEq)]
pub struct PairOptions {
    /// Largest Hamming distance (of 256 bits) of a kept match. Default 64.
    pub max_hamming: u32,
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
            max_hamming: 64,
            ransac_threshold_px: 1.5,
            confidence: 0.99,
            max_iterations: 200,
        }
    }
}

impl PairOptions {
    /// Fails with a message naming the field out of range.
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=256).contains(&self.max_hamming) {
            return Err(format!(
                "max_hamming is {}, must lie in 1..=256",
                self.max_hamming
            ));
        }
        if !(self.ransac_threshold_px.is_finite() && self.ransac_threshold_px > 0.0) {
            return Err("ransac_threshold_px must be finite and > 0".into());
        }
        if !(self.confidence.is_finite() && self.confidence > 0.0 && self.confidence < 1.0) {
            return Err("confidence must lie in (0, 1)".into());
        }
        if !(1..=100_000).contains(&self.max_iterations) {
            return Err("max_iterations must lie in 1..=100000".into());
        }
        Ok(())
    }
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

/// ORB descriptors as an OpenCV matrix borrowing them (one row of 32 bytes each).
fn descriptor_mat(descriptors: &[Descriptor]) -> opencv::Result<BoxedRef<'_, Mat>> {
    Mat::new_rows_cols_with_data(
        descriptors.len() as i32,
        DESCRIPTOR_BYTES as i32,
        descriptors.as_flattened(),
    )
}

/// Mutual nearest-neighbour matches of `query` to `view` (`query_idx` indexes the query,
/// `train_idx` the view) within `max_hamming` bits.
pub(crate) fn mutual_matches(
    query: KeypointsRef<'_>,
    view: KeypointsRef<'_>,
    max_hamming: u32,
) -> Result<Vec<DMatch>, VisionError> {
    if query.points.is_empty() || view.points.is_empty() {
        return Ok(Vec::new());
    }
    let query_mat = descriptor_mat(query.descriptors)?;
    let view_mat = descriptor_mat(view.descriptors)?;
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

/// Matches `query` to `view` and counts the geometric inliers. Deterministic (OpenCV's RANSAC
/// uses a fixed seed). Options are assumed valid ([`PairOptions::validate`]).
pub fn check_pair(
    query: KeypointsRef<'_>,
    view: KeypointsRef<'_>,
    options: &PairOptions,
) -> Result<PairCheck, VisionError> {
    if query.points.len() < MIN_MATCHES || view.points.len() < MIN_MATCHES {
        return Ok(PairCheck::default());
    }
    let kept = mutual_matches(query, view, options.max_hamming)?;
    let count = kept.len() as u32;
    if kept.len() < MIN_MATCHES {
        return Ok(PairCheck {
            matches: count,
            inliers: 0,
        });
    }
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
        calib3d::FM_RANSAC,
        options.ransac_threshold_px,
        options.confidence,
        options.max_iterations as i32,
        &mut mask,
    )?;
    let inliers = if fundamental.empty() || mask.empty() {
        0
    } else {
        opencv::core::count_non_zero(&mask)? as u32
    };
    Ok(PairCheck {
        matches: count,
        inliers,
    })
}
