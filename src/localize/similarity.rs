//! Cosine similarity of a query to every view, and pooling of view scores into place scores.

use crate::map::Map;
use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};

/// Computes `out[v] = <descriptors[v], query>` for every view with one faer matrix-vector
/// product (single-threaded). Both sides are unit-norm, so this is the cosine similarity.
/// Cost: one pass over the N x D descriptor matrix (memory-bound).
pub(crate) fn view_similarities(map: &Map, query: &[f32], out: &mut [f32]) {
    let (n, d) = (map.view_count(), map.dim());
    debug_assert_eq!(query.len(), d);
    debug_assert_eq!(out.len(), n);
    let lhs = MatRef::from_row_major_slice(map.descriptors(), n, d);
    let rhs = MatRef::from_column_major_slice(query, d, 1);
    let dst = MatMut::from_column_major_slice_mut(out, n, 1);
    matmul(dst, Accum::Replace, lhs, rhs, 1.0f32, Par::Seq);
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
