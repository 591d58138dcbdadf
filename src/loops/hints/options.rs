//! Options of loop hints: the candidates considered, the gates' bounds, and the odometry
//! agreement gate.

use super::super::error::LoopsError;
use crate::bounds::Bounds;
use crate::verify::{
    FeatureKind, FundamentalEstimator, PairOptions, PinholeCamera, RelativePoseOptions,
    PAIR_MIN_INLIERS_RANGE,
};

/// The odometry agreement gate: bounds on the difference between the hint's relative pose and
/// the host's odometry between the two keyframes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OdometryGate {
    /// Largest rotation difference, degrees. Default 30 (VINS-Fusion's loop_fusion).
    pub max_rotation_deg: f64,
    /// Largest translation difference, metres, plus `max_translation_per_m` for every metre
    /// the odometry travelled between the two keyframes; an unscaled hint's direction is
    /// scaled by the odometry's baseline first. Default 1 (with 0.02 per metre), chosen on
    /// generated train and tr-t revisits over VINS-Fusion's fixed 20 m: look-alike stretches
    /// of a corridor pass a fixed bound that true loops after long detours need
    /// (BENCHMARKS.md).
    pub max_translation_m: f64,
    /// The odometry's drift per metre travelled that the translation bound allows for (0.02:
    /// 2 cm per metre); 0 gives a fixed bound. Applies between keyframes of this session
    /// (reloaded ones have another session's odometry). Default 0.02.
    pub max_translation_per_m: f64,
}

impl Default for OdometryGate {
    fn default() -> Self {
        Self {
            max_rotation_deg: 30.0,
            max_translation_m: 1.0,
            max_translation_per_m: 0.02,
        }
    }
}

/// How hints are found and gated.
#[derive(Clone, Debug, PartialEq)]
pub struct HintOptions {
    /// Loop candidates verified per keyframe, most similar first. Default 5.
    pub candidates: usize,
    /// Candidates come from different stretches of the route: one whose id is less than this
    /// from a more similar candidate's is skipped ([`LoopQuery::min_id_gap`](crate::loops::LoopQuery::min_id_gap)); 0 = off.
    /// Default 10.
    pub candidate_id_gap: u64,
    /// Keyframes with an id within this many of the query's are never candidates (DBoW2's
    /// `max_id = id - window`). Default 30.
    pub exclude_recent_ids: u64,
    /// Keyframes less than this many seconds older than the query are never candidates.
    /// Default 10.
    pub exclude_recent_s: f64,
    /// Fewest inliers of an accepted candidate. Default 30.
    pub min_inliers: u32,
    /// Consecutive keyframes whose best candidates must agree (their place groups overlap),
    /// the current one included. Default 3 (ORB-SLAM's).
    pub consistent_keyframes: usize,
    /// The pace rule of the consistency gate: consecutive keyframes agree only when their
    /// candidates' timestamps differ by at most this many times the keyframes' own time step
    /// plus [`Self::match_pace_slack_s`], unless the odometry puts the two candidates within
    /// [`DatabaseOptions::neighbour_radius_m`](crate::loops::DatabaseOptions::neighbour_radius_m)
    /// of each other (one spot passed twice). A revisit runs at a vehicle's pace; a match
    /// that slides along a look-alike stretch faster does not. 0 = off. Default 3.
    pub max_match_pace: f64,
    /// The pace rule's slack, seconds (keyframes of either pass taken at uneven times).
    /// Default 0.5.
    pub match_pace_slack_s: f64,
    /// The odometry agreement gate (applied when both keyframes have poses and the hint a pose).
    pub odometry: Option<OdometryGate>,
    /// Matching and fundamental-matrix fit for point features (XFeat, ORB): by default XFeat
    /// matches below cosine 0.82 dropped (XFeat's own matcher's floor) and RANSAC at 1.5 px
    /// with 100 iterations (chosen on generated train and tr-t revisits in bright and dim
    /// light: the precision of 200 iterations on every match at two thirds of the keyframe
    /// time, BENCHMARKS.md). USAC_FAST ([`FundamentalEstimator::UsacFast`]) fits in a
    /// quarter of the time and kept the precision on train worlds and KITTI 00, but not on
    /// KITTI at 320x240 (15 hints without a revisit), and refuses a camera that only turned.
    pub pair: PairOptions,
    /// The same for dense cells. Default [`PairOptions::cells_default`].
    pub cells_pair: PairOptions,
    /// Candidates proposed by the odometry besides appearance's: the keyframes nearest the
    /// new one's odometry camera position that could pass the odometry gate (within its
    /// translation bound plus `odometry_search_m`, facing within its rotation bound), this
    /// session's only; needs poses and the odometry gate. 0 = none. Default 1.
    pub odometry_candidates: usize,
    /// How much farther than the odometry gate's translation bound an odometry candidate may
    /// be: the two cameras' true distance at a loop (metres, >= 0). Default 2.
    pub odometry_search_m: f64,
    /// Keyframes of a candidate's group (its place, the linked places, its stretch) checked
    /// when it is refined, nearest in id first; 0 = no refinement. Default 5 (2 kept the
    /// recall on bright generated train revisits with 0.6 times the checks, but lost it in dim
    /// light and on Gardens Point, BENCHMARKS.md).
    pub refine_keyframes: usize,
    /// Intrinsics of the camera (the same for every keyframe); without them hints have no pose.
    pub camera: Option<PinholeCamera>,
    /// The relative pose fit.
    pub pose: RelativePoseOptions,
}

