//! Relative pose of a query camera against a matched keyframe's camera, with a covariance, for
//! loop-closure hints.
//!
//! With the matched keyframe's scene points (in its camera frame) the pose is metric: a RANSAC
//! perspective-n-point fit (the pose-fix solver of [`super::locate`]) with `scale_known`. Without
//! them it comes from an essential matrix (OpenCV's RANSAC five-point solver and its cheirality
//! check, `recoverPose`): rotation and a unit translation direction, `scale_known == false`.
//! When the views differ by a rotation only (too little parallax, or an essential matrix
//! without consensus, as at a revisit in the same lane), a rotation that explains the rays is
//! the model: the pose has that rotation and a zero translation.
//!
//! The covariance is `sigma^2 (J^T J)^-1` at the solution, `J` the Jacobian of the inliers'
//! residuals (reprojection error with points, Sampson distance without, both in pixels) with
//! respect to a right perturbation `matched_T_query * Exp(xi)`, `xi = (rx, ry, rz, tx, ty, tz)`:
//! GTSAM's Pose3 tangent order, rotation first (radians), then translation (metres, in the
//! query camera frame); `sigma^2` is the inliers' mean squared residual. Without scale, the
//! Sampson distance does not see the translation's length, so a unit-variance prior (1 m^2)
//! is added along the translation direction: hosts estimate the scale themselves.

use super::geometry::{
    mutual_matches, PairFit, ANY_COSINE, PAIR_MIN_INLIERS_RANGE, RANSAC_ITERATIONS_RANGE,
    RANSAC_THRESHOLD_PX_RANGE,
};
use super::keypoints::KeypointsRef;
use super::pose::{locate_pairs_seeded, LocateOptions, PinholeCamera};
use crate::bounds::Bounds;
use crate::errors::VisionError;
use nalgebra::{
    Isometry3, Matrix3, Matrix6, Point3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3,
    Vector6,
};
use opencv::calib3d;
use opencv::core::{Mat, Point2d, Point2f, Point3f, Vector};
use opencv::prelude::*;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// Options of [`relative_pose`].
#[derive(Clone, Debug, PartialEq)]
pub struct RelativePoseOptions {
    /// Fewest inliers for a pose. Default 30 (as pose fixes, [`LocateOptions`]).
    pub min_inliers: u32,
    /// Without points: inlier threshold on the epipolar distance, pixels. Default 1.5.
    pub threshold_px: f64,
    /// With points: inlier threshold on the reprojection error, pixels. Looser than the
    /// epipolar one: a scene point's depth error adds to the keypoint's, and revisits see it
    /// from farther than neighbouring keyframes. Default 5 (VINS-Fusion's loop PnP allows
    /// about 3.5 at this focal length; chosen on generated train revisits, BENCHMARKS.md).
    pub reprojection_px: f64,
    /// RANSAC iterations at most. Default 1000.
    pub max_iterations: u32,
    /// Without points: the smallest median angle between an inlier's two rays once the
    /// rotation is removed; below it the views differ by a rotation only, the translation
    /// direction is noise, and the pose is the rotation that brings the most rays within this
    /// angle of each other (zero translation). Default 1 degree.
    pub min_parallax_deg: f64,
}

impl Default for RelativePoseOptions {
    fn default() -> Self {
        Self {
            min_inliers: 30,
            threshold_px: 1.5,
            reprojection_px: 5.0,
            max_iterations: 1000,
            min_parallax_deg: 1.0,
        }
    }
}

impl RelativePoseOptions {
    /// Fails with a message naming the field out of range.
    pub fn validate(&self) -> Result<(), String> {
        PAIR_MIN_INLIERS_RANGE.check("min_inliers", self.min_inliers)?;
        RANSAC_THRESHOLD_PX_RANGE.check("threshold_px", self.threshold_px)?;
        RANSAC_THRESHOLD_PX_RANGE.check("reprojection_px", self.reprojection_px)?;
        RANSAC_ITERATIONS_RANGE.check("max_iterations", self.max_iterations)?;
        Self::MIN_PARALLAX_DEG_RANGE.check("min_parallax_deg", self.min_parallax_deg)
    }

