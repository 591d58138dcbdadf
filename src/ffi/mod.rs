//! The C ABI: a thin layer over the Rust API and the only place with `extern "C"` items and
//! raw-pointer handling.
//!
//! House rules (see ARCHITECTURE.md): every function is prefixed `topoloc_`; handles are opaque
//! and come in `_new`/`_load` + `_free` pairs, `_free(NULL)` being a no-op; every fallible
//! function returns a [`topoloc_status`] and leaves the details in a thread-local message
//! (`topoloc_last_error_message`); out-parameters are written only on success (except the
//! documented `needed`/`count` sizes); options structs start with `struct_size` and are filled by
//! `*_default()`; no panic crosses the boundary (`TOPOLOC_ERR_PANIC`).
//!
//! Thread safety: `const topoloc_map*` and `const topoloc_graph*` may be used from many threads
//! at once; builders, localizers, describers and loop detectors are single-threaded state (one
//! thread at a time; they may move between threads), entered through a busy flag that turns a
//! concurrent call into `TOPOLOC_ERR_CONCURRENT_USE` (`handles.rs`).

#![deny(missing_docs)]
#![allow(non_camel_case_types)]
// These are C entry points: their pointer contracts are documented per function in the header
// and checked (NULL, sizes) by the helpers in boundary.rs; marking them `unsafe` would change
// nothing for C callers.
#![allow(clippy::not_unsafe_ptr_arg_deref)]

// Plumbing shared by the entry points (no `extern "C"` items).
mod boundary;
mod convert;
mod error;
mod handles;
mod status;
mod versioned;

// The entry points, declared in the order include/topoloc.h presents them (cbindgen follows
// this order): versions and errors, host logging, maps, map keypoints, the localizer, builders, describers, skeleton graphs, loop
// closure and its image keyframes, trajectory metrics.
mod version;

mod logging;

mod map;

mod map_keypoints;

mod localizer;

mod builder;

mod images;

mod describer;

mod skeleton;

mod loops;

mod loop_images;

mod trajectory;

mod option_defaults;

pub use builder::*;
pub use describer::*;
pub use images::*;
pub use localizer::*;
pub use logging::*;
pub use loop_images::*;
pub use loops::*;
pub use map::*;
pub use map_keypoints::*;
pub use option_defaults::{option_defaults, option_ranges, OptionDefault, OptionRange};
pub use skeleton::*;
pub use status::topoloc_status;
pub use trajectory::*;
pub use version::*;

#[cfg(test)]
mod tests;
