//! The gates a loop candidate passes to become a hint (see the module `hints`): verified
//! candidates and their refinement, the geometric gates (inliers, pose, odometry agreement) and
//! the consistency gate.

use super::super::database::{KeyframeEntry, LoopQuery, Match};
use super::super::error::LoopsError;
use super::streak::Streak;
use super::{KeyframeFeatures, LoopDetector, Work};
use crate::map::PlaceId;
use crate::profile::{measure, Stage};
use crate::verify::{
    fit_pair_reaching, relative_pose_from_fit, FeatureKind, PairFit, PoseRefusal, RelativePose,
    ScenePoints,
};
use nalgebra::{Isometry3, Point3};
use std::collections::HashMap;

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
    /// The candidate holds the very keypoints of the new keyframe: its own image, added again
    /// or in a map built from this run's images. A live session needs a map of an earlier run,
    /// or none; the detector logs a warning.
    SelfMatch,
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
            Gate::SelfMatch => "self_match",
        }
    }
}

/// The geometric gates' verdict on one candidate: passed, or the refusing gate with the pose
/// if one was fitted.
pub(super) type Geometry = Result<Passed, (Gate, Option<RelativePose>)>;

/// A candidate that passed the geometric gates.
#[derive(Clone, Copy)]
pub(super) struct Passed {
    /// Its pose (`None` without intrinsics or with cells).
    pub pose: Option<RelativePose>,
    /// How far the pose's translation is from the odometry's, metres, when the odometry gate
    /// compared them.
    pub odometry_m: Option<f64>,
}

/// What the gates decided for the best candidate.
pub(super) struct Gated {
    pub gate: Gate,
    pub pose: Option<RelativePose>,
    /// The consistency streak including this keyframe.
    pub streak: Option<Streak>,
}

impl LoopDetector {
    /// The verified candidates, most inliers first (ties: the more similar), each with its
    /// share of all their inliers as its confidence.
    pub(super) fn verified_candidates(
        &self,
        entry: &KeyframeEntry<'_>,
        features: &KeyframeFeatures,
        checks: &mut Checks,
    ) -> Result<Vec<VerifiedCandidate>, LoopsError> {
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
        let mut verified: Vec<VerifiedCandidate> = Vec::new();
        for candidate in candidates {
            let Some(inliers) = self.inliers_with(features, candidate.keyframe_id, checks)? else {
                continue;
            };
            verified.push(VerifiedCandidate {
                id: candidate.keyframe_id,
                place: candidate.place,
                similarity: candidate.similarity,
                inliers,
                confidence: 0.0,
            });
        }
        share_and_rank(&mut verified);
        Ok(verified)
    }

