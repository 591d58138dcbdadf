//! Graph metrics over per-frame predictions (seed thesis §4.4.3): MNA, OHA, k-hop accuracy, R@N.

use super::{fraction, EvalError, FrameRanking, HopDistances, ScoredOutcome};
use crate::map::PlaceId;
use serde::{Deserialize, Serialize};

/// The localizer's answer for one query frame, with its ground truth.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Prediction {
    /// True place of the query frame.
    pub truth: PlaceId,
    /// Predicted places, best first (top-N); empty when the localizer gave no answer, which
    /// counts as wrong.
    pub ranked: Vec<PlaceId>,
    /// The localizer's confidence in its top-1 place.
    pub confidence: f32,
    /// The same answer as frame indices, for frame-aligned datasets (see
    /// [`recall_at_n_frames`](super::recall_at_n_frames)).
    pub frames: Option<FrameRanking>,
}

impl Prediction {
    /// The best predicted place, if any.
    pub fn top1(&self) -> Option<PlaceId> {
        self.ranked.first().copied()
    }

    /// The best `n` predicted places (all of them when fewer are ranked).
    pub fn top_n(&self, n: usize) -> &[PlaceId] {
        &self.ranked[..n.min(self.ranked.len())]
    }
}

/// Recall at one list depth.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecallAtN {
    /// Number of ranked places considered.
    pub n: usize,
    /// Fraction of queries with any of the top `n` places within one hop of the truth.
    pub recall: f64,
}

/// Summary of the graph metrics over a set of query frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GraphMetrics {
    /// Number of query frames evaluated.
    pub queries: usize,
    /// Macro node accuracy: fraction of queries whose top-1 place is the true place.
    pub mna: f64,
    /// One-hop accuracy: fraction of queries whose top-1 place is at most one hop from the truth.
    pub oha: f64,
    /// R@N for each requested N, in the order requested.
    pub recall_at_n: Vec<RecallAtN>,
}

/// Computes graph metrics of predictions against the hop distances of their map.
///
/// Construction checks every place id once, so the metric methods cannot fail. BFS results
/// are cached in the [`HopDistances`], so calling several metrics costs little.
#[derive(Clone, Copy, Debug)]
pub struct GraphEvaluator<'a> {
    hops: &'a HopDistances,
    predictions: &'a [Prediction],
}

impl<'a> GraphEvaluator<'a> {
    /// Fails with [`EvalError::UnknownPlace`] if a true or ranked place is not in the graph.
    pub fn new(hops: &'a HopDistances, predictions: &'a [Prediction]) -> Result<Self, EvalError> {
        let places = hops.place_count();
        for (query, prediction) in predictions.iter().enumerate() {
            let mut ids = std::iter::once(&prediction.truth).chain(&prediction.ranked);
            if let Some(&place) = ids.find(|&&p| p as usize >= places) {
                return Err(EvalError::UnknownPlace {
                    query,
                    place,
                    places,
                });
            }
        }
        Ok(Self { hops, predictions })
    }

    /// Fraction of queries with any of the top `n` places at most `max_hops` hops from the
    /// truth. The metrics below are special cases of it.
    pub fn hit_rate(&self, n: usize, max_hops: u32) -> f64 {
        let hits = self
            .predictions
            .iter()
            .filter(|p| self.any_within(p.top_n(n), p.truth, max_hops))
            .count();
        fraction(hits, self.predictions.len())
    }

    /// Macro node accuracy: fraction of queries whose top-1 place is the true place.
    pub fn mna(&self) -> f64 {
        self.hop_accuracy(0)
    }

    /// Fraction of queries whose top-1 place is at most `k` hops from the true place.
    pub fn hop_accuracy(&self, k: u32) -> f64 {
        self.hit_rate(1, k)
    }

    /// One-hop accuracy: fraction of queries whose top-1 place is at most one hop from the truth.
    pub fn oha(&self) -> f64 {
        self.hop_accuracy(1)
    }

    /// R@N: fraction of queries with any of the top `n` places at most one hop from the truth
    /// (R@1 equals [`oha`](Self::oha)).
    pub fn recall_at_n(&self, n: usize) -> f64 {
        self.hit_rate(n, 1)
    }

    /// MNA, OHA and R@N for every N in `ns`.
    pub fn metrics(&self, ns: &[usize]) -> GraphMetrics {
        GraphMetrics {
            queries: self.predictions.len(),
            mna: self.mna(),
            oha: self.oha(),
            recall_at_n: ns
                .iter()
                .map(|&n| RecallAtN {
                    n,
                    recall: self.recall_at_n(n),
                })
                .collect(),
        }
    }

