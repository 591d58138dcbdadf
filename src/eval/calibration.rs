//! Reliability of the confidence: does a confidence of 0.8 mean right 80 % of the time?

use super::{fraction, EvalError, ScoredOutcome};
use serde::{Deserialize, Serialize};

/// One confidence bin of a reliability table.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CalibrationBin {
    /// Lower edge (inclusive).
    pub lower: f64,
    /// Upper edge (exclusive, except 1.0 for the last bin).
    pub upper: f64,
    /// Number of outcomes in the bin.
    pub count: usize,
    /// Mean confidence of those outcomes (0 for an empty bin).
    pub mean_confidence: f64,
    /// Fraction of those outcomes that were correct (0 for an empty bin).
    pub accuracy: f64,
}

/// Reliability table and expected calibration error.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// Equal-width bins covering `[0, 1]`, lowest first.
    pub bins: Vec<CalibrationBin>,
    /// ECE: sum over bins of `count / total * |accuracy - mean_confidence|`, in `[0, 1]`.
    pub expected_calibration_error: f64,
}

/// Reliability table of `outcomes` over `bin_count` equal-width bins of `[0, 1]`; the
/// confidence `c` falls in bin `floor(c * bin_count)`, and 1.0 in the last bin. Fails when
/// `bin_count` is 0 or a confidence is NaN or outside `[0, 1]`. An empty input gives empty
/// bins and an ECE of 0.
pub fn calibration(outcomes: &[ScoredOutcome], bin_count: usize) -> Result<Calibration, EvalError> {
    if bin_count == 0 {
        return Err(EvalError::NoBins);
    }
    let mut confidence_sums = vec![0.0f64; bin_count];
    let mut correct = vec![0usize; bin_count];
    let mut counts = vec![0usize; bin_count];
    for (query, outcome) in outcomes.iter().enumerate() {
        let value = outcome.confidence;
        if !(0.0..=1.0).contains(&value) {
            return Err(EvalError::ConfidenceOutOfRange { query, value });
        }
        let bin = ((value as f64 * bin_count as f64) as usize).min(bin_count - 1);
        confidence_sums[bin] += f64::from(value);
        correct[bin] += usize::from(outcome.correct);
        counts[bin] += 1;
    }

    let width = 1.0 / bin_count as f64;
    let bins: Vec<CalibrationBin> = (0..bin_count)
        .map(|b| CalibrationBin {
            lower: b as f64 * width,
            upper: if b + 1 == bin_count {
                1.0
            } else {
                (b + 1) as f64 * width
            },
            count: counts[b],
            mean_confidence: if counts[b] == 0 {
                0.0
            } else {
                confidence_sums[b] / counts[b] as f64
            },
            accuracy: fraction(correct[b], counts[b]),
        })
        .collect();
    let expected_calibration_error = bins
        .iter()
        .map(|b| fraction(b.count, outcomes.len()) * (b.accuracy - b.mean_confidence).abs())
        .sum();
    Ok(Calibration {
        bins,
        expected_calibration_error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::outcomes;

    #[test]
    fn hand_computed_ece() {
        // Bin [0.25, 0.5): confidences 0.3, 0.4, one right -> mean 0.35, accuracy 0.5.
        // Bin [0.75, 1]: confidences 0.9, 0.8, 1.0, two right -> mean 0.9, accuracy 2/3.
        // ECE = 2/5 * 0.15 + 3/5 * (0.9 - 2/3) = 0.06 + 0.14 = 0.2.
        let table = calibration(
            &outcomes(&[
                (0.3, true),
                (0.9, true),
                (0.4, false),
                (1.0, false),
                (0.8, true),
            ]),
            4,
        )
        .unwrap();
        assert!(
            (table.expected_calibration_error - 0.2).abs() < 1e-6,
            "{}",
            table.expected_calibration_error
        );
        let counts: Vec<usize> = table.bins.iter().map(|b| b.count).collect();
        assert_eq!(counts, [0, 2, 0, 3]);
        let (low, high) = (table.bins[1], table.bins[3]);
        assert!((low.mean_confidence - 0.35).abs() < 1e-6 && (low.accuracy - 0.5).abs() < 1e-12);
        assert!(
            (high.mean_confidence - 0.9).abs() < 1e-6 && (high.accuracy - 2.0 / 3.0).abs() < 1e-12
        );
        assert_eq!((low.lower, low.upper, high.upper), (0.25, 0.5, 1.0));
        assert_eq!(
            (table.bins[0].mean_confidence, table.bins[0].accuracy),
            (0.0, 0.0)
        );
    }

    #[test]
    fn perfectly_calibrated_bins_give_zero_error() {
        let table = calibration(&outcomes(&[(0.5, true), (0.5, false), (1.0, true)]), 2).unwrap();
        assert!(table.expected_calibration_error.abs() < 1e-12);
    }

    #[test]
    fn bad_inputs() {
        assert_eq!(calibration(&[], 0).unwrap_err(), EvalError::NoBins);
        let empty = calibration(&[], 3).unwrap();
        assert_eq!(
            (empty.bins.len(), empty.expected_calibration_error),
            (3, 0.0)
        );
        assert_eq!(
            calibration(&outcomes(&[(0.5, true), (1.5, true)]), 2).unwrap_err(),
            EvalError::ConfidenceOutOfRange {
                query: 1,
                value: 1.5
            }
        );
        assert!(matches!(
            calibration(&outcomes(&[(f32::NAN, true)]), 2),
            Err(EvalError::ConfidenceOutOfRange { query: 0, .. })
        ));
    }
}