impl Default for HintOptions {
    fn default() -> Self {
        Self {
            candidates: 5,
            candidate_id_gap: 10,
            exclude_recent_ids: 30,
            exclude_recent_s: 10.0,
            min_inliers: 30,
            consistent_keyframes: 3,
            max_match_pace: 3.0,
            match_pace_slack_s: 0.5,
            odometry: Some(OdometryGate::default()),
            pair: PairOptions {
                estimator: FundamentalEstimator::Ransac,
                max_iterations: 100,
                min_cosine: 0.82,
                ..PairOptions::default()
            },
            cells_pair: PairOptions::cells_default(),
            odometry_candidates: 1,
            odometry_search_m: 2.0,
            refine_keyframes: 5,
            camera: None,
            pose: RelativePoseOptions::default(),
        }
    }
}

impl OdometryGate {
    /// Accepted values of [`Self::max_rotation_deg`] and [`Self::max_translation_m`].
    pub const BOUND_RANGE: Bounds = Bounds::above(0.0);
    /// Accepted values of [`Self::max_translation_per_m`].
    pub const PER_M_RANGE: Bounds = Bounds::at_least(0.0);

    /// Fails with [`LoopsError::InvalidOption`] naming the bound out of range (for hosts
    /// that hold a gate's bounds while the gate is off).
    pub fn validate(&self) -> Result<(), LoopsError> {
        self.check_ranges().map_err(LoopsError::InvalidOption)
    }

    fn check_ranges(&self) -> Result<(), String> {
        Self::BOUND_RANGE.check("odometry max_rotation_deg", self.max_rotation_deg)?;
        Self::BOUND_RANGE.check("odometry max_translation_m", self.max_translation_m)?;
        Self::PER_M_RANGE.check("odometry max_translation_per_m", self.max_translation_per_m)
    }
}

impl HintOptions {
    /// Accepted values of [`Self::candidates`].
    pub const CANDIDATES_RANGE: Bounds = Bounds::whole(1, 64);
    /// Accepted values of [`Self::exclude_recent_s`].
    pub const EXCLUDE_RECENT_S_RANGE: Bounds = Bounds::at_least(0.0);
    /// Accepted values of [`Self::min_inliers`].
    pub const MIN_INLIERS_RANGE: Bounds = PAIR_MIN_INLIERS_RANGE;
    /// Accepted values of [`Self::consistent_keyframes`].
    pub const CONSISTENT_KEYFRAMES_RANGE: Bounds = Bounds::whole(1, 100);
    /// Accepted values of [`Self::max_match_pace`] (0: off).
    pub const MAX_MATCH_PACE_RANGE: Bounds = Bounds::at_least(0.0);
    /// Accepted values of [`Self::match_pace_slack_s`].
    pub const MATCH_PACE_SLACK_S_RANGE: Bounds = Bounds::at_least(0.0);
    /// Accepted values of [`Self::odometry_candidates`] (0: none).
    pub const ODOMETRY_CANDIDATES_RANGE: Bounds = Bounds::whole(0, 64);
    /// Accepted values of [`Self::odometry_search_m`].
    pub const ODOMETRY_SEARCH_M_RANGE: Bounds = Bounds::at_least(0.0);
    /// Accepted values of [`Self::refine_keyframes`] (0: no refinement).
    pub const REFINE_KEYFRAMES_RANGE: Bounds = Bounds::whole(0, 64);
    /// Accepted values of [`Self::candidate_id_gap`] and [`Self::exclude_recent_ids`] (ids;
    /// any: their cost does not grow with their value).
    pub const ID_COUNT_RANGE: Bounds = Bounds::whole_at_least(0);

    fn check_ranges(&self) -> Result<(), String> {
        Self::CANDIDATES_RANGE.check("candidates", self.candidates)?;
        Self::ID_COUNT_RANGE.check("candidate_id_gap", self.candidate_id_gap)?;
        Self::ID_COUNT_RANGE.check("exclude_recent_ids", self.exclude_recent_ids)?;
        Self::EXCLUDE_RECENT_S_RANGE.check("exclude_recent_s", self.exclude_recent_s)?;
        Self::MIN_INLIERS_RANGE.check("min_inliers", self.min_inliers)?;
        Self::CONSISTENT_KEYFRAMES_RANGE
            .check("consistent_keyframes", self.consistent_keyframes)?;
        Self::MAX_MATCH_PACE_RANGE.check("max_match_pace", self.max_match_pace)?;
        Self::MATCH_PACE_SLACK_S_RANGE.check("match_pace_slack_s", self.match_pace_slack_s)?;
        if let Some(gate) = &self.odometry {
            gate.check_ranges()?;
        }
        if let Some(camera) = &self.camera {
            camera.validate()?;
        }
        Self::ODOMETRY_CANDIDATES_RANGE.check("odometry_candidates", self.odometry_candidates)?;
        Self::ODOMETRY_SEARCH_M_RANGE.check("odometry_search_m", self.odometry_search_m)?;
        Self::REFINE_KEYFRAMES_RANGE.check("refine_keyframes", self.refine_keyframes)
    }

    /// The matching and fit options for features of `kind`.
    pub fn pair_for(&self, kind: FeatureKind) -> &PairOptions {
        match kind {
            FeatureKind::Cells => &self.cells_pair,
            FeatureKind::Orb | FeatureKind::XFeat => &self.pair,
        }
    }

    /// Fails with [`LoopsError::InvalidOption`] naming the field out of range.
    pub fn validate(&self) -> Result<(), LoopsError> {
        self.check_ranges().map_err(LoopsError::InvalidOption)?;
        self.pair
            .validate()
            .map_err(|e| LoopsError::InvalidOption(format!("pair: {e}")))?;
        self.cells_pair
            .validate()
            .map_err(|e| LoopsError::InvalidOption(format!("cells_pair: {e}")))?;
        self.pose
            .validate()
            .map_err(|e| LoopsError::InvalidOption(format!("pose: {e}")))
    }
}
