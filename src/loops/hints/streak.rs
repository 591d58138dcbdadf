//! The consistency streak: the place consecutive keyframes' best candidates agreed on, the
//! hints held while the streak grows, and the route check that confirms them when a later
//! keyframe completes it.

use super::super::database::KeyframeEntry;
use super::super::error::LoopsError;
use super::{Gate, LoopDetector, LoopHint};
use crate::map::PlaceId;

/// The consistency streak after a keyframe whose best candidate passed the geometric gates.
#[derive(Clone, Copy, Debug)]
pub(super) struct Streak {
    /// The place of that keyframe's candidate.
    pub place: PlaceId,
    /// Consecutive agreeing keyframes, that one included.
    pub agreeing: usize,
    /// That keyframe's timestamp, seconds.
    pub query_timestamp: f64,
    /// Its candidate keyframe.
    pub matched_id: u64,
}

impl LoopDetector {
    /// How many consecutive keyframes agree with the new one's candidate (keyframe
    /// `matched_id` of `place`), counting its own: one more than the streak's when the
    /// candidate's group overlaps the previous candidate's and it keeps the streak's pace
    /// ([`LoopDetector::keeps_pace`]), else 1 (a new streak).
    pub(super) fn agreeing(
        &self,
        entry: &KeyframeEntry<'_>,
        place: PlaceId,
        matched_id: u64,
    ) -> Result<usize, LoopsError> {
        let Some(streak) = self.streak else {
            return Ok(1);
        };
        let agrees = self.database.groups_overlap(streak.place, place)
            && self.keeps_pace(&streak, entry, matched_id)?;
        Ok(if agrees { streak.agreeing + 1 } else { 1 })
    }

    /// Whether the new keyframe's candidate follows the streak's previous one at a pace a
    /// vehicle keeps ([`HintOptions::max_match_pace`](super::HintOptions::max_match_pace)):
    /// the two candidates' timestamps differ by at most `max_match_pace` times the keyframes'
    /// own step plus `match_pace_slack_s`. A match sliding back along a look-alike stretch
    /// while the keyframes advance breaks the streak. Always true when the odometry puts the
    /// two candidates beside each other ([`KeyframeDatabase::are_neighbours`]: one spot
    /// passed twice, matched on either pass), when either was reloaded from a map (its time
    /// is another session's), when the host erased the streak's candidate, or with the rule
    /// off.
    ///
    /// [`KeyframeDatabase::are_neighbours`]: super::super::KeyframeDatabase::are_neighbours
    fn keeps_pace(
        &self,
        streak: &Streak,
        entry: &KeyframeEntry<'_>,
        matched_id: u64,
    ) -> Result<bool, LoopsError> {
        let pace = self.options.max_match_pace;
        if pace == 0.0 || !self.database.contains(streak.matched_id) {
            return Ok(true);
        }
        if self
            .database
            .are_neighbours(streak.matched_id, matched_id)?
        {
            return Ok(true);
        }
        let (before, now) = (
            self.database.timestamp_of(streak.matched_id)?,
            self.database.timestamp_of(matched_id)?,
        );
        if !(before.is_finite() && now.is_finite()) {
            return Ok(true);
        }
        let step = entry.timestamp - streak.query_timestamp;
        Ok((now - before).abs() <= pace * step + self.options.match_pace_slack_s)
    }

    /// Keeps the streak's pending hints in step with the new keyframe's: an inconsistent hint
    /// joins them (a new streak starts them afresh), an accepted one confirms and returns
    /// those that agree with it along the route ([`LoopDetector::route_agrees`]), any other
    /// outcome drops them (the streak broke).
    pub(super) fn follow_streak(
        &mut self,
        hint: Option<&LoopHint>,
    ) -> Result<Vec<LoopHint>, LoopsError> {
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
    /// poses, the odometry gate, or a shared session (and world frame) for b and d and for a
    /// and c, nothing is compared (true).
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
        let frames = &self.database;
        if !frames.share_world_frame(earlier.query_id, accepted.query_id)?
            || !frames.share_world_frame(earlier.matched_id, accepted.matched_id)?
        {
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
}
