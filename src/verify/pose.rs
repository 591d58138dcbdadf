//! Metric pose of the query camera against one map view: the query's keypoints are matched to
//! the view's, those whose scene point the map knows (map frame, [`ViewKeypoints`] world points)
//! give 2D-3D pairs, and a perspective-n-point fit with RANSAC places the camera in the map
//! frame. This is what a SLAM pose graph needs from a loop-closure hint, and what lets the
//! metric filter know where in a place the camera is, which appearance alone cannot tell to
//! better than half a metre.
//!
//! [`ViewKeypoints`]: super::ViewKeypoints

use super::geometry::{
    mutual_matches, ANY_COSINE, RANSAC_ITERATIONS_RANGE, RANSAC_THRESHOLD_PX_RANGE,
};
use super::keypoints::KeypointsRef;
use crate::bounds::Bounds;
use crate::errors::VisionError;
use nalgebra::{
    Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3,
};
use opencv::calib3d;
use opencv::core::{
    Mat, Point2f, Point3f, TermCriteria, TermCriteria_COUNT, TermCriteria_EPS, Vector,
};
use opencv::prelude::*;

/// Fewest 2D-3D pairs a pose is fitted to.
pub const MIN_PAIRS: usize = 6;

/// Pinhole intrinsics of the query camera, in pixels of the image as given to the localizer
/// and in OpenCV's convention: the centre of the top-left pixel is (0, 0), and the optical
/// frame has z forward, x right, y down. Images are assumed undistorted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PinholeCamera {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
}

impl PinholeCamera {
    /// Fails with a message naming the bad field: focal lengths must be finite and > 0, the
    /// principal point finite.
    pub fn validate(&self) -> Result<(), String> {
        Self::FOCAL_RANGE.check("camera.fx", self.fx)?;
        Self::FOCAL_RANGE.check("camera.fy", self.fy)?;
        Self::PRINCIPAL_POINT_RANGE.check("camera.cx", self.cx)?;
        Self::PRINCIPAL_POINT_RANGE.check("camera.cy", self.cy)
    }

    /// Accepted values of the focal lengths [`Self::fx`] and [`Self::fy`], pixels.
    pub const FOCAL_RANGE: Bounds = Bounds::above(0.0);
    /// Accepted values of the principal point [`Self::cx`], [`Self::cy`], pixels.
    pub const PRINCIPAL_POINT_RANGE: Bounds = Bounds::finite();

    /// The pixel of a point in the camera's optical frame; `None` behind the camera.
    pub fn project(&self, p: &Vector3<f64>) -> Option<Vector2<f64>> {
        (p.z > 1e-9)
            .then(|| Vector2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy))
    }

    fn matrix(&self) -> opencv::Result<Mat> {
        Mat::from_slice_2d(&[
            [self.fx, 0.0, self.cx],
            [0.0, self.fy, self.cy],
            [0.0, 0.0, 1.0],
        ])
    }
}

/// Options of [`locate`].
#[derive(Clone, Debug, PartialEq)]
pub struct LocateOptions {
    /// Fewest RANSAC inliers for a pose to be accepted. Default 30: fixes with fewer inliers
    /// were often far off on the suite's worlds (the shares by inlier count are in
    /// docs/benchmarks/issue-04.md, "Metric mode with pose fixes").
    pub min_inliers: u32,
    /// RANSAC inlier threshold: reprojection error, pixels. Default 2.0.
    pub reprojection_px: f32,
    /// RANSAC iterations at most. Default 100.
    pub max_iterations: u32,
}

impl Default for LocateOptions {
    fn default() -> Self {
        Self {
            min_inliers: 30,
            reprojection_px: 2.0,
            max_iterations: 100,
        }
    }
}

impl LocateOptions {
    /// Fails with a message naming the field out of range.
    pub fn validate(&self) -> Result<(), String> {
        Self::MIN_INLIERS_RANGE.check("min_inliers", self.min_inliers)?;
        RANSAC_THRESHOLD_PX_RANGE.check("reprojection_px", self.reprojection_px)?;
        RANSAC_ITERATIONS_RANGE.check("max_iterations", self.max_iterations)
    }