    /// Each prediction's confidence, marked correct when its top-1 place is at most `max_hops`
    /// hops from the truth (0: the exact place), for [`precision_recall`](super::precision_recall)
    /// and [`calibration`](super::calibration).
    pub fn scored_outcomes(&self, max_hops: u32) -> Vec<ScoredOutcome> {
        self.predictions
            .iter()
            .map(|p| ScoredOutcome {
                confidence: p.confidence,
                correct: self.any_within(p.top_n(1), p.truth, max_hops),
            })
            .collect()
    }

    fn any_within(&self, candidates: &[PlaceId], truth: PlaceId, max_hops: u32) -> bool {
        candidates
            .iter()
            .any(|&c| c == truth || self.hops.hops(truth, c).is_some_and(|h| h <= max_hops))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain() -> HopDistances {
        HopDistances::from_adjacency(&[vec![1], vec![2], vec![3], vec![4], vec![]]).unwrap()
    }

    fn prediction(truth: PlaceId, ranked: &[PlaceId], confidence: f32) -> Prediction {
        Prediction {
            truth,
            ranked: ranked.to_vec(),
            confidence,
            frames: None,
        }
    }

    /// On the chain 0-1-2-3-4. Hops of the ranked places from the truth, per query:
    /// [0, 2], [1, 0], [4, 1, 3], [4, 2, 1], [].
    fn predictions() -> Vec<Prediction> {
        vec![
            prediction(2, &[2, 0], 0.9),
            prediction(2, &[3, 2], 0.8),
            prediction(0, &[4, 1, 3], 0.4),
            prediction(4, &[0, 2, 3], 0.3),
            prediction(1, &[], 0.0),
        ]
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn hand_computed_graph_metrics() {
        let (hops, predictions) = (chain(), predictions());
        let eval = GraphEvaluator::new(&hops, &predictions).unwrap();
        let metrics = eval.metrics(&[1, 2, 3, 10]);
        assert_eq!(metrics.queries, 5);
        assert!(close(metrics.mna, 0.2));
        assert!(close(metrics.oha, 0.4));
        let recalls: Vec<f64> = metrics.recall_at_n.iter().map(|r| r.recall).collect();
        for (got, want) in recalls.iter().zip([0.4, 0.6, 0.8, 0.8]) {
            assert!(close(*got, want), "{recalls:?}");
        }
        assert_eq!(metrics.recall_at_n[1].n, 2);
        assert!(close(eval.hop_accuracy(0), 0.2));
        assert!(close(eval.hop_accuracy(3), 0.4));
        assert!(close(eval.hop_accuracy(4), 0.8));
        assert!(close(eval.hit_rate(2, 0), 0.4));
        assert_eq!(eval.recall_at_n(0), 0.0);
    }

    #[test]
    fn scored_outcomes_follow_the_hop_tolerance() {
        let (hops, predictions) = (chain(), predictions());
        let eval = GraphEvaluator::new(&hops, &predictions).unwrap();
        let exact: Vec<bool> = eval.scored_outcomes(0).iter().map(|o| o.correct).collect();
        assert_eq!(exact, [true, false, false, false, false]);
        let one_hop = eval.scored_outcomes(1);
        assert_eq!(
            one_hop.iter().map(|o| o.correct).collect::<Vec<_>>(),
            [true, true, false, false, false]
        );
        assert_eq!(one_hop[2].confidence, 0.4);
    }

    #[test]
    fn unknown_places_and_empty_input() {
        let hops = chain();
        let bad = [prediction(1, &[1], 0.5), prediction(1, &[2, 7], 0.5)];
        let err = GraphEvaluator::new(&hops, &bad).unwrap_err();
        assert_eq!(
            err,
            EvalError::UnknownPlace {
                query: 1,
                place: 7,
                places: 5
            }
        );
        let bad_truth = [prediction(5, &[1], 0.5)];
        assert!(GraphEvaluator::new(&hops, &bad_truth).is_err());

        let empty = GraphEvaluator::new(&hops, &[]).unwrap().metrics(&[1]);
        assert_eq!(
            (
                empty.queries,
                empty.mna,
                empty.oha,
                empty.recall_at_n[0].recall
            ),
            (0, 0.0, 0.0, 0.0)
        );
    }
}
