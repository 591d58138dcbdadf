//! Map builders that sit above the map: from an ordered keyframe sequence ([`from_keyframes`],
//! places by spacing and appearance novelty), from images ([`build_from_images`]: describe,
//! fit the describer model, assemble), and the TUM trajectory reader that feeds them poses.
//! (Graphs from occupancy grids are [`crate::skeleton`]'s.)

mod images;
mod keyframes;
mod tum;

pub use images::{
    build_from_images, BuildStage, ImageLayout, ImageMapError, ImageMapOptions, ImageMapReport,
    ImageSource, PlaceLayout, DEFAULT_MAP_FEATURES,
};
pub use keyframes::{from_keyframes, Keyframe, KeyframeOptions};
pub use tum::{parse_tum, read_tum, TimedPose};
