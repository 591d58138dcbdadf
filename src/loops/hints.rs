//! Verified loop-closure hints: for each new keyframe, the database's loop candidates (recent
//! keyframes excluded, at most one per stretch of `candidate_id_gap` consecutive ids, so that
//! one look-alike stretch cannot fill every slot), with host odometry also the keyframes
//! nearest its odometry pose that the odometry gate could pass, are checked geometrically
//! against the keyframe's local features, and a candidate becomes a hint only when it passes
//! every gate:
//!
//! 1. a candidate exists outside the exclusion window ([`Gate::NoCandidate`]);
//! 2. the candidate with the most fundamental-matrix inliers, refined within its group (the
//!    keyframes of its place and the linked places, and of its stretch: neighbouring
//!    keyframes look alike, geometry picks the nearest), has at least `min_inliers`
//!    ([`Gate::TooFewInliers`]);
//! 3. with camera intrinsics and point-accurate features, a relative pose is found
//!    ([`Gate::NoPose`]; dense cells verify but give no pose);
//! 4. with odometry poses on both keyframes, the pose agrees with the odometry's relative
//!    pose (VINS-Fusion's loop check: |delta yaw| and |delta t| bounds; an unscaled pose's
//!    direction is scaled by the odometry's baseline, [`Gate::Odometry`]);
//!
//!    a candidate refused by gate 3 or 4 gives way to the next with enough inliers (most
//!    first, each refined), so a look-alike with more inliers than the true match does not
//!    hide it when geometry or odometry can tell them apart; with odometry, every candidate
//!    with enough inliers is tried and the passing one the odometry agrees with most is kept
//!    (a look-alike stretch a few metres on can pass the drift bound beside the true one);
//! 5. the candidates that passed 2-4 for the last `consistent_keyframes` keyframes agree: each
//!    one's group (its place and the linked places) shares a place with the previous one's
//!    ([`Gate::Inconsistent`], ORB-SLAM's consistency groups on the place graph).
//!
//! At most one hint per keyframe. A refused candidate is reported with the gate that refused
//! it, so the host can log why no loop was closed. The keyframes that began a streak were
//! refused as inconsistent only because the streak was not long enough yet: when a later
//! keyframe completes it, their hints are delivered with that keyframe as confirmed
//! ([`Processed::confirmed`]), so a revisit yields hints from its first keyframe on. Errors (bad features, keyframes out of
//! order, duplicate ids) leave the detector exactly as it was.

use super::database::{Added, DatabaseOptions, KeyframeDatabase, KeyframeEntry, LoopQuery, Match};
use super::error::LoopsError;
use crate::map::{Map, PlaceId};
use crate::verify::{
    fit_pair_reaching, relative_pose_from_fit, FeatureKind, FundamentalEstimator, Keypoints,
    PairFit, PairOptions, PinholeCamera, PoseRefusal, RelativePose, RelativePoseOptions,
};
use nalgebra::{Isometry3, Point3};
use std::collections::HashMap;

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
    /// from a more similar candidate's is skipped ([`LoopQuery::min_id_gap`]); 0 = off.
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

/// A keyframe's local features: its keypoints and, when the host has them, the scene point of
/// each in the keyframe's camera frame (metres; NaN in all three coordinates when unknown).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KeyframeFeatures {
    /// Keypoints with their descriptors (ORB from the host, XFeat, or dense cells).
    pub keypoints: Keypoints,
    /// Scene points, one per keypoint, in the camera frame.
    pub camera_points: Option<Vec<[f32; 3]>>,
}

/// Which gate refused the best candidate, or that it was accepted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Gate {
    /// Accepted: the hint is a loop closure.
    Accepted,
    /// No keyframe outside the exclusion window with keypoints of this kind (or the new
    /// keyframe has none).
    NoCandidate,
    /// The best candidate had fewer inliers than `min_inliers`.
    TooFewInliers,
    /// Too few consecutive keyframes agreed on the place.
    Inconsistent {
        /// Consecutive agreeing keyframes so far, this one included.
        agreeing: usize,
    },
    /// No relative pose could be fitted.
    NoPose(PoseRefusal),
    /// The pose disagrees with the host's odometry.
    Odometry {
        /// Rotation difference, degrees.
        rotation_deg: f64,
        /// Translation difference, metres (unscaled hints: their direction scaled by the
        /// odometry's baseline).
        translation_m: f64,
    },
}