    /// Accepted values of [`Self::min_inliers`].
    pub const MIN_INLIERS_RANGE: Bounds = Bounds::whole(MIN_PAIRS as u64, 10_000);
}

/// A camera pose found by [`locate`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Located {
    /// The query camera in the map frame, `world_T_optical` (optical axes: z forward, x right,
    /// y down).
    pub world_t_optical: Isometry3<f64>,
    /// 2D-3D pairs consistent with the pose.
    pub inliers: u32,
}

impl Located {
    /// The camera centre in the map frame.
    pub fn position(&self) -> Point3<f64> {
        Point3::from(self.world_t_optical.translation.vector)
    }
}

/// Places the query camera against one view: matches `query` to `view` (mutual nearest
/// neighbours within `max_hamming` bits), keeps the pairs whose view keypoint has a known scene
/// point in `view_world_points` (one per view keypoint, NaN when unknown), and fits the pose
/// with RANSAC. `None` when fewer than `options.min_inliers` pairs agree on one pose.
/// Deterministic (OpenCV's RANSAC uses a fixed seed). Options and camera are assumed valid.
pub fn locate(
    query: KeypointsRef<'_>,
    view: KeypointsRef<'_>,
    view_world_points: &[[f32; 3]],
    camera: &PinholeCamera,
    max_hamming: u32,
    options: &LocateOptions,
) -> Result<Option<Located>, VisionError> {
    if view_world_points.len() != view.points.len() {
        return Err(VisionError::InvalidArgument(format!(
            "{} scene points for {} view keypoints",
            view_world_points.len(),
            view.points.len()
        )));
    }
    let (image_points, object_points) = scene_pairs(query, view, view_world_points, max_hamming)?;
    locate_pairs(&image_points, &object_points, camera, options)
}

/// The pose fit of [`locate`] on given 2D-3D pairs (query pixels, scene points); `None` when
/// fewer than `options.min_inliers` pairs agree on one pose or the fit is degenerate.
pub(super) fn locate_pairs(
    image_points: &Vector<Point2f>,
    object_points: &Vector<Point3f>,
    camera: &PinholeCamera,
    options: &LocateOptions,
) -> Result<Option<Located>, VisionError> {
    locate_pairs_seeded(image_points, object_points, None, camera, options)
}

/// [`locate_pairs`] sampling only the `seed` pairs (those already known to agree, e.g. a
/// fundamental matrix's inliers): RANSAC on them stops after a few iterations where a run on
/// every pair would exhaust its iterations on a wrong candidate. The pose is then refitted on
/// every pair within the threshold, and `min_inliers` counts those. Seeds of fewer than
/// [`MIN_PAIRS`] pairs sample every pair.
pub(super) fn locate_pairs_seeded(
    image_points: &Vector<Point2f>,
    object_points: &Vector<Point3f>,
    seed: Option<&[bool]>,
    camera: &PinholeCamera,
    options: &LocateOptions,
) -> Result<Option<Located>, VisionError> {
    let needed = (options.min_inliers as usize).max(MIN_PAIRS);
    if object_points.len() < needed {
        return Ok(None);
    }
    let k = camera.matrix()?;
    let seeded = seed.filter(|s| s.iter().filter(|&&x| x).count() >= MIN_PAIRS);
    let fit = match seeded {
        None => ransac_pose(object_points, image_points, &k, options)?,
        Some(seed) => {
            let pick = |i: usize| seed.get(i).copied().unwrap_or(false);
            let object: Vector<Point3f> = (0..object_points.len())
                .filter(|&i| pick(i))
                .map(|i| object_points.get(i))
                .collect::<opencv::Result<_>>()?;
            let image: Vector<Point2f> = (0..image_points.len())
                .filter(|&i| pick(i))
                .map(|i| image_points.get(i))
                .collect::<opencv::Result<_>>()?;
            let sampled = LocateOptions {
                min_inliers: MIN_PAIRS as u32,
                ..options.clone()
            };
            match ransac_pose(&object, &image, &k, &sampled)? {
                Some(fit) => widen(&fit, &k, image_points, object_points, camera, options)?,
                None => None,
            }
        }
    };
    let Some(fit) = fit else {
        return Ok(None);
    };
    let count = fit.object_inliers.len() as u32;
    let Some((optical_r_world, t)) = refine_pose(&fit, &k)? else {
        return Ok(None);
    };
    // A pose that puts an inlier behind the camera is a degenerate fit, not a place.
    for p in &fit.object_inliers {
        let scene = Vector3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z));
        if (optical_r_world * scene + t).z <= 0.0 {
            return Ok(None);
        }
    }
    // OpenCV gives optical_T_world; invert it.
    let world_r_optical: Matrix3<f64> = optical_r_world.matrix().transpose();
    let centre = -(world_r_optical * t);
    Ok(Some(Located {
        world_t_optical: Isometry3::from_parts(
            Translation3::from(centre),
            UnitQuaternion::from_matrix(&world_r_optical),
        ),
        inliers: count,
    }))
}

