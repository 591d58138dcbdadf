//! Descriptor backends: images in, global descriptors out.
//!
//! [`image`] validates and converts host images; [`onnx`] runs a CNN (ONNX Runtime) and pools
//! its multi-level feature maps ([`mlf`]); [`pca`] projects raw vectors to D dimensions with a
//! projection fitted on the map's own views.

pub mod image;
pub mod mlf;
pub mod onnx;
pub mod pca;

use std::path::PathBuf;

/// What can go wrong when describing images.
#[derive(Debug, thiserror::Error)]
pub enum DescribeError {
    /// The image buffer is unusable (size, stride, length); the message says why.
    #[error("invalid image: {0}")]
    InvalidImage(String),
    /// A parameter is out of range.
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// A runtime or model file is missing or cannot be loaded.
    #[error("{what} unavailable (tried {tried:?}): {hint}")]
    BackendUnavailable {
        /// What is missing.
        what: String,
        /// Every path tried, in order.
        tried: Vec<PathBuf>,
        /// How to fix it.
        hint: String,
    },
    /// The model loaded but does not work as expected (corrupt file, missing outputs, run error).
    #[error("model error: {0}")]
    Model(String),
    /// OpenCV failed.
    #[error("OpenCV: {0}")]
    OpenCv(#[from] opencv::Error),
}