    /// The verified candidates as the host sees them: each candidate that refinement swapped
    /// for a keyframe of its group with more inliers is replaced by that keyframe (with its own
    /// similarity), so the list always holds the hint's matched keyframe; a keyframe listed
    /// twice is kept once. Confidences are then shared again and the list ranked.
    pub(super) fn settle(
        &self,
        entry: &KeyframeEntry<'_>,
        mut verified: Vec<VerifiedCandidate>,
        refined: &[(u64, VerifiedCandidate)],
    ) -> Result<Vec<VerifiedCandidate>, LoopsError> {
        for &(original, chosen) in refined {
            if verified.iter().any(|v| v.id == chosen.id) {
                verified.retain(|v| v.id != original);
            } else if let Some(slot) = verified.iter_mut().find(|v| v.id == original) {
                *slot = VerifiedCandidate {
                    similarity: self.database.similarity(entry.descriptor, chosen.id)?,
                    ..chosen
                };
            }
        }
        share_and_rank(&mut verified);
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
    pub(super) fn decide(
        &self,
        entry: &KeyframeEntry<'_>,
        features: &KeyframeFeatures,
        verified: &[VerifiedCandidate],
        checks: &mut Checks,
    ) -> Result<Option<(VerifiedCandidate, Gated)>, LoopsError> {
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
        // A candidate that is the keyframe's own image means the map holds this run: no
        // candidate of this keyframe means anything to the host.
        if let Some(own) = verified.iter().find(|v| self.is_own_image(features, v.id)) {
            return Ok(Some((*own, refused(Gate::SelfMatch, None))));
        }
        let first = self.refine(entry, features, first, checks)?;
        if first.inliers < self.options.min_inliers {
            return Ok(Some((first, refused(Gate::TooFewInliers, None))));
        }
        let mut first_refusal = None;
        let mut chosen: Option<(VerifiedCandidate, Passed)> = None;
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
        let agreeing = self.agreeing(entry, refined.place, refined.id)?;
        let gate = if agreeing < self.options.consistent_keyframes {
            Gate::Inconsistent { agreeing }
        } else {
            Gate::Accepted
        };
        let gated = Gated {
            gate,
            pose: passed.pose,
            streak: Some(Streak {
                place: refined.place,
                agreeing,
                query_timestamp: entry.timestamp,
                matched_id: refined.id,
            }),
        };
        Ok(Some((refined, gated)))
    }

    /// Whether keyframe `id` has exactly the query's keypoints (positions and descriptors):
    /// the same image. Cost: one comparison pass, stopped at the first difference.
    fn is_own_image(&self, features: &KeyframeFeatures, id: u64) -> bool {
        let query = &features.keypoints;
        self.features
            .get(&id)
            .is_some_and(|stored| !query.is_empty() && stored.keypoints == *query)
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
        best: VerifiedCandidate,
        checks: &mut Checks,
    ) -> Result<VerifiedCandidate, LoopsError> {
        let max_id = self.max_candidate_id(entry).unwrap_or(0);
        let mut refined = best;
        // The stretch the candidate stands for (the keyframes the id gap skipped) and its
        // place group.
        // The nearest `refine_keyframes` on either side are enough: the group keeps at most
        // that many, nearest first. Walking the held ids (not the id range) keeps the cost
        // independent of the gap's value.
        let reach = self.options.candidate_id_gap.saturating_sub(1);
        let usable = |id: &u64| *id != best.id && *id <= max_id && self.features.contains_key(id);
        let per_side = self.options.refine_keyframes;
        let below = self
            .database
            .ids_between(best.id.saturating_sub(reach), best.id)
            .rev()
            .filter(usable)
            .take(per_side);
        let above = self
            .database
            .ids_between(best.id, best.id.saturating_add(reach))
            .filter(usable)
            .take(per_side);
        let stretch: Vec<u64> = below.chain(above).collect();
        let mut group: Vec<u64> = self
            .database
            .group_keyframes(best.place)
            .into_iter()
            .filter(|&id| id != best.id && id <= max_id)
            .chain(stretch)
            .collect();
        group.sort_by_key(|&id| (id.abs_diff(best.id), id));
        group.dedup();
        group.truncate(self.options.refine_keyframes);
        for id in group {
            let Some(inliers) = self.inliers_with(features, id, checks)? else {
                continue;
            };
            if inliers > refined.inliers {
                // The refined keyframe stands in for the candidate ([`Self::settle`] gives it
                // its own similarity and confidence).
                refined = VerifiedCandidate {
                    id,
                    place: self.database.place_of(id)?,
                    inliers,
                    ..best
                };
            }
        }
        if refined.id != best.id {
            checks.refined.push((best.id, refined));
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
        candidate: &VerifiedCandidate,
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
        let points = ScenePoints {
            query: features.camera_points.as_deref(),
            matched: stored.camera_points.as_deref(),
        };
        let fitted = measure(Stage::Pose, || {
            relative_pose_from_fit(
                features.keypoints.as_ref(),
                stored.keypoints.as_ref(),
                points,
                fit,
                &camera,
                &self.options.pose,
            )
        })
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
    /// both have poses in one world frame (the matched one is of this session, or was
    /// reloaded from a map: [`LoopDetector::from_map`] assumes the map's frame).
    fn odometry_between(
        &self,
        entry: &KeyframeEntry<'_>,
        matched: u64,
    ) -> Result<Option<Isometry3<f64>>, LoopsError> {
        let Some(query) = entry.world_t_camera() else {
            return Ok(None);
        };
        if !self.database.in_current_session(matched)? {
            return Ok(None);
        }
        Ok(self
            .database
            .world_t_camera(matched)?
            .map(|matched| matched.inverse() * query))
    }
}

/// The pair checks of one query: their fits, by keyframe id, the candidates refinement
/// swapped (`(candidate, the keyframe that replaced it)`), and the work counted.
#[derive(Default)]
pub(super) struct Checks {
    pub fits: HashMap<u64, PairFit>,
    pub refined: Vec<(u64, VerifiedCandidate)>,
    pub work: Work,
}

/// Gives each candidate its share of all the candidates' inliers as its confidence, then ranks
/// them by inliers (stable: among equal inliers, the more similar, earlier one stays first).
fn share_and_rank(verified: &mut [VerifiedCandidate]) {
    let total: u32 = verified.iter().map(|v| v.inliers).sum();
    for v in verified.iter_mut() {
        v.confidence = if total > 0 {
            v.inliers as f32 / total as f32
        } else {
            0.0
        };
    }
    verified.sort_by_key(|v| std::cmp::Reverse(v.inliers));
}

/// A loop candidate of a keyframe with its pair check: what a host that runs its own check
/// ranks ([`Processed::candidates`](super::Processed::candidates)). A candidate that refinement
/// swapped for a keyframe of its group with more inliers is listed as that keyframe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VerifiedCandidate {
    /// The candidate keyframe's id.
    pub id: u64,
    /// Its place.
    pub place: PlaceId,
    /// Cosine similarity of the keyframe's global descriptor to the candidate's.
    pub similarity: f32,
    /// Fundamental-matrix inliers of the pair check.
    pub inliers: u32,
    /// Its share of the inliers of every verified candidate of the keyframe (0..=1).
    pub confidence: f32,
}
