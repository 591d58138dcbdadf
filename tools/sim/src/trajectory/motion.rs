//! Time along a dense path: the speed profile, stops and turns in place, and frame sampling with
//! a rate-limited, noisy heading.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use rand::rngs::SmallRng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use topoloc::build::TimedPose;

/// How the vehicle moves along a path and how frames are taken.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MotionOptions {
    /// Frame rate, Hz (1..=100; 10 to 20 is typical). Default 15.
    pub rate_hz: f64,
    /// Each leg (start to goal) cruises at a speed drawn uniformly from this range, m/s
    /// (0 < min <= max <= 5). Default `(0.5, 1.5)`.
    pub speed_range_mps: (f64, f64),
    /// Acceleration and braking, m/s^2 (0.05..=10). Default 0.5.
    pub accel_mps2: f64,
    /// Most lateral (centripetal) acceleration in turns, m/s^2 (0.05..=20). Default 0.5.
    pub lateral_accel_mps2: f64,
    /// Most yaw rate, rad/s (0.1..=2 pi); the speed drops in turns so that the heading can
    /// follow. Default 1.0 (57 deg/s).
    pub max_yaw_rate_rad_s: f64,
    /// Radius of the arcs that round path corners, metres (0..=10; 0 keeps corners sharp:
    /// stop and turn in place). Default 0.8.
    pub corner_radius_m: f64,
    /// Standard deviation of the heading noise, radians (0..=pi/4). Default 0.05 (3 deg).
    pub yaw_noise_std_rad: f64,
    /// Standard deviation of the pitch and roll noise, radians (0..=0.5). Default 0: level
    /// camera.
    pub tilt_noise_std_rad: f64,
    /// Correlation time of the angle noise, seconds (0.01..=60). Default 1.
    pub noise_tau_s: f64,
    /// Pause at each goal before the next leg, seconds (0..=60), after turning to the new
    /// direction in place. Default 0.5.
    pub goal_pause_s: f64,
}

impl Default for MotionOptions {
    fn default() -> Self {
        Self {
            rate_hz: 15.0,
            speed_range_mps: (0.5, 1.5),
            accel_mps2: 0.5,
            lateral_accel_mps2: 0.5,
            max_yaw_rate_rad_s: 1.0,
            corner_radius_m: 0.8,
            yaw_noise_std_rad: 0.05,
            tilt_noise_std_rad: 0.0,
            noise_tau_s: 1.0,
            goal_pause_s: 0.5,
        }
    }
}

/// A turn sharper than this at one path vertex (radians) is taken by stopping and turning in
/// place: it is a corner the smoother could not round.
const SHARP_TURN_RAD: f64 = 0.6;

/// Horizontal step below which a segment has no heading of its own (metres).
const MIN_HEADING_STEP_M: f64 = 1e-3;

/// One vertex of the dense path.
#[derive(Clone, Copy, Debug)]
pub(super) struct Knot {
    pub position: Point3<f64>,
    /// The vehicle stops here (a goal); it turns in place and pauses `pause_s`.
    pub stop: bool,
    /// Seconds to wait here after turning (goals only).
    pub pause_s: f64,
    /// Cruise speed of the segment leaving this knot, m/s.
    pub cruise_mps: f64,
}

/// Wraps an angle to (-pi, pi].
pub(crate) fn wrap_angle(a: f64) -> f64 {
    let w = (a + PI).rem_euclid(2.0 * PI) - PI;
    if w <= -PI {
        w + 2.0 * PI
    } else {
        w
    }
}

/// The sampled motion: frames and the time each knot is reached.
pub(super) struct Sampled {
    pub frames: Vec<TimedPose>,
    pub arrival_s: Vec<f64>,
}

