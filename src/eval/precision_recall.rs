//! Precision-recall of the localizer's answers when ranked by confidence.

use super::{fraction, EvalError, ScoredOutcome};
use serde::{Deserialize, Serialize};

/// One point of a precision-recall curve: the answers with `confidence >= threshold` are
/// accepted.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PrPoint {
    /// Lowest accepted confidence.
    pub threshold: f32,
    /// Correct accepted answers / accepted answers.
    pub precision: f64,
    /// Correct accepted answers / all queries (every query has a true match).
    pub recall: f64,
}

/// Precision-recall curve and its summaries.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PrCurve {
    /// One point per distinct confidence, from the highest threshold down (recall increasing).
    pub points: Vec<PrPoint>,
    /// Area under the curve, step-wise: sum over points of `(recall_k - recall_{k-1}) * precision_k`
    /// with `recall_0 = 0`.
    pub average_precision: f64,
    /// R@100P: the largest recall reached with precision exactly 1 (0 when the most confident
    /// answers already include a wrong one).
    pub recall_at_full_precision: f64,
}

/// Precision-recall of `outcomes` ranked by confidence, highest first. Outcomes with equal
/// confidence form one threshold step: they are accepted or rejected together, so the result
/// does not depend on their input order. An empty input gives an empty curve and zero
/// summaries. A NaN confidence is rejected with [`EvalError::NanConfidence`]; infinite
/// confidences are ranked like any other value.
pub fn precision_recall(outcomes: &[ScoredOutcome]) -> Result<PrCurve, EvalError> {
    if let Some(query) = outcomes.iter().position(|o| o.confidence.is_nan()) {
        return Err(EvalError::NanConfidence { query });
    }
    let mut ranked: Vec<&ScoredOutcome> = outcomes.iter().collect();
    ranked.sort_by(|x, y| y.confidence.total_cmp(&x.confidence));

    let mut curve = PrCurve::default();
    let (mut accepted, mut true_positives, mut previous_recall) = (0, 0, 0.0);
    // `==` (unlike total_cmp) also merges -0.0 with 0.0, which the sort put next to each other.
    for step in ranked.chunk_by(|x, y| x.confidence == y.confidence) {
        accepted += step.len();
        true_positives += step.iter().filter(|o| o.correct).count();
        let point = PrPoint {
            threshold: step[0].confidence,
            precision: fraction(true_positives, accepted),
            recall: fraction(true_positives, outcomes.len()),
        };
        curve.average_precision += (point.recall - previous_recall) * point.precision;
        previous_recall = point.recall;
        // Once a wrong answer is accepted precision stays below 1, so this keeps the last
        // recall of the all-correct prefix.
        if true_positives == accepted {
            curve.recall_at_full_precision = point.recall;
        }
        curve.points.push(point);
    }
    Ok(curve)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::outcomes;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn ties_form_one_step_whatever_their_order() {
        // Steps: 0.9 -> 1/1 of 5; 0.8 -> 2/3 of 5; 0.5 -> 3/4 of 5; 0.3 -> 3/5 of 5.
        let want_points = [
            (0.9, 1.0, 0.2),
            (0.8, 2.0 / 3.0, 0.4),
            (0.5, 0.75, 0.6),
            (0.3, 0.6, 0.6),
        ];
        let want_ap = 0.2 * 1.0 + 0.2 * (2.0 / 3.0) + 0.2 * 0.75;
        for order in [
            [
                (0.8, true),
                (0.3, false),
                (0.9, true),
                (0.8, false),
                (0.5, true),
            ],
            [
                (0.8, false),
                (0.5, true),
                (0.9, true),
                (0.3, false),
                (0.8, true),
            ],
        ] {
            let curve = precision_recall(&outcomes(&order)).unwrap();
            assert_eq!(curve.points.len(), want_points.len());
            for (got, &(threshold, precision, recall)) in curve.points.iter().zip(&want_points) {
                assert_eq!(got.threshold, threshold);
                assert!(
                    close(got.precision, precision) && close(got.recall, recall),
                    "{got:?}"
                );
            }
            assert!(
                close(curve.average_precision, want_ap),
                "{}",
                curve.average_precision
            );
            assert!(close(curve.recall_at_full_precision, 0.2));
        }
    }

    #[test]
    fn full_precision_recall_stops_at_the_first_wrong_answer() {
        let curve = precision_recall(&outcomes(&[
            (0.9, true),
            (0.8, true),
            (0.7, false),
            (0.6, true),
            (0.5, true),
        ]))
        .unwrap();
        assert!(close(curve.recall_at_full_precision, 0.4));
        // 0.2*1 + 0.2*1 + 0*(2/3) + 0.2*(3/4) + 0.2*(4/5)
        assert!(close(curve.average_precision, 0.71));
    }

    #[test]
    fn wrong_answer_tied_with_the_best_spoils_full_precision() {
        let curve = precision_recall(&outcomes(&[(0.9, true), (0.9, false), (0.5, true)])).unwrap();
        assert_eq!(curve.recall_at_full_precision, 0.0);
        assert!(close(curve.points[0].precision, 0.5));
    }

    #[test]
    fn perfect_predictor() {
        let curve = precision_recall(&outcomes(&[(0.2, true), (0.9, true), (0.6, true)])).unwrap();
        assert!(close(curve.average_precision, 1.0));
        assert!(close(curve.recall_at_full_precision, 1.0));
        assert_eq!(
            curve.points.iter().map(|p| p.threshold).collect::<Vec<_>>(),
            [0.9, 0.6, 0.2]
        );
    }

    #[test]
    fn empty_input_and_nan() {
        assert_eq!(precision_recall(&[]).unwrap(), PrCurve::default());
        let err = precision_recall(&outcomes(&[(0.5, true), (f32::NAN, true)])).unwrap_err();
        assert_eq!(err, EvalError::NanConfidence { query: 1 });
    }
}
