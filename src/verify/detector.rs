//! One detector over the local-feature kinds a map can store, so builders and localizers pick
//! the kind by value (a map's stored kind, a build option) rather than by type.

use super::keypoints::{FeatureKind, KeypointDetector, Keypoints};
use super::xfeat::{XFeatDetector, XFeatOptions};
use crate::errors::VisionError;
use crate::image::ImageView;
use crate::profile::{measure, Stage};

/// A loaded detector of one feature kind; one per thread.
pub enum FeatureDetector {
    /// OpenCV ORB.
    Orb(KeypointDetector),
    /// XFeat by ONNX Runtime.
    XFeat(Box<XFeatDetector>),
}

impl FeatureDetector {
    /// A detector of `kind` keeping at most `max_keypoints` per image; `xfeat` says where the
    /// XFeat network is (unused for ORB). Errors as [`KeypointDetector::new`] and
    /// [`XFeatDetector::new`]; dense cells, made by the describer, are an invalid argument.
    pub fn new(
        kind: FeatureKind,
        max_keypoints: usize,
        xfeat: &XFeatOptions,
    ) -> Result<Self, VisionError> {
        Ok(match kind {
            FeatureKind::Orb => FeatureDetector::Orb(KeypointDetector::new(max_keypoints)?),
            FeatureKind::XFeat => {
                FeatureDetector::XFeat(Box::new(XFeatDetector::new(xfeat, max_keypoints)?))
            }
            FeatureKind::Cells => {
                return Err(VisionError::InvalidArgument(
                    "dense cells have no detector of their own: they come from the describer's forward pass (Describer::describe_with_tap, then cells_from_map)".into(),
                ))
            }
        })
    }

    /// The kind it detects.
    pub fn kind(&self) -> FeatureKind {
        match self {
            FeatureDetector::Orb(_) => FeatureKind::Orb,
            FeatureDetector::XFeat(_) => FeatureKind::XFeat,
        }
    }

    /// Detects and describes the keypoints of `image` (positions in the image as given).
    pub fn detect(&mut self, image: &ImageView<'_>) -> Result<Keypoints, VisionError> {
        measure(Stage::LocalFeatures, || match self {
            FeatureDetector::Orb(d) => d.detect(image),
            FeatureDetector::XFeat(d) => d.detect(image),
        })
    }
}
