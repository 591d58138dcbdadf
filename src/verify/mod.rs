//! Geometric verification of place candidates (the seed's GC re-ranking, and the evidence behind
//! a loop-closure hint).
//!
//! Maps built from images store ORB keypoints of every view ([`ViewKeypoints`], written to the
//! map file since format 1.2). When verification is on, the localizer detects keypoints in the
//! query image, checks the views most similar to it of the most probable places
//! ([`check_pair`]: mutual nearest-neighbour matches and a RANSAC fundamental matrix), and
//! weighs each checked place's belief by `exp(inlier_weight * inliers)`. Look-alike places
//! (same wallpaper, another room) rarely agree with the query on one rigid scene, so their
//! inlier counts stay low where the true place's are high.
//!
//! When the map also stores the scene point of each view keypoint (format 1.3) and the
//! localizer knows the query camera's intrinsics ([`VerificationOptions::camera`]), the view
//! with the most inliers is used to place the camera metrically ([`locate`]): a pose fix for
//! the host's pose graph and, in metric mode, a measurement of the particles' position.

use crate::bounds::Bounds;

mod cells;
mod depth;
mod detector;
mod geometry;
mod keypoints;
mod pose;
mod relative;
pub mod xfeat;

pub use cells::{cells_from_map, CELL_TAP, DEFAULT_CELLS};
pub use depth::{camera_points_from_depth, DepthImage};
pub use detector::FeatureDetector;
pub use geometry::{
    check_pair, fit_pair, fit_pair_reaching, spatial_check, FundamentalEstimator, PairCheck,
    PairFit, PairOptions, SpatialCheck, MIN_MATCHES, PAIR_MIN_INLIERS_RANGE,
    RANSAC_ITERATIONS_RANGE, RANSAC_THRESHOLD_PX_RANGE,
};
pub use keypoints::{
    CellDescriptor, Descriptor, Descriptors, DescriptorsRef, FeatureKind, KeypointDetector,
    Keypoints, KeypointsRef, ViewKeypoints, XFeatDescriptor, CELL_DIM, DESCRIPTOR_BYTES,
    MAX_KEYPOINTS, XFEAT_DIM,
};
pub use pose::{locate, LocateOptions, Located, PinholeCamera, MIN_PAIRS};
pub use relative::{
    essential_pose, relative_pose, relative_pose_from_fit, PoseRefusal, PoseTranslation,
    RelativePose, RelativePoseOptions, ScenePoints,
};
pub use xfeat::{
    XFeatDetector, XFeatOptions, DEFAULT_XFEAT_KEYPOINTS, DEFAULT_XFEAT_MAX_PIXELS,
    MAX_XFEAT_PIXELS,
};

/// Keypoints per view a map built from images stores by default, and a query detects.
pub const DEFAULT_KEYPOINTS: usize = 500;

/// What a checked view's evidence is: the seed's two scores.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum VerificationScore {
    /// GC: inliers of a robust fundamental-matrix fit ([`check_pair`]).
    #[default]
    Inliers,
    /// s-GC: the sampling-free spatial score of the mutual matches ([`spatial_check`]), as an
    /// agreeing-match count (the score times the query's keypoints), so that `inlier_weight`
    /// applies to it as to inliers. No RANSAC: deterministic and cheaper per candidate.
    Spatial,
}

/// When and how the localizer verifies candidates. Off by default (`candidates == 0`):
/// verification needs the frame's image and a map holding keypoints, and costs one ORB match and
/// RANSAC fit per checked view (timings in BENCHMARKS.md).
#[derive(Clone, Debug, PartialEq)]
pub struct VerificationOptions {
    /// Most probable places checked per frame; 0 turns verification off. Default 0.
    pub candidates: usize,
    /// Views checked per candidate place: those most similar to the query. Default 2.
    pub views_per_candidate: usize,
    /// Log-likelihood of one inlier: a checked place's belief is multiplied by
    /// `exp(inlier_weight * inliers)` before normalising. Default 0.05 (0.025-0.2 compared
    /// with `topoloc suite`, BENCHMARKS.md).
    pub inlier_weight: f32,
    /// Keypoints detected in the query image, of the kind the map stores. Default
    /// [`DEFAULT_KEYPOINTS`].
    pub query_keypoints: usize,
    /// Where the XFeat network is, for maps storing XFeat keypoints.
    pub xfeat: XFeatOptions,
    /// Matching and RANSAC for keypoints (ORB, XFeat). Default [`PairOptions::default`].
    pub pair: PairOptions,
    /// The same for dense cells. Default [`PairOptions::cells_default`].
    pub cells_pair: PairOptions,
    /// GC inliers (default) or the s-GC spatial score as each checked view's evidence.
    pub score: VerificationScore,
    /// Intrinsics of the query camera. With them, and a map storing keypoint scene points, the
    /// best-verified view gives a metric pose of the camera ([`locate`]). Default `None`.
    pub camera: Option<PinholeCamera>,
    /// The pose fit against the best-verified view.
    pub locate: LocateOptions,
    /// Off-map evidence from the checks: the most inliers (or s-GC evidence) among the checked
    /// places at which a frame is as likely off the map as on it. The frame's off-map update
    /// then uses the likelihood ratio `exp((off_map_inliers - most) / off_map_inlier_scale)`
    /// in place of the appearance scores'. `Some(0.0)` leaves the off-map decision to
    /// appearance. Default `None`: the map's feature kind's
    /// ([`FeatureKind::default_off_map_inliers`]).
    pub off_map_inliers: Option<f32>,
    /// Inliers per e-fold of that likelihood ratio (> 0). Default
    /// [`DEFAULT_OFF_MAP_INLIER_SCALE`].
    pub off_map_inlier_scale: f32,
}

