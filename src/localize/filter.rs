//! Forward filter (HMM) over the place graph, and a two-state on-map / off-map filter beside it.
//!
//! **Place belief** over the M places, each frame:
//!
//! 1. *Predict.* From place i the robot stays with probability `s_i` or moves to a neighbour j
//!    with probability `(1 - s_i) w_ij / sum_k w_ik` (edge weights; a place without neighbours
//!    keeps its belief). `s_i` is the `stay_probability` option, or, when the frame carries
//!    odometry and the place's edges have lengths, `exp(-d / mean_edge_length_i)` for a travelled
//!    distance d. The result is mixed with a uniform jump (`jump_probability`) so that a
//!    kidnapped robot recovers.
//! 2. *Update.* Place likelihood `exp((score_i - m) / T)` with the place score (best view
//!    similarity), temperature T and m the largest exponent argument (the shift cancels in the
//!    normalisation and keeps exp() in range). Normalise.
//!
//! **Off-map probability** q, filtered separately so that a stretch of unrecognisable frames
//! does not erase the place belief: q enters with `off_map_probability` per frame and stays with
//! `stay_probability`; its update weighs the off-map likelihood against the on-map marginal
//! likelihood `sum_i prior_i * likelihood_i`. The off-map hypothesis scores what the best of M
//! unrelated places would score in this frame: `mean + (sqrt(2 ln M) + margin) * std` of the
//! frame's place scores without the best one (the expected maximum of M Gaussian draws plus
//! `off_map_margin` standard deviations), never below the absolute floor `off_map_similarity`.
//! Maps with fewer than [`MIN_PLACES_FOR_BACKGROUND`] places use the floor alone.
//!
//! Single-frame mode skips the prediction and starts every frame from the initial prior.

use crate::map::Map;

/// Below this many places the frame's score statistics say nothing about the background.
pub(crate) const MIN_PLACES_FOR_BACKGROUND: usize = 10;

/// Fixed parameters of the filter, validated by the localizer options.
#[derive(Clone, Copy, Debug)]
pub(crate) struct FilterParams {
    pub temperature: f64,
    pub stay_probability: f64,
    pub jump_probability: f64,
    pub off_map_probability: f64,
    pub off_map_similarity: f64,
    pub off_map_margin: f64,
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

/// Place belief, off-map probability, and scratch buffers.
pub(crate) struct Belief {
    /// Posterior over the M places given that the robot is on the map.
    pub places: Vec<f64>,
    /// Posterior probability that the robot is off the map.
    pub off_map: f64,
    scratch: Vec<f64>,
    /// Mean length of each place's edges, when both ends have positions.
    mean_edge_length: Vec<Option<f64>>,
}

impl Belief {
    pub fn new(map: &Map) -> Self {
        let m = map.place_count();
        let positions = map.place_positions();
        let mean_edge_length = (0..m)
            .map(|p| {
                let here = positions[p]?;
                let (ids, _) = map.neighbours(p as u32).expect("place in range");
                let lengths: Vec<f64> = ids
                    .iter()
                    .map(|&j| positions[j as usize].map(|q| (q - here).norm()))
                    .collect::<Option<_>>()?;
                let mean = lengths.iter().sum::<f64>() / lengths.len().max(1) as f64;
                (!lengths.is_empty() && mean > 0.0).then_some(mean)
            })
            .collect();
        Self {
            places: vec![0.0; m],
            off_map: 0.0,
            scratch: vec![0.0; m],
            mean_edge_length,
        }
    }

    /// Sets the belief to the prior used before any frame: uniform over places, off-map with
    /// `off_map_probability`.
    pub fn set_initial(&mut self, params: &FilterParams) {
        let m = self.places.len();
        self.places.fill(1.0 / m as f64);
        self.off_map = params.off_map_probability;
    }

    /// Propagates the belief along the graph. `travelled` is the odometry distance in metres
    /// since the previous frame, when the frame carries odometry.
    pub fn predict(&mut self, map: &Map, params: &FilterParams, travelled: Option<f64>) {
        let m = self.places.len();
        let moved = &mut self.scratch;
        moved.fill(0.0);
        for i in 0..m {
            let b = self.places[i];
            if b == 0.0 {
                continue;
            }
            let (ids, weights) = map.neighbours(i as u32).expect("place in range");
            let total_weight: f64 = weights.iter().map(|&w| f64::from(w)).sum();
            if ids.is_empty() || total_weight <= 0.0 {
                moved[i] += b;
                continue;
            }
            let stay = match (travelled, self.mean_edge_length[i]) {
                (Some(d), Some(len)) => (-d / len).exp(),
                _ => params.stay_probability,
            };
            moved[i] += b * stay;
            let share = b * (1.0 - stay) / total_weight;
            for (&j, &w) in ids.iter().zip(weights) {
                moved[j as usize] += share * f64::from(w);
            }
        }
        let keep = 1.0 - params.jump_probability;
        let uniform = params.jump_probability / m as f64;
        for (b, &p) in self.places.iter_mut().zip(moved.iter()) {
            *b = keep * p + uniform;
        }
        self.off_map = self.off_map * params.stay_probability
            + (1.0 - self.off_map) * params.off_map_probability;
    }

    /// Multiplies by the observation likelihoods and normalises both filters. If every place
    /// underflows to zero (possible only with zero jump probability), the place belief restarts
    /// from the likelihood alone.
    pub fn update(&mut self, params: &FilterParams, place_scores: &[f32]) {
        let max_score = place_scores
            .iter()
            .fold(f32::NEG_INFINITY, |a, &b| a.max(b)) as f64;
        let off_score = off_map_score(params, place_scores, max_score);
        let shift = max_score.max(off_score);
        let inv_t = 1.0 / params.temperature;
        let mut on_map_likelihood = 0.0;
        for (b, &s) in self.places.iter_mut().zip(place_scores) {
            *b *= ((f64::from(s) - shift) * inv_t).exp();
            on_map_likelihood += *b;
        }
        if !(on_map_likelihood > 0.0 && on_map_likelihood.is_finite()) {
            let off_map = self.off_map;
            self.set_initial(params);
            self.off_map = off_map;
            return self.update(params, place_scores);
        }
        let inv_total = 1.0 / on_map_likelihood;
        self.places.iter_mut().for_each(|b| *b *= inv_total);

        let off = self.off_map * ((off_score - shift) * inv_t).exp();
        let on = (1.0 - self.off_map) * on_map_likelihood;
        self.off_map = if off + on > 0.0 {
            off / (off + on)
        } else {
            0.0
        };
    }
}
