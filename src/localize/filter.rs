//! Forward filter (HMM) over the place graph, with one extra "off-map" state.
//!
//! States are the M places plus an off-map state. Each frame:
//!
//! 1. **Predict.** From place i the robot stays with probability `s_i` or moves to a neighbour j
//!    with probability `(1 - s_i) w_ij / sum_k w_ik` (edge weights; a place without neighbours
//!    keeps its belief). `s_i` is the `stay_probability` option, or, when the frame carries
//!    odometry and the place's edges have lengths, `exp(-d / mean_edge_length_i)` for a travelled
//!    distance d. The off-map state stays with `stay_probability` and otherwise re-enters the
//!    map uniformly. The result is mixed with a uniform jump (`jump_probability`, so a kidnapped
//!    robot recovers) and an entry into the off-map state (`off_map_probability`).
//! 2. **Update.** Place likelihood `exp((score_i - m) / T)` with the place score (best view
//!    similarity), temperature T and m the largest exponent argument (the shift cancels in the
//!    normalisation and keeps exp() in range); the off-map state's likelihood uses the
//!    `off_map_similarity` option as its score.
//! 3. Normalise.
//!
//! Single-frame mode skips step 1 and uses the initial prior every frame.

use crate::map::Map;

/// Fixed parameters of the filter, validated by the localizer options.
#[derive(Clone, Copy, Debug)]
pub(crate) struct FilterParams {
    pub temperature: f64,
    pub stay_probability: f64,
    pub jump_probability: f64,
    pub off_map_probability: f64,
    pub off_map_similarity: f64,
}

/// Belief over places plus the off-map state (last entry), and scratch buffers.
pub(crate) struct Belief {
    /// M + 1 probabilities; index M is off-map.
    pub probabilities: Vec<f64>,
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
                let lengths: Option<Vec<f64>> = ids.iter().map(|&j| positions[j as usize].map(|q| (q - here).norm())).collect();
                let lengths = lengths?;
                let mean = lengths.iter().sum::<f64>() / lengths.len().max(1) as f64;
                (!lengths.is_empty() && mean > 0.0).then_some(mean)
            })
            .collect();
        Self { probabilities: vec![0.0; m + 1], scratch: vec![0.0; m + 1], mean_edge_length }
    }

    /// Sets the belief to the prior used before any frame: the off-map state gets
    /// `off_map_probability`, places share the rest uniformly.
    pub fn set_initial(&mut self, params: &FilterParams) {
        let m = self.probabilities.len() - 1;
        let place_mass = (1.0 - params.off_map_probability) / m as f64;
        self.probabilities[..m].fill(place_mass);
        self.probabilities[m] = params.off_map_probability;
    }

    /// Step 1: propagates the belief along the graph. `travelled` is the odometry distance in
    /// metres since the previous frame, when the frame carries odometry.
    pub fn predict(&mut self, map: &Map, params: &FilterParams, travelled: Option<f64>) {
        let m = self.probabilities.len() - 1;
        let local = &mut self.scratch;
        local.fill(0.0);
        for i in 0..m {
            let b = self.probabilities[i];
            if b == 0.0 {
                continue;
            }
            let (ids, weights) = map.neighbours(i as u32).expect("place in range");
            let total_weight: f64 = weights.iter().map(|&w| f64::from(w)).sum();
            if ids.is_empty() || total_weight <= 0.0 {
                local[i] += b;
                continue;
            }
            let stay = match (travelled, self.mean_edge_length[i]) {
                (Some(d), Some(len)) => (-d / len).exp(),
                _ => params.stay_probability,
            };
            local[i] += b * stay;
            let move_mass = b * (1.0 - stay) / total_weight;
            for (&j, &w) in ids.iter().zip(weights) {
                local[j as usize] += move_mass * f64::from(w);
            }
        }
        let off = self.probabilities[m];
        local[m] = off * params.stay_probability;
        let reentry = off * (1.0 - params.stay_probability) / m as f64;

        let keep = 1.0 - params.jump_probability - params.off_map_probability;
        let uniform = params.jump_probability / m as f64;
        for i in 0..m {
            self.probabilities[i] = keep * (local[i] + reentry) + uniform;
        }
        self.probabilities[m] = keep * local[m] + params.off_map_probability;
    }

    /// Steps 2 and 3: multiplies by the observation likelihood and normalises. If every state
    /// underflows to zero (only possible with zero jump probability), the belief restarts from
    /// the likelihood alone.
    pub fn update(&mut self, params: &FilterParams, place_scores: &[f32]) {
        let m = self.probabilities.len() - 1;
        let max_score = place_scores.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b)) as f64;
        let shift = max_score.max(params.off_map_similarity);
        let inv_t = 1.0 / params.temperature;
        let mut total = 0.0;
        for i in 0..m {
            let likelihood = ((f64::from(place_scores[i]) - shift) * inv_t).exp();
            self.probabilities[i] *= likelihood;
            total += self.probabilities[i];
        }
        self.probabilities[m] *= ((params.off_map_similarity - shift) * inv_t).exp();
        total += self.probabilities[m];
        if !(total > 0.0 && total.is_finite()) {
            self.set_initial(params);
            return self.update(params, place_scores);
        }
        let inv_total = 1.0 / total;
        self.probabilities.iter_mut().for_each(|p| *p *= inv_total);
    }
}
