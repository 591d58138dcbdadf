//! `topoloc simulate`: writes a dataset of the simulator's splits for `topoloc eval --dataset`.
//!
//! Generates world K of a split (train, tr-t, tr-a, test), builds its graph from the voxel
//! skeleton and its map exactly as `topoloc demo` does, saves the map as `OUT/map.topoloc`, and
//! flies N query trajectories (seeds `Split::trajectory_seed(K, i)`), each written as a dataset
//! folder `OUT/traj-00i/` (topoloc-sim format: PNG images, TUM ground truth and odometry, the
//! ground-truth nodes CSV, intrinsics, the place graph and a manifest).

use crate::backend_args::{progress_bar, Backend};
use crate::demo::choose_backend;
use crate::progress::StepBars;
use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;
use topoloc::build::ImageMapOptions;
use topoloc::describe::BackendConfig;
use topoloc_sim::dataset::{DatasetInfo, DatasetWriter};
use topoloc_sim::render::{Condition, ConditionKind};
use topoloc_sim::scenario::{build_scene, fly, Flight, ScenarioOptions, Scene};
use topoloc_sim::style::Split;
use topoloc_sim::world::WorldParams;

/// File name of the map inside `--out`.
pub const MAP_FILE: &str = "map.topoloc";

/// Options of `simulate`.
#[derive(clap::Args, Clone, Debug)]
pub struct SimulateArgs {
    /// Split: train, tr-t (training worlds, new trajectories), tr-a (new training-style worlds)
    /// or test (worlds of the unseen style).
    #[arg(long, default_value = "train", value_parser = parse_split)]
    pub split: Split,
    /// World index K within the split.
    #[arg(long, default_value_t = 0)]
    pub world: u32,
    /// Rooms per storey (default: drawn from the split's style).
    #[arg(long)]
    pub rooms: Option<u32>,
    /// Storeys (default: drawn from the split's style).
    #[arg(long)]
    pub floors: Option<u32>,
    /// Query trajectories to fly, each written as OUT/traj-00i.
    #[arg(long, default_value_t = 1)]
    pub trajectories: u32,
    /// Legs per trajectory (one of them revisits an earlier goal when there are two or more).
    #[arg(long, default_value_t = 4)]
    pub legs: usize,
    /// Query light and rate, map backend.
    #[command(flatten)]
    pub query: QueryArgs,
    /// Map capture.
    #[command(flatten)]
    pub capture: CaptureArgs,
    /// Output folder (new or empty): OUT/map.topoloc and OUT/traj-000, traj-001, ...
    #[arg(long)]
    pub out: PathBuf,
    /// Print one JSON summary object on stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Query frames' light and rate, and the map's descriptor backend, shared by `simulate` and
/// `suite`.
#[derive(clap::Args, Clone, Debug)]
pub struct QueryArgs {
    /// Query frames per second.
    #[arg(long, default_value_t = 10.0)]
    pub rate_hz: f64,
    /// Lighting of the query frames (maps are captured in bright light).
    #[arg(long, default_value = "dim", value_parser = parse_condition)]
    pub condition: ConditionKind,
    /// Descriptor backend of the map; default: ONNX when its model is set up, else VLAD.
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
}

pub(crate) fn parse_split(name: &str) -> Result<Split, String> {
    name.parse()
}

pub(crate) fn parse_condition(name: &str) -> Result<ConditionKind, String> {
    ConditionKind::from_name(name).ok_or_else(|| {
        let names: Vec<_> = ConditionKind::ALL.iter().map(|k| k.name()).collect();
        format!("expected one of {}", names.join(", "))
    })
}

/// Runs the command.
pub fn run(args: &SimulateArgs) -> Result<()> {
    let start = Instant::now();
    check_empty(&args.out)?;
    let say = |text: String| {
        if !args.json {
            eprintln!("{text}");
        }
    };
    let (backend, backend_note) = choose_backend(args.query.backend);
    say(format!("backend: {backend_note}"));
    let mut world = args.split.world_params(args.world);
    world.rooms_per_floor = args.rooms.unwrap_or(world.rooms_per_floor);
    world.floors = args.floors.unwrap_or(world.floors);
    let mut options = scenario_options(
        world,
        backend,
        &args.capture,
        args.query.condition,
        args.legs,
        args.query.rate_hz,
    );

    let bars = StepBars::new(args.json);
    let scene = build_scene(&options, &|step, done, total| {
        bars.report(step, done, total)
    })?;
    bars.finish();
    let map_path = args.out.join(MAP_FILE);
    scene
        .map
        .save(&map_path)
        .with_context(|| format!("saving {}", map_path.display()))?;
    say(format!(
        "{} world {} (seed {:#x}, {} style, {} storeys x {} rooms): {} places, {} views, {} edges; map {}",
        args.split,
        args.world,
        options.world.seed,
        options.world.style.name,
        options.world.floors,
        options.world.rooms_per_floor,
        scene.map.place_count(),
        scene.map.view_count(),
        scene.map.edge_count(),
        map_path.display()
    ));

    let flights_start = Instant::now();
    let mut trajectories = Vec::new();
    for i in 0..args.trajectories {
        options.trajectory.seed = args.split.trajectory_seed(args.world, i);
        let flight = fly(
            &scene,
            &options,
            &options.capture.intrinsics,
            &|step, done, total| bars.report(step, done, total),
        )?;
        bars.finish();
        let dir = args.out.join(format!("traj-{i:03}"));
        write_dataset(&dir, &scene, &flight, &options, args)?;
        say(format!(
            "{}: {} frames over {:.0} m under '{}' light",
            dir.display(),
            flight.images.len(),
            flight.trajectory.length_m,
            args.query.condition.name()
        ));
        trajectories.push(json!({
            "path": dir.display().to_string(),
            "trajectory_seed": options.trajectory.seed,
            "frames": flight.images.len(),
            "visible_frames": flight.truth.iter().filter(|t| t.visible).count(),
            "length_m": flight.trajectory.length_m,
        }));
    }
    if args.json {
        let t = &scene.timings;
        println!(
            "{}",
            json!({
                "out": args.out.display().to_string(),
                "map": map_path.display().to_string(),
                "split": args.split.name(), "world": args.world, "world_seed": options.world.seed,
                "style": options.world.style.name, "condition": args.query.condition.name(),
                "backend": scene.map.descriptor().to_string(),
                "places": scene.map.place_count(), "views": scene.map.view_count(),
                "edges": scene.map.edge_count(),
                "trajectories": trajectories,
                "seconds": {"world": t.world_s, "skeleton": t.skeleton_s, "capture": t.capture_s,
                            "map": t.map_s, "trajectories": flights_start.elapsed().as_secs_f64(),
                            "total": start.elapsed().as_secs_f64()},
            })
        );
    } else {
        say(format!("done in {:.1} s", start.elapsed().as_secs_f64()));
    }
    Ok(())
}

/// Views captured per place by `demo`, `simulate` and `suite` unless `--views-per-place` says
/// otherwise. The seed's micro nodes are 4 views 90 degrees apart; 12 (30 degrees apart) was
/// measured better on generated worlds (test world 0: filter MNA 0.26 with 4, 0.42 with 8,
/// 0.50 with 12, 0.47 with 16; BENCHMARKS.md), since a query turned 45 degrees from every
/// view shares only half its field of view with each.
pub(crate) const VIEWS_PER_PLACE: usize = 12;

/// Map capture options shared by `demo`, `simulate` and `suite`.
#[derive(clap::Args, Clone, Debug)]
pub struct CaptureArgs {
    /// Map views per place, evenly turned in yaw, 1..=16 (4 is the seed's micro nodes).
    #[arg(long, default_value_t = VIEWS_PER_PLACE)]
    pub views_per_place: usize,
    /// Also capture those views from 4 points this far around each place (metres, 0 = off;
    /// points kept where free, in sight of the place and nearest to it). 0.8 raised test-split
    /// MNA/OHA by about 0.05 at 5x the views and map build time (BENCHMARKS.md).
    #[arg(long, default_value_t = 0.0)]
    pub ring_m: f64,
}

/// The scenario of `demo`, `simulate` and `suite`: `world` with `capture` views per place
/// captured in bright light and described with `backend`, queried under `condition`
/// along `legs` legs (one of them back to an earlier goal, a loop, when there are two or more)
/// at `rate_hz`; the trajectory seed is left to the caller.
pub(crate) fn scenario_options(
    world: WorldParams,
    backend: BackendConfig,
    capture: &CaptureArgs,
    condition: ConditionKind,
    legs: usize,
    rate_hz: f64,
) -> ScenarioOptions {
    let mut options = ScenarioOptions::new(
        world,
        ImageMapOptions {
            backend,
            ..ImageMapOptions::default()
        },
    );
    options.capture.views_per_place = capture.views_per_place;
    options.capture.ring_radius_m = capture.ring_m;
    options.query_condition = Condition::preset(condition);
    options.trajectory.goals = legs;
    options.trajectory.revisits = options.trajectory.revisits.min(legs.saturating_sub(1));
    options.trajectory.motion.rate_hz = rate_hz;
    options
}

/// Refuses an output folder that already holds something (stale trajectories would mix in).
fn check_empty(out: &Path) -> Result<()> {
    if out.exists() {
        let mut entries = std::fs::read_dir(out)
            .with_context(|| format!("--out {}: cannot read the folder", out.display()))?;
        if entries.next().is_some() {
            bail!(
                "--out {}: folder is not empty; simulate into a new or empty folder",
                out.display()
            );
        }
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))
}