impl Gate {
    /// Short lower-case name for logs (`accepted`, `no_candidate`, ...).
    pub fn name(&self) -> &'static str {
        match self {
            Gate::Accepted => "accepted",
            Gate::NoCandidate => "no_candidate",
            Gate::TooFewInliers => "too_few_inliers",
            Gate::Inconsistent { .. } => "inconsistent",
            Gate::NoPose(_) => "no_pose",
            Gate::Odometry { .. } => "odometry",
        }
    }
}

/// The best verified candidate of a keyframe, accepted or not.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopHint {
    /// The query keyframe's id.
    pub query_id: u64,
    /// The place the query keyframe joined.
    pub query_place: PlaceId,
    /// The matched keyframe's id.
    pub matched_id: u64,
    /// The matched keyframe's place.
    pub place: PlaceId,
    /// Fundamental-matrix inliers.
    pub inliers: u32,
    /// The candidate's share of the inliers of every verified candidate (0..=1): near 1 when
    /// no other candidate agrees with the query, near 1/n among n look-alikes.
    pub confidence: f32,
    /// The relative pose, when intrinsics were given and it was fitted.
    pub pose: Option<RelativePose>,
    /// Which gate refused it, or [`Gate::Accepted`].
    pub gate: Gate,
}

impl LoopHint {
    /// True when every gate passed.
    pub fn accepted(&self) -> bool {
        self.gate == Gate::Accepted
    }
}

/// What processing a keyframe did.
#[derive(Clone, Debug, PartialEq)]
pub struct Processed {
    /// Where the keyframe went in the place graph.
    pub added: Added,
    /// The best verified candidate; `None` when there was none ([`Gate::NoCandidate`]).
    pub hint: Option<LoopHint>,
    /// Hints of earlier keyframes that this one confirmed: the keyframes of the streak it
    /// completed, whose candidates passed every other gate but were refused as
    /// [`Gate::Inconsistent`] while the streak was short, and whose pose, with odometry,
    /// agrees with this keyframe's along the route. Now [`Gate::Accepted`], oldest first,
    /// each with its own `query_id`; empty unless this keyframe's hint was accepted.
    /// Every keyframe gets at most one accepted hint, as its own or as a confirmed one.
    pub confirmed: Vec<LoopHint>,
    /// The geometric work it took, for hosts that budget or log the cost.
    pub work: Work,
}

/// Geometric work done for one keyframe: what its time is made of besides describing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Work {
    /// Pair checks (matching and a fundamental-matrix fit), candidates and refinements.
    pub pair_checks: u32,
    /// Relative-pose fits.
    pub pose_fits: u32,
}

impl Processed {
    /// The gate that decided: the hint's, or [`Gate::NoCandidate`].
    pub fn gate(&self) -> Gate {
        self.hint.map_or(Gate::NoCandidate, |h| h.gate)
    }

    /// The accepted hint, if any.
    pub fn accepted(&self) -> Option<&LoopHint> {
        self.hint.as_ref().filter(|h| h.accepted())
    }
}

/// A keyframe database with each keyframe's local features, producing gated hints.
pub struct LoopDetector {
    database: KeyframeDatabase,
    options: HintOptions,
    features: HashMap<u64, KeyframeFeatures>,
    kind: Option<FeatureKind>,
    /// The place the last keyframes' best candidates agreed on, and how many in a row.
    streak: Streak,
    /// The hints of the current streak's keyframes, refused as inconsistent: confirmed when
    /// a later keyframe completes the streak, dropped when it breaks.
    pending: Vec<LoopHint>,
    /// What the last successful [`LoopDetector::process`] confirmed.
    confirmed: Vec<LoopHint>,
    /// The largest id of a previous session's keyframes ([`LoopDetector::from_map`]): they are
    /// never inside the exclusion window, whatever this session's ids.
    reloaded_max_id: Option<u64>,
}

