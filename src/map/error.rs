//! Errors of map building, loading and saving.

use super::{PlaceId, ViewId};
use crate::descriptor::{DescriptorError, DescriptorIdentity, ExpectedDescriptor, IdentityError};
use std::path::PathBuf;

/// Everything that can go wrong while building, loading, saving or querying a map.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// Reading or writing a file failed.
    #[error("I/O error on '{path}': {source}")]
    Io {
        /// File involved.
        path: PathBuf,
        /// Underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not a topoloc map at all (not safetensors, or safetensors without topoloc metadata).
    #[error("not a topoloc map: {0}")]
    NotAMap(String),
    /// The file starts like a topoloc map but ends early.
    #[error("truncated map file: {0}")]
    Truncated(String),
    /// The file is damaged: bad checksum, inconsistent arrays, invalid values.
    #[error("corrupt map file: {0}")]
    Corrupt(String),
    /// The file was written by a newer, incompatible format version.
    #[error("map format version {found} is newer than the supported {supported}; upgrade topoloc")]
    UnsupportedVersion {
        /// Version in the file.
        found: String,
        /// Newest major version this build reads.
        supported: u32,
    },
    /// The map was built with another descriptor than the caller uses.
    #[error("descriptor mismatch: the map holds {map}, the caller expects {expected}")]
    DescriptorMismatch {
        /// The map's descriptor.
        map: DescriptorIdentity,
        /// What the caller asked for.
        expected: ExpectedDescriptor,
    },
    /// A map must have at least one place.
    #[error("the map has no places")]
    EmptyMap,
    /// A place index out of range.
    #[error("unknown place {place}: the map has {places} places")]
    UnknownPlace {
        /// Index given.
        place: PlaceId,
        /// Places in the map.
        places: usize,
    },
    /// A view index out of range.
    #[error("unknown view {view}: the map has {views} views")]
    UnknownView {
        /// Index given.
        view: ViewId,
        /// Views in the map.
        views: usize,
    },
    /// A descriptor given to the builder is unusable.
    #[error("bad descriptor: {0}")]
    Descriptor(#[from] DescriptorError),
    /// A number given to the builder (position, pose, weight) is NaN or infinite.
    #[error("non-finite value: {0}")]
    NonFinite(String),
    /// An argument is out of its valid range.
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// The map's contents are inconsistent (found while building or validating).
    #[error("invalid map: {0}")]
    Invalid(String),
}

impl From<IdentityError> for MapError {
    fn from(e: IdentityError) -> Self {
        match e {
            IdentityError::Invalid(msg) => MapError::InvalidArgument(msg),
            IdentityError::Mismatch { map, expected } => {
                MapError::DescriptorMismatch { map, expected }
            }
        }
    }
}
