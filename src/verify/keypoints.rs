//! ORB keypoints of one image, and the per-view store a map keeps them in.

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

/// Keypoints of one image: pixel positions (x right, y down, in the image as given) and their
/// ORB descriptors, in the same order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Keypoints {
    /// Pixel positions.
    pub points: Vec<[f32; 2]>,
    /// ORB descriptors, one per point.
    pub descriptors: Vec<Descriptor>,
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
            descriptors: &self.descriptors,
        }
    }
}

/// Borrowed keypoints (of a query, or of a map view from [`ViewKeypoints::view`]).
#[derive(Clone, Copy, Debug)]
pub struct KeypointsRef<'a> {
    /// Pixel positions.
    pub points: &'a [[f32; 2]],
    /// ORB descriptors, one per point.
    pub descriptors: &'a [Descriptor],
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
    /// Images narrower or lower than [`MIN_ORB_SIDE`] are refused with
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
            descriptors: bytes
                .chunks_exact(DESCRIPTOR_BYTES)
                .map(|c| c.try_into().expect("32 bytes"))
                .collect(),
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
    descriptors: Vec<Descriptor>,
    /// Map-frame position of each keypoint's scene point; NaN where unknown.
    world_points: Option<Vec<[f32; 3]>>,
}

impl ViewKeypoints {
    /// Concatenates the keypoints of each view, in view order.
    pub fn from_views<'a>(views: impl IntoIterator<Item = &'a Keypoints>) -> Self {
        let mut store = Self {
            offsets: vec![0],
            ..Self::default()
        };
        for view in views {
            store.points.extend_from_slice(&view.points);
            store.descriptors.extend_from_slice(&view.descriptors);
            store.offsets.push(store.points.len() as u64);
        }
        store
    }

    /// Rebuilds a store from its arrays (as a map file holds them); fails unless `offsets`
    /// starts at 0, never decreases and ends at the number of points, no view has more than
    /// [`MAX_KEYPOINTS`], points and descriptors have the same count, and every position is
    /// finite and inside the largest accepted image (0..=[`MAX_IMAGE_SIDE`] on both axes).
    pub fn from_parts(
        offsets: Vec<u64>,
        points: Vec<[f32; 2]>,
        descriptors: Vec<Descriptor>,
    ) -> Result<Self, String> {
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
            descriptors: &self.descriptors[range],
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
    pub fn descriptors(&self) -> &[Descriptor] {
        &self.descriptors
    }
}
