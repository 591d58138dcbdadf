//! topoloc: visual topological localization and loop-closure hints for SLAM systems.
//!
//! A robot loads a pre-built graph map of places ([`map::Map`]), feeds every camera frame (its
//! image or its global descriptor) to a [`localize::Localizer`], and gets back the most probable
//! place with a confidence, top-k candidates and an off-map flag. The method follows the
//! graph-based localization of the seed thesis (chapter 4): places (macro nodes) with several
//! views (micro nodes), similarity of the query to every view, and a spatio-temporal filter over
//! the graph.
//!
//! # Layers
//! Modules are layered; a module imports only from layers below it. This table is the one place
//! the layers are written: `tests/layers.rs` reads it and holds every `crate::` path of `src/`
//! against it, and checks that the submodules of every module import each other without cycles.
//!
//! | layer | modules | what |
//! |---|---|---|
//! | 8 | `ffi` | the C ABI: the only place with `extern "C"` items |
//! | 7 | [`loops`] | keyframe database (online place graph, loop and relocalization queries) |
//! | 6 | [`localize`] | per-frame localization: similarity, graph filter, particles, verification |
//! | 5 | [`build`], [`skeleton`], [`eval`] | maps from images and keyframes; graphs from occupancy grids; metrics |
//! | 4 | [`map`] | the graph of places and views, and its file format |
//! | 3 | [`describe`], [`verify`] | descriptor backends; local features and geometric checks |
//! | 2 | [`image`], [`descriptor`], [`onnx_runtime`] | leaf vocabulary: image views and pixel formats, descriptor identity; the ONNX Runtime library |
//! | 1 | [`errors`], [`bounds`], [`profile`] | the error kinds several image-work modules share; the values each option accepts; time per pipeline stage |
//!
//! [`eval`] (metrics: MNA, OHA, R@N, precision-recall, calibration, trajectory ATE/RPE) reads
//! maps and results and is read by no other module of the library but `ffi`, which exposes its
//! trajectory metrics to C. Generated descriptor worlds for tests and
//! benchmarks live in the dev-only crate `topoloc-synthetic` (`tools/synthetic`), not here.

#![warn(missing_docs)]

pub mod bounds;
pub mod build;
pub mod describe;
pub mod descriptor;
pub mod errors;
pub mod eval;
pub mod ffi;
pub mod image;
pub mod localize;
pub mod loops;
pub mod map;
pub mod onnx_runtime;
pub mod profile;
pub mod skeleton;
pub mod verify;

pub use descriptor::{DescriptorIdentity, ExpectedDescriptor};
pub use localize::{
    Candidate, Frame, GrnnError, GrnnOptions, Localization, LocalizeError, Localizer,
    LocalizerOptions, MetricOptions, Mode, PoseFix,
};
pub use map::{LoadOptions, Map, MapBuilder, MapError};

/// Crate version, `MAJOR.MINOR.PATCH`.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