/// The place consecutive keyframes' best candidates agreed on, and how many in a row.
type Streak = Option<(PlaceId, usize)>;

/// The geometric gates' verdict on one candidate: passed, or the refusing gate with the pose
/// if one was fitted.
type Geometry = Result<Passed, (Gate, Option<RelativePose>)>;

/// A candidate that passed the geometric gates.
#[derive(Clone, Copy)]
struct Passed {
    /// Its pose (`None` without intrinsics or with cells).
    pose: Option<RelativePose>,
    /// How far the pose's translation is from the odometry's, metres, when the odometry gate
    /// compared them.
    odometry_m: Option<f64>,
}

/// What the gates decided for the best candidate.
struct Gated {
    gate: Gate,
    pose: Option<RelativePose>,
    /// The consistency streak including this keyframe.
    streak: Streak,
}

impl LoopDetector {
    /// A detector over `database` (empty, or reloaded from a map: its keyframes have no
    /// features, so they are never verified candidates). Options are validated.
    pub fn new(database: KeyframeDatabase, options: HintOptions) -> Result<Self, LoopsError> {
        options.validate()?;
        Ok(Self {
            database,
            options,
            features: HashMap::new(),
            kind: None,
            streak: None,
            pending: Vec::new(),
            confirmed: Vec::new(),
            reloaded_max_id: None,
        })
    }

    /// A detector over a map's views as keyframes ([`KeyframeDatabase::from_map`]) with the
    /// keypoints the map stores as their features, and, where the map has both a view's pose
    /// and its keypoints' scene points, those points in the view's camera frame: a second
    /// session closes loops against the first.
    pub fn from_map(
        map: &Map,
        database: DatabaseOptions,
        options: HintOptions,
    ) -> Result<Self, LoopsError> {
        let mut detector = Self::new(KeyframeDatabase::from_map(map, database)?, options)?;
        detector.reloaded_max_id = map.views().iter().filter_map(|v| v.keyframe_id).max();
        let Some(stored) = map.keypoints() else {
            return Ok(detector);
        };
        for (v, view) in map.views().iter().enumerate() {
            let (Some(id), Some(keypoints)) = (view.keyframe_id, stored.view(v)) else {
                continue;
            };
            let camera_points = match (view.world_t_camera, stored.view_world_points(v)) {
                (Some(world_t_camera), Some(world)) => Some(
                    world
                        .iter()
                        .map(|p| {
                            let c = world_t_camera.inverse_transform_point(&Point3::new(
                                f64::from(p[0]),
                                f64::from(p[1]),
                                f64::from(p[2]),
                            ));
                            [c.x as f32, c.y as f32, c.z as f32]
                        })
                        .collect(),
                ),
                _ => None,
            };
            let features = KeyframeFeatures {
                keypoints: keypoints.to_keypoints(),
                camera_points,
            };
            detector.check_features(&features)?;
            detector.kind = Some(stored.kind());
            detector.features.insert(id, features);
        }
        Ok(detector)
    }

    /// The keyframe database.
    pub fn database(&self) -> &KeyframeDatabase {
        &self.database
    }

    /// The options.
    pub fn options(&self) -> &HintOptions {
        &self.options
    }

