//! Per-frame buffers of a localizer, sized once for the map and reused by every frame, and the
//! selection of the most probable places in them (shared by the localizer and verification).

use crate::map::Map;

/// Per-frame buffers, sized once for the map and reused by every frame.
pub(super) struct Scratch {
    /// The frame's descriptor when the localizer described its image.
    pub described: Vec<f32>,
    /// The unit-norm query descriptor.
    pub query: Vec<f32>,
    /// Cosine similarity of the query to every view.
    pub view_scores: Vec<f32>,
    /// Best view similarity of every place.
    pub place_scores: Vec<f32>,
    /// Each place's best view (by similarity, then by verification).
    pub best_views: Vec<u32>,
    /// Place ids, partially sorted by probability for selection.
    pub order: Vec<u32>,
}

impl Scratch {
    /// Buffers for `map`.
    pub fn new(map: &Map) -> Self {
        let (n, m) = (map.view_count(), map.place_count());
        Self {
            described: Vec::with_capacity(map.dim()),
            query: Vec::with_capacity(map.dim()),
            view_scores: vec![0.0; n],
            place_scores: vec![0.0; m],
            best_views: vec![0; m],
            order: (0..m as u32).collect(),
        }
    }
}

/// Moves the `k` (>= 1) most probable places of `order` (place ids) to its front, ties broken by
/// the lower id; sorts them best first when `sorted`.
pub(super) fn select_most_probable(order: &mut [u32], probability: &[f64], k: usize, sorted: bool) {
    let by_probability = |a: &u32, b: &u32| {
        probability[*b as usize]
            .total_cmp(&probability[*a as usize])
            .then(a.cmp(b))
    };
    if k < order.len() {
        order.select_nth_unstable_by(k - 1, by_probability);
    }
    if sorted {
        order[..k].sort_unstable_by(by_probability);
    }
}
