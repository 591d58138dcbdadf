//! Recall with a frame tolerance, for datasets where query and map frames are aligned
//! (query frame i was taken where map frame i was).

use serde::{Deserialize, Serialize};

/// Ground truth and ranked answer of one query, as frame indices of a frame-aligned dataset.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameRanking {
    /// Map frame that truly matches the query frame.
    pub truth: usize,
    /// Retrieved map frames, best first.
    pub ranked: Vec<usize>,
}

/// Fraction of queries for which any of the first `n` ranked map frames lies within
/// `tolerance` frames of the true one (`|ranked - truth| <= tolerance`). Queries with fewer
/// than `n` ranked frames use all of them; `n == 0` or no query gives 0.
///
/// Accepts any iterator of rankings, e.g. `&rankings` or
/// `predictions.iter().filter_map(|p| p.frames.as_ref())`.
pub fn recall_at_n_frames<'a>(
    queries: impl IntoIterator<Item = &'a FrameRanking>,
    tolerance: usize,
    n: usize,
) -> f64 {
    let (mut hits, mut total) = (0, 0);
    for query in queries {
        total += 1;
        if query
            .ranked
            .iter()
            .take(n)
            .any(|&frame| frame.abs_diff(query.truth) <= tolerance)
        {
            hits += 1;
        }
    }
    super::fraction(hits, total)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rankings() -> Vec<FrameRanking> {
        vec![
            FrameRanking {
                truth: 10,
                ranked: vec![3, 12, 40],
            },
            FrameRanking {
                truth: 0,
                ranked: vec![1],
            },
            FrameRanking {
                truth: 50,
                ranked: vec![],
            },
        ]
    }

    #[test]
    fn tolerance_and_depth_decide_hits() {
        let queries = rankings();
        assert!((recall_at_n_frames(&queries, 2, 1) - 1.0 / 3.0).abs() < 1e-12);
        assert!((recall_at_n_frames(&queries, 2, 2) - 2.0 / 3.0).abs() < 1e-12);
        assert!((recall_at_n_frames(&queries, 2, 10) - 2.0 / 3.0).abs() < 1e-12);
        assert_eq!(recall_at_n_frames(&queries, 0, 3), 0.0);
        assert!((recall_at_n_frames(&queries, 7, 1) - 2.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn degenerate_inputs_give_zero() {
        assert_eq!(recall_at_n_frames(&rankings(), 100, 0), 0.0);
        assert_eq!(recall_at_n_frames(&[], 1, 1), 0.0);
    }
}
