//! `topoloc suite`: the seed-style benchmark table on generated worlds.
//!
//! For each split (train, tr-t, tr-a, test) and each of its first N worlds, builds the world's
//! skeleton graph and map and flies one query trajectory (seeds `Split::trajectory_seed(K, 0)`)
//! exactly as `topoloc demo` and `topoloc simulate` do (12 views per place unless
//! `--views-per-place` says otherwise), then localizes every frame with each
//! localizer configuration (single-frame, filter, filter with drifting odometry, that with
//! geometric verification of the most probable places unless `--verify 0` (scored by GC inliers,
//! and by the s-GC spatial score: the seed's ablation), and metric mode
//! (particles moved by the odometry) without and with verification, and with pose fixes from
//! the best-verified view (the map's keypoint scene points, the sim camera's intrinsics), and
//! the learned GRNN alone (also without carrying its recurrent state: the seed's "without
//! temporal module"), with GC and with s-GC; `--configurations` picks some). Prints MNA and
//! OHA per split as mean ± standard deviation over the worlds, the way the seed's tables do
//! (thesis Table 4.2), and the graph sizes they were measured on.

use crate::demo::{evaluate, ConfigResult};
use crate::progress::StepBars;
use crate::scenario_args::{choose_backend, parse_split, scenario_options, CaptureArgs, QueryArgs};
use anyhow::Result;
use serde_json::json;
use std::time::Instant;
use topoloc::describe::DescriberOptions;
use topoloc::eval::HopDistances;
use topoloc::image::ImageView;
use topoloc::verify::{VerificationOptions, VerificationScore};
use topoloc::{GrnnOptions, LocalizerOptions, MetricOptions, Mode};
use topoloc_sim::capture::image_view;
use topoloc_sim::scenario::{build_scene, describe_flight, fly};
use topoloc_sim::style::Split;

/// Options of `suite`.
#[derive(clap::Args, Clone, Debug)]
pub struct SuiteArgs {
    /// Splits to run, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "train,tr-t,tr-a,test", value_parser = parse_split)]
    pub splits: Vec<Split>,
    /// Worlds per split (worlds K..K+N of each, K = `--first-world`).
    #[arg(long, default_value_t = 3)]
    pub worlds: u32,
    /// First world of each split: worlds 0-2 are for development, report on worlds no choice
    /// saw (6 and up).
    #[arg(long, default_value_t = 0)]
    pub first_world: u32,
    /// ONNX model of the GRNN configurations (default: the one built into the library).
    #[arg(long)]
    pub grnn_model: Option<std::path::PathBuf>,
    /// Rooms per storey (default 5, which gives graphs of about 50-300 views like the seed's;
    /// 0 draws it from the split's style).
    #[arg(long, default_value_t = 5)]
    pub rooms: u32,
    /// Storeys (default 1; 0 draws it from the split's style).
    #[arg(long, default_value_t = 1)]
    pub floors: u32,
    /// Legs of each query trajectory (one revisits an earlier goal when there are two or more).
    #[arg(long, default_value_t = 3)]
    pub legs: usize,
    /// Query light and rate, map backend.
    #[command(flatten)]
    pub query: QueryArgs,
    /// Map capture.
    #[command(flatten)]
    pub capture: CaptureArgs,
    /// Places verified geometrically per frame in the verification configuration (0 leaves
    /// that configuration out).
    #[arg(long, default_value_t = 5)]
    pub verify: usize,
    /// Log-likelihood of one verification inlier (see `topoloc::verify`).
    #[arg(long, default_value_t = VerificationOptions::default().inlier_weight)]
    pub inlier_weight: f32,
    /// Log-likelihood of one verification inlier in metric mode: smaller than the graph
    /// filter's, since a verified view also matches from a few metres away and the particles
    /// should keep to the odometry.
    #[arg(long, default_value_t = 0.01)]
    pub metric_inlier_weight: f32,
    /// Seed of metric mode's particle filter (`MetricOptions::seed`).
    #[arg(long, default_value_t = 0)]
    pub metric_seed: u64,
    /// Configurations to run, comma-separated (default: all): single-frame, filter,
    /// filter+odometry, filter+odometry+verification (GC), filter+odometry+s-gc, metric+odometry,
    /// metric+odometry+verification, metric+odometry+pose-fix, grnn-no-temporal, grnn, grnn+gc,
    /// grnn+s-gc.
    #[arg(long, value_delimiter = ',', value_parser = parse_configuration)]
    pub configurations: Vec<String>,
    /// Print one JSON object (per split and configuration: every world's figures, mean, std).
    #[arg(long)]
    pub json: bool,
}

