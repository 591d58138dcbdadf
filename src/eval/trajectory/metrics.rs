//! ATE, ARE, RPE and R_traj of an estimate against its reference.

use super::align::{associate, umeyama, Alignment, Similarity, MAX_DIFF_S_RANGE, OFFSET_S_RANGE};
use super::{path_length, Trajectory, TrajectoryError};
use crate::bounds::Bounds;
use nalgebra::{Isometry3, Translation3, Vector3};

/// How [`evaluate`] associates and aligns.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrajectoryOptions {
    /// The alignment of the estimate to the reference. Default [`Alignment::Sim3`] (the
    /// seed thesis: "after performing both scale and reference system alignment").
    pub alignment: Alignment,
    /// Largest timestamp difference of an associated pair, seconds. Default 0.01 (evo's).
    pub max_diff_s: f64,
    /// Added to the estimate's timestamps before associating, seconds. Default 0.
    pub offset_s: f64,
    /// The RPE's step, in associated pairs: the motion from pair 0 to `rpe_delta`, from
    /// `rpe_delta` to `2 rpe_delta`, ... (evo's `--delta` in frames). Default 1.
    pub rpe_delta: usize,
}

impl TrajectoryOptions {
    /// Accepted values of [`Self::max_diff_s`], seconds.
    pub const MAX_DIFF_S_RANGE: Bounds = MAX_DIFF_S_RANGE;
    /// Accepted values of [`Self::offset_s`], seconds.
    pub const OFFSET_S_RANGE: Bounds = OFFSET_S_RANGE;
    /// Accepted values of [`Self::rpe_delta`].
    pub const RPE_DELTA_RANGE: Bounds = Bounds::whole_at_least(1);
}

impl Default for TrajectoryOptions {
    fn default() -> Self {
        Self {
            alignment: Alignment::Sim3,
            max_diff_s: 0.01,
            offset_s: 0.0,
            rpe_delta: 1,
        }
    }
}

/// Statistics of one error over the associated pairs (evo's `get_all_statistics`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorStats {
    /// Root mean square.
    pub rmse: f64,
    /// Mean.
    pub mean: f64,
    /// Median (the mean of the middle two for an even count).
    pub median: f64,
    /// Population standard deviation.
    pub std: f64,
    /// Smallest.
    pub min: f64,
    /// Largest.
    pub max: f64,
}

