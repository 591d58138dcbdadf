//! Keypoints of one image (ORB, or learned XFeat features), and the per-view store a map keeps
//! them in.

use crate::errors::VisionError;
use crate::image::{ImageView, MAX_IMAGE_SIDE};
use opencv::core::{KeyPoint, Mat, Ptr, Size, Vector};
use opencv::features2d::{ORB_ScoreType, ORB};
use opencv::prelude::*;

/// Bytes of one ORB descriptor (256 binary tests).
pub const DESCRIPTOR_BYTES: usize = 32;
/// Most keypoints a detector may keep per image.
pub const MAX_KEYPOINTS: usize = 5000;

/// Smallest image width or height ORB can take. The detector builds an 8-level pyramid with
/// scale factor 1.2; level 7 is `round(side / 1.2^7) = round(side / 3.58)` pixels, which is 0
/// for a 1-pixel side, and OpenCV's resize then fails an assertion (`inv_scale_x > 0`).
/// Measured: every side of 2 pixels or more (2 x 2 up to 2 x 8192) is accepted, and images
/// narrower than 2 x 31 + 1 (twice the edge threshold) simply give no keypoints.
pub const MIN_ORB_SIDE: u32 = 2;

/// One ORB descriptor.
pub type Descriptor = [u8; DESCRIPTOR_BYTES];
/// Dimensions of one XFeat descriptor.
pub const XFEAT_DIM: usize = 64;
/// One XFeat descriptor: the unit 64-vector quantised as `round(127 x d)` (64 bytes).
pub type XFeatDescriptor = [i8; XFEAT_DIM];
/// Channels of one dense cell: MobileNetV2 block 13 (stride 16), the default ONNX model's `f13`.
pub const CELL_DIM: usize = 96;
/// One dense-cell descriptor, quantised as `round(127 x unit vector)` (96 bytes).
pub type CellDescriptor = [i8; CELL_DIM];

/// Which local features a set of keypoints carries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum FeatureKind {
    /// ORB: FAST corners with 256-bit binary descriptors, matched by Hamming distance.
    #[default]
    Orb,
    /// XFeat (CVPR 2024): learned keypoints with 64-d descriptors, matched by cosine.
    XFeat,
    /// Dense cells of the describer's own CNN (MobileNetV2 block 13, stride 16), from the
    /// forward pass that makes the global descriptor (the Patch-NetVLAD idea); matched by
    /// cosine. Positions are cell centres, so they verify places but are too coarse for poses.
    Cells,
}

impl FeatureKind {
    /// Lower-case name (`orb`, `xfeat`), as the CLI and reports spell it.
    pub fn name(self) -> &'static str {
        match self {
            FeatureKind::Orb => "orb",
            FeatureKind::XFeat => "xfeat",
            FeatureKind::Cells => "cells",
        }
    }

    /// The default [`super::VerificationOptions::off_map_inliers`] for maps of this kind: 26
    /// for XFeat and cells (chosen on generated train worlds with XFeat, BENCHMARKS.md,
    /// "Off-map flags"); 0 (appearance decides) for ORB, whose inliers do not tell right
    /// places from wrong ones on real images.
    pub fn default_off_map_inliers(self) -> f32 {
        match self {
            FeatureKind::Orb => 0.0,
            FeatureKind::XFeat | FeatureKind::Cells => 26.0,
        }
    }
}

/// The descriptors of a set of keypoints, all of one kind, one per point.
#[derive(Clone, Debug, PartialEq)]
pub enum Descriptors {
    /// ORB descriptors.
    Orb(Vec<Descriptor>),
    /// Quantised XFeat descriptors.
    XFeat(Vec<XFeatDescriptor>),
    /// Quantised dense-cell descriptors.
    Cells(Vec<CellDescriptor>),
}

impl Default for Descriptors {
    fn default() -> Self {
        Descriptors::Orb(Vec::new())
    }
}

