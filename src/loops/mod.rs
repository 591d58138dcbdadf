//! Loop closure for SLAM hosts: a keyframe database that groups the host's keyframes into
//! places online (the graph grows as the robot explores) and answers loop and relocalization
//! queries by appearance, DBoW2-style (`query(descriptor, max_results, max_id)`), robust to
//! light where bag-of-words is not because it compares the map's global descriptors.
//!
//! What is here: [`KeyframeDatabase`] (add, loop candidates excluding recent keyframes,
//! relocalization candidates, erase, save as a topoloc map and reload it for a later session).
//! [`LoopDetector`] keeps each keyframe's local features beside it and turns the candidates
//! into verified, gated loop-closure hints with relative poses and covariances.
//! [`KeyframeDescriber`] turns a keyframe image into both inputs (global descriptor and local
//! features) for hosts that hand over images.

mod database;
mod describe;
mod error;
mod hints;

pub use database::{Added, DatabaseOptions, KeyframeDatabase, KeyframeEntry, LoopQuery, Match};
pub use describe::{KeyframeDescriber, DEFAULT_LOOP_FEATURES};
pub use error::LoopsError;
pub use hints::{
    Gate, HintOptions, KeyframeFeatures, LoopDetector, LoopHint, OdometryGate, Processed,
    VerifiedCandidate, Work,
};
