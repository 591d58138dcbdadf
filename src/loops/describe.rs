//! Keyframe images to what a [`super::LoopDetector`] takes: the global descriptor and the
//! local features, from one pass of the describer when the features are its CNN's dense cells
//! (never two forward passes for one image), else from a keypoint detector (XFeat, ORB).

use super::error::LoopsError;
use super::hints::KeyframeFeatures;
use crate::describe::{BackendKind, Describer};
use crate::image::ImageView;
use crate::profile::{measure, Stage};
use crate::verify::{
    cells_from_map, FeatureDetector, FeatureKind, XFeatOptions, CELL_TAP, DEFAULT_CELLS,
    DEFAULT_KEYPOINTS,
};

/// The local features a keyframe describer extracts by default, in every layer (the CLI's
/// `loops`, the C keyframe describer's options, C++ and Python): XFeat, whose hints carry a
/// pose where intrinsics are given (BENCHMARKS.md says which data chose it).
pub const DEFAULT_LOOP_FEATURES: FeatureKind = FeatureKind::XFeat;

/// Describes keyframe images: a map's describer (the global descriptor the database compares)
/// and local features of one kind ([`DEFAULT_CELLS`] dense cells, or [`DEFAULT_KEYPOINTS`]
/// keypoints). Not `Sync`: one per detector thread.
pub struct KeyframeDescriber {
    describer: Describer,
    features: LocalFeatures,
}

/// Where the local features come from.
enum LocalFeatures {
    /// The describer's own feature map (ONNX backend).
    Cells,
    /// A keypoint detector run on the image.
    Detector(FeatureDetector),
}

impl KeyframeDescriber {
    /// `describer` with local features of `kind`; `xfeat` locates the XFeat model for
    /// [`FeatureKind::XFeat`]. Fails with [`LoopsError::InvalidOption`] for cells on a
    /// describer without a CNN (VLAD), and with [`LoopsError::Vision`] when the detector cannot
    /// be loaded (a missing XFeat model names what to install).
    pub fn new(
        describer: Describer,
        kind: FeatureKind,
        xfeat: &XFeatOptions,
    ) -> Result<Self, LoopsError> {
        let features = match kind {
            FeatureKind::Cells if describer.model().spec.kind() != BackendKind::Onnx => {
                return Err(LoopsError::InvalidOption(format!(
                    "dense cells come from the describer's CNN feature map: the describer is {}, they need ONNX (or choose XFeat or ORB keypoints)",
                    describer.model().spec.kind().name()
                )))
            }
            FeatureKind::Cells => LocalFeatures::Cells,
            kind => {
                LocalFeatures::Detector(FeatureDetector::new(kind, DEFAULT_KEYPOINTS, xfeat)?)
            }
        };
        Ok(Self {
            describer,
            features,
        })
    }

    /// The kind of local features it gives.
    pub fn kind(&self) -> FeatureKind {
        match &self.features {
            LocalFeatures::Cells => FeatureKind::Cells,
            LocalFeatures::Detector(d) => d.kind(),
        }
    }

    /// The describer of the global descriptor.
    pub fn describer(&self) -> &Describer {
        &self.describer
    }

    /// Describes `image`: its global descriptor into `descriptor` (the describer's D values)
    /// and its local features (no scene points: attach the host's with
    /// [`KeyframeFeatures::camera_points`]). Fails with [`LoopsError::Vision`] on an image the
    /// backend cannot use (invalid, uninformative).
    pub fn describe(
        &mut self,
        image: &ImageView<'_>,
        descriptor: &mut Vec<f32>,
    ) -> Result<KeyframeFeatures, LoopsError> {
        let keypoints = match &mut self.features {
            LocalFeatures::Cells => {
                let tap = self
                    .describer
                    .describe_with_tap(image, descriptor, CELL_TAP)?;
                measure(Stage::LocalFeatures, || {
                    cells_from_map(
                        &tap.values,
                        [tap.channels, tap.height, tap.width],
                        tap.cell_size,
                        DEFAULT_CELLS,
                    )
                })?
            }
            LocalFeatures::Detector(detector) => {
                self.describer.describe(image, descriptor)?;
                detector.detect(image)?
            }
        };
        Ok(KeyframeFeatures {
            keypoints,
            camera_points: None,
        })
    }
}