    /// Accepted values of [`Self::min_parallax_deg`].
    pub const MIN_PARALLAX_DEG_RANGE: Bounds = Bounds::half_open(0.0, 90.0);
}

/// A relative pose found by [`relative_pose`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelativePose {
    /// The query camera in the matched camera's frame (optical frames: z forward, x right,
    /// y down). Without scale its translation has unit length, or is zero when the views
    /// differ by a rotation only (the cameras are at about the same place, relative to the
    /// scene's depth; the covariance then gives each translation axis a variance of 1 m^2).
    pub matched_t_query: Isometry3<f64>,
    /// True when the translation is metric (the matched keyframe's scene points were used).
    pub scale_known: bool,
    /// Correspondences consistent with the pose.
    pub inliers: u32,
    /// Root mean square residual of the inliers, pixels.
    pub rms_px: f64,
    /// Covariance of the right perturbation, GTSAM Pose3 order (rotation rad, translation m).
    pub covariance: Matrix6<f64>,
}

/// What a relative pose's translation holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseTranslation {
    /// Metres: the matched keyframe's scene points fixed the scale.
    Metric,
    /// A unit-length direction: the scale is the host's to find.
    Direction,
    /// Zero: the views differ by a rotation only (the cameras about one place, relative to
    /// the scene's depth); the rotation holds, the covariance gives each translation axis
    /// 1 m^2.
    RotationOnly,
}

impl RelativePose {
    /// What the translation of [`Self::matched_t_query`] holds.
    pub fn translation(&self) -> PoseTranslation {
        if self.scale_known {
            PoseTranslation::Metric
        } else if self.matched_t_query.translation.vector == Vector3::zeros() {
            PoseTranslation::RotationOnly
        } else {
            PoseTranslation::Direction
        }
    }
}

/// Why [`relative_pose`] gave no pose (a hint's gate status names it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PoseRefusal {
    /// Fewer usable correspondences than `min_inliers`.
    TooFewMatches {
        /// Correspondences found (with a scene point, when points are used).
        found: u32,
    },
    /// No pose with `min_inliers` inliers (RANSAC found no consensus, or a degenerate fit).
    NoConsensus {
        /// Inliers of the best fit.
        inliers: u32,
    },
    /// The two views differ by a rotation only (no points), so the direction is unobservable,
    /// and no rotation brings `min_inliers` rays within `min_parallax_deg`.
    TooLittleParallax {
        /// Median parallax of the inliers, degrees.
        degrees: f64,
    },
}

/// Matches `query` to `matched` (mutual nearest neighbours; ORB within `max_hamming` bits) and
/// finds the relative pose, metric when `matched_points` gives each matched keypoint's scene
/// point in the matched camera's frame (NaN when unknown; with too few known, the pose is the
/// two-view one, without scale). Camera and options are assumed
/// valid; `matched_points` of another length than the keypoints is an invalid argument.
pub fn relative_pose(
    query: KeypointsRef<'_>,
    matched: KeypointsRef<'_>,
    matched_points: Option<&[[f32; 3]]>,
    camera: &PinholeCamera,
    max_hamming: u32,
    options: &RelativePoseOptions,
) -> Result<Result<RelativePose, PoseRefusal>, VisionError> {
    let matches: Vec<[u32; 2]> = mutual_matches(query, matched, max_hamming, ANY_COSINE)?
        .iter()
        .map(|m| [m.query_idx as u32, m.train_idx as u32])
        .collect();
    let points = ScenePoints {
        query: None,
        matched: matched_points,
    };
    pose_of_matches(query, matched, points, &matches, None, camera, options)
}

/// The scene points (camera frame, NaN where unknown; one per keypoint) of either view of a
/// pair, for [`relative_pose_from_fit`].
#[derive(Clone, Copy, Debug, Default)]
pub struct ScenePoints<'a> {
    /// The query keyframe's points, in its camera frame.
    pub query: Option<&'a [[f32; 3]]>,
    /// The matched keyframe's points, in its camera frame.
    pub matched: Option<&'a [[f32; 3]]>,
}