    /// Queries, verifies and gates the keyframe's loop candidates, then adds the keyframe.
    /// Errors (inconsistent features, features of another kind than earlier keyframes', and
    /// every error of [`KeyframeDatabase::add`]) change nothing.
    pub fn process(
        &mut self,
        entry: &KeyframeEntry<'_>,
        features: KeyframeFeatures,
    ) -> Result<Processed, LoopsError> {
        self.check_features(&features)?;
        let mut checks = Checks::default();
        let verified = self.verified_candidates(entry, &features, &mut checks)?;
        let decided = self.decide(entry, &features, &verified, &mut checks)?;
        let added = self.database.add(entry)?;
        let (hint, streak) = match decided {
            None => (None, None),
            Some((best, Gated { gate, pose, streak })) => {
                let hint = LoopHint {
                    query_id: entry.id,
                    query_place: added.place,
                    matched_id: best.id,
                    place: best.place,
                    inliers: best.inliers,
                    confidence: best.confidence,
                    pose,
                    gate,
                };
                (Some(hint), streak)
            }
        };
        self.kind
            .get_or_insert(features.keypoints.descriptors.kind());
        self.features.insert(entry.id, features);
        self.streak = streak;
        self.confirmed = self.follow_streak(hint.as_ref())?;
        match &hint {
            Some(h) => log::debug!(
                "keyframe {}: candidate keyframe {} (place {}), {} inliers, gate {:?}; {} confirmed",
                entry.id,
                h.matched_id,
                h.place,
                h.inliers,
                h.gate,
                self.confirmed.len()
            ),
            None => log::trace!("keyframe {}: no candidate verified", entry.id),
        }
        Ok(Processed {
            added,
            hint,
            confirmed: self.confirmed.clone(),
            work: checks.work,
        })
    }

    /// The hints the last successful [`LoopDetector::process`] confirmed
    /// ([`Processed::confirmed`]); replaced by the next one, kept by errors and erasures.
    pub fn confirmed(&self) -> &[LoopHint] {
        &self.confirmed
    }

    /// Keeps the streak's pending hints in step with the new keyframe's: an inconsistent hint
    /// joins them (a new streak starts them afresh), an accepted one confirms and returns
    /// those that agree with it along the route ([`LoopDetector::route_agrees`]), any other
    /// outcome drops them (the streak broke).
    fn follow_streak(&mut self, hint: Option<&LoopHint>) -> Result<Vec<LoopHint>, LoopsError> {
        match hint.map(|h| (h, h.gate)) {
            Some((h, Gate::Inconsistent { agreeing })) => {
                if agreeing == 1 {
                    self.pending.clear();
                }
                self.pending.push(*h);
                Ok(Vec::new())
            }
            Some((accepted, Gate::Accepted)) => {
                let mut confirmed = Vec::new();
                for earlier in std::mem::take(&mut self.pending) {
                    if self.route_agrees(&earlier, accepted)? {
                        confirmed.push(LoopHint {
                            gate: Gate::Accepted,
                            ..earlier
                        });
                    }
                }
                Ok(confirmed)
            }
            _ => {
                self.pending.clear();
                Ok(Vec::new())
            }
        }
    }

    /// Whether a streak's earlier hint (keyframe a matched to b) and its accepted one (c to
    /// d) agree along the route: going from a to b by the earlier hint, from b to d by the
    /// odometry of their session, and from d to c by the accepted hint must bring a where the
    /// odometry takes it to c, within the odometry gate's bounds (the translation bound
    /// growing with the path travelled from a to c and from b to d). A look-alike that began
    /// the streak, beside the true place, fits a pose metres off and fails. The rotation is
    /// compared whenever both hints have a pose, the translation when both are metric; without
    /// poses, the odometry gate, or a shared session for b and d, nothing is compared (true).
    fn route_agrees(&self, earlier: &LoopHint, accepted: &LoopHint) -> Result<bool, LoopsError> {
        let (Some(gate), Some(pose_ab), Some(pose_dc)) =
            (self.options.odometry, &earlier.pose, &accepted.pose)
        else {
            return Ok(true);
        };
        let reloaded = |id: u64| self.reloaded_max_id.is_some_and(|max| id <= max);
        if reloaded(earlier.matched_id) != reloaded(accepted.matched_id) {
            return Ok(true);
        }
        let camera = |id: u64| self.database.world_t_camera(id);
        let (Some(a), Some(b), Some(c), Some(d)) = (
            camera(earlier.query_id)?,
            camera(earlier.matched_id)?,
            camera(accepted.query_id)?,
            camera(accepted.matched_id)?,
        ) else {
            return Ok(true);
        };
        // a_T_c: by the odometry, and through the matched keyframes.
        let odometry = a.inverse() * c;
        let through =
            pose_ab.matched_t_query.inverse() * (b.inverse() * d) * pose_dc.matched_t_query;
        if odometry.rotation.angle_to(&through.rotation).to_degrees() > gate.max_rotation_deg {
            return Ok(false);
        }
        if !(pose_ab.scale_known && pose_dc.scale_known) {
            return Ok(true);
        }
        let travelled = |x: u64, y: u64| -> Result<f64, LoopsError> {
            let (x, y) = (self.database.travelled_m(x)?, self.database.travelled_m(y)?);
            Ok(x.zip(y).map_or(0.0, |(x, y)| (y - x).abs()))
        };
        let path = travelled(earlier.query_id, accepted.query_id)?
            + travelled(earlier.matched_id, accepted.matched_id)?;
        let bound = gate.max_translation_m + gate.max_translation_per_m * path;
        Ok((odometry.translation.vector - through.translation.vector).norm() <= bound)
    }

