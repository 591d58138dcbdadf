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
//!    ([`Gate::TooFewInliers`]); no candidate may be the keyframe's own image (the very same
//!    keypoints: a map built from this run's images, [`Gate::SelfMatch`], logged as a
//!    warning);
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
//!    ([`Gate::Inconsistent`], ORB-SLAM's consistency groups on the place graph), and the
//!    match keeps the keyframes' pace (`max_match_pace`: a match that slides along a
//!    look-alike stretch faster than the keyframes advance starts a new streak).
//!
//! At most one hint per keyframe. A refused candidate is reported with the gate that refused
//! it, so the host can log why no loop was closed. The keyframes that began a streak were
//! refused as inconsistent only because the streak was not long enough yet: when a later
//! keyframe completes it, their hints are delivered with that keyframe as confirmed
//! ([`Processed::confirmed`]), so a revisit yields hints from its first keyframe on. Errors (bad features, keyframes out of
//! order, duplicate ids) leave the detector exactly as it was.

mod gates;
mod options;
mod streak;

use super::database::{Added, DatabaseOptions, KeyframeDatabase, KeyframeEntry};
use super::error::LoopsError;
use crate::map::{Map, PlaceId};
use crate::verify::{Descriptors, FeatureKind, Keypoints, RelativePose, ViewKeypoints};
use nalgebra::Point3;
use std::collections::HashMap;

use gates::{Checks, Gated};
pub use gates::{Gate, VerifiedCandidate};
pub use options::{HintOptions, OdometryGate};
use streak::Streak;

