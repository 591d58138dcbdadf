//! Evaluation metrics: the graph metrics of the seed thesis (§4.4.3) and the usual
//! place-recognition metrics.
//!
//! - [`HopDistances`]: BFS hop counts between places, cached per source place.
//! - [`GraphEvaluator`]: MNA, OHA, k-hop accuracy and R@N over per-frame [`Prediction`]s.
//! - [`recall_at_n_frames`]: recall with a frame tolerance, for frame-aligned datasets.
//! - [`precision_recall`]: PR curve, average precision and R@100P from [`ScoredOutcome`]s.
//! - [`calibration`]: reliability table and expected calibration error of the confidence.
//! - [`evaluate`] of a [`Trajectory`]: ATE, ARE, RPE and R_traj of a SLAM estimate against
//!   ground truth, with evo's association and Umeyama alignment ([`trajectory`]).
//!
//! Every rate is a fraction in `[0, 1]` of query frames; an empty input gives 0, never a panic.

mod calibration;
mod frames;
mod graph;
mod hops;
mod precision_recall;
pub mod trajectory;

pub use calibration::{calibration, Calibration, CalibrationBin};
pub use frames::{recall_at_n_frames, FrameRanking};
pub use graph::{GraphEvaluator, GraphMetrics, Prediction, RecallAtN};
pub use hops::HopDistances;
pub use precision_recall::{precision_recall, PrCurve, PrPoint};
pub use trajectory::{
    associate, evaluate, umeyama, Alignment, ErrorStats, Similarity, Trajectory, TrajectoryError,
    TrajectoryFormat, TrajectoryOptions, TrajectoryReport,
};

use crate::map::PlaceId;
use serde::{Deserialize, Serialize};

/// One query frame reduced to what ranking and calibration metrics need.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ScoredOutcome {
    /// The localizer's confidence in its answer (higher is surer).
    pub confidence: f32,
    /// Whether the answer was right (e.g. top-1 place equals the true place).
    pub correct: bool,
}

/// Invalid input to an evaluation function.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// An adjacency list names a neighbour that is not a place of the graph.
    #[error("place {place} lists neighbour {neighbour}, but the graph has {places} places")]
    UnknownNeighbour {
        /// Place whose list is wrong.
        place: PlaceId,
        /// Neighbour id given.
        neighbour: PlaceId,
        /// Places in the graph.
        places: usize,
    },
    /// A prediction names a true or predicted place that is not a place of the graph.
    #[error("query {query} names place {place}, but the graph has {places} places")]
    UnknownPlace {
        /// Index of the prediction.
        query: usize,
        /// Place id given.
        place: PlaceId,
        /// Places in the graph.
        places: usize,
    },
    /// A confidence is NaN, so it cannot be ranked.
    #[error("query {query} has a NaN confidence")]
    NanConfidence {
        /// Index of the outcome.
        query: usize,
    },
    /// A confidence lies outside `[0, 1]` (or is NaN) where a probability is required.
    #[error("query {query} has confidence {value}, expected a value in [0, 1]")]
    ConfidenceOutOfRange {
        /// Index of the outcome.
        query: usize,
        /// Confidence given.
        value: f32,
    },
    /// A reliability table needs at least one bin.
    #[error("calibration needs at least one bin")]
    NoBins,
}

/// `count / total`, or 0 when `total` is 0.
fn fraction(count: usize, total: usize) -> f64 {
    if total == 0 {
        0.0
    } else {
        count as f64 / total as f64
    }
}

/// Test helper: outcomes from `(confidence, correct)` pairs.
#[cfg(test)]
pub(crate) fn outcomes(list: &[(f32, bool)]) -> Vec<ScoredOutcome> {
    list.iter()
        .map(|&(confidence, correct)| ScoredOutcome {
            confidence,
            correct,
        })
        .collect()
}
