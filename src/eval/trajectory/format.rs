//! Trajectory text formats: TUM, KITTI odometry, EuRoC ground-truth CSV.

use super::{Trajectory, TrajectoryError};
use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion};

/// How a trajectory file is laid out. Lines starting with `#` and blank lines are skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrajectoryFormat {
    /// TUM RGB-D: `timestamp tx ty tz qx qy qz qw` per line (seconds, metres, Hamilton
    /// quaternion with w last), whitespace-separated.
    Tum,
    /// KITTI odometry: 12 numbers per line, the row-major 3x4 `[R | t]` of `world_T_camera`;
    /// no timestamps (the frame index is used; see [`Trajectory::with_timestamps`]).
    Kitti,
    /// EuRoC ground truth CSV: `timestamp_ns, px, py, pz, qw, qx, qy, qz, ...` (w first;
    /// further columns ignored).
    Euroc,
}

impl TrajectoryFormat {
    /// The format of `text` by its first data line: comma-separated is EuRoC, 8 numbers TUM,
    /// 12 KITTI; `None` otherwise.
    pub fn detect(text: &str) -> Option<Self> {
        let line = text
            .lines()
            .map(str::trim)
            .find(|l| !l.is_empty() && !l.starts_with('#'))?;
        if line.contains(',') {
            return Some(TrajectoryFormat::Euroc);
        }
        match line.split_whitespace().count() {
            8 => Some(TrajectoryFormat::Tum),
            12 => Some(TrajectoryFormat::Kitti),
            _ => None,
        }
    }

    /// Lower-case name (`tum`, `kitti`, `euroc`).
    pub fn name(self) -> &'static str {
        match self {
            TrajectoryFormat::Tum => "tum",
            TrajectoryFormat::Kitti => "kitti",
            TrajectoryFormat::Euroc => "euroc",
        }
    }
}

/// Largest deviation of a quaternion's norm from 1, and of `R^T R` from the identity, that a
/// file may hold (rounding in the file, not a different rotation).
const ROTATION_TOLERANCE: f64 = 1e-2;

pub(super) fn parse(text: &str, format: TrajectoryFormat) -> Result<Trajectory, TrajectoryError> {
    let (mut timestamps, mut poses) = (Vec::new(), Vec::new());
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = |message: String| TrajectoryError::Parse {
            line: n + 1,
            message,
        };
        let values: Vec<f64> = match format {
            TrajectoryFormat::Euroc => line
                .split(',')
                .map(str::trim)
                .map(number)
                .collect::<Result<_, _>>(),
            _ => line.split_whitespace().map(number).collect(),
        }
        .map_err(bad)?;
        let (timestamp, pose) = match format {
            TrajectoryFormat::Tum => {
                let [t, x, y, z, qx, qy, qz, qw] = values[..] else {
                    return Err(bad(format!("{} values, TUM has 8", values.len())));
                };
                (t, pose([x, y, z], [qw, qx, qy, qz]).map_err(bad)?)
            }
            TrajectoryFormat::Euroc => {
                let [t, x, y, z, qw, qx, qy, qz, ..] = values[..] else {
                    return Err(bad(format!(
                        "{} values, EuRoC has at least 8",
                        values.len()
                    )));
                };
                (t / 1e9, pose([x, y, z], [qw, qx, qy, qz]).map_err(bad)?)
            }
            TrajectoryFormat::Kitti => {
                let [r00, r01, r02, x, r10, r11, r12, y, r20, r21, r22, z] = values[..] else {
                    return Err(bad(format!("{} values, KITTI has 12", values.len())));
                };
                let r = Matrix3::new(r00, r01, r02, r10, r11, r12, r20, r21, r22);
                (poses.len() as f64, kitti_pose([x, y, z], r).map_err(bad)?)
            }
        };
        timestamps.push(timestamp);
        poses.push(pose);
    }
    Trajectory::new(timestamps, poses)
}

fn number(field: &str) -> Result<f64, String> {
    let value: f64 = field
        .parse()
        .map_err(|_| format!("{field:?} is not a number"))?;
    if value.is_finite() {
        Ok(value)
    } else {
        Err(format!("{field} is not finite"))
    }
}

/// A pose from a position and a quaternion `[w, x, y, z]` whose norm is 1 up to rounding.
pub(super) fn pose(t: [f64; 3], q: [f64; 4]) -> Result<Isometry3<f64>, String> {
    let q = Quaternion::new(q[0], q[1], q[2], q[3]);
    if (q.norm() - 1.0).abs() > ROTATION_TOLERANCE {
        return Err(format!("the quaternion's norm is {}, not 1", q.norm()));
    }
    Ok(Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// A pose from a position and a matrix that is a rotation up to rounding.
fn kitti_pose(t: [f64; 3], r: Matrix3<f64>) -> Result<Isometry3<f64>, String> {
    let off = (r.transpose() * r - Matrix3::identity()).abs().max();
    if off > ROTATION_TOLERANCE || r.determinant() <= 0.0 {
        return Err(format!(
            "the 3x3 part is not a rotation (R^T R differs from I by {off}, det {})",
            r.determinant()
        ));
    }
    // The nearest rotation (polar decomposition by SVD).
    let svd = r.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err("the 3x3 part has no SVD".into());
    };
    let rotation = Rotation3::from_matrix_unchecked(u * v_t);
    Ok(Isometry3::from_parts(
        Translation3::new(t[0], t[1], t[2]),
        UnitQuaternion::from_rotation_matrix(&rotation),
    ))
}
