//! Odometry for `topoloc localize`: a TUM trajectory (`timestamp tx ty tz qx qy qz qw`,
//! `world_T_camera`) read with errors that name the line and the field, and its poses matched
//! to frame times (the nearest pose within a tolerance).

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use std::path::{Path, PathBuf};
use topoloc::build::TimedPose;

/// The fields of a TUM line, in order.
pub const TUM_FIELDS: [&str; 8] = ["timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"];

/// What is wrong with a TUM file; every variant names the file, and the line when there is one.
#[derive(Debug, thiserror::Error)]
pub enum TumError {
    /// The file cannot be read.
    #[error("cannot read odometry file {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A line has another number of fields than 8.
    #[error("{} line {line}: {found} fields, expected 8 (timestamp tx ty tz qx qy qz qw)", path.display())]
    FieldCount {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Fields found.
        found: usize,
    },
    /// A field is not a number.
    #[error("{} line {line}, field {column} ({field}): '{text}' is not a number", path.display())]
    NotANumber {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// 1-based field number.
        column: usize,
        /// Field name (see [`TUM_FIELDS`]).
        field: &'static str,
        /// The text found.
        text: String,
    },
    /// A field is NaN or infinite.
    #[error("{} line {line}, field {column} ({field}): {value} is not finite", path.display())]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// 1-based field number.
        column: usize,
        /// Field name.
        field: &'static str,
        /// The value.
        value: f64,
    },
    /// The quaternion is (close to) zero.
    #[error("{} line {line}, fields 5-8 (qx qy qz qw): zero quaternion", path.display())]
    ZeroQuaternion {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
    },
    /// A timestamp is earlier than the previous pose's.
    #[error("{} line {line}, field 1 (timestamp): {timestamp} is earlier than {previous} on line {previous_line}; a TUM trajectory is in time order", path.display())]
    Backwards {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Its timestamp.
        timestamp: f64,
        /// Line of the previous pose.
        previous_line: usize,
        /// Its timestamp.
        previous: f64,
    },
    /// No pose at all (only comments or blank lines).
    #[error("{} holds no pose (expected lines 'timestamp tx ty tz qx qy qz qw')", path.display())]
    Empty {
        /// The file.
        path: PathBuf,
    },
}

/// A TUM trajectory in time order.
#[derive(Clone, Debug)]
pub struct Odometry {
    /// Poses, timestamps non-decreasing.
    pub poses: Vec<TimedPose>,
}