/// [`relative_pose`] on the matches of a pair check already made ([`super::fit_pair`], same
/// keypoints): no second matching, and the metric fit samples the fundamental matrix's
/// inliers only (every match within the reprojection threshold then counts), so a candidate
/// whose matches mostly disagree costs a few RANSAC iterations, not all of them. The metric
/// fit uses the matched keyframe's points (PnP of the query's pixels); where too few matches
/// have one, the query's points (PnP of the matched pixels, as VINS-Fusion fits its loops with
/// the current keyframe's points), the pose and covariance then inverted. Without points, the
/// essential matrix is fitted to every match as in [`relative_pose`]. A fit of other keypoints
/// (indices out of range) is an invalid argument.
pub fn relative_pose_from_fit(
    query: KeypointsRef<'_>,
    matched: KeypointsRef<'_>,
    points: ScenePoints<'_>,
    fit: &PairFit,
    camera: &PinholeCamera,
    options: &RelativePoseOptions,
) -> Result<Result<RelativePose, PoseRefusal>, VisionError> {
    let in_range = |m: &[u32; 2]| {
        (m[0] as usize) < query.points.len() && (m[1] as usize) < matched.points.len()
    };
    if fit.inliers.len() != fit.matches.len() || !fit.matches.iter().all(in_range) {
        return Err(VisionError::InvalidArgument(
            "the pair fit is not of these keypoints".into(),
        ));
    }
    let seed = Some(fit.inliers.as_slice());
    pose_of_matches(query, matched, points, &fit.matches, seed, camera, options)
}

/// The pose of the other camera: `query_t_matched` from `matched_t_query`, with the covariance
/// of its right perturbation (`Ad(T) Σ Ad(T)^T`, `T` the pose inverted, rotation first).
fn inverted(pose: RelativePose) -> RelativePose {
    let t = pose.matched_t_query;
    let rotation = *t.rotation.to_rotation_matrix().matrix();
    let mut adjoint = Matrix6::<f64>::zeros();
    adjoint.fixed_view_mut::<3, 3>(0, 0).copy_from(&rotation);
    adjoint.fixed_view_mut::<3, 3>(3, 3).copy_from(&rotation);
    adjoint
        .fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&(t.translation.vector.cross_matrix() * rotation));
    RelativePose {
        matched_t_query: t.inverse(),
        covariance: adjoint * pose.covariance * adjoint.transpose(),
        ..pose
    }
}

/// The pose from given matches (`[query index, matched index]`, in range); `seed` marks the
/// matches the metric fit samples (all when `None`). In order: PnP against the matched
/// keyframe's points, PnP against the query's (inverted), then the essential matrix; a metric
/// fit that finds too few matches with a point gives way to the next.
fn pose_of_matches(
    query: KeypointsRef<'_>,
    matched: KeypointsRef<'_>,
    points: ScenePoints<'_>,
    matches: &[[u32; 2]],
    seed: Option<&[bool]>,
    camera: &PinholeCamera,
    options: &RelativePoseOptions,
) -> Result<Result<RelativePose, PoseRefusal>, VisionError> {
    // Too few matches carry a scene point (depth missing where they are: sky, glass, out of
    // range): the other view's points, or the views alone without scale, may still give it.
    let too_few = |fit: &Result<RelativePose, PoseRefusal>| {
        matches!(fit, Err(PoseRefusal::TooFewMatches { .. }))
    };
    if let Some(matched_points) = points.matched {
        let metric = metric_pose(
            query,
            matched,
            matched_points,
            matches,
            seed,
            camera,
            options,
        )?;
        if !too_few(&metric) {
            return Ok(metric);
        }
    }
    if let Some(query_points) = points.query {
        let swapped: Vec<[u32; 2]> = matches.iter().map(|m| [m[1], m[0]]).collect();
        let metric = metric_pose(
            matched,
            query,
            query_points,
            &swapped,
            seed,
            camera,
            options,
        )?;
        if !too_few(&metric) {
            return Ok(metric.map(inverted));
        }
    }
    let query_px: Vec<[f32; 2]> = matches
        .iter()
        .map(|m| query.points[m[0] as usize])
        .collect();
    let matched_px: Vec<[f32; 2]> = matches
        .iter()
        .map(|m| matched.points[m[1] as usize])
        .collect();
    essential_pose(&query_px, &matched_px, camera, options)
}

