//! Map capture: at each place of a graph, render views turned evenly in yaw (the seed's four
//! micro nodes at 0, 90, 180 and 270 degrees) and build a topoloc map from them with a
//! descriptor backend.
//!
//! View `j` of place `i` is the map's view `views_per_place * i + j`, taken at the place's
//! position with yaw `j * 360 / views_per_place` degrees and no pitch. Optional ring points
//! around each place (`ring_radius_m`) add the same yaw views from there, as a mapping run gives
//! many keyframes per place; their views come after all the place-centre views, so the centre
//! views keep the ids above (the ones ground truth names). Rendering runs in parallel
//! over views (rayon); each view's noise seed is derived from the capture seed and its index, so
//! a capture is deterministic.

use crate::camera::{pose, Intrinsics, Pose};
use crate::render::{Condition, Image, RenderError, Renderer};
use nalgebra::Point3;
use rayon::prelude::*;
use std::f64::consts::TAU;
use topoloc::build::{
    build_from_images, BuildStage, ImageLayout, ImageMapError, ImageMapOptions, ImageMapReport,
    ImageSource, PlaceLayout,
};
use topoloc::image::{ImageView, PixelFormat};
use topoloc::map::Map;
use topoloc::skeleton::{OccupancyGrid, TopoGraph};

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
    /// Radius of the ring of extra capture points around each place, metres, 0..=5; 0 (the
    /// default) captures at the place only. A ring point is kept only when its voxel is free,
    /// the place is in its line of sight and no other place is nearer to it, so it stays in
    /// the place's own cell.
    pub ring_radius_m: f64,
    /// Points on the ring, evenly spaced starting 45 degrees off the x axis, 0..=16. Default 4.
    pub ring_points: usize,
}

impl Default for CaptureOptions {
    fn default() -> Self {
        Self {
            views_per_place: 4,
            intrinsics: Intrinsics::default_camera(),
            condition: Condition::default(),
            seed: 0,
            ring_radius_m: 0.0,
            ring_points: 4,
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

/// The extra capture points of place `i` of `positions`: `options.ring_points` points at
/// `options.ring_radius_m` around it, kept where free, in sight of the place and nearest to it.
fn ring_points(
    grid: &OccupancyGrid,
    positions: &[Point3<f64>],
    i: usize,
    options: &CaptureOptions,
) -> Vec<Point3<f64>> {
    if options.ring_radius_m <= 0.0 {
        return Vec::new();
    }
    let centre = positions[i];
    (0..options.ring_points)
        .map(|k| {
            let angle = TAU * (k as f64 + 0.5) / options.ring_points as f64;
            Point3::new(
                centre.x + options.ring_radius_m * angle.cos(),
                centre.y + options.ring_radius_m * angle.sin(),
                centre.z,
            )
        })
        .filter(|q| {
            let own = (q - centre).norm_squared();
            grid.segment_is_free(&centre, q)
                && positions
                    .iter()
                    .enumerate()
                    .all(|(j, p)| j == i || (q - p).norm_squared() > own)
        })
        .collect()
}

/// Renders the views of every place of `graph` in `grid` (the world the renderer draws; ring
/// points are checked against it). Fails for invalid intrinsics or condition, or a view count,
/// ring radius or ring point count out of range (the error names the field).
pub fn capture(
    renderer: &Renderer,
    grid: &OccupancyGrid,
    graph: &TopoGraph,
    options: &CaptureOptions,
) -> Result<Capture, CaptureError> {
    if !(1..=16).contains(&options.views_per_place) {
        return Err(CaptureError::InvalidArgument(format!(
            "views_per_place is {}, must lie in 1..=16",
            options.views_per_place
        )));
    }
    if !(options.ring_radius_m.is_finite() && (0.0..=5.0).contains(&options.ring_radius_m)) {
        return Err(CaptureError::InvalidArgument(format!(
            "ring_radius_m is {}, must lie in 0..=5",
            options.ring_radius_m
        )));
    }
    if options.ring_points > 16 {
        return Err(CaptureError::InvalidArgument(format!(
            "ring_points is {}, must lie in 0..=16",
            options.ring_points
        )));
    }
    let positions: Vec<Point3<f64>> = graph.places.iter().map(|p| p.position).collect();
    let at = |i: usize, point: Point3<f64>| {
        view_poses(point, options.views_per_place)
            .into_iter()
            .map(move |p| (i as u32, p))
    };
    let centre_views = positions.iter().enumerate().flat_map(|(i, &p)| at(i, p));
    let ring_views = (0..positions.len()).flat_map(|i| {
        ring_points(grid, &positions, i, options)
            .into_iter()
            .flat_map(move |q| at(i, q))
    });
    let views: Vec<(u32, Pose)> = centre_views.chain(ring_views).collect();
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
        positions,
        edges: graph.edges.iter().map(|e| (e.a, e.b)).collect(),
        views,
    };
    Ok(Capture { images, layout })
}

/// Attaches to `map` (built from `capture` by [`build_map`], so with one keypoint entry per
/// captured view) the world point each view keypoint sees, ray cast in `renderer`'s world: the
/// scene points that let a localizer place the camera metrically against a view. Keypoints
/// whose ray leaves the world get NaN. Fails when the map stores no keypoints or not one entry
/// per view.
pub fn with_scene_points(
    map: Map,
    renderer: &Renderer,
    capture: &Capture,
    intrinsics: &Intrinsics,
) -> Result<Map, CaptureError> {
    let keypoints = map.keypoints().cloned().ok_or_else(|| {
        CaptureError::InvalidArgument(
            "the map stores no keypoints to attach scene points to".into(),
        )
    })?;
    if keypoints.view_count() != capture.layout.views.len() {
        return Err(CaptureError::InvalidArgument(format!(
            "the map has keypoints for {} views, the capture {} views",
            keypoints.view_count(),
            capture.layout.views.len()
        )));
    }
    let scene: Vec<[f32; 3]> = capture
        .layout
        .views
        .par_iter()
        .enumerate()
        .flat_map_iter(|(v, (_, pose))| {
            let points = keypoints.view(v).expect("view in range").points;
            points.iter().map(move |p| {
                // OpenCV keypoints put the centre of the top-left pixel at (0, 0).
                renderer
                    .surface_point(
                        pose,
                        intrinsics,
                        f64::from(p[0]) + 0.5,
                        f64::from(p[1]) + 0.5,
                    )
                    .map_or([f32::NAN; 3], |q| [q.x as f32, q.y as f32, q.z as f32])
            })
        })
        .collect();
    let keypoints = keypoints
        .with_world_points(scene)
        .map_err(CaptureError::InvalidArgument)?;
    map.with_keypoints(keypoints)
        .map_err(|e| CaptureError::InvalidArgument(e.to_string()))
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
