//! A drifting odometry stream beside the ground truth, as a visual-inertial odometry would give:
//! the frame-to-frame motions of the ground truth, corrupted by a scale error, a gyro (yaw) bias
//! and white noise, integrated from the first ground-truth pose.
//!
//! Roll and pitch follow the ground truth (gravity makes them observable to a VIO); heading and
//! position drift. With drift angle `d_k` (odometry heading minus true heading) the model is
//!
//! ```text
//! d_k = d_{k-1} + yaw_bias * dt_k + N(0, yaw_noise^2 * dt_k)
//! p'_k = p'_{k-1} + Rz(d_{k-1}) * (1 + scale_error) * (p_k - p_{k-1}) + N(0, trans_noise^2 * |p_k - p_{k-1}|) per axis
//! R'_k = Rz(d_k) * R_k
//! ```
//!
//! which equals integrating the body-frame motions `(T_{k-1})^-1 T_k` with the corrupted
//! heading.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::rngs::SmallRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use topoloc::build::TimedPose;

/// How odometry drifts. All zero: odometry equals the ground truth.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct OdometryNoise {
    /// Relative translation scale error: every step is stretched by `1 + scale_error`
    /// (-0.5..=0.5).
    pub scale_error: f64,
    /// Gyro bias about world z, rad/s (-0.5..=0.5): the heading drifts by this much per second.
    pub yaw_bias_rad_s: f64,
    /// Heading random walk, rad/sqrt(s) (0..=1): white gyro noise integrated.
    pub yaw_noise_rad_per_sqrt_s: f64,
    /// Translation white noise, m/sqrt(m) (0..=1): per axis, the standard deviation of a step's
    /// error is this times the square root of the step length.
    pub translation_noise_m_per_sqrt_m: f64,
}

impl Default for OdometryNoise {
    fn default() -> Self {
        Self::typical_vio()
    }
}

impl OdometryNoise {
    /// No noise: odometry equals the ground truth.
    pub fn none() -> Self {
        Self {
            scale_error: 0.0,
            yaw_bias_rad_s: 0.0,
            yaw_noise_rad_per_sqrt_s: 0.0,
            translation_noise_m_per_sqrt_m: 0.0,
        }
    }

    /// A good VIO: 1% scale error, 0.1 deg/s residual gyro bias, small noise (about 1% drift
    /// of the distance travelled).
    pub fn typical_vio() -> Self {
        Self {
            scale_error: 0.01,
            yaw_bias_rad_s: 0.1f64.to_radians(),
            yaw_noise_rad_per_sqrt_s: 0.002,
            translation_noise_m_per_sqrt_m: 0.01,
        }
    }

    /// A struggling odometry (texture-poor scenes, fast turns): 5% scale error, 0.5 deg/s
    /// bias, five times the noise of [`typical_vio`](Self::typical_vio).
    pub fn bad() -> Self {
        Self {
            scale_error: 0.05,
            yaw_bias_rad_s: 0.5f64.to_radians(),
            yaw_noise_rad_per_sqrt_s: 0.01,
            translation_noise_m_per_sqrt_m: 0.05,
        }
    }

    /// The preset called `name`: `"none"`, `"vio"` or `"bad"`.
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "none" => Some(Self::none()),
            "vio" => Some(Self::typical_vio()),
            "bad" => Some(Self::bad()),
            _ => None,
        }
    }

    /// Checks ranges; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        for (field, value, min, max) in [
            ("odometry.scale_error", self.scale_error, -0.5, 0.5),
            ("odometry.yaw_bias_rad_s", self.yaw_bias_rad_s, -0.5, 0.5),
            (
                "odometry.yaw_noise_rad_per_sqrt_s",
                self.yaw_noise_rad_per_sqrt_s,
                0.0,
                1.0,
            ),
            (
                "odometry.translation_noise_m_per_sqrt_m",
                self.translation_noise_m_per_sqrt_m,
                0.0,
                1.0,
            ),
        ] {
            if !(value.is_finite() && (min..=max).contains(&value)) {
                return Err(format!("{field} is {value}: must lie in [{min}, {max}]"));
            }
        }
        Ok(())
    }
}

