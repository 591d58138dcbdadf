//! Errors on their way out through the C ABI: each Rust error kind maps to one status code by
//! its variant (never by its text), with the message for `topoloc_last_error_message`.

use super::status::topoloc_status::{self, *};
use crate::build::ImageMapError;
use crate::descriptor::{DescriptorError, IdentityError};
use crate::errors::VisionError;
use crate::eval::TrajectoryError;
use crate::localize::{GrnnError, LocalizeError, TimestampError};
use crate::loops::LoopsError;
use crate::map::MapError;
use crate::skeleton::SkeletonError;

/// An error on its way out through the C ABI: a status and the message for
/// `topoloc_last_error_message`.
#[derive(Debug)]
pub(crate) struct FfiError {
    pub status: topoloc_status,
    pub message: String,
}

impl FfiError {
    pub fn new(status: topoloc_status, message: impl Into<String>) -> Self {
        Self {
            status,
            message: message.into(),
        }
    }

    pub fn null(name: &str) -> Self {
        Self::new(
            TOPOLOC_ERR_NULL_ARGUMENT,
            format!("argument '{name}' is NULL"),
        )
    }

    pub fn invalid(message: impl Into<String>) -> Self {
        Self::new(TOPOLOC_ERR_INVALID_ARGUMENT, message)
    }

    pub fn invalid_option(message: impl Into<String>) -> Self {
        Self::new(TOPOLOC_ERR_INVALID_OPTION, message)
    }

    /// `name` is in use by another call (another thread, or a callback re-entering it).
    pub fn concurrent_use(name: &str) -> Self {
        Self::new(
            TOPOLOC_ERR_CONCURRENT_USE,
            format!(
                "'{name}' is in use by another call (another thread, or a callback re-entering \
                 it): use it from one thread at a time"
            ),
        )
    }
}

impl From<DescriptorError> for FfiError {
    fn from(e: DescriptorError) -> Self {
        let status = match e {
            DescriptorError::Dimension { .. } => TOPOLOC_ERR_DIMENSION_MISMATCH,
            DescriptorError::NonFinite => TOPOLOC_ERR_NON_FINITE,
            DescriptorError::Zero => TOPOLOC_ERR_ZERO_DESCRIPTOR,
        };
        Self::new(status, e.to_string())
    }
}

impl From<MapError> for FfiError {
    fn from(e: MapError) -> Self {
        let status = match &e {
            MapError::Io { .. } => TOPOLOC_ERR_IO,
            MapError::NotAMap(_) => TOPOLOC_ERR_NOT_A_MAP,
            MapError::Truncated(_) => TOPOLOC_ERR_TRUNCATED,
            MapError::Corrupt(_) => TOPOLOC_ERR_CORRUPT,
            MapError::UnsupportedVersion { .. } => TOPOLOC_ERR_UNSUPPORTED_VERSION,
            MapError::DescriptorMismatch { .. } => TOPOLOC_ERR_DESCRIPTOR_MISMATCH,
            MapError::EmptyMap => TOPOLOC_ERR_EMPTY_MAP,
            MapError::UnknownPlace { .. } => TOPOLOC_ERR_UNKNOWN_PLACE,
            MapError::UnknownView { .. } => TOPOLOC_ERR_UNKNOWN_VIEW,
            MapError::Descriptor(d) => return FfiError::from(d.clone()),
            MapError::NonFinite(_) => TOPOLOC_ERR_NON_FINITE,
            MapError::InvalidArgument(_) => TOPOLOC_ERR_INVALID_ARGUMENT,
            MapError::Invalid(_) => TOPOLOC_ERR_INVALID_MAP,
        };
        Self::new(status, e.to_string())
    }
}

impl From<IdentityError> for FfiError {
    fn from(e: IdentityError) -> Self {
        MapError::from(e).into()
    }
}

impl From<SkeletonError> for FfiError {
    fn from(e: SkeletonError) -> Self {
        match e {
            SkeletonError::InvalidArgument(_) => Self::invalid(e.to_string()),
        }
    }
}

