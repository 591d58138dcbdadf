//! Association by timestamps and Umeyama alignment, with evo's contracts.

use super::{Trajectory, TrajectoryError};
use crate::bounds::Bounds;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// Accepted values of the largest timestamp difference of an associated pair, seconds.
pub(super) const MAX_DIFF_S_RANGE: Bounds = Bounds::at_least(0.0);
/// Accepted values of the offset added to the estimate's timestamps, seconds.
pub(super) const OFFSET_S_RANGE: Bounds = Bounds::finite();

/// How an estimate is aligned to its reference before the errors are measured.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Alignment {
    /// As given (both in one world frame).
    None,
    /// The rigid motion that best fits the associated positions (`evo_ape -a`).
    Se3,
    /// The rigid motion and scale (`evo_ape -as`): the seed thesis's definition, and what
    /// monocular estimates (arbitrary scale) need.
    #[default]
    Sim3,
}

impl Alignment {
    /// Lower-case name (`none`, `se3`, `sim3`).
    pub fn name(self) -> &'static str {
        match self {
            Alignment::None => "none",
            Alignment::Se3 => "se3",
            Alignment::Sim3 => "sim3",
        }
    }
}

/// A similarity transform `p -> scale * rotation * p + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Similarity {
    /// Rotation.
    pub rotation: UnitQuaternion<f64>,
    /// Translation, metres.
    pub translation: Vector3<f64>,
    /// Scale (1 for a rigid alignment).
    pub scale: f64,
}

impl Similarity {
    /// The identity.
    pub fn identity() -> Self {
        Self {
            rotation: UnitQuaternion::identity(),
            translation: Vector3::zeros(),
            scale: 1.0,
        }
    }

    /// Applies the transform to a point.
    pub fn transform_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * p * self.scale + self.translation
    }
}

/// Pairs of indices `(reference, estimate)` whose timestamps match, as evo's
/// `associate_trajectories(reference, estimate, max_diff, offset)`: each timestamp of the
/// shorter trajectory (the estimate when both are as long) is paired with the nearest of the
/// other's (the earlier on a tie), `offset_s` added to the estimate's, when they differ by at
/// most `max_diff_s`. A timestamp of the longer one may be paired more than once. In order of
/// the shorter trajectory.
pub fn associate(
    reference: &Trajectory,
    estimate: &Trajectory,
    max_diff_s: f64,
    offset_s: f64,
) -> Result<Vec<(usize, usize)>, TrajectoryError> {
    MAX_DIFF_S_RANGE
        .check("max_diff_s", max_diff_s)
        .and_then(|()| OFFSET_S_RANGE.check("offset_s", offset_s))
        .map_err(TrajectoryError::InvalidOption)?;
    let estimate_longer = estimate.len() > reference.len();
    let (short, long, offset) = match estimate_longer {
        true => (&reference.timestamps, &estimate.timestamps, offset_s),
        false => (&estimate.timestamps, &reference.timestamps, -offset_s),
    };
    let mut pairs = Vec::new();
    for (i, &t) in short.iter().enumerate() {
        // The long timestamps do not decrease, and neither do they with the offset added.
        let diff = |j: usize| (long[j] + offset - t).abs();
        let after = long.partition_point(|&s| s + offset < t);
        let nearest = match (after.checked_sub(1), (after < long.len()).then_some(after)) {
            (Some(before), Some(after)) if diff(after) < diff(before) => after,
            (Some(before), _) => before,
            (None, Some(after)) => after,
            (None, None) => continue,
        };
        // Equal timestamps before `nearest`: the first of them, as a first minimum.
        let first = long[..nearest].partition_point(|&s| s < long[nearest]);
        let nearest = if diff(first) == diff(nearest) {
            first
        } else {
            nearest
        };
        if diff(nearest) <= max_diff_s {
            pairs.push(match estimate_longer {
                true => (i, nearest),
                false => (nearest, i),
            });
        }
    }
    if pairs.is_empty() {
        return Err(TrajectoryError::TooFewPairs(format!(
            "no estimated pose has a reference pose within {max_diff_s} s (offset {offset_s} s)"
        )));
    }
    Ok(pairs)
}

/// The similarity that maps the points `from` onto `to` in the least-squares sense
/// (Umeyama 1991; evo's `umeyama_alignment(from, to, with_scale)`); without `with_scale` the
/// scale is 1. Fails with [`TrajectoryError::Degenerate`] when the points span less than a
/// plane, and on fewer than 3 points or lists of unequal length.
pub fn umeyama(
    from: &[Vector3<f64>],
    to: &[Vector3<f64>],
    with_scale: bool,
) -> Result<Similarity, TrajectoryError> {
    if from.len() != to.len() || from.len() < 3 {
        return Err(TrajectoryError::TooFewPairs(format!(
            "alignment needs at least 3 point pairs, got {} and {}",
            from.len(),
            to.len()
        )));
    }
    let n = from.len() as f64;
    let mean = |v: &[Vector3<f64>]| v.iter().sum::<Vector3<f64>>() / n;
    let (mean_from, mean_to) = (mean(from), mean(to));
    let variance_from = from
        .iter()
        .map(|p| (p - mean_from).norm_squared())
        .sum::<f64>()
        / n;
    let covariance = from
        .iter()
        .zip(to)
        .map(|(f, t)| (t - mean_to) * (f - mean_from).transpose())
        .sum::<Matrix3<f64>>()
        / n;
    let svd = covariance.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(TrajectoryError::Degenerate);
    };
    let rank = svd
        .singular_values
        .iter()
        .filter(|&&d| d > f64::EPSILON)
        .count();
    if rank < 2 {
        return Err(TrajectoryError::Degenerate);
    }
    let mut s = Matrix3::identity();
    if u.determinant() * v_t.determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let rotation = u * s * v_t;
    let scale = match with_scale {
        true => (Matrix3::from_diagonal(&svd.singular_values) * s).trace() / variance_from,
        false => 1.0,
    };
    let rotation =
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rotation));
    Ok(Similarity {
        rotation,
        translation: mean_to - rotation * mean_from * scale,
        scale,
    })
}