/// The odometry stream of `ground_truth` (same timestamps), drifting as `noise` says, noise
/// drawn from `seed`. The first pose equals the ground truth's. Fails with the reason of
/// [`OdometryNoise::validate`], or when timestamps go backwards (naming the frame).
pub fn odometry(
    ground_truth: &[TimedPose],
    noise: &OdometryNoise,
    seed: u64,
) -> Result<Vec<TimedPose>, String> {
    noise.validate()?;
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut gauss = || -> f64 { StandardNormal.sample(&mut rng) };
    let Some(first) = ground_truth.first() else {
        return Ok(Vec::new());
    };
    let mut out = Vec::with_capacity(ground_truth.len());
    out.push(*first);
    let mut drift = 0.0;
    let mut position = first.world_t_camera.translation.vector;
    for (k, pair) in ground_truth.windows(2).enumerate() {
        let dt = pair[1].timestamp - pair[0].timestamp;
        if dt.is_nan() || dt < 0.0 {
            return Err(format!(
                "ground truth frame {}: timestamp {} is before the previous {}",
                k + 1,
                pair[1].timestamp,
                pair[0].timestamp
            ));
        }
        let step =
            pair[1].world_t_camera.translation.vector - pair[0].world_t_camera.translation.vector;
        let spread = noise.translation_noise_m_per_sqrt_m * step.norm().sqrt();
        let jitter = Vector3::new(gauss(), gauss(), gauss()) * spread;
        let heading = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), drift);
        position += heading * (step * (1.0 + noise.scale_error)) + jitter;
        drift += noise.yaw_bias_rad_s * dt + noise.yaw_noise_rad_per_sqrt_s * dt.sqrt() * gauss();
        let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), drift)
            * pair[1].world_t_camera.rotation;
        out.push(TimedPose {
            timestamp: pair[1].timestamp,
            world_t_camera: Isometry3::from_parts(Translation3::from(position), rotation),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{pose, yaw_of};
    use nalgebra::Point3;

    /// A 1 m/s walk at 10 Hz: straight along x for `straight` frames, then a circle.
    fn walk(frames: usize) -> Vec<TimedPose> {
        (0..frames)
            .map(|k| {
                let t = k as f64 / 10.0;
                let (position, yaw) = if t < 20.0 {
                    (Point3::new(t, 0.0, 1.5), 0.0)
                } else {
                    let a = (t - 20.0) / 5.0;
                    (
                        Point3::new(20.0 + 5.0 * a.sin(), 5.0 - 5.0 * a.cos(), 1.5),
                        a,
                    )
                };
                TimedPose {
                    timestamp: t,
                    world_t_camera: pose(position, yaw, 0.05 * t.sin()),
                }
            })
            .collect()
    }

    fn error_at(a: &[TimedPose], b: &[TimedPose], k: usize) -> f64 {
        (a[k].world_t_camera.translation.vector - b[k].world_t_camera.translation.vector).norm()
    }

    #[test]
    fn zero_noise_reproduces_the_ground_truth() {
        let truth = walk(400);
        let odom = odometry(&truth, &OdometryNoise::none(), 5).unwrap();
        assert_eq!(odom.len(), truth.len());
        for (a, b) in odom.iter().zip(&truth) {
            assert_eq!(a.timestamp, b.timestamp);
            assert!(
                (a.world_t_camera.translation.vector - b.world_t_camera.translation.vector).norm()
                    < 1e-9
            );
            assert!(
                a.world_t_camera
                    .rotation
                    .angle_to(&b.world_t_camera.rotation)
                    < 1e-9
            );
        }
    }

    #[test]
    fn bias_makes_drift_grow_with_distance() {
        let truth = walk(200); // straight: 20 m
        let biased = OdometryNoise {
            yaw_bias_rad_s: 0.01,
            ..OdometryNoise::none()
        };
        let odom = odometry(&truth, &biased, 1).unwrap();
        let errors: Vec<f64> = [0, 50, 100, 199]
            .iter()
            .map(|&k| error_at(&odom, &truth, k))
            .collect();
        assert_eq!(errors[0], 0.0);
        assert!(errors.windows(2).all(|w| w[1] > w[0]), "{errors:?}");
        // Heading drift d = bias t bends a straight line: lateral error ~ bias t^2 / 2 at 1 m/s.
        let expected = 0.01 * 19.9f64.powi(2) / 2.0;
        assert!(
            (errors[3] - expected).abs() < 0.05 * expected,
            "{} vs {expected}",
            errors[3]
        );
        let heading_error = yaw_of(&odom[199].world_t_camera) - yaw_of(&truth[199].world_t_camera);
        assert!((heading_error - 0.199).abs() < 1e-9);
        // Roll and pitch are kept: only the heading drifts.
        let pitch = |p: &TimedPose| (p.world_t_camera.rotation * Vector3::x()).z;
        assert!((pitch(&odom[150]) - pitch(&truth[150])).abs() < 1e-12);

        let scaled = OdometryNoise {
            scale_error: 0.05,
            ..OdometryNoise::none()
        };
        let odom = odometry(&truth, &scaled, 1).unwrap();
        assert!(
            (error_at(&odom, &truth, 100) - 0.5).abs() < 1e-9,
            "5% of 10 m"
        );
    }

    #[test]
    fn presets_rank_by_drift_and_noise_is_seeded() {
        let truth = walk(600);
        let last = truth.len() - 1;
        let mean_error = |noise: OdometryNoise| {
            (0..20)
                .map(|seed| error_at(&odometry(&truth, &noise, seed).unwrap(), &truth, last))
                .sum::<f64>()
                / 20.0
        };
        let (vio, bad) = (
            mean_error(OdometryNoise::typical_vio()),
            mean_error(OdometryNoise::bad()),
        );
        assert!(vio > 0.0 && bad > 2.0 * vio, "vio {vio}, bad {bad}");
        let noise = OdometryNoise::typical_vio();
        assert_eq!(
            odometry(&truth, &noise, 3).unwrap(),
            odometry(&truth, &noise, 3).unwrap()
        );
        assert_ne!(
            odometry(&truth, &noise, 3).unwrap(),
            odometry(&truth, &noise, 4).unwrap()
        );
        assert_eq!(OdometryNoise::preset("bad"), Some(OdometryNoise::bad()));
        assert_eq!(OdometryNoise::preset("worse"), None);
    }

    #[test]
    fn bad_input_is_named() {
        let bad = OdometryNoise {
            scale_error: f64::NAN,
            ..OdometryNoise::none()
        };
        assert!(odometry(&walk(3), &bad, 0)
            .unwrap_err()
            .contains("odometry.scale_error"));
        let mut truth = walk(3);
        truth[2].timestamp = 0.0;
        assert!(odometry(&truth, &OdometryNoise::none(), 0)
            .unwrap_err()
            .contains("frame 2"));
        assert!(odometry(&[], &OdometryNoise::bad(), 0).unwrap().is_empty());
    }
}
