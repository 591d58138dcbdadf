//! Descriptor backends: images in, global descriptors out.
//!
//! Host images come in as [`crate::image::ImageView`]s; [`onnx`] runs a CNN (ONNX Runtime) and pools
//! its multi-level feature maps ([`mlf`]); [`pca`] projects raw vectors to D dimensions with a
//! projection fitted on the map's own views; [`vlad`] aggregates OpenCV local features.
//! [`describer`] ties them together: fitting a map's model and describing query images with it.

pub mod describer;
pub mod limits;
pub mod mlf;
pub mod onnx;
pub mod pca;
pub mod vlad;

pub use describer::{
    BackendConfig, BackendKind, BackendSpec, Describer, DescriberModel, DescriberOptions,
    Extractor, FitOptions, RawFeatures,
};
pub use pca::PcaPrecision;