impl Odometry {
    /// Reads and checks a TUM file (`#` comments and blank lines allowed).
    pub fn read(path: &Path) -> Result<Self, TumError> {
        let text = std::fs::read_to_string(path).map_err(|source| TumError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses TUM text; `path` only names the source in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, TumError> {
        let path_buf = || path.to_path_buf();
        let mut poses: Vec<TimedPose> = Vec::new();
        let mut previous_line = 0;
        for (number, raw) in text.lines().enumerate() {
            let line = number + 1;
            let trimmed = raw.trim();
            if trimmed.is_empty() || trimmed.starts_with('#') {
                continue;
            }
            let fields: Vec<&str> = trimmed.split_whitespace().collect();
            if fields.len() != TUM_FIELDS.len() {
                return Err(TumError::FieldCount {
                    path: path_buf(),
                    line,
                    found: fields.len(),
                });
            }
            let mut v = [0.0f64; 8];
            for (k, text) in fields.iter().enumerate() {
                let value = text.parse::<f64>().map_err(|_| TumError::NotANumber {
                    path: path_buf(),
                    line,
                    column: k + 1,
                    field: TUM_FIELDS[k],
                    text: (*text).to_string(),
                })?;
                if !value.is_finite() {
                    return Err(TumError::NonFinite {
                        path: path_buf(),
                        line,
                        column: k + 1,
                        field: TUM_FIELDS[k],
                        value,
                    });
                }
                v[k] = value;
            }
            let q = Quaternion::new(v[7], v[4], v[5], v[6]);
            if q.norm() < 1e-9 {
                return Err(TumError::ZeroQuaternion {
                    path: path_buf(),
                    line,
                });
            }
            if let Some(last) = poses.last().filter(|p| v[0] < p.timestamp) {
                return Err(TumError::Backwards {
                    path: path_buf(),
                    line,
                    timestamp: v[0],
                    previous_line,
                    previous: last.timestamp,
                });
            }
            previous_line = line;
            poses.push(TimedPose {
                timestamp: v[0],
                world_t_camera: Isometry3::from_parts(
                    Translation3::new(v[1], v[2], v[3]),
                    UnitQuaternion::from_quaternion(q),
                ),
            });
        }
        if poses.is_empty() {
            return Err(TumError::Empty { path: path_buf() });
        }
        Ok(Self { poses })
    }

    /// The pose nearest in time to `t`, if it lies within `tolerance` seconds (ties: the
    /// earlier pose).
    pub fn pose_at(&self, t: f64, tolerance: f64) -> Option<&TimedPose> {
        let after = self.poses.partition_point(|p| p.timestamp < t);
        let candidates = [after.checked_sub(1), Some(after)];
        candidates
            .into_iter()
            .flatten()
            .filter_map(|i| self.poses.get(i))
            .min_by(|a, b| (a.timestamp - t).abs().total_cmp(&(b.timestamp - t).abs()))
            .filter(|p| (p.timestamp - t).abs() <= tolerance)
    }

    /// Time of the first and the last pose.
    pub fn span(&self) -> (f64, f64) {
        (
            self.poses[0].timestamp,
            self.poses[self.poses.len() - 1].timestamp,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Odometry, TumError> {
        Odometry::parse(text, Path::new("odo.txt"))
    }

    #[test]
    fn errors_name_the_line_and_the_field() {
        let err = parse("# header\n0 0 0 0 0 0 0 1\n1 0 0 x 0 0 0 1\n")
            .unwrap_err()
            .to_string();
        assert_eq!(err, "odo.txt line 3, field 4 (tz): 'x' is not a number");
        let err = parse("0 0 0\n").unwrap_err().to_string();
        assert!(err.contains("line 1: 3 fields, expected 8"), "{err}");
        let err = parse("0 0 0 0 0 0 0 inf\n").unwrap_err().to_string();
        assert!(err.contains("field 8 (qw): inf is not finite"), "{err}");
        let err = parse("0 0 0 0 0 0 0 0\n").unwrap_err().to_string();
        assert!(
            err.contains("line 1") && err.contains("zero quaternion"),
            "{err}"
        );
        let err = parse("2 0 0 0 0 0 0 1\n\n1 0 0 0 0 0 0 1\n")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("line 3, field 1 (timestamp): 1 is earlier than 2 on line 1"),
            "{err}"
        );
        assert!(matches!(parse("# only\n"), Err(TumError::Empty { .. })));
    }

    #[test]
    fn frames_take_the_nearest_pose_within_the_tolerance() {
        let odometry = parse("0.0 0 0 0 0 0 0 1\n0.1 1 0 0 0 0 0 1\n0.2 2 0 0 0 0 0 2\n").unwrap();
        let x = |t: f64, tol: f64| {
            odometry
                .pose_at(t, tol)
                .map(|p| p.world_t_camera.translation.x)
        };
        assert_eq!(x(0.0, 0.02), Some(0.0));
        assert_eq!(x(0.09, 0.02), Some(1.0));
        assert_eq!(x(0.14, 0.05), Some(1.0));
        assert_eq!(x(0.16, 0.05), Some(2.0));
        assert_eq!(x(0.05, 0.02), None, "between poses, beyond the tolerance");
        assert_eq!(x(0.215, 0.02), Some(2.0), "after the last pose");
        assert_eq!(x(-0.5, 0.02), None, "before the first pose");
        let q = odometry.poses[2].world_t_camera.rotation;
        assert!((q.w - 1.0).abs() < 1e-12, "normalised");
        assert_eq!(odometry.span(), (0.0, 0.2));
    }
}
