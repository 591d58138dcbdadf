//! Error kinds shared by the image-work layers ([`crate::describe`], [`crate::verify`]).
//!
//! A leaf of the layer order (see the crate documentation): it imports nothing of the crate.

use std::path::PathBuf;

/// What can go wrong in image work: describing images (CNN, VLAD), detecting and matching
/// local features, geometric checks. Shared by [`crate::describe`] and [`crate::verify`].
#[derive(Debug, thiserror::Error)]
pub enum VisionError {
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

impl VisionError {
    /// The same error again (same variant, same message): for an error that several workers
    /// report, so that each keeps its kind (a missing model stays `BackendUnavailable`).
    pub fn duplicate(&self) -> Self {
        match self {
            Self::InvalidImage(m) => Self::InvalidImage(m.clone()),
            Self::InvalidArgument(m) => Self::InvalidArgument(m.clone()),
            Self::BackendUnavailable { what, tried, hint } => Self::BackendUnavailable {
                what: what.clone(),
                tried: tried.clone(),
                hint: hint.clone(),
            },
            Self::Model(m) => Self::Model(m.clone()),
            Self::Uninformative(m) => Self::Uninformative(m.clone()),
            Self::Mismatch(m) => Self::Mismatch(m.clone()),
            Self::OpenCv(e) => Self::OpenCv(opencv::Error::new(e.code, e.message.clone())),
        }
    }
}