impl Descriptors {
    /// No descriptors of `kind`.
    pub fn empty(kind: FeatureKind) -> Self {
        match kind {
            FeatureKind::Orb => Descriptors::Orb(Vec::new()),
            FeatureKind::XFeat => Descriptors::XFeat(Vec::new()),
            FeatureKind::Cells => Descriptors::Cells(Vec::new()),
        }
    }

    /// The kind of feature.
    pub fn kind(&self) -> FeatureKind {
        self.as_ref().kind()
    }

    /// Number of descriptors.
    pub fn len(&self) -> usize {
        self.as_ref().len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// A borrowed view.
    pub fn as_ref(&self) -> DescriptorsRef<'_> {
        match self {
            Descriptors::Orb(d) => DescriptorsRef::Orb(d),
            Descriptors::XFeat(d) => DescriptorsRef::XFeat(d),
            Descriptors::Cells(d) => DescriptorsRef::Cells(d),
        }
    }

    /// Appends `more`; fails (and appends nothing) when it is of another kind.
    pub fn extend_from(&mut self, more: DescriptorsRef<'_>) -> Result<(), String> {
        match (self, more) {
            (Descriptors::Orb(d), DescriptorsRef::Orb(m)) => d.extend_from_slice(m),
            (Descriptors::XFeat(d), DescriptorsRef::XFeat(m)) => d.extend_from_slice(m),
            (Descriptors::Cells(d), DescriptorsRef::Cells(m)) => d.extend_from_slice(m),
            (own, more) => {
                return Err(format!(
                    "{} descriptors cannot join {} descriptors",
                    more.kind().name(),
                    own.kind().name()
                ))
            }
        }
        Ok(())
    }

    /// The descriptors' bytes, row after row, as a map file holds them (`i8` as two's
    /// complement).
    pub fn to_bytes(&self) -> std::borrow::Cow<'_, [u8]> {
        match self {
            Descriptors::Orb(d) => std::borrow::Cow::Borrowed(d.as_flattened()),
            Descriptors::XFeat(d) => d.as_flattened().iter().map(|&v| v as u8).collect(),
            Descriptors::Cells(d) => d.as_flattened().iter().map(|&v| v as u8).collect(),
        }
    }

    /// Bytes of one descriptor of this kind.
    pub fn row_bytes(&self) -> usize {
        match self {
            Descriptors::Orb(_) => DESCRIPTOR_BYTES,
            Descriptors::XFeat(_) => XFEAT_DIM,
            Descriptors::Cells(_) => CELL_DIM,
        }
    }
}

impl From<Vec<Descriptor>> for Descriptors {
    fn from(d: Vec<Descriptor>) -> Self {
        Descriptors::Orb(d)
    }
}

impl From<Vec<XFeatDescriptor>> for Descriptors {
    fn from(d: Vec<XFeatDescriptor>) -> Self {
        Descriptors::XFeat(d)
    }
}

