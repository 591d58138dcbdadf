//! Map capture: at each place of a graph, render views turned evenly in yaw (the seed's four
//! micro nodes at 0, 90, 180 and 270 degrees) and build a topoloc map from them with a
//! descriptor backend.
//!
//! View `j` of place `i` is the map's view `views_per_place * i + j`, taken at the place's
//! position with yaw `j * 360 / views_per_place` degrees and no pitch. Rendering runs in parallel
//! over views (rayon); each view's noise seed is derived from the capture seed and its index, so
//! a capture is deterministic.

use crate::camera::{pose, Intrinsics, Pose};
use crate::render::{Condition, Image, RenderError, Renderer};
use nalgebra::Point3;
use rayon::prelude::*;
use std::f64::consts::TAU;
use topoloc::describe::image::{ImageView, PixelFormat};
use topoloc::map::{
    build_from_images, BuildStage, ImageLayout, ImageMapError, ImageMapOptions, ImageMapReport,
    ImageSource, Map, PlaceLayout, TopoGraph,
};

/// How the views of a map are captured.
#[derive(Clone, Debug, PartialEq)]
pub struct CaptureOptions {
    /// Views per place, evenly turned in yaw, 1..=16. Default 4.
    pub views_per_place: usize,
    /// Camera of the views. Default: [`Intrinsics::default_camera`].
    pub intrinsics: Intrinsics,
    /// Lighting of the mapping run. Default: bright.
    pub condition: Condition,
    /// Seed of the sensor noise.
    pub seed: u64,
}

impl Default for CaptureOptions {
    fn default() -> Self {
        Self {
            views_per_place: 4,
            intrinsics: Intrinsics::default_camera(),
            condition: Condition::default(),
            seed: 0,
        }
    }
}

/// Errors of [`capture`].
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// An option is out of range (the message names it).
    #[error("capture: {0}")]
    InvalidArgument(String),
    /// Rendering a view failed (invalid intrinsics or condition).
    #[error(transparent)]
    Render(#[from] RenderError),
}

/// The captured views of a graph and where they were taken.
#[derive(Clone, Debug)]
pub struct Capture {
    /// One image per view, place-major.
    pub images: Vec<Image>,
    /// Places, edges, and each view's place and pose, ready for [`build_from_images`].
    pub layout: PlaceLayout,
}

/// Yaw of view `j` of `views_per_place`, radians.
pub fn view_yaw(j: usize, views_per_place: usize) -> f64 {
    TAU * j as f64 / views_per_place as f64
}

/// The poses of the views of a place at `position`.
pub fn view_poses(position: Point3<f64>, views_per_place: usize) -> Vec<Pose> {
    (0..views_per_place)
        .map(|j| pose(position, view_yaw(j, views_per_place), 0.0))
        .collect()
}

/// Renders the views of every place of `graph`. Fails for invalid intrinsics or condition, or a
/// view count outside 1..=16 (the error names the field).
pub fn capture(
    renderer: &Renderer,
    graph: &TopoGraph,
    options: &CaptureOptions,
) -> Result<Capture, CaptureError> {
    if !(1..=16).contains(&options.views_per_place) {
        return Err(CaptureError::InvalidArgument(format!(
            "views_per_place is {}, must lie in 1..=16",
            options.views_per_place
        )));
    }
    let views: Vec<(u32, Pose)> = graph
        .places
        .iter()
        .enumerate()
        .flat_map(|(i, place)| {
            view_poses(place.position, options.views_per_place)
                .into_iter()
                .map(move |p| (i as u32, p))
        })
        .collect();
    let images = views
        .par_iter()
        .enumerate()
        .map(|(index, (_, pose))| {
            renderer.try_render(
                pose,
                &options.intrinsics,
                &options.condition,
                options.seed.wrapping_add(index as u64),
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let layout = PlaceLayout {
        positions: graph.places.iter().map(|p| p.position).collect(),
        edges: graph.edges.iter().map(|e| (e.a, e.b)).collect(),
        views,
    };
    Ok(Capture { images, layout })
}

/// A packed RGB view of a rendered image, for the library's describers.
pub fn image_view(image: &Image) -> ImageView<'_> {
    ImageView::packed(image.width, image.height, PixelFormat::Rgb8, &image.rgb)
}

/// Describes the captured views with `options.backend`, fits the describer on them and builds
/// the map on the capture's graph. `progress` is called as by [`build_from_images`].
pub fn build_map(
    capture: &Capture,
    options: &ImageMapOptions,
    progress: &mut dyn FnMut(BuildStage, usize, usize) -> bool,
) -> Result<(Map, ImageMapReport), ImageMapError> {
    let sources: Vec<ImageSource<'_>> = capture
        .images
        .iter()
        .map(|image| ImageSource::Pixels(image_view(image)))
        .collect();
    build_from_images(
        &sources,
        ImageLayout::Graph(&capture.layout),
        options,
        progress,
    )
}