/// Times the path (accelerate, cruise, slow in turns, stop at goals and sharp corners, turn in
/// place there) and samples it at `motion.rate_hz`.
pub(super) fn sample(knots: &[Knot], motion: &MotionOptions, rng: &mut SmallRng) -> Sampled {
    let n = knots.len();
    let ds: Vec<f64> = knots
        .windows(2)
        .map(|w| (w[1].position - w[0].position).norm())
        .collect();
    let headings = segment_headings(knots);
    // Turn angle (3D) and heading change at each knot, between its incoming and outgoing segments.
    let mut turn = vec![0.0; n];
    let mut heading_change = vec![0.0; n];
    for i in 1..n.saturating_sub(1) {
        let (a, b) = (
            knots[i].position - knots[i - 1].position,
            knots[i + 1].position - knots[i].position,
        );
        turn[i] = (a.dot(&b) / (a.norm() * b.norm())).clamp(-1.0, 1.0).acos();
        heading_change[i] = wrap_angle(headings[i] - headings[i - 1]);
    }
    let stops: Vec<bool> = (0..n)
        .map(|i| i == 0 || i + 1 == n || knots[i].stop || turn[i] > SHARP_TURN_RAD)
        .collect();
    let mut speed: Vec<f64> = (0..n)
        .map(|i| {
            if stops[i] {
                return 0.0;
            }
            let span = (ds[i - 1] + ds[i]) / 2.0;
            let mut v = knots[i - 1].cruise_mps.min(knots[i].cruise_mps);
            if turn[i] > 0.0 {
                v = v.min((motion.lateral_accel_mps2 * span / turn[i]).sqrt());
            }
            if heading_change[i] != 0.0 {
                v = v.min(motion.max_yaw_rate_rad_s * span / heading_change[i].abs());
            }
            v
        })
        .collect();
    let a = motion.accel_mps2;
    for i in 1..n {
        speed[i] = speed[i].min((speed[i - 1].powi(2) + 2.0 * a * ds[i - 1]).sqrt());
    }
    for i in (0..n.saturating_sub(1)).rev() {
        speed[i] = speed[i].min((speed[i + 1].powi(2) + 2.0 * a * ds[i]).sqrt());
    }
    let duration: Vec<f64> = (0..n.saturating_sub(1))
        .map(|i| {
            let sum = speed[i] + speed[i + 1];
            if sum > 1e-9 {
                2.0 * ds[i] / sum
            } else {
                2.0 * (ds[i] / a).sqrt()
            }
        })
        .collect();
    let dwell: Vec<f64> = (0..n)
        .map(|i| {
            if i == 0 || i + 1 == n || !stops[i] {
                0.0
            } else {
                heading_change[i].abs() / motion.max_yaw_rate_rad_s + knots[i].pause_s
            }
        })
        .collect();
    let mut arrival_s = vec![0.0; n];
    for i in 1..n {
        arrival_s[i] = arrival_s[i - 1] + dwell[i - 1] + duration[i - 1];
    }
    let end = arrival_s[n - 1];

    let dt = 1.0 / motion.rate_hz;
    let frame_count = (end * motion.rate_hz + 1e-9).floor() as usize + 1;
    let mut noise = NoiseProcess::new(motion, dt, rng);
    let mut frames = Vec::with_capacity(frame_count);
    let mut i = 0;
    let mut yaw = headings.first().copied().unwrap_or(0.0);
    for k in 0..frame_count {
        let t = k as f64 * dt;
        while i + 1 < n && t >= arrival_s[i + 1] {
            i += 1;
        }
        let depart = arrival_s[i] + dwell[i];
        let (position, desired) = if i + 1 == n || t <= depart {
            let outgoing = headings.get(i).or(headings.last()).copied().unwrap_or(yaw);
            (knots[i].position, outgoing)
        } else {
            let tau = t - depart;
            let s = travelled(tau, duration[i], speed[i], speed[i + 1], a);
            let fraction = (s / ds[i]).clamp(0.0, 1.0);
            let (p, q) = (knots[i].position, knots[i + 1].position);
            (p + (q - p) * fraction, headings[i])
        };
        if k > 0 {
            let step = motion.max_yaw_rate_rad_s * dt;
            yaw = wrap_angle(yaw + wrap_angle(desired - yaw).clamp(-step, step));
        }
        let [yaw_noise, pitch, roll] = noise.next(rng);
        let rotation = UnitQuaternion::from_euler_angles(roll, -pitch, wrap_angle(yaw + yaw_noise));
        frames.push(TimedPose {
            timestamp: t,
            world_t_camera: Isometry3::from_parts(Translation3::from(position.coords), rotation),
        });
    }
    Sampled { frames, arrival_s }
}