/// Borrowed descriptors of one kind.
#[derive(Clone, Copy, Debug)]
pub enum DescriptorsRef<'a> {
    /// ORB descriptors.
    Orb(&'a [Descriptor]),
    /// Quantised XFeat descriptors.
    XFeat(&'a [XFeatDescriptor]),
    /// Quantised dense-cell descriptors.
    Cells(&'a [CellDescriptor]),
}

impl<'a> DescriptorsRef<'a> {
    /// The kind of feature.
    pub fn kind(self) -> FeatureKind {
        match self {
            DescriptorsRef::Orb(_) => FeatureKind::Orb,
            DescriptorsRef::XFeat(_) => FeatureKind::XFeat,
            DescriptorsRef::Cells(_) => FeatureKind::Cells,
        }
    }

    /// Number of descriptors.
    pub fn len(self) -> usize {
        match self {
            DescriptorsRef::Orb(d) => d.len(),
            DescriptorsRef::XFeat(d) => d.len(),
            DescriptorsRef::Cells(d) => d.len(),
        }
    }

    /// True when there are none.
    pub fn is_empty(self) -> bool {
        self.len() == 0
    }

    /// An owned copy.
    pub fn to_owned(self) -> Descriptors {
        match self {
            DescriptorsRef::Orb(d) => Descriptors::Orb(d.to_vec()),
            DescriptorsRef::XFeat(d) => Descriptors::XFeat(d.to_vec()),
            DescriptorsRef::Cells(d) => Descriptors::Cells(d.to_vec()),
        }
    }

    /// The descriptors in `range` (which must lie inside).
    pub fn slice(self, range: std::ops::Range<usize>) -> DescriptorsRef<'a> {
        match self {
            DescriptorsRef::Orb(d) => DescriptorsRef::Orb(&d[range]),
            DescriptorsRef::XFeat(d) => DescriptorsRef::XFeat(&d[range]),
            DescriptorsRef::Cells(d) => DescriptorsRef::Cells(&d[range]),
        }
    }
}

/// Keypoints of one image: pixel positions (x right, y down, in the image as given) and their
/// descriptors, in the same order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Keypoints {
    /// Pixel positions.
    pub points: Vec<[f32; 2]>,
    /// Descriptors, one per point.
    pub descriptors: Descriptors,
}

impl Keypoints {
    /// Number of keypoints.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True without keypoints (a blank or featureless image).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// A borrowed view of the keypoints.
    pub fn as_ref(&self) -> KeypointsRef<'_> {
        KeypointsRef {
            points: &self.points,
            descriptors: self.descriptors.as_ref(),
        }
    }
}

/// Borrowed keypoints (of a query, or of a map view from [`ViewKeypoints::view`]).
#[derive(Clone, Copy, Debug)]
pub struct KeypointsRef<'a> {
    /// Pixel positions.
    pub points: &'a [[f32; 2]],
    /// Descriptors, one per point.
    pub descriptors: DescriptorsRef<'a>,
}

impl KeypointsRef<'_> {
    /// An owned copy.
    pub fn to_keypoints(self) -> Keypoints {
        Keypoints {
            points: self.points.to_vec(),
            descriptors: self.descriptors.to_owned(),
        }
    }
}

/// Detects ORB keypoints; one per thread (OpenCV detectors are not shared).
pub struct KeypointDetector {
    orb: Ptr<ORB>,
    max_keypoints: usize,
}

impl KeypointDetector {
    /// A detector keeping at most `max_keypoints` (1..=[`MAX_KEYPOINTS`]) per image.
    pub fn new(max_keypoints: usize) -> Result<Self, VisionError> {
        if !(1..=MAX_KEYPOINTS).contains(&max_keypoints) {
            return Err(VisionError::InvalidArgument(format!(
                "keypoints per image is {max_keypoints}, must lie in 1..={MAX_KEYPOINTS}"
            )));
        }
        // OpenCV's defaults except the count and a FAST threshold of 10 (not 20), so that dim
        // frames still give keypoints: scale 1.2 over 8 levels, edge and patch 31 pixels,
        // 2-point BRIEF tests (256 bits), Harris ranking.
        let orb = ORB::create(
            max_keypoints as i32,
            1.2,
            8,
            31,
            0,
            2,
            ORB_ScoreType::HARRIS_SCORE,
            31,
            10,
        )?;
        Ok(Self { orb, max_keypoints })
    }

    /// Most keypoints kept per image.
    pub fn max_keypoints(&self) -> usize {
        self.max_keypoints
    }