/// One localizer configuration compared by the suite.
struct Configuration {
    /// Name in the table and in `--configurations`.
    name: &'static str,
    /// Graph filter, single-frame or metric.
    mode: Mode,
    /// Whether the drifting odometry is given.
    odometry: bool,
    /// Whether the most probable places are verified geometrically (`--verify` of them).
    verify: bool,
    /// Whether the best-verified view also places the camera metrically (a pose fix from the
    /// map's keypoint scene points), weighing the particles by position; the places are then
    /// not weighed by their inlier counts.
    pose_fix: bool,
    /// The evidence of a verified view: GC inliers or the s-GC spatial score.
    score: VerificationScore,
    /// GRNN only: the recurrent state is not carried between frames (the seed's "without
    /// temporal module" ablation, [`GrnnOptions::forget_state`]).
    forget_state: bool,
}

const fn configuration(
    name: &'static str,
    mode: Mode,
    odometry: bool,
    verify: bool,
    pose_fix: bool,
) -> Configuration {
    Configuration {
        name,
        mode,
        odometry,
        verify,
        pose_fix,
        score: VerificationScore::Inliers,
        forget_state: false,
    }
}

/// A verifying configuration scored by s-GC instead of GC inliers.
const fn spatially_scored(c: Configuration) -> Configuration {
    Configuration {
        score: VerificationScore::Spatial,
        ..c
    }
}

/// A GRNN configuration whose recurrent state starts from zeros at every frame.
const fn without_temporal(c: Configuration) -> Configuration {
    Configuration {
        forget_state: true,
        ..c
    }
}

/// The localizer configurations compared.
const CONFIGURATIONS: [Configuration; 12] = [
    configuration("single-frame", Mode::SingleFrame, false, false, false),
    configuration("filter", Mode::Filter, false, false, false),
    configuration("filter+odometry", Mode::Filter, true, false, false),
    configuration(
        "filter+odometry+verification",
        Mode::Filter,
        true,
        true,
        false,
    ),
    spatially_scored(configuration(
        "filter+odometry+s-gc",
        Mode::Filter,
        true,
        true,
        false,
    )),
    configuration("metric+odometry", Mode::Metric, true, false, false),
    configuration(
        "metric+odometry+verification",
        Mode::Metric,
        true,
        true,
        false,
    ),
    configuration("metric+odometry+pose-fix", Mode::Metric, true, true, true),
    without_temporal(configuration(
        "grnn-no-temporal",
        Mode::Grnn,
        false,
        false,
        false,
    )),
    configuration("grnn", Mode::Grnn, false, false, false),
    configuration("grnn+gc", Mode::Grnn, false, true, false),
    spatially_scored(configuration("grnn+s-gc", Mode::Grnn, false, true, false)),
];

/// Accepts the name of one of [`CONFIGURATIONS`].
fn parse_configuration(name: &str) -> Result<String, String> {
    match CONFIGURATIONS.iter().find(|c| c.name == name) {
        Some(c) => Ok(c.name.to_string()),
        None => Err(format!(
            "unknown configuration '{name}'; one of: {}",
            CONFIGURATIONS.map(|c| c.name).join(", ")
        )),
    }
}

/// The configurations run with `args`.
fn configurations(args: &SuiteArgs) -> impl Iterator<Item = &'static Configuration> + '_ {
    let verify = args.verify > 0;
    CONFIGURATIONS
        .iter()
        .filter(move |c| verify || !c.verify)
        .filter(move |c| {
            args.configurations.is_empty() || args.configurations.iter().any(|o| o == c.name)
        })
}