/// Distance covered `tau` seconds into a segment of `duration` seconds entered at `v0` and
/// left at `v1` (constant acceleration; accelerate-then-brake when both speeds are zero).
fn travelled(tau: f64, duration: f64, v0: f64, v1: f64, accel: f64) -> f64 {
    if v0 + v1 > 1e-9 {
        v0 * tau + 0.5 * (v1 - v0) / duration * tau * tau
    } else if tau <= duration / 2.0 {
        0.5 * accel * tau * tau
    } else {
        let left = duration - tau;
        accel * (duration / 2.0).powi(2) - 0.5 * accel * left * left
    }
}

/// Heading (yaw of the horizontal direction) of each segment; nearly vertical segments inherit
/// their neighbour's.
fn segment_headings(knots: &[Knot]) -> Vec<f64> {
    let own: Vec<Option<f64>> = knots
        .windows(2)
        .map(|w| {
            let d = w[1].position - w[0].position;
            (d.xy().norm() > MIN_HEADING_STEP_M).then(|| d.y.atan2(d.x))
        })
        .collect();
    let first = own.iter().flatten().next().copied().unwrap_or(0.0);
    let mut last = first;
    own.iter()
        .map(|h| {
            last = h.unwrap_or(last);
            last
        })
        .collect()
}

/// Correlated (Ornstein-Uhlenbeck) noise on yaw, pitch and roll, stationary from the start.
struct NoiseProcess {
    keep: f64,
    std: [f64; 3],
    state: [f64; 3],
}

impl NoiseProcess {
    fn new(motion: &MotionOptions, dt: f64, rng: &mut SmallRng) -> Self {
        let std = [
            motion.yaw_noise_std_rad,
            motion.tilt_noise_std_rad,
            motion.tilt_noise_std_rad,
        ];
        let state =
            std.map(|s| s * <StandardNormal as Distribution<f64>>::sample(&StandardNormal, rng));
        Self {
            keep: (-dt / motion.noise_tau_s).exp(),
            std,
            state,
        }
    }

    fn next(&mut self, rng: &mut SmallRng) -> [f64; 3] {
        let fresh = (1.0 - self.keep * self.keep).sqrt();
        for k in 0..3 {
            let w: f64 = StandardNormal.sample(rng);
            self.state[k] = self.keep * self.state[k] + fresh * self.std[k] * w;
        }
        self.state
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_angle_stays_in_range() {
        for a in [-7.0, -PI, -1.0, 0.0, 1.0, PI, 7.0, 3.0 * PI] {
            let w = wrap_angle(a);
            assert!(w > -PI - 1e-12 && w <= PI + 1e-12, "{a} -> {w}");
            assert!((a.cos() - w.cos()).abs() < 1e-12 && (a.sin() - w.sin()).abs() < 1e-12);
        }
    }

    #[test]
    fn zero_speed_segments_accelerate_then_brake() {
        let duration = 2.0 * (1.0f64 / 0.5).sqrt();
        assert!((travelled(duration, duration, 0.0, 0.0, 0.5) - 1.0).abs() < 1e-12);
        assert!((travelled(duration / 2.0, duration, 0.0, 0.0, 0.5) - 0.5).abs() < 1e-12);
        assert!((travelled(2.0, 2.0, 0.5, 1.5, 0.5) - 2.0).abs() < 1e-12);
    }
}
