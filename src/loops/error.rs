//! Errors of the keyframe database. On any error the database is exactly what it was before
//! the call.

use crate::descriptor::DescriptorError;
use crate::errors::VisionError;
use crate::map::MapError;

/// What can go wrong when adding, querying, erasing or saving keyframes.
#[derive(Debug, thiserror::Error)]
pub enum LoopsError {
    /// An option is out of range; the message names it.
    #[error("invalid database option: {0}")]
    InvalidOption(String),
    /// The keyframe's or query's descriptor is unusable (length, NaN/Inf, zeros).
    #[error("bad descriptor: {0}")]
    Descriptor(#[from] DescriptorError),
    /// A keyframe with this id is in the database already.
    #[error("keyframe id {0} is in the database already")]
    DuplicateId(u64),
    /// Keyframes must come in order: ids increasing and timestamps not decreasing.
    #[error("keyframe out of order: {0}")]
    OutOfOrder(String),
    /// No keyframe with this id is in the database.
    #[error("no keyframe with id {0}")]
    UnknownKeyframe(u64),
    /// A timestamp or pose is NaN or infinite; the message names the field.
    #[error("non-finite value: {0}")]
    NonFinite(String),
    /// A keyframe's local features are unusable (counts, positions, kind, scene points); the
    /// message names the field.
    #[error("bad keyframe features: {0}")]
    InvalidKeyframe(String),
    /// Building, saving or reading the map the database is stored as failed.
    #[error(transparent)]
    Map(#[from] MapError),
    /// Describing a keyframe image failed ([`super::KeyframeDescriber`]): the image, the
    /// backend, or a missing model (the message names what to install).
    #[error(transparent)]
    Vision(#[from] VisionError),
}