/// The 2D-3D pairs of the mutual matches whose view keypoint has a known scene point: query
/// pixels and scene points.
fn scene_pairs(
    query: KeypointsRef<'_>,
    view: KeypointsRef<'_>,
    view_world_points: &[[f32; 3]],
    max_hamming: u32,
) -> Result<(Vector<Point2f>, Vector<Point3f>), VisionError> {
    let matches = mutual_matches(query, view, max_hamming, ANY_COSINE)?;
    let mut image_points = Vector::<Point2f>::new();
    let mut object_points = Vector::<Point3f>::new();
    for m in &matches {
        let scene = view_world_points[m.train_idx as usize];
        if scene[0].is_finite() {
            let pixel = query.points[m.query_idx as usize];
            image_points.push(Point2f::new(pixel[0], pixel[1]));
            object_points.push(Point3f::new(scene[0], scene[1], scene[2]));
        }
    }
    Ok((image_points, object_points))
}

/// A camera pose as OpenCV's PnP gives it: `optical_R_world` and `optical_t_world`.
type OpticalFromWorld = (Rotation3<f64>, Vector3<f64>);

/// A RANSAC PnP pose (optical_T_world as OpenCV's rotation and translation vectors) and the
/// pairs that agree with it.
struct PnpFit {
    rvec: Mat,
    tvec: Mat,
    object_inliers: Vector<Point3f>,
    image_inliers: Vector<Point2f>,
}

/// RANSAC PnP with AP3P minimal sets (OpenCV refits the inliers with EPnP): the pose and its
/// inlier pairs, or `None` below
/// `options.min_inliers` or on a solver error (degenerate samples).
fn ransac_pose(
    object_points: &Vector<Point3f>,
    image_points: &Vector<Point2f>,
    k: &Mat,
    options: &LocateOptions,
) -> Result<Option<PnpFit>, VisionError> {
    let mut rvec = Mat::default();
    let mut tvec = Mat::default();
    let mut inliers = Mat::default();
    let found = calib3d::solve_pnp_ransac(
        object_points,
        image_points,
        k,
        &Mat::default(),
        &mut rvec,
        &mut tvec,
        false,
        options.max_iterations as i32,
        options.reprojection_px,
        0.99,
        &mut inliers,
        calib3d::SOLVEPNP_AP3P,
    );
    let count = inliers.rows().max(0) as u32;
    if !matches!(found, Ok(true))
        || count < options.min_inliers
        || rvec.total() != 3
        || tvec.total() != 3
    {
        return Ok(None);
    }
    let indices: Vec<usize> = (0..count as i32)
        .map(|i| inliers.at::<i32>(i).map(|&j| j as usize))
        .collect::<opencv::Result<_>>()?;
    let object_inliers: Vector<Point3f> = indices
        .iter()
        .map(|&j| object_points.get(j))
        .collect::<opencv::Result<_>>()?;
    let image_inliers: Vector<Point2f> = indices
        .iter()
        .map(|&j| image_points.get(j))
        .collect::<opencv::Result<_>>()?;
    Ok(Some(PnpFit {
        rvec,
        tvec,
        object_inliers,
        image_inliers,
    }))
}

