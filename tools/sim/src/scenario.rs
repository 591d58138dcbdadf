//! A whole experiment in one place: generate a world, build its graph from the voxel skeleton,
//! capture the views and build the map, fly a query trajectory under another condition, and
//! describe its frames. `topoloc demo`, the benchmark suite and the tests run these steps.
//!
//! The steps are separate functions so that callers can reuse a scene for several flights
//! ([`build_scene`] then [`fly`] and [`describe_flight`] per trajectory).

use crate::camera::Intrinsics;
use crate::capture::{
    build_map, capture, image_view, with_scene_points, CaptureError, CaptureOptions,
};
use crate::ground_truth::{ground_truth, FrameTruth, PlaceGraph};
use crate::odometry::{odometry, OdometryNoise};
use crate::render::{Condition, ConditionKind, Image, RenderError, Renderer};
use crate::trajectory::{Planner, PlannerOptions, Trajectory, TrajectoryError, TrajectorySpec};
use crate::world::{World, WorldError, WorldParams};
use nalgebra::Isometry3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;
use topoloc::build::{BuildStage, ImageMapError, ImageMapOptions, TimedPose};
use topoloc::describe::{Describer, DescriberOptions};
use topoloc::errors::VisionError;
use topoloc::map::{Map, MapError};
use topoloc::skeleton::SkeletonError;
use topoloc::skeleton::{skeleton_graph, SkeletonOptions, TopoGraph};
use topoloc_synthetic::{Sequence, SequenceFrame};

/// Everything that defines an experiment.
#[derive(Clone, Debug)]
pub struct ScenarioOptions {
    /// The world.
    pub world: WorldParams,
    /// Graph building from the world's occupancy grid.
    pub skeleton: SkeletonOptions,
    /// Views of the map (camera, mapping condition).
    pub capture: CaptureOptions,
    /// Descriptor backend and fitting of the map.
    pub map: ImageMapOptions,
    /// Clearance of the query trajectory; its height band comes from the world's flight bands.
    pub clearance_m: f64,
    /// Query trajectory (seed, legs, revisits, motion).
    pub trajectory: TrajectorySpec,
    /// Condition of the query frames.
    pub query_condition: Condition,
    /// Drift of the odometry stream given to the filter.
    pub odometry: OdometryNoise,
}

impl ScenarioOptions {
    /// A world of `params`, its map captured in bright light and queried at dim light with
    /// typical VIO odometry; other choices are the modules' defaults.
    pub fn new(params: WorldParams, map: ImageMapOptions) -> Self {
        Self {
            world: params,
            skeleton: scene_skeleton_options(),
            capture: CaptureOptions::default(),
            map,
            clearance_m: 0.3,
            trajectory: TrajectorySpec::default(),
            query_condition: Condition::preset(ConditionKind::Dim),
            odometry: OdometryNoise::typical_vio(),
        }
    }
}

/// Graph building for generated worlds: places at least 0.35 m from obstacles (the skeleton
/// runs through free space, not along furniture), spurs shorter than 2.5 m pruned, nodes within
/// 2 m merged and edges up to 5 m, which keeps room corners out of the graph and gives graphs of
/// the seed's size (a place per room area, doors, corridor stretches). Measured with
/// `topoloc suite` (BENCHMARKS.md): the library's finer defaults put places in room corners,
/// facing blank walls, and halve MNA.
pub fn scene_skeleton_options() -> SkeletonOptions {
    SkeletonOptions {
        min_clearance_m: 0.35,
        min_spur_m: 2.5,
        merge_radius_m: 2.0,
        max_edge_m: 5.0,
        ..SkeletonOptions::default()
    }
}

/// The long steps, for progress reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// Rendering the map's views.
    Capture,
    /// Describing the map's views and fitting the describer.
    BuildMap,
    /// Rendering the query frames.
    Render,
    /// Describing the query frames.
    Describe,
}

