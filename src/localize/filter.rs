//! Forward filter (HMM) over the place graph with direction and speed, and a two-state
//! on-map / off-map filter beside it.
//!
//! **Motion belief.** The hidden state is a heading (at place a, facing neighbour b; see
//! `motion.rs`) times a speed class v (the chance of advancing one edge per frame, from the
//! `speeds` option). Each frame:
//!
//! 1. *Predict.* A state advances with probability v (or `min(1, d / length)` when the frame
//!    carries odometry with travelled distance d and the edge has a length) onto the
//!    continuations of its heading, which do not turn back except at a dead end, and otherwise
//!    stays. Of the staying belief, `turn_probability` spreads over the other headings of the
//!    same place (the robot turns). `speed_change_probability` moves belief to the neighbouring
//!    speed classes. Finally a uniform jump (`jump_probability`) lets a kidnapped robot recover.
//! 2. *Update.* Every state at place a is weighted by `exp((score_a - m) / T)` with the place
//!    score (best view similarity), temperature T and m the best place score (the shift cancels
//!    in the normalisation, and the best place's likelihood is exactly 1). Normalise. The place belief is the marginal over headings
//!    and speeds.
//!
//! Carrying direction and speed is what lets evidence accumulate along a route: a first-order
//! filter that only knows adjacency lags a camera that advances one place per frame and cannot
//! beat single-frame matching on real sequences (BENCHMARKS.md).
//!
//! **Off-map probability** q, filtered separately so that a stretch of unrecognisable frames
//! does not erase the motion belief: q enters with `off_map_probability` per frame and stays with
//! `stay_probability`; its update weighs the off-map likelihood against the on-map marginal
//! likelihood `sum_places predicted_place * likelihood`, both at their own temperature
//! `off_map_temperature` (deciding on-map vs off-map is a different question from which place,
//! and wants sharper evidence). The off-map hypothesis scores what the best of M
//! unrelated places would score in this frame: `mean + (sqrt(2 ln M) + margin) * std` of the
//! frame's place scores without the best one (the expected maximum of M Gaussian draws plus
//! `off_map_margin` standard deviations), never below the absolute floor `off_map_similarity`.
//! Maps with fewer than [`MIN_PLACES_FOR_BACKGROUND`] places use the floor alone. With
//! geometric verification on, the localizer redoes this update with the verification inliers'
//! likelihood ratio instead ([`Belief::replace_off_map_evidence`]): the appearance scores of a
//! building's look-alike places do not tell on-map from off-map frames, the inliers do.
//!
//! Single-frame mode skips the prediction and starts every frame from the initial prior.

use super::motion::Headings;
use crate::map::Map;

/// Below this many places the frame's score statistics say nothing about the background.
pub(crate) const MIN_PLACES_FOR_BACKGROUND: usize = 10;

/// Fixed parameters of the filter, validated by the localizer options.
#[derive(Clone, Debug)]
pub(crate) struct FilterParams {
    pub temperature: f64,
    pub stay_probability: f64,
    pub speeds: Vec<f64>,
    pub speed_change_probability: f64,
    pub turn_probability: f64,
    pub jump_probability: f64,
    pub off_map_probability: f64,
    pub off_map_similarity: f64,
    pub off_map_margin: f64,
    pub off_map_temperature: f64,
}

/// Score of the off-map hypothesis for one frame (see the module documentation). The
/// background statistics leave the best score out, so that a strong match does not inflate them.
fn off_map_score(params: &FilterParams, place_scores: &[f32], max_score: f64) -> f64 {
    let m = place_scores.len();
    if m < MIN_PLACES_FOR_BACKGROUND {
        return params.off_map_similarity;
    }
    let (sum, sum_sq) = place_scores.iter().fold((0.0, 0.0), |(a, b), &s| {
        (a + f64::from(s), b + f64::from(s).powi(2))
    });
    let n = (m - 1) as f64;
    let mean = (sum - max_score) / n;
    let variance = ((sum_sq - max_score * max_score) / n - mean * mean).max(0.0);
    let expected_max_z = (2.0 * n.ln()).sqrt();
    (mean + (expected_max_z + params.off_map_margin) * variance.sqrt())
        .max(params.off_map_similarity)
}