/// The seeded fit refined on its inliers ([`refine_pose`]; OpenCV's own refit of the inliers
/// can be poor on a plane), with every pair within `options.reprojection_px` of that pose (in
/// front of the camera) as its inliers; `None` below `options.min_inliers`.
fn widen(
    fit: &PnpFit,
    k: &Mat,
    image_points: &Vector<Point2f>,
    object_points: &Vector<Point3f>,
    camera: &PinholeCamera,
    options: &LocateOptions,
) -> Result<Option<PnpFit>, VisionError> {
    let Some((r, t)) = refine_pose(fit, k)? else {
        return Ok(None);
    };
    let threshold = f64::from(options.reprojection_px);
    let (mut object_inliers, mut image_inliers) = (Vector::new(), Vector::new());
    for (p, q) in object_points.iter().zip(image_points.iter()) {
        let c = r * Vector3::new(f64::from(p.x), f64::from(p.y), f64::from(p.z)) + t;
        let seen = Vector2::new(f64::from(q.x), f64::from(q.y));
        if camera
            .project(&c)
            .is_some_and(|px| (px - seen).norm() <= threshold)
        {
            object_inliers.push(p);
            image_inliers.push(q);
        }
    }
    if (object_inliers.len() as u32) < options.min_inliers {
        return Ok(None);
    }
    let column = |v: Vector3<f64>| Mat::from_slice(v.as_slice()).and_then(|m| m.try_clone());
    Ok(Some(PnpFit {
        rvec: column(r.scaled_axis())?,
        tvec: column(t)?,
        object_inliers,
        image_inliers,
    }))
}

/// Refits the RANSAC pose on its inliers by SQPnP (globally optimal; EPnP is poor on a single
/// plane, a wall; kept only when it succeeds) and polishes it by Levenberg-Marquardt. OpenCV's
/// solvers raise errors on degenerate samples (SQPnP asserts on nearly coincident points,
/// hence not used for the minimal sets): degenerate geometry gives `None`, not a failed frame.
/// Returns optical_R_world and optical_t_world.
fn refine_pose(fit: &PnpFit, k: &Mat) -> Result<Option<OpticalFromWorld>, VisionError> {
    let (object_inliers, image_inliers) = (&fit.object_inliers, &fit.image_inliers);
    let (mut rvec, mut tvec) = (fit.rvec.clone(), fit.tvec.clone());
    let (mut rvec_sq, mut tvec_sq) = (Mat::default(), Mat::default());
    let refit = calib3d::solve_pnp(
        object_inliers,
        image_inliers,
        k,
        &Mat::default(),
        &mut rvec_sq,
        &mut tvec_sq,
        false,
        calib3d::SOLVEPNP_SQPNP,
    );
    if matches!(refit, Ok(true)) && rvec_sq.total() == 3 && tvec_sq.total() == 3 {
        (rvec, tvec) = (rvec_sq, tvec_sq);
    }
    let criteria = TermCriteria::new(TermCriteria_COUNT + TermCriteria_EPS, 20, 1e-8)?;
    if calib3d::solve_pnp_refine_lm(
        object_inliers,
        image_inliers,
        k,
        &Mat::default(),
        &mut rvec,
        &mut tvec,
        criteria,
    )
    .is_err()
    {
        return Ok(None);
    }
    let vector = |m: &Mat| -> opencv::Result<Vector3<f64>> {
        Ok(Vector3::new(
            *m.at::<f64>(0)?,
            *m.at::<f64>(1)?,
            *m.at::<f64>(2)?,
        ))
    };
    let (r, t) = (vector(&rvec)?, vector(&tvec)?);
    if !(r.iter().chain(t.iter()).all(|x| x.is_finite())) {
        return Ok(None);
    }
    Ok(Some((Rotation3::from_scaled_axis(r), t)))
}