    /// Removes a keyframe and its features (ORB-SLAM culls keyframes); a pending hint from or
    /// to it is dropped, so none is ever confirmed against an erased keyframe.
    pub fn erase(&mut self, id: u64) -> Result<(), LoopsError> {
        self.database.erase(id)?;
        self.features.remove(&id);
        self.pending
            .retain(|h| h.query_id != id && h.matched_id != id);
        Ok(())
    }

    /// Features must be consistent and of the kind the earlier keyframes have.
    fn check_features(&self, features: &KeyframeFeatures) -> Result<(), LoopsError> {
        let k = &features.keypoints;
        let bad = |m: String| Err(LoopsError::InvalidKeyframe(m));
        if k.points.len() != k.descriptors.len() {
            return bad(format!(
                "{} keypoints but {} descriptors",
                k.points.len(),
                k.descriptors.len()
            ));
        }
        if let Some(i) = k
            .points
            .iter()
            .position(|p| !p.iter().all(|v| v.is_finite()))
        {
            return bad(format!("keypoint {i} is at {:?}", k.points[i]));
        }
        let kind = k.descriptors.kind();
        if let Some(expected) = self.kind.filter(|&e| e != kind && !k.is_empty()) {
            return bad(format!(
                "keypoints are {} but earlier keyframes' are {}",
                kind.name(),
                expected.name()
            ));
        }
        if let Some(points) = &features.camera_points {
            if points.len() != k.points.len() {
                return bad(format!(
                    "{} camera points for {} keypoints",
                    points.len(),
                    k.points.len()
                ));
            }
            let valid =
                |p: &[f32; 3]| p.iter().all(|v| v.is_finite()) || p.iter().all(|v| v.is_nan());
            if let Some(i) = points.iter().position(|p| !valid(p)) {
                return bad(format!(
                    "camera point {i} is {:?}: finite, or NaN in all three coordinates",
                    points[i]
                ));
            }
        }
        Ok(())
    }

    /// The verified candidates, most inliers first (ties: the more similar), each with its
    /// share of all their inliers as its confidence.
    fn verified_candidates(
        &self,
        entry: &KeyframeEntry<'_>,
        features: &KeyframeFeatures,
        checks: &mut Checks,
    ) -> Result<Vec<Verified>, LoopsError> {
        let Some(max_id) = self.max_candidate_id(entry) else {
            return Ok(Vec::new());
        };
        let query = LoopQuery {
            max_results: self.options.candidates,
            max_id: Some(max_id),
            before_timestamp: Some(entry.timestamp - self.options.exclude_recent_s),
            min_id_gap: self.options.candidate_id_gap,
        };
        let mut candidates = self.database.loop_candidates(entry.descriptor, &query)?;
        for nearby in self.odometry_candidates(entry, &query)? {
            if candidates
                .iter()
                .all(|c| c.keyframe_id != nearby.keyframe_id)
            {
                candidates.push(nearby);
            }
        }
        let mut verified: Vec<Verified> = Vec::new();
        for candidate in candidates {
            let Some(inliers) = self.inliers_with(features, candidate.keyframe_id, checks)? else {
                continue;
            };
            verified.push(Verified {
                id: candidate.keyframe_id,
                place: candidate.place,
                inliers,
                confidence: 0.0,
            });
        }
        let total: u32 = verified.iter().map(|v| v.inliers).sum();
        for v in &mut verified {
            v.confidence = if total > 0 {
                v.inliers as f32 / total as f32
            } else {
                0.0
            };
        }
        // Stable: among equal inliers, the more similar (earlier) candidate stays first.
        verified.sort_by_key(|v| std::cmp::Reverse(v.inliers));
        Ok(verified)
    }