    /// Validates the image, converts it to grey at its own size, detects and describes.
    /// A featureless image gives no keypoints, not an error.
    /// Images narrower or lower than `MIN_ORB_SIDE` are refused with
    /// [`VisionError::InvalidImage`] before OpenCV sees them.
    pub fn detect(&mut self, image: &ImageView<'_>) -> Result<Keypoints, VisionError> {
        image.validate()?;
        if image.width < MIN_ORB_SIDE || image.height < MIN_ORB_SIDE {
            return Err(VisionError::InvalidImage(format!(
                "image is {}x{}: keypoint detection needs at least {MIN_ORB_SIDE} pixels on a side",
                image.width, image.height
            )));
        }
        let size = Size::new(image.width as i32, image.height as i32);
        let rgb = image.to_rgb_resized(size)?;
        let mut grey = Mat::default();
        opencv::imgproc::cvt_color_def(&rgb, &mut grey, opencv::imgproc::COLOR_RGB2GRAY)?;
        let mut found = Vector::<KeyPoint>::new();
        let mut descriptors = Mat::default();
        self.orb.detect_and_compute(
            &grey,
            &opencv::core::no_array(),
            &mut found,
            &mut descriptors,
            false,
        )?;
        if found.is_empty() || descriptors.empty() {
            return Ok(Keypoints::default());
        }
        let bytes = descriptors.data_bytes()?;
        if descriptors.cols() as usize != DESCRIPTOR_BYTES
            || bytes.len() != found.len() * DESCRIPTOR_BYTES
        {
            return Err(VisionError::Model(format!(
                "ORB gave {} descriptors of {} bytes for {} keypoints",
                descriptors.rows(),
                descriptors.cols(),
                found.len()
            )));
        }
        Ok(Keypoints {
            points: found.iter().map(|k| [k.pt().x, k.pt().y]).collect(),
            descriptors: Descriptors::Orb(
                bytes
                    .chunks_exact(DESCRIPTOR_BYTES)
                    .map(|c| c.try_into().expect("32 bytes"))
                    .collect(),
            ),
        })
    }
}

/// Keypoints of every view of a map, concatenated: view `v` owns entries
/// `offsets[v]..offsets[v + 1]`. Optionally, the map-frame 3D position of each keypoint's
/// scene point (from depth, a SLAM system's map points, or `topoloc-sim`'s ray caster), which
/// lets the localizer place the camera metrically against a view ([`crate::verify::locate`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewKeypoints {
    offsets: Vec<u64>,
    points: Vec<[f32; 2]>,
    descriptors: Descriptors,
    /// Map-frame position of each keypoint's scene point; NaN where unknown.
    world_points: Option<Vec<[f32; 3]>>,
}