/// A query pixel and the matched keyframe's scene point it sees (matched camera frame).
type PixelScene = ([f32; 2], [f32; 3]);

/// The metric case: PnP against the matched keyframe's points (the matches' pairs handed to
/// the pose-fix solver), then the covariance from the reprojection residuals of the pairs
/// within the threshold.
fn metric_pose(
    query: KeypointsRef<'_>,
    matched: KeypointsRef<'_>,
    points: &[[f32; 3]],
    matches: &[[u32; 2]],
    seed: Option<&[bool]>,
    camera: &PinholeCamera,
    options: &RelativePoseOptions,
) -> Result<Result<RelativePose, PoseRefusal>, VisionError> {
    let locate_options = LocateOptions {
        min_inliers: options.min_inliers,
        reprojection_px: options.reprojection_px as f32,
        max_iterations: options.max_iterations,
    };
    if points.len() != matched.points.len() {
        return Err(VisionError::InvalidArgument(format!(
            "{} scene points for {} matched keypoints",
            points.len(),
            matched.points.len()
        )));
    }
    // Pairs with a scene point, and whether each is in the seed.
    let (pairs, seeded): (Vec<PixelScene>, Vec<bool>) = matches
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let pair = (query.points[m[0] as usize], points[m[1] as usize]);
            (pair, seed.is_none_or(|s| s[i]))
        })
        .filter(|((_, p), _)| p[0].is_finite())
        .unzip();
    if pairs.len() < options.min_inliers as usize {
        return Ok(Err(PoseRefusal::TooFewMatches {
            found: pairs.len() as u32,
        }));
    }
    let image_points: Vector<Point2f> = pairs
        .iter()
        .map(|(p, _)| Point2f::new(p[0], p[1]))
        .collect();
    let object_points: Vector<Point3f> = pairs
        .iter()
        .map(|(_, s)| Point3f::new(s[0], s[1], s[2]))
        .collect();
    let seed = seed.map(|_| seeded.as_slice());
    let Some(located) =
        locate_pairs_seeded(&image_points, &object_points, seed, camera, &locate_options)?
    else {
        return Ok(Err(PoseRefusal::NoConsensus { inliers: 0 }));
    };
    let pose = located.world_t_optical;
    let residual = |pose: &Isometry3<f64>, (pixel, scene): &PixelScene| {
        reprojection(camera, pose, pixel, scene)
    };
    let inliers: Vec<&PixelScene> = pairs
        .iter()
        .filter(|pair| residual(&pose, pair).is_some_and(|r| r.norm() <= options.reprojection_px))
        .collect();
    let covariance = covariance(
        &pose,
        &inliers,
        |p, pair| residual(p, pair).map_or(vec![1e3, 1e3], |r| vec![r.x, r.y]),
        &[],
    );
    Ok(Ok(RelativePose {
        matched_t_query: pose,
        scale_known: true,
        inliers: located.inliers,
        rms_px: covariance.1,
        covariance: covariance.0,
    }))
}

/// Reprojection error (pixels) of `scene` (matched frame) in the query camera at
/// `matched_t_query`; `None` behind the camera.
fn reprojection(
    camera: &PinholeCamera,
    matched_t_query: &Isometry3<f64>,
    pixel: &[f32; 2],
    scene: &[f32; 3],
) -> Option<Vector2<f64>> {
    let p = matched_t_query.inverse_transform_point(&Point3::new(
        f64::from(scene[0]),
        f64::from(scene[1]),
        f64::from(scene[2]),
    ));
    let seen = Vector2::new(f64::from(pixel[0]), f64::from(pixel[1]));
    camera.project(&p.coords).map(|px| px - seen)
}