    /// The odometry's candidates ([`HintOptions::odometry_candidates`]); none without a pose or
    /// the odometry gate.
    fn odometry_candidates(
        &self,
        entry: &KeyframeEntry<'_>,
        query: &LoopQuery,
    ) -> Result<Vec<Match>, LoopsError> {
        let (Some(gate), Some(pose)) = (self.options.odometry, entry.world_t_camera()) else {
            return Ok(Vec::new());
        };
        if self.options.odometry_candidates == 0 {
            return Ok(Vec::new());
        }
        let near = LoopQuery {
            max_results: self.options.odometry_candidates,
            ..*query
        };
        let radius = |travelled: f64| {
            gate.max_translation_m
                + gate.max_translation_per_m * travelled
                + self.options.odometry_search_m
        };
        self.database.nearby_candidates(
            entry.descriptor,
            &pose,
            radius,
            gate.max_rotation_deg,
            &near,
        )
    }

    /// Runs the gates over the verified candidates: those with enough inliers, most first,
    /// each refined within its group, until one passes the geometric gates (pose and odometry);
    /// then the consistency gate on it. When none passes, the first refusal is reported (the
    /// candidate with the most inliers). `None` when there was no candidate.
    fn decide(
        &self,
        entry: &KeyframeEntry<'_>,
        features: &KeyframeFeatures,
        verified: &[Verified],
        checks: &mut Checks,
    ) -> Result<Option<(Verified, Gated)>, LoopsError> {
        let Some(&first) = verified.first() else {
            return Ok(None);
        };
        let refused = |gate, pose| Gated {
            gate,
            pose,
            streak: None,
        };
        // The best candidate is refined before the inlier gate: its stretch may hold a
        // keyframe the query agrees with more.
        let first = self.refine(entry, features, first, checks)?;
        if first.inliers < self.options.min_inliers {
            return Ok(Some((first, refused(Gate::TooFewInliers, None))));
        }
        let mut first_refusal = None;
        let mut chosen: Option<(Verified, Passed)> = None;
        let others = verified[1..]
            .iter()
            .take_while(|v| v.inliers >= self.options.min_inliers);
        for (i, &candidate) in std::iter::once(&first).chain(others).enumerate() {
            let refined = match i {
                0 => candidate,
                _ => self.refine(entry, features, candidate, checks)?,
            };
            match self.geometry(entry, features, &refined, checks)? {
                Ok(passed) => {
                    // With odometry, the passing candidate it agrees with most: a look-alike
                    // stretch a few metres on passes the bound after a long drift, and the
                    // true keyframe beside it agrees better. Without, the most inliers.
                    let Some(disagreement) = passed.odometry_m else {
                        chosen = Some((refined, passed));
                        break;
                    };
                    let better = chosen.as_ref().is_none_or(|(_, best)| {
                        best.odometry_m.is_some_and(|best| disagreement < best)
                    });
                    if better {
                        chosen = Some((refined, passed));
                    }
                }
                Err((gate, pose)) => {
                    first_refusal.get_or_insert((refined, refused(gate, pose)));
                }
            }
        }
        let Some((refined, passed)) = chosen else {
            return Ok(first_refusal);
        };
        let agreeing = match self.streak {
            Some((place, n)) if self.database.groups_overlap(place, refined.place) => n + 1,
            _ => 1,
        };
        let gate = if agreeing < self.options.consistent_keyframes {
            Gate::Inconsistent { agreeing }
        } else {
            Gate::Accepted
        };
        let gated = Gated {
            gate,
            pose: passed.pose,
            streak: Some((refined.place, agreeing)),
        };
        Ok(Some((refined, gated)))
    }