/// Motion belief, place marginals, off-map probability, and scratch buffers.
#[derive(Clone)]
pub(crate) struct Belief {
    headings: Headings,
    speeds: usize,
    /// Probability of each (heading, speed) state, index `heading * speeds + speed`, given that
    /// the robot is on the map.
    states: Vec<f64>,
    /// Initial (and jump) probability of a state of each heading: places share the mass
    /// uniformly, then the headings and speeds of each place.
    prior: Vec<f64>,
    /// Posterior over the M places given that the robot is on the map (marginal of `states`).
    pub places: Vec<f64>,
    /// Posterior probability that the robot is off the map.
    pub off_map: f64,
    /// The off-map probability predicted for the current frame, before its evidence: what
    /// [`Belief::replace_off_map_evidence`] starts from.
    predicted_off_map: f64,
    scratch: Vec<f64>,
    turned: Vec<f64>,
}

impl Belief {
    pub fn new(map: &Map, params: &FilterParams) -> Self {
        let headings = Headings::new(map);
        let m = map.place_count();
        let speeds = params.speeds.len();
        let prior = (0..headings.len())
            .map(|h| 1.0 / (m * headings.degree(headings.from[h] as usize) * speeds) as f64)
            .collect();
        let n = headings.len() * speeds;
        Self {
            states: vec![0.0; n],
            scratch: vec![0.0; n],
            turned: vec![0.0; m * speeds],
            prior,
            places: vec![0.0; m],
            off_map: 0.0,
            predicted_off_map: 0.0,
            headings,
            speeds,
        }
    }

    /// Sets the belief to the prior used before any frame: uniform over places (then over their
    /// headings and speeds), off-map with `off_map_probability`.
    pub fn set_initial(&mut self, params: &FilterParams) {
        let s = self.speeds;
        for (h, &p) in self.prior.iter().enumerate() {
            self.states[h * s..(h + 1) * s].fill(p);
        }
        self.off_map = params.off_map_probability;
        self.predicted_off_map = self.off_map;
    }

    /// Moves the belief one frame along the graph (step 1 of the module documentation).
    /// `travelled` is the odometry distance in metres since the previous frame, if known.
    pub fn predict(&mut self, params: &FilterParams, travelled: Option<f64>) {
        let (s, headings) = (self.speeds, &self.headings);
        let next = &mut self.scratch;
        next.fill(0.0);
        self.turned.fill(0.0);
        for h in 0..headings.len() {
            let stationary = headings.from[h] == headings.to[h];
            for (v, &speed) in params.speeds.iter().enumerate() {
                let mass = self.states[h * s + v];
                if mass == 0.0 {
                    continue;
                }
                let advance = match (stationary, travelled, headings.length[h]) {
                    (true, _, _) => 0.0,
                    (false, Some(d), Some(len)) if len > 0.0 => (d / len).min(1.0),
                    _ => speed,
                };
                let stay = mass * (1.0 - advance);
                next[h * s + v] += stay * (1.0 - params.turn_probability);
                self.turned[headings.from[h] as usize * s + v] += stay * params.turn_probability;
                if advance > 0.0 {
                    for (g, share) in headings.next(h) {
                        next[g * s + v] += mass * advance * share;
                    }
                }
            }
        }
        for (p, turned) in self.turned.chunks_exact(s).enumerate() {
            let range = headings.place_offsets[p] as usize..headings.place_offsets[p + 1] as usize;
            let degree = range.len() as f64;
            for h in range {
                for v in 0..s {
                    next[h * s + v] += turned[v] / degree;
                }
            }
        }
        let keep = 1.0 - params.jump_probability;
        let change = if s > 1 {
            params.speed_change_probability
        } else {
            0.0
        };
        for (h, &prior) in self.prior.iter().enumerate() {
            let row = &next[h * s..(h + 1) * s];
            for v in 0..s {
                let below = if v > 0 {
                    row[v - 1] * if v + 1 < s { 0.5 } else { 1.0 }
                } else {
                    0.0
                };
                let above = if v + 1 < s {
                    row[v + 1] * if v > 0 { 0.5 } else { 1.0 }
                } else {
                    0.0
                };
                let mixed = row[v] * (1.0 - change) + change * (below + above);
                self.states[h * s + v] = keep * mixed + params.jump_probability * prior;
            }
        }
        self.off_map = self.off_map * params.stay_probability
            + (1.0 - self.off_map) * params.off_map_probability;
    }