impl ErrorStats {
    /// The statistics of `errors` (all zero when empty).
    pub fn of(errors: &[f64]) -> Self {
        if errors.is_empty() {
            return Self::default();
        }
        let n = errors.len() as f64;
        let mean = errors.iter().sum::<f64>() / n;
        let mut sorted = errors.to_vec();
        sorted.sort_by(f64::total_cmp);
        let middle = sorted.len() / 2;
        let median = match sorted.len() % 2 {
            1 => sorted[middle],
            _ => (sorted[middle - 1] + sorted[middle]) / 2.0,
        };
        Self {
            rmse: (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
            mean,
            median,
            std: (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt(),
            min: sorted[0],
            max: sorted[sorted.len() - 1],
        }
    }
}

/// How an estimate compares with its reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrajectoryReport {
    /// Associated pose pairs.
    pub pairs: usize,
    /// The alignment applied to the estimate (identity for [`Alignment::None`]).
    pub alignment: Similarity,
    /// ATE: position error of each aligned pair, metres.
    pub ate_m: ErrorStats,
    /// ARE: rotation error of each aligned pair, degrees.
    pub are_deg: ErrorStats,
    /// RPE, translation: error of the motion over `rpe_delta` pairs, metres.
    pub rpe_m: ErrorStats,
    /// RPE, rotation, degrees.
    pub rpe_deg: ErrorStats,
    /// The aligned estimate's path length (all its poses), metres.
    pub estimate_length_m: f64,
    /// The reference's path length (all its poses), metres.
    pub reference_length_m: f64,
    /// R_traj: `estimate_length_m / reference_length_m` (0 for a reference of no length).
    pub length_ratio: f64,
}

/// Judges `estimate` against `reference` (evo's `evo_ape` and `evo_rpe` with `--align`,
/// `--correct_scale`, `--t_max_diff`, `--t_offset`, `--delta`): associates them by
/// timestamps, aligns the estimate on the associated positions, and measures. Fails when no
/// pair associates, when fewer than 3 pairs are to be aligned or fewer than `rpe_delta + 1`
/// measured, and when the positions are degenerate.
pub fn evaluate(
    reference: &Trajectory,
    estimate: &Trajectory,
    options: &TrajectoryOptions,
) -> Result<TrajectoryReport, TrajectoryError> {
    TrajectoryOptions::RPE_DELTA_RANGE
        .check("rpe_delta", options.rpe_delta)
        .map_err(TrajectoryError::InvalidOption)?;
    let pairs = associate(reference, estimate, options.max_diff_s, options.offset_s)?;
    if pairs.len() <= options.rpe_delta {
        return Err(TrajectoryError::TooFewPairs(format!(
            "{} associated pairs, the RPE over {} needs more",
            pairs.len(),
            options.rpe_delta
        )));
    }
    let reference_poses: Vec<Isometry3<f64>> =
        pairs.iter().map(|&(r, _)| reference.poses[r]).collect();
    let alignment = match options.alignment {
        Alignment::None => Similarity::identity(),
        Alignment::Se3 | Alignment::Sim3 => {
            let positions = |poses: &[Isometry3<f64>], pick: fn(&(usize, usize)) -> usize| {
                pairs
                    .iter()
                    .map(|p| poses[pick(p)].translation.vector)
                    .collect::<Vec<Vector3<f64>>>()
            };
            umeyama(
                &positions(&estimate.poses, |p| p.1),
                &positions(&reference.poses, |p| p.0),
                options.alignment == Alignment::Sim3,
            )?
        }
    };
    // Every estimated pose aligned once: the associated ones are measured, all make the path.
    let aligned: Vec<Isometry3<f64>> = estimate
        .poses
        .iter()
        .map(|p| {
            Isometry3::from_parts(
                Translation3::from(alignment.transform_point(&p.translation.vector)),
                alignment.rotation * p.rotation,
            )
        })
        .collect();
    let estimate_poses: Vec<Isometry3<f64>> = pairs.iter().map(|&(_, e)| aligned[e]).collect();
    let (mut ate, mut are) = (Vec::new(), Vec::new());
    for (r, e) in reference_poses.iter().zip(&estimate_poses) {
        let error = r.inverse() * e;
        ate.push(error.translation.vector.norm());
        are.push(error.rotation.angle().to_degrees());
    }
    let (mut rpe_t, mut rpe_r) = (Vec::new(), Vec::new());
    // Consecutive steps of `rpe_delta` (0 -> d, d -> 2d, ...), as evo without `all_pairs`.
    let d = options.rpe_delta;
    for i in (0..pairs.len() - d).step_by(d) {
        let moved_ref = reference_poses[i].inverse() * reference_poses[i + d];
        let moved_est = estimate_poses[i].inverse() * estimate_poses[i + d];
        let error = moved_ref.inverse() * moved_est;
        rpe_t.push(error.translation.vector.norm());
        rpe_r.push(error.rotation.angle().to_degrees());
    }
    let (estimate_length_m, reference_length_m) = (path_length(&aligned), reference.path_length());
    Ok(TrajectoryReport {
        pairs: pairs.len(),
        alignment,
        ate_m: ErrorStats::of(&ate),
        are_deg: ErrorStats::of(&are),
        rpe_m: ErrorStats::of(&rpe_t),
        rpe_deg: ErrorStats::of(&rpe_r),
        estimate_length_m,
        reference_length_m,
        length_ratio: match reference_length_m > 0.0 {
            true => estimate_length_m / reference_length_m,
            false => 0.0,
        },
    })
}
