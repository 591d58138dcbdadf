//! Camera trajectories in the TUM RGB-D format: one pose per line,
//! `timestamp tx ty tz qx qy qz qw` (`world_T_camera`, metres), `#` comments.

use crate::map::MapError;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use std::path::Path;

/// One timestamped pose of a TUM file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimedPose {
    /// Time in seconds.
    pub timestamp: f64,
    /// `world_T_camera`.
    pub world_t_camera: Isometry3<f64>,
}

/// Parses TUM text; errors name the line and what is wrong with it.
pub fn parse_tum(text: &str) -> Result<Vec<TimedPose>, MapError> {
    let mut poses = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad =
            |why: String| MapError::InvalidArgument(format!("TUM line {}: {why}", number + 1));
        let values: Vec<f64> = line
            .split_whitespace()
            .map(|v| v.parse::<f64>().map_err(|e| bad(format!("'{v}': {e}"))))
            .collect::<Result<_, _>>()?;
        if values.len() != 8 {
            return Err(bad(format!(
                "{} values, expected 8 (timestamp tx ty tz qx qy qz qw)",
                values.len()
            )));
        }
        if !values.iter().all(|v| v.is_finite()) {
            return Err(bad("non-finite value".into()));
        }
        let q = Quaternion::new(values[7], values[4], values[5], values[6]);
        if q.norm() < 1e-9 {
            return Err(bad("zero quaternion".into()));
        }
        poses.push(TimedPose {
            timestamp: values[0],
            world_t_camera: Isometry3::from_parts(
                Translation3::new(values[1], values[2], values[3]),
                UnitQuaternion::from_quaternion(q),
            ),
        });
    }
    Ok(poses)
}

/// Reads a TUM trajectory file.
pub fn read_tum(path: &Path) -> Result<Vec<TimedPose>, MapError> {
    let text = std::fs::read_to_string(path).map_err(|source| MapError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_tum(&text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_poses_and_names_bad_lines() {
        let poses =
            parse_tum("# t x y z qx qy qz qw\n1.5 1 2 3 0 0 0 2\n\n2.0 0 0 0 0 0 1 0\n").unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[0].timestamp, 1.5);
        assert_eq!(poses[0].world_t_camera.translation.vector.y, 2.0);
        assert!(
            (poses[0].world_t_camera.rotation.w - 1.0).abs() < 1e-12,
            "normalised"
        );
        let err = parse_tum("1 2 3\n").unwrap_err().to_string();
        assert!(err.contains("line 1") && err.contains("3 values"), "{err}");
        let err = parse_tum("0 0 0 0 0 0 0 1\n1 0 0 x 0 0 0 1\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("line 2") && err.contains("'x'"), "{err}");
        assert!(parse_tum("0 0 0 0 0 0 0 0\n").is_err());
    }
}