/// Writes one flight as a dataset folder: the images in parallel, then the records and the
/// manifest.
fn write_dataset(
    dir: &Path,
    scene: &Scene,
    flight: &Flight,
    options: &ScenarioOptions,
    args: &SimulateArgs,
) -> Result<()> {
    let writer = DatasetWriter::create(dir, options.capture.intrinsics)?;
    let bar = if args.json {
        indicatif::ProgressBar::hidden()
    } else {
        progress_bar(flight.images.len(), "writing")
    };
    flight
        .images
        .par_iter()
        .enumerate()
        .try_for_each(|(frame, image)| {
            writer.write_image(frame, &image.rgb)?;
            bar.inc(1);
            anyhow::Ok(())
        })?;
    bar.finish_and_clear();
    let info = DatasetInfo {
        world_seed: options.world.seed,
        trajectory_seed: options.trajectory.seed,
        split: args.split.name().into(),
        style: options.world.style.name.clone(),
        condition: args.query.condition.name().into(),
        rate_hz: options.trajectory.motion.rate_hz,
        // scenario::fly draws the odometry noise from the trajectory seed.
        odometry_seed: options.trajectory.seed,
        odometry_noise: options.odometry,
    };
    writer.finish(
        &info,
        &scene.place_graph,
        &flight.trajectory.frames,
        &flight.odometry,
        &flight.truth,
    )?;
    Ok(())
}