/// The unscaled case from pixel correspondences (`query_px[i]` matches `matched_px[i]`).
pub fn essential_pose(
    query_px: &[[f32; 2]],
    matched_px: &[[f32; 2]],
    camera: &PinholeCamera,
    options: &RelativePoseOptions,
) -> Result<Result<RelativePose, PoseRefusal>, VisionError> {
    let n = query_px.len().min(matched_px.len());
    if n < options.min_inliers as usize {
        return Ok(Err(PoseRefusal::TooFewMatches { found: n as u32 }));
    }
    // Views a rotation apart (a revisit in the same lane) degenerate the essential matrix: the
    // rotation alone is then the model.
    let pairs: Vec<([f32; 2], [f32; 2])> = query_px[..n]
        .iter()
        .copied()
        .zip(matched_px[..n].iter().copied())
        .collect();
    let or_rotation_only =
        |refusal: PoseRefusal| Ok(rotation_only_pose(camera, &pairs, options).map_err(|_| refusal));
    let cv = |p: &[f32; 2]| Point2d::new(f64::from(p[0]), f64::from(p[1]));
    let from: Vector<Point2d> = matched_px[..n].iter().map(cv).collect();
    let to: Vector<Point2d> = query_px[..n].iter().map(cv).collect();
    let k = Mat::from_slice_2d(&[
        [camera.fx, 0.0, camera.cx],
        [0.0, camera.fy, camera.cy],
        [0.0, 0.0, 1.0],
    ])?;
    let mut mask = Mat::default();
    let e = calib3d::find_essential_mat(
        &from,
        &to,
        &k,
        calib3d::RANSAC,
        0.999,
        options.threshold_px,
        options.max_iterations as i32,
        &mut mask,
    )?;
    if e.rows() != 3 || e.cols() != 3 {
        // OpenCV stacks several solutions or none for degenerate input.
        return or_rotation_only(PoseRefusal::NoConsensus { inliers: 0 });
    }
    let (mut r, mut t) = (Mat::default(), Mat::default());
    let good = calib3d::recover_pose_estimated(&e, &from, &to, &k, &mut r, &mut t, &mut mask)?;
    if good < options.min_inliers as i32 {
        return or_rotation_only(PoseRefusal::NoConsensus {
            inliers: good.max(0) as u32,
        });
    }
    let rotation = matrix3(&r)?;
    let direction = Vector3::new(
        *t.at_2d::<f64>(0, 0)?,
        *t.at_2d::<f64>(1, 0)?,
        *t.at_2d::<f64>(2, 0)?,
    );
    // OpenCV: p_query = R p_matched + t, i.e. query_T_matched; invert it.
    let query_t_matched = Isometry3::from_parts(
        Translation3::from(direction.normalize()),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rotation)),
    );
    let mut pose = query_t_matched.inverse();
    pose.translation.vector = pose.translation.vector.normalize();
    let inliers: Vec<([f32; 2], [f32; 2])> = (0..n)
        .filter(|&i| mask.at::<u8>(i as i32).is_ok_and(|&m| m != 0))
        .map(|i| (query_px[i], matched_px[i]))
        .collect();
    let parallax = median_parallax(camera, &pose, &inliers);
    if parallax < options.min_parallax_deg {
        return or_rotation_only(PoseRefusal::TooLittleParallax { degrees: parallax });
    }
    let refs: Vec<&([f32; 2], [f32; 2])> = inliers.iter().collect();
    let along = pose.rotation.inverse() * pose.translation.vector;
    let (covariance, rms) = covariance(
        &pose,
        &refs,
        |p, (q, m)| vec![sampson_px(camera, p, q, m)],
        &[along.normalize()],
    );
    Ok(Ok(RelativePose {
        matched_t_query: pose,
        scale_known: false,
        inliers: inliers.len() as u32,
        rms_px: rms,
        covariance,
    }))
}