    /// GC inliers of the query against keyframe `id` (checked once per query: the fit is kept
    /// for the pose); `None` when it has no features of the query's kind (reloaded without
    /// keypoints, or another kind).
    fn inliers_with(
        &self,
        features: &KeyframeFeatures,
        id: u64,
        checks: &mut Checks,
    ) -> Result<Option<u32>, LoopsError> {
        let Some(stored) = self.features.get(&id) else {
            return Ok(None);
        };
        let kind = features.keypoints.descriptors.kind();
        if stored.keypoints.descriptors.kind() != kind {
            return Ok(None);
        }
        if let Some(fit) = checks.fits.get(&id) {
            return Ok(Some(fit.check().inliers));
        }
        checks.work.pair_checks += 1;
        // A pair with fewer matches than the inlier gate asks for cannot pass: not fitted.
        let fit = fit_pair_reaching(
            features.keypoints.as_ref(),
            stored.keypoints.as_ref(),
            self.options.pair_for(kind),
            self.options.min_inliers,
        )
        .map_err(|e| LoopsError::InvalidKeyframe(e.to_string()))?;
        let inliers = fit.check().inliers;
        checks.fits.insert(id, fit);
        Ok(Some(inliers))
    }

    /// The largest id outside the exclusion window (`None`: no keyframe is): this session's
    /// keyframes `exclude_recent_ids` or more before the query, and every reloaded one.
    fn max_candidate_id(&self, entry: &KeyframeEntry<'_>) -> Option<u64> {
        let recent = entry.id.checked_sub(self.options.exclude_recent_ids.max(1));
        recent.max(self.reloaded_max_id)
    }

    /// The keyframe of the candidate's group (its place, the linked places, and the keyframes
    /// within `candidate_id_gap` ids) that the query agrees with most: appearance ranks
    /// neighbouring keyframes of one stretch almost alike, geometry tells the nearest. Checks
    /// at most `refine_keyframes` of them, the nearest in id to the candidate (a place grown online
    /// may hold many); keyframes inside the exclusion window are skipped.
    fn refine(
        &self,
        entry: &KeyframeEntry<'_>,
        features: &KeyframeFeatures,
        best: Verified,
        checks: &mut Checks,
    ) -> Result<Verified, LoopsError> {
        let max_id = self.max_candidate_id(entry).unwrap_or(0);
        let mut refined = best;
        // The stretch the candidate stands for (the keyframes the id gap skipped) and its
        // place group.
        let gap = self.options.candidate_id_gap;
        let stretch = (best.id.saturating_sub(gap.saturating_sub(1))
            ..=best.id.saturating_add(gap.saturating_sub(1)))
            .filter(|id| self.features.contains_key(id));
        let mut group: Vec<u64> = self
            .database
            .group_keyframes(best.place)
            .into_iter()
            .chain(stretch)
            .filter(|&id| id != best.id && id <= max_id)
            .collect();
        group.sort_by_key(|&id| (id.abs_diff(best.id), id));
        group.dedup();
        group.truncate(self.options.refine_keyframes);
        for id in group {
            let Some(inliers) = self.inliers_with(features, id, checks)? else {
                continue;
            };
            if inliers > refined.inliers {
                refined = Verified {
                    id,
                    place: self.database.place_of(id)?,
                    inliers,
                    confidence: best.confidence,
                };
            }
        }
        Ok(refined)
    }