impl From<LocalizeError> for FfiError {
    fn from(e: LocalizeError) -> Self {
        match e {
            LocalizeError::Descriptor(d) => d.into(),
            LocalizeError::Map(m) => m.into(),
            LocalizeError::InvalidOption(_) => Self::new(TOPOLOC_ERR_INVALID_OPTION, e.to_string()),
            LocalizeError::Timestamp(TimestampError::NonFinite(_)) => {
                Self::new(TOPOLOC_ERR_NON_FINITE, e.to_string())
            }
            LocalizeError::Timestamp(TimestampError::Backwards { .. }) => {
                Self::new(TOPOLOC_ERR_TIMESTAMP, e.to_string())
            }
            LocalizeError::Odometry(_) => Self::new(TOPOLOC_ERR_NON_FINITE, e.to_string()),
            LocalizeError::Describe(d) => d.into(),
            LocalizeError::NoDescriber(_) => Self::new(TOPOLOC_ERR_NO_DESCRIBER, e.to_string()),
            // verify_candidates > 0 on a map without keypoints.
            LocalizeError::Verification(_) | LocalizeError::Metric(_) => {
                Self::new(TOPOLOC_ERR_INVALID_OPTION, e.to_string())
            }
            LocalizeError::Grnn(GrnnError::Unavailable(v)) => v.into(),
            // A file that is not ONNX, or an ONNX file of another contract.
            LocalizeError::Grnn(
                GrnnError::NotOnnx(_) | GrnnError::Contract(_) | GrnnError::Run(_),
            ) => Self::new(TOPOLOC_ERR_MODEL, e.to_string()),
            // The map does not suit the model.
            LocalizeError::Grnn(GrnnError::GraphTooLarge { .. } | GrnnError::NoGraph(_)) => {
                Self::new(TOPOLOC_ERR_INVALID_OPTION, e.to_string())
            }
        }
    }
}

impl From<VisionError> for FfiError {
    fn from(e: VisionError) -> Self {
        let status = match &e {
            VisionError::InvalidImage(_) => TOPOLOC_ERR_INVALID_IMAGE,
            VisionError::InvalidArgument(_) => TOPOLOC_ERR_INVALID_ARGUMENT,
            VisionError::BackendUnavailable { .. } => TOPOLOC_ERR_BACKEND_UNAVAILABLE,
            VisionError::Model(_) | VisionError::OpenCv(_) => TOPOLOC_ERR_MODEL,
            VisionError::Uninformative(_) => TOPOLOC_ERR_UNINFORMATIVE_IMAGE,
            VisionError::Mismatch(_) => TOPOLOC_ERR_DESCRIPTOR_MISMATCH,
        };
        Self::new(status, e.to_string())
    }
}

impl From<ImageMapError> for FfiError {
    fn from(e: ImageMapError) -> Self {
        let message = e.to_string();
        let status = match e {
            ImageMapError::Image { error, .. } | ImageMapError::Describe(error) => {
                FfiError::from(error).status
            }
            ImageMapError::Map(m) => FfiError::from(m).status,
            ImageMapError::Cancelled => TOPOLOC_ERR_CANCELLED,
        };
        Self::new(status, message)
    }
}

impl From<LoopsError> for FfiError {
    fn from(e: LoopsError) -> Self {
        match e {
            LoopsError::Descriptor(d) => d.into(),
            LoopsError::Map(m) => m.into(),
            LoopsError::Vision(v) => v.into(),
            LoopsError::InvalidOption(_) => Self::new(TOPOLOC_ERR_INVALID_OPTION, e.to_string()),
            LoopsError::NonFinite(_) => Self::new(TOPOLOC_ERR_NON_FINITE, e.to_string()),
            LoopsError::DuplicateId(_)
            | LoopsError::OutOfOrder(_)
            | LoopsError::UnknownKeyframe(_)
            | LoopsError::InvalidKeyframe(_) => Self::invalid(e.to_string()),
        }
    }
}

impl From<TrajectoryError> for FfiError {
    fn from(e: TrajectoryError) -> Self {
        match e {
            TrajectoryError::Io(_) => Self::new(TOPOLOC_ERR_IO, e.to_string()),
            TrajectoryError::InvalidOption(_) => {
                Self::new(TOPOLOC_ERR_INVALID_OPTION, e.to_string())
            }
            TrajectoryError::Parse { .. }
            | TrajectoryError::UnknownFormat
            | TrajectoryError::Invalid(_)
            | TrajectoryError::TooFewPairs(_)
            | TrajectoryError::Degenerate => Self::invalid(e.to_string()),
        }
    }
}