    /// Multiplies by the observation likelihoods and normalises both filters, then computes the
    /// place marginals. If every state underflows to zero (possible only with zero jump
    /// probability), the motion belief restarts from the prior.
    pub fn update(&mut self, params: &FilterParams, place_scores: &[f32]) {
        let max_score = place_scores
            .iter()
            .fold(f32::NEG_INFINITY, |a, &b| a.max(b)) as f64;
        let off_score = off_map_score(params, place_scores, max_score);
        self.predicted_off_map = self.off_map;
        let s = self.speeds;
        // Predicted place marginals first: the off-map filter weighs them with its own
        // temperature, against the off-map score (both shifted by the larger of the two).
        self.places.fill(0.0);
        for (h, states) in self.states.chunks_exact(s).enumerate() {
            self.places[self.headings.from[h] as usize] += states.iter().sum::<f64>();
        }
        let off_shift = max_score.max(off_score);
        let inv_t_off = 1.0 / params.off_map_temperature;
        let off_map_scale = |score: f64| ((score - off_shift) * inv_t_off).exp();
        let on_map_evidence: f64 = self
            .places
            .iter()
            .zip(place_scores)
            .map(|(p, &score)| p * off_map_scale(f64::from(score)))
            .sum();
        let off_map_evidence = off_map_scale(off_score);

        // Place likelihoods relative to the best place: the best is exactly 1, so the motion
        // belief cannot underflow to zero wherever the prior is positive.
        let inv_t = 1.0 / params.temperature;
        let likelihood: &mut Vec<f64> = &mut self.places;
        likelihood
            .iter_mut()
            .zip(place_scores)
            .for_each(|(l, &score)| *l = ((f64::from(score) - max_score) * inv_t).exp());
        self.weigh_and_normalise(params);
        let off = self.off_map * off_map_evidence;
        let on = (1.0 - self.off_map) * on_map_evidence;
        self.off_map = if off + on > 0.0 {
            off / (off + on)
        } else {
            0.0
        };
    }

    /// Multiplies every state by the likelihood of its place (held in `places`), normalises, and
    /// leaves the place marginals in `places`. If every state underflows to zero (possible only
    /// with zero jump probability), the motion belief restarts from the prior.
    fn weigh_and_normalise(&mut self, params: &FilterParams) {
        let mut total = self.weigh_states();
        if !(total > 0.0 && total.is_finite()) {
            // The predicted belief had no mass where the evidence is (zero jump probability):
            // restart the motion belief from the prior, whose every state is positive.
            let off_map = self.off_map;
            self.set_initial(params);
            self.off_map = off_map;
            total = self.weigh_states();
        }
        let inv_total = 1.0 / total;
        self.places.fill(0.0);
        for (h, states) in self.states.chunks_exact_mut(self.speeds).enumerate() {
            let mut sum = 0.0;
            for state in states {
                *state *= inv_total;
                sum += *state;
            }
            self.places[self.headings.from[h] as usize] += sum;
        }
    }

    /// A second observation on the motion belief: multiplies every state at place p by
    /// `factor(p)` (positive, at most 1 for numerical safety) and normalises. The off-map
    /// probability is left as it is.
    pub fn weigh_places(&mut self, params: &FilterParams, factor: impl Fn(usize) -> f64) {
        for (p, l) in self.places.iter_mut().enumerate() {
            *l = factor(p);
        }
        self.weigh_and_normalise(params);
    }

    /// Redoes the current frame's off-map update with other evidence: `off_over_on`, the
    /// likelihood ratio of the frame off the map against on it (positive, finite), in place of
    /// the appearance scores' (geometric verification, which tells the two apart where global
    /// descriptors cannot; BENCHMARKS.md).
    pub fn replace_off_map_evidence(&mut self, off_over_on: f64) {
        let off = self.predicted_off_map * off_over_on;
        let on = 1.0 - self.predicted_off_map;
        self.off_map = if off + on > 0.0 && off.is_finite() {
            off / (off + on)
        } else {
            1.0
        };
    }

    /// Copies the belief into `backup` (same shape), to undo a frame that fails half-way.
    pub fn save(&self, backup: &mut Belief) {
        backup.states.copy_from_slice(&self.states);
        backup.places.copy_from_slice(&self.places);
        backup.off_map = self.off_map;
        backup.predicted_off_map = self.predicted_off_map;
    }

    /// Multiplies every state by the likelihood of its place (held in `places`) and returns the
    /// total mass.
    fn weigh_states(&mut self) -> f64 {
        let mut total = 0.0;
        for (h, states) in self.states.chunks_exact_mut(self.speeds).enumerate() {
            let l = self.places[self.headings.from[h] as usize];
            for state in states {
                *state *= l;
                total += *state;
            }
        }
        total
    }
}