/// A keyframe's local features: its keypoints and, when the host has them, the scene point of
/// each in the keyframe's camera frame (metres; NaN in all three coordinates when unknown).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KeyframeFeatures {
    /// Keypoints with their descriptors (ORB from the host, XFeat, or dense cells).
    pub keypoints: Keypoints,
    /// Scene points, one per keypoint, in the camera frame.
    pub camera_points: Option<Vec<[f32; 3]>>,
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
    /// The matched keyframe's share of the inliers of every verified candidate
    /// ([`Processed::candidates`], where it is listed) (0..=1): near 1 when no other
    /// candidate agrees with the query, near 1/n among n look-alikes.
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
    /// Every loop candidate that was verified, most inliers first (ties: the more similar),
    /// accepted or not: for hosts that run their own check on several (ORB-SLAM3 takes 3 loop
    /// and 3 merge candidates). A candidate refined to a neighbouring keyframe is listed as
    /// that keyframe, so the hint's matched keyframe is always here. Empty when there was none.
    pub candidates: Vec<VerifiedCandidate>,
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
    /// The consistency streak after the last keyframe (`None`: its candidate failed a gate
    /// before the consistency gate, or it had none).
    streak: Option<Streak>,
    /// The hints of the current streak's keyframes, refused as inconsistent: confirmed when
    /// a later keyframe completes the streak, dropped when it breaks.
    pending: Vec<LoopHint>,
    /// What the last successful [`LoopDetector::process`] confirmed.
    confirmed: Vec<LoopHint>,
    /// The last successful [`LoopDetector::process`]'s verified candidates.
    candidates: Vec<VerifiedCandidate>,
    /// The largest id of a previous session's keyframes ([`LoopDetector::from_map`]): they are
    /// never inside the exclusion window, whatever this session's ids.
    reloaded_max_id: Option<u64>,
    /// Keyframes refused as [`Gate::SelfMatch`] so far (their warning is logged for the
    /// first and then every hundredth).
    self_matches: u64,
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
            candidates: Vec::new(),
            reloaded_max_id: None,
            self_matches: 0,
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

    /// The detector as a topoloc map: the database's map ([`KeyframeDatabase::to_map`]) with
    /// every keyframe's local features as its view's keypoints and, where a keyframe has both
    /// an odometry pose and scene points, those points in the map frame (NaN where unknown), so
    /// that [`LoopDetector::from_map`] verifies against them in a later session. Keyframes
    /// without features get views without keypoints. Fails on an empty detector.
    pub fn to_map(&self) -> Result<Map, LoopsError> {
        let map = self.database.to_map()?;
        let Some(kind) = self.kind else {
            return Ok(map);
        };
        let none = Keypoints {
            points: Vec::new(),
            descriptors: Descriptors::empty(kind),
        };
        let features: Vec<Option<&KeyframeFeatures>> = map
            .views()
            .iter()
            .map(|view| view.keyframe_id.and_then(|id| self.features.get(&id)))
            .collect();
        let stored = ViewKeypoints::from_views(
            kind,
            features.iter().map(|f| f.map_or(&none, |f| &f.keypoints)),
        )
        .map_err(|e| LoopsError::InvalidOption(format!("keypoints to save: {e}")))?;
        let map = map.with_keypoints(stored)?;
        let unknown = [f32::NAN; 3];
        let mut any_point = false;
        let mut world_points = Vec::with_capacity(map.keypoints().map_or(0, |k| k.total()));
        for (view, features) in map.views().iter().zip(&features) {
            let Some(features) = features else { continue };
            match (view.world_t_camera, &features.camera_points) {
                (Some(world_t_camera), Some(points)) => {
                    any_point = true;
                    world_points.extend(points.iter().map(|p| {
                        let w = world_t_camera.transform_point(&Point3::new(
                            f64::from(p[0]),
                            f64::from(p[1]),
                            f64::from(p[2]),
                        ));
                        [w.x as f32, w.y as f32, w.z as f32]
                    }));
                }
                _ => world_points.extend(std::iter::repeat_n(unknown, features.keypoints.len())),
            }
        }
        if !any_point {
            return Ok(map);
        }
        Ok(map.with_keypoint_world_points(world_points)?)
    }

    /// Saves [`LoopDetector::to_map`] as a topoloc map file (atomic, see [`Map::save`]); reload
    /// it with [`Map::load`] and [`LoopDetector::from_map`].
    pub fn save(&self, path: impl AsRef<std::path::Path>) -> Result<(), LoopsError> {
        Ok(self.to_map()?.save(path)?)
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
        let verified = self.settle(entry, verified, &checks.refined)?;
        let added = self.database.add(entry)?;
        let (hint, streak) = match decided {
            None => (None, None),
            Some((best, Gated { gate, pose, streak })) => {
                let confidence = verified
                    .iter()
                    .find(|v| v.id == best.id)
                    .map_or(best.confidence, |v| v.confidence);
                let hint = LoopHint {
                    query_id: entry.id,
                    query_place: added.place,
                    matched_id: best.id,
                    place: best.place,
                    inliers: best.inliers,
                    confidence,
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
        self.candidates = verified;
        if hint.is_some_and(|h| h.gate == Gate::SelfMatch) {
            self.warn_self_match(entry.id, hint.map_or(0, |h| h.matched_id));
        }
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
            candidates: self.candidates.clone(),
            work: checks.work,
        })
    }

    /// Logs that keyframe `id` matched its own image in keyframe `matched` (the first time and
    /// every hundredth after): the host's likeliest mistake, a map built from this run's images.
    fn warn_self_match(&mut self, id: u64, matched: u64) {
        self.self_matches += 1;
        if self.self_matches % 100 == 1 {
            log::warn!(
                "keyframe {id} has exactly the keypoints of keyframe {matched}: the same image \
                 ({} such keyframes so far). If the detector was made from a map built from this \
                 run's own images, every keyframe matches itself: a live session needs a map of \
                 an earlier run (from_map) or none (new)",
                self.self_matches
            );
        }
    }

    /// The hints the last successful [`LoopDetector::process`] confirmed
    /// ([`Processed::confirmed`]); replaced by the next one, kept by errors and erasures.
    pub fn confirmed(&self) -> &[LoopHint] {
        &self.confirmed
    }

    /// The verified candidates of the last successful [`LoopDetector::process`]
    /// ([`Processed::candidates`]); replaced by the next one, kept by errors. A candidate
    /// erased since is left out.
    pub fn candidates(&self) -> impl Iterator<Item = &VerifiedCandidate> {
        self.candidates
            .iter()
            .filter(|c| self.features.contains_key(&c.id))
    }

    /// Starts a new session whose odometry is in a new world frame
    /// ([`KeyframeDatabase::begin_session`]): ORB-SLAM3 starting a new map, VINS-Fusion a new
    /// sequence. The keyframes held become an earlier session's, as a map's are for
    /// [`LoopDetector::from_map`]: never inside the exclusion window (a map just lost may be
    /// found again at once), not compared by time or pace, and not by the odometry gate or the
    /// route check, which compare poses of one world frame only. The consistency streak and
    /// its pending hints end. The next keyframe's timestamp may be earlier than the last one's;
    /// ids must still increase. Cannot fail.
    pub fn begin_session(&mut self) {
        self.reloaded_max_id = self.reloaded_max_id.max(self.database.max_id());
        self.database.begin_session();
        self.streak = None;
        self.pending.clear();
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
}
