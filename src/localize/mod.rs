//! Per-frame localization against a map: similarity of the query descriptor to every view,
//! place scores, and a forward filter over the graph (see [`filter`](self) docs in
//! `filter.rs`), giving the most probable place, a confidence, top-k candidates and an
//! off-map flag. [`Mode::Metric`] replaces the graph filter's place belief by a particle
//! filter over camera poses (`particles.rs`), on maps with positions and view poses, and
//! [`Mode::Grnn`] by the seed's learned graph recurrent network (`grnn/`); the off-map state
//! comes from the graph filter in every mode. Optionally the most probable places
//! are verified geometrically against the query image ([`crate::verify`]) and their belief
//! weighed by the inliers found; with the camera's intrinsics and a map storing keypoint scene
//! points, the best-verified view also gives a metric pose of the camera
//! ([`Localization::pose_fix`]), which metric mode uses to weigh its particles.

mod error;
mod estimator;
mod filter;
mod grnn;
mod localizer;
mod motion;
mod options;
mod particles;
mod result;
mod scratch;
mod similarity;
mod verification;

pub use error::{LocalizeError, TimestampError};
pub use grnn::{GrnnError, GrnnOptions};
pub use localizer::Localizer;
pub use options::{LocalizerOptions, Mode, MAX_SPEED_CLASSES};
pub use particles::{MetricOptions, MAX_PARTICLES};
pub use result::{Candidate, Frame, Localization, PoseFix};