/// The views of `pairs` (query pixel, matched pixel) differ by a rotation only: the rotation
/// that best aligns the most rays within `min_parallax_deg` (RANSAC over two-ray rotations,
/// then a least-squares refit on the rays it explains), with zero translation, when it
/// explains at least `min_inliers` of them; otherwise [`PoseRefusal::NoConsensus`]. Its
/// covariance carries a unit-variance prior (1 m^2) on each translation axis: the rays say the
/// cameras are at about the same place, relative to the scene's depth, not how far apart.
fn rotation_only_pose(
    camera: &PinholeCamera,
    pairs: &[([f32; 2], [f32; 2])],
    options: &RelativePoseOptions,
) -> Result<RelativePose, PoseRefusal> {
    let rays: Vec<(Vector3<f64>, Vector3<f64>)> = pairs
        .iter()
        .map(|(q, m)| (bearing(camera, q), bearing(camera, m)))
        .collect();
    let max_angle = options.min_parallax_deg.to_radians();
    let explained = |rotation: &Rotation3<f64>| -> Vec<usize> {
        (0..rays.len())
            .filter(|&i| angle(&(rotation * rays[i].0), &rays[i].1) <= max_angle)
            .collect()
    };
    let mut rng = SmallRng::seed_from_u64(ROTATION_RANSAC_SEED);
    let mut best: Vec<usize> = Vec::new();
    if rays.len() >= 2 {
        for _ in 0..options.max_iterations {
            let i = rng.random_range(0..rays.len());
            let j = rng.random_range(0..rays.len());
            if i == j {
                continue;
            }
            let Some(rotation) = aligning_rotation([i, j].iter().map(|&k| &rays[k])) else {
                continue;
            };
            let inliers = explained(&rotation);
            if inliers.len() > best.len() {
                best = inliers;
            }
        }
    }
    let mut rotation = None;
    for _ in 0..2 {
        let Some(refit) = aligning_rotation(best.iter().map(|&k| &rays[k])) else {
            break;
        };
        best = explained(&refit);
        rotation = Some(refit);
    }
    let Some(rotation) = rotation.filter(|_| best.len() >= options.min_inliers as usize) else {
        return Err(PoseRefusal::NoConsensus {
            inliers: best.len() as u32,
        });
    };
    let pose = Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_rotation_matrix(&rotation),
    );
    let inliers: Vec<&([f32; 2], [f32; 2])> = best.iter().map(|&k| &pairs[k]).collect();
    let residual = |p: &Isometry3<f64>, (q, m): &([f32; 2], [f32; 2])| {
        let seen = Vector2::new(f64::from(m[0]), f64::from(m[1]));
        camera
            .project(&(p.rotation * bearing(camera, q)))
            .map_or(vec![1e3, 1e3], |px| {
                let r = px - seen;
                vec![r.x, r.y]
            })
    };
    let axes = [Vector3::x(), Vector3::y(), Vector3::z()];
    let (covariance, rms) = covariance(&pose, &inliers, residual, &axes);
    Ok(RelativePose {
        matched_t_query: pose,
        scale_known: false,
        inliers: inliers.len() as u32,
        rms_px: rms,
        covariance,
    })
}

/// Seed of the rotation-only RANSAC: the same pairs always give the same pose.
const ROTATION_RANSAC_SEED: u64 = 0x7090_10c0;

/// The rotation taking each pair's first ray (query frame) closest to its second (matched
/// frame), least squares (Kabsch); `None` without two rays that span a plane.
fn aligning_rotation<'a>(
    rays: impl Iterator<Item = &'a (Vector3<f64>, Vector3<f64>)>,
) -> Option<Rotation3<f64>> {
    let mut correlation = Matrix3::<f64>::zeros();
    for (q, m) in rays {
        correlation += m * q.transpose();
    }
    let svd = correlation.svd(true, true);
    if svd.singular_values[1] < 1e-9 {
        return None;
    }
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut fix = Matrix3::identity();
    fix[(2, 2)] = (u * v_t).determinant().signum();
    Some(Rotation3::from_matrix_unchecked(u * fix * v_t))
}

/// Angle (radians) between two unit rays.
fn angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.dot(b).clamp(-1.0, 1.0).acos()
}

fn matrix3(m: &Mat) -> Result<Matrix3<f64>, VisionError> {
    let mut out = Matrix3::zeros();
    for r in 0..3 {
        for c in 0..3 {
            out[(r, c)] = *m.at_2d::<f64>(r as i32, c as i32)?;
        }
    }
    Ok(out)
}

/// The bearing (unit ray in the camera frame) of a pixel.
fn bearing(camera: &PinholeCamera, p: &[f32; 2]) -> Vector3<f64> {
    Vector3::new(
        (f64::from(p[0]) - camera.cx) / camera.fx,
        (f64::from(p[1]) - camera.cy) / camera.fy,
        1.0,
    )
    .normalize()
}

