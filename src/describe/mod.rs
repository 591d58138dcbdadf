//! Descriptor backends: images in, global descriptors out.
//!
//! [`image`] validates and converts host images; [`onnx`] runs a CNN (ONNX Runtime) and pools
//! its multi-level feature maps ([`mlf`]); [`pca`] projects raw vectors to D dimensions with a
//! projection fitted on the map's own views; [`vlad`] aggregates OpenCV local features.
//! [`describer`] ties them together: fitting a map's model and describing query images with it.

pub mod describer;
pub mod image;
pub mod mlf;
pub mod onnx;
pub mod pca;
pub mod vlad;

use std::path::PathBuf;

pub use describer::{
    BackendConfig, BackendKind, BackendSpec, Describer, DescriberModel, DescriberOptions,
    Extractor, FitOptions, RawFeatures,
};

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
    /// The image carries no place information (blank, constant, no local feature).
    #[error("uninformative image: {0}")]
    Uninformative(String),
    /// The backend or model differs from the one the map was built with.
    #[error("describer mismatch: {0}")]
    Mismatch(String),
    /// OpenCV failed.
    #[error("OpenCV: {0}")]
    OpenCv(#[from] opencv::Error),
}
