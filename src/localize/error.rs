//! Errors of the localizer.

use super::grnn::GrnnError;
use crate::descriptor::DescriptorError;
use crate::errors::VisionError;
use crate::map::MapError;

/// What can go wrong when creating a localizer or processing a frame. On error the localizer's
/// state is exactly what it was before the call.
#[derive(Debug, thiserror::Error)]
pub enum LocalizeError {
    /// The query descriptor has the wrong length, NaN/Inf, or is all zeros.
    #[error("bad query descriptor: {0}")]
    Descriptor(#[from] DescriptorError),
    /// The map does not fit the localizer (descriptor mismatch, ...).
    #[error(transparent)]
    Map(#[from] MapError),
    /// An option is out of range; the message names it.
    #[error("invalid localizer option: {0}")]
    InvalidOption(String),
    /// Frame timestamp is NaN/Inf or earlier than the previous frame's.
    #[error("bad timestamp: {0}")]
    Timestamp(TimestampError),
    /// Describing the frame's image failed (bad image, uninformative image, backend error), or
    /// the describer does not fit the map.
    #[error(transparent)]
    Describe(#[from] VisionError),
    /// The frame has an image but no descriptor, and the localizer has no describer (create it
    /// with `Localizer::with_describer` on a map built from images).
    #[error("cannot describe images: {0}")]
    NoDescriber(String),
    /// Geometric verification is on but the map stores no keypoints. (A frame without an
    /// image while verifying is a [`VisionError::InvalidImage`].)
    #[error("cannot verify: {0}")]
    Verification(String),
    /// Metric mode was asked for on a map without place positions or view poses.
    #[error("cannot localize metrically: {0}")]
    Metric(String),
    /// The learned estimator ([`super::Mode::Grnn`]) cannot load its model, the model does not
    /// fit the map, or a step failed.
    #[error(transparent)]
    Grnn(#[from] GrnnError),
    /// Odometry is not finite.
    #[error("bad odometry: {0}")]
    Odometry(String),
}

/// What is wrong with a frame's timestamp.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TimestampError {
    /// NaN or infinite.
    #[error("{0} is not finite")]
    NonFinite(f64),
    /// Earlier than the previous frame's (filter and metric modes need time to move forward).
    #[error("{timestamp} is earlier than the previous frame's {previous}; reset the localizer to start a new sequence")]
    Backwards {
        /// The frame's timestamp.
        timestamp: f64,
        /// The previous frame's.
        previous: f64,
    },
}