/// One world's run: its size and each configuration's result.
struct WorldRun {
    world: u32,
    places: usize,
    views: usize,
    frames: usize,
    results: Vec<ConfigResult>,
}

/// Runs the command.
pub fn run(args: &SuiteArgs) -> Result<()> {
    anyhow::ensure!(args.worlds >= 1, "--worlds must be at least 1");
    anyhow::ensure!(
        !args.splits.is_empty(),
        "--splits must name at least one split"
    );
    anyhow::ensure!(
        configurations(args).next().is_some(),
        "no configuration to run (--configurations names only verification ones, and --verify is 0)"
    );
    let start = Instant::now();
    let (backend, backend_note) = choose_backend(args.query.backend);
    if !args.json {
        eprintln!("backend: {backend_note}");
    }
    let bars = StepBars::new(args.json);
    let mut runs: Vec<(Split, Vec<WorldRun>)> = Vec::new();
    for &split in &args.splits {
        let mut worlds = Vec::new();
        for k in args.first_world..args.first_world + args.worlds {
            let mut world = split.world_params(k);
            if args.rooms > 0 {
                world.rooms_per_floor = args.rooms;
            }
            if args.floors > 0 {
                world.floors = args.floors;
            }
            let mut options = scenario_options(
                world,
                backend.clone(),
                &args.capture,
                args.query.condition,
                args.legs,
                args.query.rate_hz,
            );
            options.trajectory.seed = split.trajectory_seed(k, 0);
            let report = |step, done, total| bars.report(step, done, total);
            let scene = build_scene(&options, &report)?;
            let flight = fly(&scene, &options, &options.capture.intrinsics, &report)?;
            let (sequence, _) =
                describe_flight(&scene, &flight, &DescriberOptions::default(), &report)?;
            bars.finish();
            let hops = HopDistances::from_map(&scene.map);
            let images: Vec<ImageView<'_>> = flight.images.iter().map(image_view).collect();
            let results = configurations(args)
                .map(|c| {
                    let verification = VerificationOptions {
                        candidates: if c.verify { args.verify } else { 0 },
                        inlier_weight: match (c.pose_fix, c.mode) {
                            (true, _) => 0.0,
                            (false, Mode::Metric) => args.metric_inlier_weight,
                            (false, _) => args.inlier_weight,
                        },
                        camera: c.pose_fix.then(|| options.capture.intrinsics.pinhole()),
                        score: c.score,
                        ..VerificationOptions::default()
                    };
                    let options = LocalizerOptions {
                        mode: c.mode,
                        verification,
                        metric: MetricOptions {
                            seed: args.metric_seed,
                            ..MetricOptions::default()
                        },
                        grnn: GrnnOptions {
                            model: args.grnn_model.clone(),
                            forget_state: c.forget_state,
                            ..GrnnOptions::default()
                        },
                        ..LocalizerOptions::default()
                    };
                    let given = c.verify.then_some(images.as_slice());
                    evaluate(
                        c.name, &scene.map, &sequence, &hops, options, c.odometry, given,
                    )
                })
                .collect::<Result<Vec<_>>>()?;
            if !args.json {
                let figures: Vec<String> = results
                    .iter()
                    .map(|r| {
                        format!(
                            "{} {:.3}/{:.3} ({:.2} ms)",
                            r.name, r.mna, r.oha, r.ms_median
                        )
                    })
                    .collect();
                eprintln!(
                    "{split} world {k}: {} places, {} views, {} frames; MNA/OHA {}",
                    scene.map.place_count(),
                    scene.map.view_count(),
                    sequence.frames.len(),
                    figures.join(", ")
                );
            }
            worlds.push(WorldRun {
                world: k,
                places: scene.map.place_count(),
                views: scene.map.view_count(),
                frames: sequence.frames.len(),
                results,
            });
        }
        runs.push((split, worlds));
    }
    if args.json {
        println!("{}", summary_json(args, &backend_note, &runs, start));
    } else {
        print_table(args, &runs);
        println!(
            "{} worlds per split, {} views per place, query light '{}', {:.0} s in all",
            args.worlds,
            args.capture.views_per_place,
            args.query.condition.name(),
            start.elapsed().as_secs_f64()
        );
    }
    Ok(())
}