    /// The geometric gates for one candidate: its relative pose (with intrinsics and
    /// point-accurate features), then the odometry agreement. `Ok` with the pose (`None`
    /// without intrinsics or with cells), or the refusing gate with the pose if one was fitted.
    fn geometry(
        &self,
        entry: &KeyframeEntry<'_>,
        features: &KeyframeFeatures,
        candidate: &Verified,
        checks: &mut Checks,
    ) -> Result<Geometry, LoopsError> {
        let stored = &self.features[&candidate.id];
        let kind = features.keypoints.descriptors.kind();
        let Some(camera) = self.options.camera.filter(|_| kind != FeatureKind::Cells) else {
            return Ok(Ok(Passed {
                pose: None,
                odometry_m: None,
            }));
        };
        let Some(fit) = checks.fits.get(&candidate.id) else {
            return Err(LoopsError::InvalidKeyframe(format!(
                "keyframe {} reached the pose fit unchecked",
                candidate.id
            )));
        };
        checks.work.pose_fits += 1;
        let fitted = relative_pose_from_fit(
            features.keypoints.as_ref(),
            stored.keypoints.as_ref(),
            stored.camera_points.as_deref(),
            fit,
            &camera,
            &self.options.pose,
        )
        .map_err(|e| LoopsError::InvalidKeyframe(e.to_string()))?;
        let pose = match fitted {
            Ok(pose) => pose,
            Err(refusal) => return Ok(Err((Gate::NoPose(refusal), None))),
        };
        let odometry = (
            self.options.odometry,
            self.odometry_between(entry, candidate.id)?,
        );
        if let (Some(bounds), Some(odometry)) = odometry {
            let rotation_deg = odometry
                .rotation
                .angle_to(&pose.matched_t_query.rotation)
                .to_degrees();
            // Without scale, the odometry's baseline scales the fitted direction: a look-alike
            // place elsewhere fits a direction the odometry's motion disagrees with.
            let odometry_t = odometry.translation.vector;
            let fitted_t = match pose.scale_known {
                true => pose.matched_t_query.translation.vector,
                false => pose.matched_t_query.translation.vector * odometry_t.norm(),
            };
            let translation_m = (fitted_t - odometry_t).norm();
            let travelled = self.travelled_between(entry, candidate.id)?.unwrap_or(0.0);
            let max_translation_m =
                bounds.max_translation_m + bounds.max_translation_per_m * travelled;
            if rotation_deg > bounds.max_rotation_deg || translation_m > max_translation_m {
                let gate = Gate::Odometry {
                    rotation_deg,
                    translation_m,
                };
                return Ok(Err((gate, Some(pose))));
            }
            return Ok(Ok(Passed {
                pose: Some(pose),
                odometry_m: Some(translation_m),
            }));
        }
        Ok(Ok(Passed {
            pose: Some(pose),
            odometry_m: None,
        }))
    }

    /// The odometry's path length from the matched keyframe to the new one, when both belong
    /// to this session and have poses.
    fn travelled_between(
        &self,
        entry: &KeyframeEntry<'_>,
        matched: u64,
    ) -> Result<Option<f64>, LoopsError> {
        let Some(query) = entry.world_t_camera() else {
            return Ok(None);
        };
        let here = self
            .database
            .travelled_to(&Point3::from(query.translation.vector));
        let there = self.database.travelled_m(matched)?;
        Ok(here.zip(there).map(|(here, there)| here - there))
    }

    /// The odometry's `matched_T_query` between the matched keyframe and the new one, when
    /// both have poses.
    fn odometry_between(
        &self,
        entry: &KeyframeEntry<'_>,
        matched: u64,
    ) -> Result<Option<Isometry3<f64>>, LoopsError> {
        let Some(query) = entry.world_t_camera() else {
            return Ok(None);
        };
        Ok(self
            .database
            .world_t_camera(matched)?
            .map(|matched| matched.inverse() * query))
    }
}

/// The pair checks of one query: their fits, by keyframe id, and the work counted.
#[derive(Default)]
struct Checks {
    fits: HashMap<u64, PairFit>,
    work: Work,
}

/// A verified candidate.
#[derive(Clone, Copy, Debug)]
struct Verified {
    id: u64,
    place: PlaceId,
    inliers: u32,
    confidence: f32,
}