/// Default [`VerificationOptions::off_map_inlier_scale`]; chosen with the XFeat threshold
/// (BENCHMARKS.md, "Off-map flags").
pub const DEFAULT_OFF_MAP_INLIER_SCALE: f32 = 4.0;

impl Default for VerificationOptions {
    fn default() -> Self {
        Self {
            candidates: 0,
            views_per_candidate: 2,
            inlier_weight: 0.05,
            query_keypoints: DEFAULT_KEYPOINTS,
            xfeat: XFeatOptions::default(),
            pair: PairOptions::default(),
            cells_pair: PairOptions::cells_default(),
            score: VerificationScore::default(),
            camera: None,
            locate: LocateOptions::default(),
            off_map_inliers: None,
            off_map_inlier_scale: DEFAULT_OFF_MAP_INLIER_SCALE,
        }
    }
}

impl VerificationOptions {
    /// Verification with `candidates` places checked per frame and the other defaults.
    pub fn with_candidates(candidates: usize) -> Self {
        Self {
            candidates,
            ..Self::default()
        }
    }

    /// The matching and fit options for features of `kind`.
    pub fn pair_for(&self, kind: FeatureKind) -> &PairOptions {
        match kind {
            FeatureKind::Cells => &self.cells_pair,
            FeatureKind::Orb | FeatureKind::XFeat => &self.pair,
        }
    }

    /// True when candidates are checked.
    pub fn enabled(&self) -> bool {
        self.candidates > 0
    }

    /// Accepted values of [`Self::candidates`] (0: verification off).
    pub const CANDIDATES_RANGE: Bounds = Bounds::whole(0, 64);
    /// Accepted values of [`Self::views_per_candidate`].
    pub const VIEWS_PER_CANDIDATE_RANGE: Bounds = Bounds::whole(1, 64);
    /// Accepted values of [`Self::inlier_weight`].
    pub const INLIER_WEIGHT_RANGE: Bounds = Bounds::at_least(0.0);
    /// Accepted values of [`Self::off_map_inliers`] when set.
    pub const OFF_MAP_INLIERS_RANGE: Bounds = Bounds::at_least(0.0);
    /// Accepted values of [`Self::off_map_inlier_scale`].
    pub const OFF_MAP_INLIER_SCALE_RANGE: Bounds = Bounds::above(0.0);
    /// Accepted values of [`Self::query_keypoints`].
    pub const QUERY_KEYPOINTS_RANGE: Bounds = Bounds::whole(1, MAX_KEYPOINTS as u64);

    /// Fails with a message naming the field out of range.
    pub fn validate(&self) -> Result<(), String> {
        Self::CANDIDATES_RANGE.check("verification.candidates", self.candidates)?;
        Self::VIEWS_PER_CANDIDATE_RANGE
            .check("verification.views_per_candidate", self.views_per_candidate)?;
        Self::INLIER_WEIGHT_RANGE.check("verification.inlier_weight", self.inlier_weight)?;
        if let Some(n) = self.off_map_inliers {
            Self::OFF_MAP_INLIERS_RANGE.check("verification.off_map_inliers", n)?;
        }
        Self::OFF_MAP_INLIER_SCALE_RANGE.check(
            "verification.off_map_inlier_scale",
            self.off_map_inlier_scale,
        )?;
        Self::QUERY_KEYPOINTS_RANGE.check("verification.query_keypoints", self.query_keypoints)?;
        if let Some(camera) = &self.camera {
            camera.validate().map_err(|e| format!("verification.{e}"))?;
            if self.candidates == 0 {
                return Err(
                    "verification.camera is set but verification.candidates is 0: pose fixes come from verified views".into(),
                );
            }
        }
        self.locate
            .validate()
            .map_err(|e| format!("verification.locate.{e}"))?;
        self.pair
            .validate()
            .map_err(|e| format!("verification.pair: {e}"))?;
        self.cells_pair
            .validate()
            .map_err(|e| format!("verification.cells_pair: {e}"))
    }
}
