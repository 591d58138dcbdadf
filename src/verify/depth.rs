//! Scene points of keypoints from a depth image: what a host with a depth camera (RGB-D SLAM)
//! or a generated sequence gives as a keyframe's 3D points
//! ([`crate::loops::KeyframeFeatures::camera_points`]), so that hints carry metric poses.

use super::pose::PinholeCamera;
use crate::errors::VisionError;

/// A depth image registered to the keyframe's image: one value per pixel, rows of `width`,
/// in units of `1 / units_per_metre` metres along the optical axis (z); 0 is no measurement.
#[derive(Clone, Copy, Debug)]
pub struct DepthImage<'a> {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Row-major values, `width * height` of them.
    pub values: &'a [u16],
    /// Units per metre: 1000 for millimetres (ROS `16UC1`, most depth cameras), 5000 for TUM
    /// RGB-D.
    pub units_per_metre: f64,
}

/// Neighbouring depths farther apart than this share of the nearer one are a depth edge: a
/// keypoint there (corners of objects are where keypoints gather) has no reliable depth.
pub const DEPTH_EDGE_RATIO: f64 = 0.05;

/// The scene point of each keypoint in the camera's optical frame (metres; x right, y down,
/// z forward), back-projected through `camera` at the depth interpolated bilinearly between
/// the four pixel centres around it (OpenCV's convention: pixel `(c, r)` is centred on
/// `(c, r)`). Keypoints outside the image, next to a pixel without measurement, or on a depth
/// edge (`DEPTH_EDGE_RATIO`) get NaN in all three coordinates. Fails, naming the field, on a
/// buffer of the wrong length, a non-positive scale or invalid intrinsics.
pub fn camera_points_from_depth(
    points: &[[f32; 2]],
    depth: &DepthImage<'_>,
    camera: &PinholeCamera,
) -> Result<Vec<[f32; 3]>, VisionError> {
    let bad = |m: String| Err(VisionError::InvalidArgument(m));
    let (w, h) = (depth.width as usize, depth.height as usize);
    if depth.values.len() != w * h {
        return bad(format!(
            "depth.values holds {} values, a {w}x{h} image needs {}",
            depth.values.len(),
            w * h
        ));
    }
    if !(depth.units_per_metre.is_finite() && depth.units_per_metre > 0.0) {
        return bad(format!(
            "depth.units_per_metre is {}, must be finite and > 0",
            depth.units_per_metre
        ));
    }
    camera.validate().map_err(VisionError::InvalidArgument)?;
    Ok(points
        .iter()
        .map(|&[x, y]| {
            let Some(z) = interpolated_depth(depth, f64::from(x), f64::from(y)) else {
                return [f32::NAN; 3];
            };
            [
                ((f64::from(x) - camera.cx) * z / camera.fx) as f32,
                ((f64::from(y) - camera.cy) * z / camera.fy) as f32,
                z as f32,
            ]
        })
        .collect())
}

/// The depth (metres) at `(x, y)`, bilinear between the surrounding pixel centres (the edge
/// pixels' own value beyond the outermost centres); `None` outside the image, next to a
/// pixel without measurement, or across a depth edge.
fn interpolated_depth(depth: &DepthImage<'_>, x: f64, y: f64) -> Option<f64> {
    let (w, h) = (depth.width as usize, depth.height as usize);
    if !(x >= -0.5 && y >= -0.5 && x < w as f64 - 0.5 && y < h as f64 - 0.5) {
        return None;
    }
    let (xc, yc) = (x.clamp(0.0, (w - 1) as f64), y.clamp(0.0, (h - 1) as f64));
    let (c0, r0) = (xc.floor() as usize, yc.floor() as usize);
    let (c1, r1) = ((c0 + 1).min(w - 1), (r0 + 1).min(h - 1));
    let (fx, fy) = (xc - c0 as f64, yc - r0 as f64);
    let at = |c: usize, r: usize| f64::from(depth.values[r * w + c]);
    let corners = [at(c0, r0), at(c1, r0), at(c0, r1), at(c1, r1)];
    let (near, far) = corners
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(n, f), &v| (n.min(v), f.max(v)));
    if near <= 0.0 || far - near > DEPTH_EDGE_RATIO * near {
        return None;
    }
    let top = corners[0] * (1.0 - fx) + corners[1] * fx;
    let bottom = corners[2] * (1.0 - fx) + corners[3] * fx;
    Some((top * (1.0 - fy) + bottom * fy) / depth.units_per_metre)
}

#[cfg(test)]
mod tests {
    use super::*;

    const CAMERA: PinholeCamera = PinholeCamera {
        fx: 100.0,
        fy: 80.0,
        cx: 3.5,
        cy: 2.5,
    };

    #[test]
    fn keypoints_back_project_through_the_camera() {
        // 8 x 6 image: depth 2 m + 0.01 m per column, pixel (6, 1) at 4 m, (0, 5) unmeasured.
        let mut values: Vec<u16> = (0..48).map(|i| 2000 + 10 * (i % 8) as u16).collect();
        values[8 + 6] = 4000;
        values[40] = 0;
        let depth = DepthImage {
            width: 8,
            height: 6,
            values: &values,
            units_per_metre: 1000.0,
        };
        let points = [
            [3.5, 2.5],
            [0.0, 0.0],
            [5.5, 0.5],
            [0.2, 4.6],
            [7.4, 2.0],
            [-0.6, 1.0],
            [2.25, 5.3],
        ];
        let out = camera_points_from_depth(&points, &depth, &CAMERA).unwrap();
        assert!(
            (out[0][2] - 2.035).abs() < 1e-6,
            "between columns 3 and 4: {:?}",
            out[0]
        );
        assert_eq!(
            [out[0][0], out[0][1]],
            [0.0, 0.0],
            "the principal point looks ahead"
        );
        let [x, y, z] = out[1];
        assert_eq!(z, 2.0, "a pixel centre takes its own depth");
        assert!((x + 3.5 * 2.0 / 100.0).abs() < 1e-6 && (y + 2.5 * 2.0 / 80.0).abs() < 1e-6);
        assert!(
            out[2].iter().all(|v| v.is_nan()),
            "next to the 4 m pixel: a depth edge"
        );
        assert!(
            out[3].iter().all(|v| v.is_nan()),
            "next to the unmeasured pixel"
        );
        assert!(
            (out[4][2] - 2.07).abs() < 1e-6,
            "beyond the last centre: {:?}",
            out[4]
        );
        assert!(out[5].iter().all(|v| v.is_nan()), "left of the image");
        assert!((out[6][2] - 2.0225).abs() < 1e-6, "last row: {:?}", out[6]);
    }

    #[test]
    fn bad_input_names_the_field() {
        let values = vec![1000u16; 48];
        let depth = DepthImage {
            width: 8,
            height: 6,
            values: &values[..40],
            units_per_metre: 1000.0,
        };
        let err = camera_points_from_depth(&[], &depth, &CAMERA).unwrap_err();
        assert!(err.to_string().contains("depth.values holds 40"), "{err}");
        let depth = DepthImage {
            values: &values,
            units_per_metre: 0.0,
            ..depth
        };
        let err = camera_points_from_depth(&[], &depth, &CAMERA).unwrap_err();
        assert!(err.to_string().contains("units_per_metre"), "{err}");
        let depth = DepthImage {
            units_per_metre: 1000.0,
            ..depth
        };
        let camera = PinholeCamera { fx: 0.0, ..CAMERA };
        let err = camera_points_from_depth(&[], &depth, &camera).unwrap_err();
        assert!(err.to_string().contains("camera.fx"), "{err}");
    }
}
