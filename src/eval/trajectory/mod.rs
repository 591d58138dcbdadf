//! Trajectory metrics of the seed thesis's chapter 3, with the contracts of the `evo` package
//! (its `evo_ape` / `evo_rpe`): an estimated trajectory is associated with a reference by
//! timestamps, aligned to it by Umeyama's method (rigid, or with scale), and judged by
//! - ATE: RMSE (and other statistics) of the position error `||t_est,i - t_ref,i||`, metres;
//! - ARE: of the rotation angle of `R_ref,i^T R_est,i`, degrees;
//! - RPE: of the same errors on the motion between consecutive associated poses;
//! - R_traj: the aligned estimate's path length over the reference's.
//!
//! [`Trajectory`] holds `world_T_body` poses with timestamps, parsed from TUM, KITTI or EuRoC
//! text ([`TrajectoryFormat`]). Bad input (a malformed line, a non-finite value, a rotation
//! that is not one, timestamps that decrease, no associated pair, positions too degenerate to
//! align) is a typed [`TrajectoryError`], never a panic.

mod align;
mod format;
mod metrics;

pub use align::{associate, umeyama, Alignment, Similarity};
pub use format::TrajectoryFormat;
pub use metrics::{evaluate, ErrorStats, TrajectoryOptions, TrajectoryReport};

use nalgebra::Isometry3;

/// Poses in time: `poses[i]` (`world_T_body`) at `timestamps[i]` seconds (frame-indexed
/// formats without times use the index).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory {
    /// Seconds, non-decreasing.
    pub timestamps: Vec<f64>,
    /// The body in the world frame at each timestamp.
    pub poses: Vec<Isometry3<f64>>,
}

impl Trajectory {
    /// A trajectory from timestamps and poses, validated: the same count, finite timestamps
    /// that do not decrease, finite poses.
    pub fn new(timestamps: Vec<f64>, poses: Vec<Isometry3<f64>>) -> Result<Self, TrajectoryError> {
        if timestamps.len() != poses.len() {
            return Err(TrajectoryError::Invalid(format!(
                "{} timestamps for {} poses",
                timestamps.len(),
                poses.len()
            )));
        }
        if let Some(i) = timestamps.iter().position(|t| !t.is_finite()) {
            return Err(TrajectoryError::Invalid(format!(
                "timestamp {i} is {}",
                timestamps[i]
            )));
        }
        if let Some(i) = timestamps.windows(2).position(|w| w[1] < w[0]) {
            return Err(TrajectoryError::Invalid(format!(
                "timestamp {} ({}) is earlier than the one before ({})",
                i + 1,
                timestamps[i + 1],
                timestamps[i]
            )));
        }
        let finite = |p: &Isometry3<f64>| {
            p.translation.vector.iter().all(|v| v.is_finite())
                && p.rotation.coords.iter().all(|v| v.is_finite())
        };
        if let Some(i) = poses.iter().position(|p| !finite(p)) {
            return Err(TrajectoryError::Invalid(format!("pose {i} is not finite")));
        }
        Ok(Self { timestamps, poses })
    }

    /// Parses `text` in `format` (see [`TrajectoryFormat`]).
    pub fn parse(text: &str, format: TrajectoryFormat) -> Result<Self, TrajectoryError> {
        format::parse(text, format)
    }

    /// Reads and parses the file at `path` in `format`, or in the format its first data line
    /// shows when `None` ([`TrajectoryFormat::detect`]; [`TrajectoryError::UnknownFormat`]
    /// when it shows none).
    pub fn read(
        path: &std::path::Path,
        format: Option<TrajectoryFormat>,
    ) -> Result<Self, TrajectoryError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| TrajectoryError::Io(format!("{}: {e}", path.display())))?;
        let format = format
            .or_else(|| TrajectoryFormat::detect(&text))
            .ok_or(TrajectoryError::UnknownFormat)?;
        Self::parse(&text, format)
    }

    /// A trajectory from `timestamps` and, per pose, the 7 values of a TUM line after its
    /// timestamp (`tx ty tz qx qy qz qw`), validated as [`Trajectory::parse`] does.
    pub fn from_tum_values(timestamps: Vec<f64>, values: &[f64]) -> Result<Self, TrajectoryError> {
        if values.len() != 7 * timestamps.len() {
            return Err(TrajectoryError::Invalid(format!(
                "{} pose values for {} timestamps, 7 each",
                values.len(),
                timestamps.len()
            )));
        }
        let poses = values
            .chunks_exact(7)
            .enumerate()
            .map(|(i, p)| {
                format::pose([p[0], p[1], p[2]], [p[6], p[3], p[4], p[5]])
                    .map_err(|m| TrajectoryError::Invalid(format!("pose {i}: {m}")))
            })
            .collect::<Result<_, _>>()?;
        Self::new(timestamps, poses)
    }

    /// The same poses at `timestamps` (e.g. KITTI's `times.txt` for its frame-indexed poses).
    pub fn with_timestamps(self, timestamps: Vec<f64>) -> Result<Self, TrajectoryError> {
        Self::new(timestamps, self.poses)
    }

    /// Number of poses.
    pub fn len(&self) -> usize {
        self.poses.len()
    }

    /// True without poses.
    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    /// Path length: the sum of the distances between consecutive positions, metres.
    pub fn path_length(&self) -> f64 {
        path_length(&self.poses)
    }
}

/// The sum of the distances between consecutive positions of `poses`, metres.
fn path_length(poses: &[Isometry3<f64>]) -> f64 {
    poses
        .windows(2)
        .map(|w| (w[1].translation.vector - w[0].translation.vector).norm())
        .sum()
}

/// Why a trajectory could not be read or judged.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TrajectoryError {
    /// The file could not be read.
    #[error("cannot read the trajectory: {0}")]
    Io(String),
    /// The first data line matches no format (8 numbers: TUM, 12: KITTI, commas: EuRoC).
    #[error("cannot tell the trajectory format from the first data line (8 numbers: TUM, 12: KITTI, commas: EuRoC)")]
    UnknownFormat,
    /// A line of the text is malformed.
    #[error("line {line}: {message}")]
    Parse {
        /// 1-based line number.
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// The trajectory's values are unusable (counts, non-finite values, order).
    #[error("invalid trajectory: {0}")]
    Invalid(String),
    /// No estimated pose has a reference pose within the time tolerance, or too few to align
    /// or to measure.
    #[error("{0}")]
    TooFewPairs(String),
    /// The associated positions span less than a plane: no alignment exists.
    #[error("the associated positions are degenerate (collinear or coincident): Umeyama alignment is not possible")]
    Degenerate,
    /// An option is out of range.
    #[error("invalid option: {0}")]
    InvalidOption(String),
}
