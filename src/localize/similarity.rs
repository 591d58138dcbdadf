//! Cosine similarity of a query to every view, and pooling of view scores into place scores.

use crate::descriptor::row_similarities;
use crate::map::Map;

/// Computes `out[v] = <descriptors[v], query>` for every view (see [`row_similarities`]).
pub(crate) fn view_similarities(map: &Map, query: &[f32], out: &mut [f32]) {
    debug_assert_eq!(out.len(), map.view_count());
    row_similarities(map.descriptors(), map.dim(), query, out);
}

/// Place score = best similarity over the place's views (the query looks one way; the view
/// facing that way is the one that should match). Also records which view won.
pub(crate) fn pool_places(
    map: &Map,
    view_scores: &[f32],
    place_scores: &mut [f32],
    best_views: &mut [u32],
) {
    place_scores.fill(f32::NEG_INFINITY);
    for (v, &s) in view_scores.iter().enumerate() {
        let p = map.view_place_unchecked(v);
        if s > place_scores[p] {
            place_scores[p] = s;
            best_views[p] = v as u32;
        }
    }
}
