//! topoloc: visual topological localization and loop-closure hints for SLAM systems.
//!
//! A robot loads a pre-built graph map of places ([`map::Map`]), feeds every camera frame's
//! global descriptor to a [`localize::Localizer`], and gets back the most probable place with a
//! confidence, top-k candidates and an off-map flag. The method follows the graph-based
//! localization of the seed thesis (chapter 4): places (macro nodes) with several views (micro
//! nodes), similarity of the query to every view, and a spatio-temporal filter over the graph.
//!
//! Modules: [`map`] (graph, file format, builders), [`localize`] (per-frame localization),
//! [`eval`] (metrics: MNA, OHA, R@N, precision-recall), [`synthetic`] (generated maps and
//! descriptor streams for demos, tests and benchmarks), [`verify`] (geometric verification of
//! candidates with ORB keypoints and RANSAC). The C ABI in `ffi` is a thin layer over
//! these and is the only place with `extern "C"` items.

#![warn(missing_docs)]

pub mod describe;
pub mod eval;
pub mod ffi;
pub mod localize;
pub mod map;
pub mod synthetic;
pub mod verify;

pub use localize::{
    Candidate, Frame, Localization, LocalizeError, Localizer, LocalizerOptions, MetricOptions,
    Mode, PoseFix,
};
pub use map::{DescriptorIdentity, ExpectedDescriptor, LoadOptions, Map, MapBuilder, MapError};

/// Crate version, `MAJOR.MINOR.PATCH`.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
