//! Pinhole intrinsics and body poses (see the crate documentation for the frames).

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// `world_T_body`: the body (and camera) frame in the world; x forward, y left, z up.
pub type Pose = Isometry3<f64>;

/// A pose at `position` with heading `yaw` (radians, about world z, 0 = world +x) and `pitch`
/// (radians, positive looks up).
pub fn pose(position: Point3<f64>, yaw: f64, pitch: f64) -> Pose {
    let rotation = UnitQuaternion::from_euler_angles(0.0, -pitch, yaw);
    Isometry3::from_parts(Translation3::from(position.coords), rotation)
}

/// The heading of a pose: the yaw of its x axis projected on the world xy plane, in (-pi, pi].
pub fn yaw_of(pose: &Pose) -> f64 {
    let forward = pose.rotation * Vector3::x();
    forward.y.atan2(forward.x)
}

/// Pinhole camera intrinsics, pixels. Pixel `(u, v)` (column, row; centre of the top-left pixel
/// is `(0.5, 0.5)`) sees the body-frame direction `(fx, -(u - cx), -(v - cy) * fx / fy)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length along u, pixels.
    pub fx: f64,
    /// Focal length along v, pixels.
    pub fy: f64,
    /// Principal point u, pixels.
    pub cx: f64,
    /// Principal point v, pixels.
    pub cy: f64,
}

impl Intrinsics {
    /// Square pixels, centred principal point, horizontal field of view `hfov_deg` degrees.
    pub fn from_hfov(width: u32, height: u32, hfov_deg: f64) -> Self {
        let fx = width as f64 / 2.0 / (hfov_deg.to_radians() / 2.0).tan();
        Self {
            width,
            height,
            fx,
            fy: fx,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
        }
    }

    /// The default camera of the simulator: 320x240, 90 degrees horizontal field of view.
    pub fn default_camera() -> Self {
        Self::from_hfov(320, 240, 90.0)
    }

    /// Checks sizes (1..=8192 per side) and finite positive focal lengths; the error names the
    /// field.
    pub fn validate(&self) -> Result<(), String> {
        for (name, side) in [("width", self.width), ("height", self.height)] {
            if !(1..=8192).contains(&side) {
                return Err(format!("intrinsics.{name} is {side}, must lie in 1..=8192"));
            }
        }
        for (name, f) in [("fx", self.fx), ("fy", self.fy)] {
            if !(f.is_finite() && f > 0.0) {
                return Err(format!(
                    "intrinsics.{name} is {f}, must be finite and positive"
                ));
            }
        }
        for (name, c) in [("cx", self.cx), ("cy", self.cy)] {
            if !c.is_finite() {
                return Err(format!("intrinsics.{name} is {c}, must be finite"));
            }
        }
        Ok(())
    }

    /// The same camera in OpenCV's pixel convention (centre of the top-left pixel at
    /// `(0, 0)`), as the localizer's pose fix takes it.
    pub fn pinhole(&self) -> topoloc::verify::PinholeCamera {
        topoloc::verify::PinholeCamera {
            fx: self.fx,
            fy: self.fy,
            cx: self.cx - 0.5,
            cy: self.cy - 0.5,
        }
    }

    /// The body-frame direction (not normalised) seen by the centre of pixel `(col, row)`.
    pub fn ray(&self, col: u32, row: u32) -> Vector3<f64> {
        let u = col as f64 + 0.5;
        let v = row as f64 + 0.5;
        Vector3::new(self.fx, -(u - self.cx), -(v - self.cy) * self.fx / self.fy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn poses_turn_about_world_z() {
        let p = pose(Point3::new(1.0, 2.0, 1.5), FRAC_PI_2, 0.0);
        let forward = p.rotation * Vector3::x();
        assert!((forward - Vector3::y()).norm() < 1e-12);
        assert!((yaw_of(&p) - FRAC_PI_2).abs() < 1e-12);
        let up = pose(Point3::origin(), 0.0, 0.3).rotation * Vector3::x();
        assert!(up.z > 0.29, "positive pitch looks up: {up}");
    }

    #[test]
    fn rays_follow_the_pixel_grid() {
        let k = Intrinsics::from_hfov(320, 240, 90.0);
        assert!((k.fx - 160.0).abs() < 1e-9);
        let centre = k.ray(160, 120);
        assert!(centre.y.abs() < 1.0 && centre.z.abs() < 1.0);
        assert!(k.ray(0, 120).y > 150.0, "left column looks left (+y)");
        assert!(k.ray(160, 0).z > 110.0, "top row looks up (+z)");
        assert!(k.validate().is_ok());
        let bad = Intrinsics { fx: 0.0, ..k };
        assert!(bad.validate().unwrap_err().contains("fx"));
    }
}
