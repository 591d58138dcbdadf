//! Options of loop hints: the candidates considered, the gates' bounds, and the odometry
//! agreement gate.

use super::super::error::LoopsError;
use crate::verify::{
    FeatureKind, FundamentalEstimator, PairOptions, PinholeCamera, RelativePoseOptions,
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
    /// The odometry agreement gate (applied when both keyframes have poses and the hint a pose).
    pub odometry: Option<OdometryGate>,
    /// Matching and fundamental-matrix fit for point features (XFeat, ORB): by default XFeat
    /// matches below cosine 0.82 dropped (XFeat's own matcher's floor) and RANSAC at 1.5 px
    /// with 100 iterations (chosen on generated train and tr-t revisits in bright and dim
    /// light: the precision of 200 iterations on every match at two thirds of the keyframe
    /// time, BENCHMARKS.md).
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

impl HintOptions {
    /// The matching and fit options for features of `kind`.
    pub fn pair_for(&self, kind: FeatureKind) -> &PairOptions {
        match kind {
            FeatureKind::Cells => &self.cells_pair,
            FeatureKind::Orb | FeatureKind::XFeat => &self.pair,
        }
    }

    /// Fails with [`LoopsError::InvalidOption`] naming the field out of range.
    pub fn validate(&self) -> Result<(), LoopsError> {
        let bad = |m: String| Err(LoopsError::InvalidOption(m));
        if !(1..=64).contains(&self.candidates) {
            return bad(format!(
                "candidates is {}, must lie in 1..=64",
                self.candidates
            ));
        }
        if !(self.exclude_recent_s.is_finite() && self.exclude_recent_s >= 0.0) {
            return bad("exclude_recent_s must be finite and >= 0".into());
        }
        if !(8..=10_000).contains(&self.min_inliers) {
            return bad(format!(
                "min_inliers is {}, must lie in 8..=10000",
                self.min_inliers
            ));
        }
        if !(1..=100).contains(&self.consistent_keyframes) {
            return bad(format!(
                "consistent_keyframes is {}, must lie in 1..=100",
                self.consistent_keyframes
            ));
        }
        if let Some(g) = &self.odometry {
            let positive = |v: f64| v.is_finite() && v > 0.0;
            if !(positive(g.max_rotation_deg) && positive(g.max_translation_m)) {
                return bad("odometry bounds must be finite and > 0".into());
            }
            if !(g.max_translation_per_m.is_finite() && g.max_translation_per_m >= 0.0) {
                return bad("odometry max_translation_per_m must be finite and >= 0".into());
            }
        }
        if let Some(camera) = &self.camera {
            camera.validate().map_err(LoopsError::InvalidOption)?;
        }
        if self.odometry_candidates > 64 {
            return bad(format!(
                "odometry_candidates is {}, must lie in 0..=64",
                self.odometry_candidates
            ));
        }
        if !(self.odometry_search_m.is_finite() && self.odometry_search_m >= 0.0) {
            return bad("odometry_search_m must be finite and >= 0".into());
        }
        if self.refine_keyframes > 64 {
            return bad(format!(
                "refine_keyframes is {}, must lie in 0..=64",
                self.refine_keyframes
            ));
        }
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