/// Mean and (population) standard deviation.
fn mean_std(values: &[f64]) -> (f64, f64) {
    let n = values.len().max(1) as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

/// One configuration's values of `metric` over the worlds of a split.
fn column(worlds: &[WorldRun], config: usize, metric: fn(&ConfigResult) -> f64) -> Vec<f64> {
    worlds.iter().map(|w| metric(&w.results[config])).collect()
}

fn print_table(args: &SuiteArgs, runs: &[(Split, Vec<WorldRun>)]) {
    let mut header = String::from("| configuration |");
    let mut rule = String::from("|---|");
    for (split, _) in runs {
        header.push_str(&format!(" {split} MNA | {split} OHA |"));
        rule.push_str("---|---|");
    }
    println!("\n{header}\n{rule}");
    for (c, configuration) in configurations(args).enumerate() {
        let mut row = format!("| {} |", configuration.name);
        for (_, worlds) in runs {
            for metric in [|r: &ConfigResult| r.mna, |r: &ConfigResult| r.oha] {
                let (mean, std) = mean_std(&column(worlds, c, metric));
                row.push_str(&format!(" {mean:.3} ± {std:.3} |"));
            }
        }
        println!("{row}");
    }
    println!();
    for (split, worlds) in runs {
        let sizes: Vec<String> = worlds
            .iter()
            .map(|w| format!("{} places/{} views/{} frames", w.places, w.views, w.frames))
            .collect();
        println!("{split}: {}", sizes.join("; "));
    }
    println!("MNA: predicted place is the true place. OHA: within one graph hop. Mean ± std over worlds.");
}

fn summary_json(
    args: &SuiteArgs,
    backend_note: &str,
    runs: &[(Split, Vec<WorldRun>)],
    start: Instant,
) -> serde_json::Value {
    let splits: serde_json::Map<String, serde_json::Value> = runs
        .iter()
        .map(|(split, worlds)| {
            let configurations: serde_json::Map<String, serde_json::Value> = configurations(args)
                .enumerate()
                .map(|(c, configuration)| {
                    let mna = column(worlds, c, |r| r.mna);
                    let oha = column(worlds, c, |r| r.oha);
                    let (mna_mean, mna_std) = mean_std(&mna);
                    let (oha_mean, oha_std) = mean_std(&oha);
                    let localize_ms = column(worlds, c, |r| r.ms_median);
                    let value = json!({
                        "mna": mna, "oha": oha, "localize_ms_median": localize_ms,
                        "mna_mean": mna_mean, "mna_std": mna_std,
                        "oha_mean": oha_mean, "oha_std": oha_std,
                    });
                    (configuration.name.to_string(), value)
                })
                .collect();
            let worlds_json: Vec<_> = worlds
                .iter()
                .map(|w| json!({"world": w.world, "places": w.places, "views": w.views, "frames": w.frames}))
                .collect();
            (
                split.name().to_string(),
                json!({"worlds": worlds_json, "configurations": configurations}),
            )
        })
        .collect();
    json!({
        "backend": backend_note, "condition": args.query.condition.name(),
        "rooms": args.rooms, "floors": args.floors, "legs": args.legs,
        "views_per_place": args.capture.views_per_place,
        "verify": args.verify, "inlier_weight": args.inlier_weight,
        "metric_inlier_weight": args.metric_inlier_weight, "metric_seed": args.metric_seed,
        "first_world": args.first_world,
        "grnn_model": args.grnn_model.as_ref().map(|p| p.display().to_string()),
        "splits": splits, "seconds": start.elapsed().as_secs_f64(),
    })
}