/// Errors of a scenario, by step.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// Generating the world.
    #[error(transparent)]
    World(#[from] WorldError),
    /// Building the graph from the world's occupancy grid.
    #[error(transparent)]
    Skeleton(#[from] SkeletonError),
    /// Building the map.
    #[error(transparent)]
    Map(#[from] MapError),
    /// Capturing the views.
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// Rendering query frames.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// Describing the views and fitting the describer.
    #[error(transparent)]
    BuildMap(#[from] ImageMapError),
    /// Planning the query trajectory.
    #[error(transparent)]
    Trajectory(#[from] TrajectoryError),
    /// Describing query frames.
    #[error(transparent)]
    Describe(#[from] VisionError),
    /// Ground truth or odometry.
    #[error("{0}")]
    Other(String),
}

/// Wall times of the steps of [`build_scene`], seconds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneTimings {
    /// Generating the world.
    pub world_s: f64,
    /// Building the graph from the skeleton.
    pub skeleton_s: f64,
    /// Preparing the renderer and rendering the views.
    pub capture_s: f64,
    /// Describing the views, fitting, assembling the map.
    pub map_s: f64,
}

/// A world with its graph and map.
pub struct Scene {
    /// The world.
    pub world: World,
    /// Its renderer.
    pub renderer: Renderer,
    /// The graph built from its skeleton.
    pub graph: TopoGraph,
    /// The same graph as ground truth sees it (positions, four view yaws).
    pub place_graph: PlaceGraph,
    /// The map built from the captured views.
    pub map: Arc<Map>,
    /// How long each step took.
    pub timings: SceneTimings,
}

/// A query flight: the trajectory, its ground truth, odometry and rendered frames.
pub struct Flight {
    /// The planned trajectory.
    pub trajectory: Trajectory,
    /// Ground truth per frame.
    pub truth: Vec<FrameTruth>,
    /// The drifting odometry stream, one pose per frame.
    pub odometry: Vec<TimedPose>,
    /// The rendered frames.
    pub images: Vec<Image>,
}

/// Generates the world, builds its graph and map. `progress(step, done, total)` may be called
/// from worker threads.
pub fn build_scene(
    options: &ScenarioOptions,
    progress: &(dyn Fn(Step, usize, usize) + Sync),
) -> Result<Scene, ScenarioError> {
    let mut timings = SceneTimings::default();
    let start = Instant::now();
    let world = World::generate(&options.world)?;
    timings.world_s = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let graph = skeleton_graph(world.grid(), &options.skeleton)?;
    timings.skeleton_s = start.elapsed().as_secs_f64();
    let positions: Vec<_> = graph.places.iter().map(|p| p.position).collect();
    let edges: Vec<_> = graph.edges.iter().map(|e| (e.a, e.b)).collect();
    let place_graph = PlaceGraph::with_views(&positions, &edges, options.capture.views_per_place);

    let start = Instant::now();
    let renderer = Renderer::new(&world);
    progress(
        Step::Capture,
        0,
        options.capture.views_per_place * positions.len(),
    );
    let captured = capture(&renderer, world.grid(), &graph, &options.capture)?;
    progress(Step::Capture, captured.images.len(), captured.images.len());
    timings.capture_s = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let (map, _) = build_map(&captured, &options.map, &mut |stage, done, total| {
        if stage == BuildStage::Describing {
            progress(Step::BuildMap, done, total);
        }
        true
    })?;
    let map = match map.keypoints() {
        Some(_) => with_scene_points(map, &renderer, &captured, &options.capture.intrinsics)?,
        None => map,
    };
    timings.map_s = start.elapsed().as_secs_f64();
    Ok(Scene {
        world,
        renderer,
        graph,
        place_graph,
        map: Arc::new(map),
        timings,
    })
}

/// The planner of a world: `clearance_m`, within the flight bands of all its storeys.
pub fn planner(world: &World, clearance_m: f64) -> Result<Planner, TrajectoryError> {
    let low = world.flight_band(0)[0];
    let high = world.flight_band(world.floor_count() - 1)[1];
    Planner::new(
        world.grid(),
        PlannerOptions {
            clearance_m,
            band: (low, high),
        },
    )
}

/// Plans the query trajectory in the scene, computes its ground truth and odometry, and
/// renders its frames under the query condition with `intrinsics`.
pub fn fly(
    scene: &Scene,
    options: &ScenarioOptions,
    intrinsics: &Intrinsics,
    progress: &(dyn Fn(Step, usize, usize) + Sync),
) -> Result<Flight, ScenarioError> {
    let trajectory =
        planner(&scene.world, options.clearance_m)?.random_trajectory(&options.trajectory)?;
    let truth = ground_truth(scene.world.grid(), &scene.place_graph, &trajectory.frames)
        .map_err(ScenarioError::Other)?;
    let odometry = odometry(
        &trajectory.frames,
        &options.odometry,
        options.trajectory.seed,
    )
    .map_err(ScenarioError::Other)?;
    let images = render_frames(&scene.renderer, &trajectory, options, intrinsics, progress)?;
    Ok(Flight {
        trajectory,
        truth,
        odometry,
        images,
    })
}

/// Renders the frames of `trajectory` (in parallel) under the query condition, with noise
/// seeded by the trajectory seed and the frame index.
fn render_frames(
    renderer: &Renderer,
    trajectory: &Trajectory,
    options: &ScenarioOptions,
    intrinsics: &Intrinsics,
    progress: &(dyn Fn(Step, usize, usize) + Sync),
) -> Result<Vec<Image>, RenderError> {
    let total = trajectory.frames.len();
    let done = AtomicUsize::new(0);
    trajectory
        .frames
        .par_iter()
        .enumerate()
        .map(|(i, frame)| {
            let image = renderer.try_render(
                &frame.world_t_camera,
                intrinsics,
                &options.query_condition,
                options.trajectory.seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            progress(
                Step::Render,
                done.fetch_add(1, Ordering::Relaxed) + 1,
                total,
            );
            image
        })
        .collect()
}

/// Frames of a robot that has left the mapped world: its drifting odometry and rendered frames.
pub struct Elsewhere {
    /// The odometry stream, one pose per frame.
    pub odometry: Vec<TimedPose>,
    /// The rendered frames.
    pub images: Vec<Image>,
}

/// Flies `options.trajectory` (its seed, legs and motion) through a world of `params` instead
/// of the scene's, keeping its first `max_frames` frames, rendered as [`fly`] renders them: the
/// frames an off-map test needs. No graph or map is built for that world.
pub fn fly_elsewhere(
    params: &WorldParams,
    options: &ScenarioOptions,
    intrinsics: &Intrinsics,
    max_frames: usize,
    progress: &(dyn Fn(Step, usize, usize) + Sync),
) -> Result<Elsewhere, ScenarioError> {
    let world = World::generate(params)?;
    let mut trajectory =
        planner(&world, options.clearance_m)?.random_trajectory(&options.trajectory)?;
    trajectory.frames.truncate(max_frames);
    let odometry = odometry(
        &trajectory.frames,
        &options.odometry,
        options.trajectory.seed,
    )
    .map_err(ScenarioError::Other)?;
    let renderer = Renderer::new(&world);
    let images = render_frames(&renderer, &trajectory, options, intrinsics, progress)?;
    Ok(Elsewhere { odometry, images })
}

/// Describes every frame of `flight` with the scene map's describer (in parallel) and returns
/// the query sequence (descriptor, odometry increment, ground truth per frame) with the
/// describe time of each frame, milliseconds.
pub fn describe_flight(
    scene: &Scene,
    flight: &Flight,
    describer: &DescriberOptions,
    progress: &(dyn Fn(Step, usize, usize) + Sync),
) -> Result<(Sequence, Vec<f64>), ScenarioError> {
    let model = scene
        .map
        .describer()
        .cloned()
        .ok_or_else(|| ScenarioError::Other("the scene's map stores no describer".into()))?;
    Describer::new(model.clone(), describer)?; // fail once, clearly, before the threads start
    let total = flight.images.len();
    let done = AtomicUsize::new(0);
    let described = flight
        .images
        .par_iter()
        .map_init(
            || Describer::new(model.clone(), describer),
            |d, image| -> Result<(Vec<f32>, f64), VisionError> {
                let d = d.as_mut().map_err(|e| VisionError::Model(e.to_string()))?;
                let mut out = Vec::new();
                let start = Instant::now();
                d.describe(&image_view(image), &mut out)?;
                let ms = start.elapsed().as_secs_f64() * 1e3;
                progress(
                    Step::Describe,
                    done.fetch_add(1, Ordering::Relaxed) + 1,
                    total,
                );
                Ok((out, ms))
            },
        )
        .collect::<Result<Vec<_>, _>>()?;
    let mut frames = Vec::with_capacity(total);
    let mut describe_ms = Vec::with_capacity(total);
    for (i, (descriptor, ms)) in described.into_iter().enumerate() {
        let odometry = match i {
            0 => Isometry3::identity(),
            _ => {
                flight.odometry[i - 1].world_t_camera.inverse() * flight.odometry[i].world_t_camera
            }
        };
        let truth = &flight.truth[i];
        frames.push(SequenceFrame {
            timestamp: flight.trajectory.frames[i].timestamp,
            descriptor,
            odometry,
            truth_place: truth.place,
            truth_view: truth.view,
            world_t_camera: flight.trajectory.frames[i].world_t_camera,
        });
        describe_ms.push(ms);
    }
    Ok((Sequence { frames }, describe_ms))
}