/// Median angle (degrees) between each inlier's matched ray and its query ray rotated into
/// the matched frame: zero for a pure rotation.
fn median_parallax(
    camera: &PinholeCamera,
    matched_t_query: &Isometry3<f64>,
    inliers: &[([f32; 2], [f32; 2])],
) -> f64 {
    let mut angles: Vec<f64> = inliers
        .iter()
        .map(|(q, m)| {
            angle(
                &(matched_t_query.rotation * bearing(camera, q)),
                &bearing(camera, m),
            )
            .to_degrees()
        })
        .collect();
    if angles.is_empty() {
        return 0.0;
    }
    angles.sort_by(f64::total_cmp);
    angles[angles.len() / 2]
}

/// Sampson distance (pixels) of a correspondence under the pose's fundamental matrix.
fn sampson_px(
    camera: &PinholeCamera,
    matched_t_query: &Isometry3<f64>,
    q: &[f32; 2],
    m: &[f32; 2],
) -> f64 {
    let query_t_matched = matched_t_query.inverse();
    let t = query_t_matched.translation.vector;
    let e = t.cross_matrix() * query_t_matched.rotation.to_rotation_matrix().matrix();
    let k_inv = Matrix3::new(
        1.0 / camera.fx,
        0.0,
        -camera.cx / camera.fx,
        0.0,
        1.0 / camera.fy,
        -camera.cy / camera.fy,
        0.0,
        0.0,
        1.0,
    );
    let f = k_inv.transpose() * e * k_inv;
    let x1 = Vector3::new(f64::from(m[0]), f64::from(m[1]), 1.0);
    let x2 = Vector3::new(f64::from(q[0]), f64::from(q[1]), 1.0);
    let fx1 = f * x1;
    let ftx2 = f.transpose() * x2;
    let denominator = fx1.x.powi(2) + fx1.y.powi(2) + ftx2.x.powi(2) + ftx2.y.powi(2);
    if denominator <= 0.0 {
        return 0.0;
    }
    x2.dot(&fx1) / denominator.sqrt()
}

/// `sigma^2 (J^T J)^-1` and the RMS residual, `J` by central differences of `residuals` under
/// right perturbations of `pose`, plus a unit-information prior on the translation along each
/// (unit, query-frame) direction of `priors`. Singular information gives an infinite
/// covariance.
fn covariance<T>(
    pose: &Isometry3<f64>,
    items: &[&T],
    residuals: impl Fn(&Isometry3<f64>, &T) -> Vec<f64>,
    priors: &[Vector3<f64>],
) -> (Matrix6<f64>, f64) {
    const STEP: f64 = 1e-6;
    let perturbed = |xi: &Vector6<f64>| {
        let delta = Isometry3::from_parts(
            Translation3::new(xi[3], xi[4], xi[5]),
            UnitQuaternion::from_scaled_axis(Vector3::new(xi[0], xi[1], xi[2])),
        );
        pose * delta
    };
    let mut information = Matrix6::<f64>::zeros();
    let (mut squared, mut count) = (0.0, 0usize);
    for item in items {
        let base = residuals(pose, item);
        squared += base.iter().map(|r| r * r).sum::<f64>();
        count += base.len();
        let mut jacobian = vec![Vector6::<f64>::zeros(); base.len()];
        for k in 0..6 {
            let mut xi = Vector6::zeros();
            xi[k] = STEP;
            let plus = residuals(&perturbed(&xi), item);
            xi[k] = -STEP;
            let minus = residuals(&perturbed(&xi), item);
            for (row, (p, m)) in jacobian.iter_mut().zip(plus.iter().zip(&minus)) {
                row[k] = (p - m) / (2.0 * STEP);
            }
        }
        for row in &jacobian {
            information += row * row.transpose();
        }
    }
    let variance = if count > 0 {
        (squared / count as f64).max(1e-6)
    } else {
        1.0
    };
    let mut scaled = information / variance;
    for d in priors {
        let mut v = Vector6::zeros();
        v.fixed_rows_mut::<3>(3).copy_from(d);
        scaled += v * v.transpose();
    }
    let covariance = scaled
        .try_inverse()
        .unwrap_or_else(|| Matrix6::from_element(f64::INFINITY));
    (covariance, variance.sqrt())
}