impl ViewKeypoints {
    /// Concatenates the keypoints of each view, in view order; fails when a view holding
    /// keypoints has features of another kind than `kind` (views without any may be of any).
    pub fn from_views<'a>(
        kind: FeatureKind,
        views: impl IntoIterator<Item = &'a Keypoints>,
    ) -> Result<Self, String> {
        let mut store = Self {
            offsets: vec![0],
            descriptors: Descriptors::empty(kind),
            ..Self::default()
        };
        for (v, view) in views.into_iter().enumerate() {
            if view.points.len() != view.descriptors.len() {
                return Err(format!(
                    "view {v} has {} keypoints but {} descriptors",
                    view.points.len(),
                    view.descriptors.len()
                ));
            }
            if !view.is_empty() {
                store
                    .descriptors
                    .extend_from(view.descriptors.as_ref())
                    .map_err(|e| format!("view {v}: {e}"))?;
                store.points.extend_from_slice(&view.points);
            }
            store.offsets.push(store.points.len() as u64);
        }
        Ok(store)
    }

    /// Rebuilds a store from its arrays (as a map file holds them); fails unless `offsets`
    /// starts at 0, never decreases and ends at the number of points, no view has more than
    /// [`MAX_KEYPOINTS`], points and descriptors have the same count, and every position is
    /// finite and inside the largest accepted image (0..=[`MAX_IMAGE_SIDE`] on both axes).
    pub fn from_parts(
        offsets: Vec<u64>,
        points: Vec<[f32; 2]>,
        descriptors: impl Into<Descriptors>,
    ) -> Result<Self, String> {
        let descriptors = descriptors.into();
        if points.len() != descriptors.len() {
            return Err(format!(
                "{} keypoints but {} descriptors",
                points.len(),
                descriptors.len()
            ));
        }
        if offsets.first() != Some(&0) || offsets.last() != Some(&(points.len() as u64)) {
            return Err(format!(
                "keypoint offsets must run from 0 to {}, found {:?} .. {:?}",
                points.len(),
                offsets.first(),
                offsets.last()
            ));
        }
        if offsets.windows(2).any(|w| w[0] > w[1]) {
            return Err("keypoint offsets decrease".into());
        }
        if let Some(v) = offsets
            .windows(2)
            .position(|w| w[1] - w[0] > MAX_KEYPOINTS as u64)
        {
            return Err(format!(
                "view {v} has {} keypoints, more than {MAX_KEYPOINTS}",
                offsets[v + 1] - offsets[v]
            ));
        }
        let side = MAX_IMAGE_SIDE as f32;
        if let Some(i) = points
            .iter()
            .position(|p| !p.iter().all(|x| (0.0..=side).contains(x)))
        {
            return Err(format!(
                "keypoint {i} lies at {:?}: positions must be finite and in 0..={side}",
                points[i]
            ));
        }
        Ok(Self {
            offsets,
            points,
            descriptors,
            world_points: None,
        })
    }

    /// Attaches the map-frame 3D position of every keypoint's scene point (same order as the
    /// keypoints; all three coordinates NaN where unknown). Fails unless there is one per
    /// keypoint and each is either finite or all NaN.
    pub fn with_world_points(mut self, world_points: Vec<[f32; 3]>) -> Result<Self, String> {
        if world_points.len() != self.points.len() {
            return Err(format!(
                "{} keypoint world points for {} keypoints",
                world_points.len(),
                self.points.len()
            ));
        }
        let valid = |p: &[f32; 3]| p.iter().all(|x| x.is_finite()) || p.iter().all(|x| x.is_nan());
        if let Some(i) = world_points.iter().position(|p| !valid(p)) {
            return Err(format!(
                "keypoint world point {i} is {:?}: must be finite, or NaN in all three coordinates when unknown",
                world_points[i]
            ));
        }
        self.world_points = Some(world_points);
        Ok(self)
    }

    /// The map-frame positions of all keypoints' scene points, view after view, if stored.
    pub fn world_points(&self) -> Option<&[[f32; 3]]> {
        self.world_points.as_deref()
    }

    /// The map-frame scene points of view `view`'s keypoints (NaN where unknown), or `None`
    /// when out of range or not stored.
    pub fn view_world_points(&self, view: usize) -> Option<&[[f32; 3]]> {
        let (a, b) = (*self.offsets.get(view)?, *self.offsets.get(view + 1)?);
        Some(&self.world_points.as_ref()?[a as usize..b as usize])
    }

    /// Number of views.
    pub fn view_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Keypoints of all views together.
    pub fn total(&self) -> usize {
        self.points.len()
    }

    /// The keypoints of view `view`, or `None` when out of range.
    pub fn view(&self, view: usize) -> Option<KeypointsRef<'_>> {
        let (a, b) = (*self.offsets.get(view)?, *self.offsets.get(view + 1)?);
        let range = a as usize..b as usize;
        Some(KeypointsRef {
            points: &self.points[range.clone()],
            descriptors: self.descriptors.as_ref().slice(range),
        })
    }

    /// The offsets array (views + 1 entries).
    pub fn offsets(&self) -> &[u64] {
        &self.offsets
    }

    /// All positions, view after view.
    pub fn points(&self) -> &[[f32; 2]] {
        &self.points
    }

    /// All descriptors, view after view.
    pub fn descriptors(&self) -> &Descriptors {
        &self.descriptors
    }

    /// The kind of features stored.
    pub fn kind(&self) -> FeatureKind {
        self.descriptors.kind()
    }
}
