//! `topoloc simulate`: writes a dataset of the simulator's splits for `topoloc eval --dataset`.
//!
//! Generates world K of a split (train, tr-t, tr-a, test), builds its graph from the voxel
//! skeleton and its map exactly as `topoloc demo` does, saves the map as `OUT/map.topoloc`, and
//! flies N query trajectories (seeds `Split::trajectory_seed(K, i)`), each written as a dataset
//! folder `OUT/traj-00i/` (topoloc-sim format: PNG images, TUM ground truth and odometry, the
//! ground-truth nodes CSV, intrinsics, the place graph and a manifest; with `--depth` also
//! depth images).

use crate::backend_args::progress_bar;
use crate::progress::StepBars;
use crate::scenario_args::{choose_backend, parse_split, scenario_options, CaptureArgs, QueryArgs};
use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;
use topoloc_sim::dataset::{DatasetInfo, DatasetWriter};
use topoloc_sim::scenario::{build_scene, fly, Flight, ScenarioOptions, Scene};
use topoloc_sim::style::Split;

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
    /// Also write each frame's depth image (traj-00i/depth/, 16-bit PNG in millimetres, as a
    /// depth camera would give it): hosts with 3D points, for `topoloc loops --depth`.
    #[arg(long)]
    pub depth: bool,
    /// Output folder (new or empty): OUT/map.topoloc and OUT/traj-000, traj-001, ...
    #[arg(long)]
    pub out: PathBuf,
    /// Print one JSON summary object on stdout instead of text.
    #[arg(long)]
    pub json: bool,
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
            if args.depth {
                let pose = &flight.trajectory.frames[frame].world_t_camera;
                let depth = scene
                    .renderer
                    .try_render_depth(pose, &options.capture.intrinsics)?;
                writer.write_depth(frame, &depth)?;
            }
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
