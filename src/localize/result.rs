//! What a localizer is given and what it answers: one [`Frame`] in, one [`Localization`] (with
//! its ranked [`Candidate`]s and an optional [`PoseFix`]) out.

use crate::image::ImageView;
use crate::map::{PlaceId, ViewId};
use nalgebra::Isometry3;

/// One camera frame: a descriptor computed by the host, or an image the localizer describes.
#[derive(Clone, Debug, Default)]
pub struct Frame<'a> {
    /// Time in seconds; must not decrease in filter mode.
    pub timestamp: f64,
    /// Global descriptor of the frame (D values; normalised internally). When empty, `image` is
    /// described with the map's own backend; when given, it is used and `image` is not described.
    pub descriptor: &'a [f32],
    /// The camera image, described when `descriptor` is empty (needs a localizer made with
    /// [`Localizer::with_describer`](crate::Localizer::with_describer)).
    pub image: Option<ImageView<'a>>,
    /// Motion since the previous frame, `previous_T_current`, from the host's odometry.
    pub odometry: Option<Isometry3<f64>>,
}

/// One ranked hypothesis.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Candidate {
    /// Place.
    pub place: PlaceId,
    /// Best-matching view of the place.
    pub view: ViewId,
    /// Posterior probability of the place.
    pub probability: f32,
    /// Cosine similarity of the query to `view`.
    pub similarity: f32,
    /// Whether the place was verified geometrically in this frame.
    pub verified: bool,
    /// Geometric inliers between the query and `view` (0 unless `verified`); with
    /// [`crate::verify::VerificationScore::Spatial`], the s-GC agreeing-match count instead.
    pub inliers: u32,
}

/// A metric pose of the camera found against one map view (see [`crate::verify::locate`]):
/// what a pose graph adds as a loop-closure constraint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseFix {
    /// The view the camera was placed against.
    pub view: ViewId,
    /// The camera in the map frame, `world_T_optical` (optical axes: z forward, x right, y
    /// down).
    pub world_t_optical: Isometry3<f64>,
    /// Keypoint pairs consistent with the pose.
    pub inliers: u32,
}

/// The answer for one frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Localization {
    /// 0-based count of frames processed since creation or reset.
    pub frame_index: u64,
    /// Most probable place.
    pub place: PlaceId,
    /// Best-matching view of that place.
    pub view: ViewId,
    /// Posterior probability that the robot is at `place` (0..1): the place belief times the
    /// probability of being on the map.
    pub confidence: f32,
    /// Cosine similarity of the query to `view`.
    pub similarity: f32,
    /// True when the robot is more likely off the map than on it.
    pub off_map: bool,
    /// Posterior probability that the robot is off the map.
    pub off_map_probability: f32,
    /// Top-k places by posterior, best first; `candidates[0]` is `place`.
    pub candidates: Vec<Candidate>,
    /// The camera's metric pose against the best-verified view, when verification has a camera
    /// ([`VerificationOptions::camera`](crate::verify::VerificationOptions::camera)), the map stores keypoint scene points and enough
    /// keypoints agree on one pose.
    pub pose_fix: Option<PoseFix>,
}
