//! `topoloc demo`: the main job on an embedded default. Generates a small indoor world
//! (topoloc-sim), builds its graph from the voxel skeleton, captures twelve yaw views per place
//! and builds the map (ONNX backend when scripts/setup-models.sh has run, else VLAD, saying which;
//! scripts/demo.sh runs it first and stops when it fails),
//! flies a query trajectory under another lighting condition, localizes every frame single-frame,
//! with the filter, with the filter plus drifting odometry, in metric mode (particles moved by
//! that odometry), and with the filter, odometry and geometric verification of the top places
//! (XFeat keypoints when their model is set up), and prints the seed's metrics
//! (MNA, OHA, R@1, R@5), precision-recall, calibration, off-map flags on the flight and on frames
//! from another world ([`crate::off_world`]), latency and peak memory. It writes a PNG:
//! the world from above with the graph, the trajectory and the predicted vs true place of the
//! run's best configuration ([`plotted_configuration`]: highest MNA, ties broken by OHA, then by
//! the order of the table), named with its MNA and OHA in the picture, the text output and the
//! JSON (`plotted_configuration`; the top-level `mna`, `oha`, `r_at_1`, `r_at_5` and
//! `ms_per_frame_median` are that configuration's).

use crate::backend_args::Backend;
use crate::off_world::{off_world_flags, off_world_frames, OffWorldFlags, SETTLE_FRAMES};
use crate::process::{median_and_p90, resident_memory_mib};
use crate::progress::StepBars;
use crate::scenario_args::{choose_backend, scenario_options, CaptureArgs};
use crate::top_view::write_top_view;
use anyhow::{Context, Result};
use serde_json::json;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;
use topoloc::describe::onnx::cache_dir;
use topoloc::describe::BackendConfig;
use topoloc::describe::DescriberOptions;
use topoloc::eval::{calibration, precision_recall, GraphEvaluator, HopDistances, Prediction};
use topoloc::image::ImageView;
use topoloc::map::{LoadOptions, PlaceId};
use topoloc::verify::xfeat::DEFAULT_XFEAT_MODEL_FILE;
use topoloc::verify::{FeatureKind, VerificationOptions};
use topoloc::{Frame, Localization, Localizer, LocalizerOptions, Map, Mode};
use topoloc_sim::capture::image_view;
use topoloc_sim::render::ConditionKind;
use topoloc_sim::scenario::{build_scene, describe_flight, fly};
use topoloc_sim::style::Style;
use topoloc_sim::world::WorldParams;
use topoloc_synthetic::Sequence;

/// Demo settings (command-line options).
#[derive(clap::Args, Clone, Debug)]
pub struct DemoArgs {
    /// World and trajectory seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Rooms per storey of the generated world (one storey).
    #[arg(long, default_value_t = 6)]
    pub rooms: u32,
    /// Legs of the query trajectory (one of them revisits an earlier goal).
    #[arg(long, default_value_t = 4)]
    pub legs: usize,
    /// Query frames per second.
    #[arg(long, default_value_t = 10.0)]
    pub rate_hz: f64,
    /// Lighting of the query flight (the map is captured in bright light).
    #[arg(long, default_value = "dim")]
    pub condition: String,
    /// Descriptor backend; default: ONNX when its model is set up, else VLAD.
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    /// Map capture.
    #[command(flatten)]
    pub capture: CaptureArgs,
    /// Top view with the graph, the trajectory and predicted vs true places (of the
    /// configuration with the highest MNA, ties broken by OHA, then by the table's order).
    #[arg(long, default_value = "topoloc-demo.png")]
    pub plot: PathBuf,
    /// Print one JSON object with the final figures instead of the table.
    #[arg(long)]
    pub json: bool,
}

/// One localizer configuration's results.
pub(crate) struct ConfigResult {
    pub name: &'static str,
    pub mna: f64,
    pub oha: f64,
    pub r_at_1: f64,
    pub r_at_5: f64,
    pub average_precision: f64,
    pub r_at_100p: f64,
    pub ece: f64,
    /// Share of frames flagged off-map.
    pub off_map_rate: f64,
    /// How frames from another world were flagged (configurations tested on them).
    pub off_world: Option<OffWorldFlags>,
    pub ms_median: f64,
    pub ms_p90: f64,
    /// Predicted place per frame.
    pub predicted: Vec<PlaceId>,
}

pub fn run(args: &DemoArgs) -> Result<()> {
    let condition = ConditionKind::from_name(&args.condition).with_context(|| {
        let names: Vec<_> = ConditionKind::ALL.iter().map(|k| k.name()).collect();
        format!(
            "--condition {}: expected one of {}",
            args.condition,
            names.join(", ")
        )
    })?;
    let say = |text: String| {
        if !args.json {
            eprintln!("{text}");
        }
    };
    let (backend, backend_note) = choose_backend(args.backend);
    say(format!("backend: {backend_note}"));
    let world = WorldParams {
        floors: 1,
        rooms_per_floor: args.rooms,
        ..WorldParams::from_style(args.seed, Style::office())
    };
    let mut options = scenario_options(
        world,
        backend,
        &args.capture,
        condition,
        args.legs,
        args.rate_hz,
    );
    options.trajectory.seed = args.seed.wrapping_add(1);
    let (features, features_note) =
        demo_features(args.capture.local_features, &options.map.backend);
    options.map.features = features;
    say(format!("local features of the map: {features_note}"));

    let bars = StepBars::new(args.json);
    let start = Instant::now();
    let scene = build_scene(&options, &|step, done, total| {
        bars.report(step, done, total)
    })?;
    bars.finish();
    let t = &scene.timings;
    let kinds = scene.graph.kind_counts();
    say(format!(
        "world: {} rooms, {:?} voxels of {} m, generated in {:.2} s",
        args.rooms,
        scene.world.grid().dims(),
        scene.world.grid().voxel_size(),
        t.world_s
    ));
    say(format!(
        "graph from the voxel skeleton: {} places ({} end, {} corner, {} branch, {} intermediate), {} edges, in {:.2} s",
        scene.graph.places.len(), kinds[0], kinds[1], kinds[2], kinds[3], scene.graph.edges.len(), t.skeleton_s
    ));
    say(format!(
        "map: {} views captured in {:.1} s, described and fitted in {:.1} s ({})",
        scene.map.view_count(),
        t.capture_s,
        t.map_s,
        scene.map.descriptor()
    ));

    let dir = tempfile::tempdir()?;
    let path = dir.path().join("demo.topoloc");
    scene.map.save(&path)?;
    let load_start = Instant::now();
    let map = Arc::new(Map::load(&path, &LoadOptions::default())?);
    let load_ms = load_start.elapsed().as_secs_f64() * 1e3;
    let file_kib = std::fs::metadata(&path)?.len() as f64 / 1024.0;
    say(format!(
        "map file: {file_kib:.0} KiB, loaded (memory-mapped, validated) in {load_ms:.2} ms"
    ));

    let intrinsics = options.capture.intrinsics;
    let flight = fly(&scene, &options, &intrinsics, &|step, done, total| {
        bars.report(step, done, total)
    })?;
    let (sequence, describe_ms) = describe_flight(
        &scene,
        &flight,
        &DescriberOptions::default(),
        &|step, done, total| bars.report(step, done, total),
    )?;
    bars.finish();
    let visible = flight.truth.iter().filter(|t| t.visible).count();
    say(format!(
        "query: {} frames at {} Hz over {:.0} m under '{}' light ({} with a place in sight), odometry with {:.0}% scale error",
        sequence.frames.len(),
        args.rate_hz,
        flight.trajectory.length_m,
        condition.name(),
        visible,
        options.odometry.scale_error * 100.0
    ));

    let elsewhere = WorldParams {
        floors: 1,
        rooms_per_floor: args.rooms,
        ..WorldParams::from_style(args.seed.wrapping_add(1), Style::lab())
    };
    let off_world = off_world_frames(
        &map,
        &elsewhere,
        &options,
        OFF_WORLD_FRAMES,
        &|step, done, total| bars.report(step, done, total),
    )?;
    bars.finish();
    say(format!(
        "off-world test: {OFF_WORLD_FRAMES} frames from a '{}' world after the first {LEAD_IN} of the flight (filter+odometry configurations)",
        off_world.style
    ));

    let hops = HopDistances::from_map(&map);
    let images: Vec<ImageView<'_>> = flight.images.iter().map(image_view).collect();
    let configs = [
        ("single-frame", Mode::SingleFrame, false, false),
        ("filter", Mode::Filter, false, false),
        ("filter+odometry", Mode::Filter, true, false),
        ("metric+odometry", Mode::Metric, true, false),
        ("filter+odometry+verification", Mode::Filter, true, true),
    ];
    let mut results = Vec::new();
    for (name, mode, odometry, verify) in configs {
        let options = LocalizerOptions {
            mode,
            verification: VerificationOptions::with_candidates(if verify {
                VERIFIED_PLACES
            } else {
                0
            }),
            ..LocalizerOptions::default()
        };
        let given = verify.then_some(images.as_slice());
        let mut result = evaluate(
            name,
            &map,
            &sequence,
            &hops,
            options.clone(),
            odometry,
            given,
        )?;
        if mode == Mode::Filter && odometry {
            result.off_world = Some(off_world_flags(
                localizer(&map, options)?,
                &sequence,
                given,
                LEAD_IN,
                &off_world,
                odometry,
            )?);
        }
        results.push(result);
    }
    let (describe_median, _) = median_and_p90(&describe_ms);
    let (_, peak_rss) = resident_memory_mib().unwrap_or((0.0, 0.0));
    let best = plotted_configuration(&results).expect("configured: five localizers");
    let caption = format!(
        "predicted places of {} (MNA {:.3}, OHA {:.3}): the highest MNA of the {} configurations",
        best.name,
        best.mna,
        best.oha,
        results.len()
    );
    write_top_view(&args.plot, &scene, &flight, &best.predicted, &caption)?;
    say(format!(
        "top view written to {}: {caption}",
        args.plot.display()
    ));

    let configurations: serde_json::Map<String, serde_json::Value> = results
        .iter()
        .map(|r| {
            (
                r.name.to_string(),
                json!({
                    "mna": r.mna, "oha": r.oha, "r_at_1": r.r_at_1, "r_at_5": r.r_at_5,
                    "average_precision": r.average_precision, "r_at_100p": r.r_at_100p,
                    "expected_calibration_error": r.ece, "off_map_rate": r.off_map_rate,
                    "off_world_flagged_after_10": r.off_world.map(|o| o.flagged_after_settle),
                    "off_world_first_flag": r.off_world.and_then(|o| o.first_flag),
                    "localize_ms_median": r.ms_median, "localize_ms_p90": r.ms_p90,
                    "ms_per_frame_median": describe_median + r.ms_median,
                }),
            )
        })
        .collect();
    if args.json {
        println!(
            "{}",
            json!({
                "backend": map.descriptor().to_string(), "seed": args.seed,
                "places": map.place_count(), "views": map.view_count(), "edges": map.edge_count(),
                "views_per_place": args.capture.views_per_place,
                "frames": sequence.frames.len(), "condition": condition.name(),
                "local_features": features.name(),
                "off_world": {"style": off_world.style, "frames": OFF_WORLD_FRAMES, "lead_in": LEAD_IN,
                              "settle": SETTLE_FRAMES},
                "map_load_ms": load_ms, "map_file_kib": file_kib,
                "seconds": {"world": t.world_s, "skeleton": t.skeleton_s, "capture": t.capture_s,
                            "map": t.map_s, "total": start.elapsed().as_secs_f64()},
                "configurations": configurations, "plotted_configuration": best.name,
                "mna": best.mna, "oha": best.oha, "r_at_1": best.r_at_1, "r_at_5": best.r_at_5,
                "describe_ms_median": describe_median,
                "ms_per_frame_median": describe_median + best.ms_median, "peak_rss_mb": peak_rss,
            })
        );
        return Ok(());
    }
    print_table(&results);
    println!(
        "top view ({}): {} (MNA {:.3}, OHA {:.3}), the highest MNA (ties: OHA, then the order above)",
        args.plot.display(),
        best.name,
        best.mna,
        best.oha
    );
    println!(
        "latency per frame: describe {describe_median:.2} ms (median, one image per thread) + localize (above)"
    );
    println!(
        "peak resident memory: {peak_rss:.1} MiB; total {:.1} s",
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Frames flown through another world for the off-map test, and frames of the flight before them.
const OFF_WORLD_FRAMES: usize = 100;
const LEAD_IN: usize = 100;

/// Places verified per frame in the verification configuration.
const VERIFIED_PLACES: usize = 5;

/// The configuration the top view draws and the JSON's top-level figures describe: the highest
/// MNA, ties broken by the higher OHA, then by the earlier in `results` (the table's order, which
/// puts the cheaper first). `None` when `results` is empty.
pub(crate) fn plotted_configuration(results: &[ConfigResult]) -> Option<&ConfigResult> {
    results.iter().reduce(|best, r| {
        let better = r.mna.total_cmp(&best.mna).then(r.oha.total_cmp(&best.oha));
        if better.is_gt() {
            r
        } else {
            best
        }
    })
}

/// The map's local features: the ones asked for, else XFeat when its model is in the cache and
/// the backend is ONNX (their off-map evidence is calibrated, BENCHMARKS.md), else ORB.
fn demo_features(
    asked: Option<crate::backend_args::LocalFeatures>,
    backend: &BackendConfig,
) -> (FeatureKind, String) {
    let xfeat = cache_dir().join(DEFAULT_XFEAT_MODEL_FILE);
    match (asked, backend) {
        (Some(f), _) => (f.into(), "asked for".into()),
        (None, BackendConfig::Onnx(_)) if xfeat.is_file() => (
            FeatureKind::XFeat,
            format!("XFeat (model found: {})", xfeat.display()),
        ),
        (None, _) => (
            FeatureKind::Orb,
            format!(
                "ORB: no XFeat model at {} or no ONNX backend (run scripts/setup-models.sh); ORB inliers do not inform the off-map flag",
                xfeat.display()
            ),
        ),
    }
}

fn print_table(results: &[ConfigResult]) {
    println!();
    println!(
        "{:<28} {:>6} {:>6} {:>6} {:>6} {:>6} {:>7} {:>6} {:>8} {:>9} {:>10} {:>10}",
        "configuration",
        "MNA",
        "OHA",
        "R@1",
        "R@5",
        "AP",
        "R@100P",
        "ECE",
        "off-map",
        "off-world",
        "ms median",
        "ms p90"
    );
    for r in results {
        let off_world = r
            .off_world
            .map_or("-".into(), |o| format!("{:.3}", o.flagged_after_settle));
        println!(
            "{:<28} {:>6.3} {:>6.3} {:>6.3} {:>6.3} {:>6.3} {:>7.3} {:>6.3} {:>8.3} {:>9} {:>10.3} {:>10.3}",
            r.name, r.mna, r.oha, r.r_at_1, r.r_at_5, r.average_precision, r.r_at_100p, r.ece, r.off_map_rate, off_world, r.ms_median, r.ms_p90
        );
    }
    println!();
    println!("MNA: predicted place is the true place. OHA (= R@1): within one graph hop. R@5: any of the top 5 within one hop.");
    println!("AP / R@100P: precision-recall with the confidence as score (correct = true place); R@100P is the recall at 100% precision.");
    println!("ECE: expected calibration error of the confidence (10 bins). Latency: one thread, filter step only.");
    println!("off-map: share of the flight's (on-map) frames flagged off-map. off-world: share of frames from another world flagged after the first {SETTLE_FRAMES}.");
}

/// A localizer on `map`; with the map's describer when it verifies by dense cells, which come
/// from the describer's forward pass.
fn localizer(map: &Arc<Map>, options: LocalizerOptions) -> Result<Localizer> {
    let cells = map.keypoints().map(|k| k.kind()) == Some(FeatureKind::Cells);
    Ok(match cells && options.verification.enabled() {
        true => Localizer::with_describer(map.clone(), options, &DescriberOptions::default())?,
        false => Localizer::new(map.clone(), options)?,
    })
}

/// Localizes every frame of `sequence` with `options` and computes the metrics; `images` (one
/// per frame) are given to the localizer beside the descriptors, for verification.
pub(crate) fn evaluate(
    name: &'static str,
    map: &Arc<Map>,
    sequence: &Sequence,
    hops: &HopDistances,
    options: LocalizerOptions,
    use_odometry: bool,
    images: Option<&[ImageView<'_>]>,
) -> Result<ConfigResult> {
    let mut localizer = localizer(map, options)?;
    let image_only = localizer.wants_image_only();
    let mut out = Localization::default();
    let mut predictions = Vec::with_capacity(sequence.frames.len());
    let mut latencies = Vec::with_capacity(sequence.frames.len());
    let mut off_map = 0usize;
    for (i, f) in sequence.frames.iter().enumerate() {
        let frame = Frame {
            timestamp: f.timestamp,
            descriptor: if image_only { &[] } else { &f.descriptor },
            odometry: use_odometry.then_some(f.odometry),
            image: images.map(|images| images[i]),
        };
        let start = Instant::now();
        localizer.process(&frame, &mut out)?;
        latencies.push(start.elapsed().as_secs_f64() * 1e3);
        off_map += usize::from(out.off_map);
        predictions.push(Prediction {
            truth: f.truth_place,
            ranked: out.candidates.iter().map(|c| c.place).collect(),
            confidence: out.confidence,
            frames: None,
        });
    }
    let evaluator = GraphEvaluator::new(hops, &predictions)?;
    let metrics = evaluator.metrics(&[1, 5]);
    let outcomes = evaluator.scored_outcomes(0);
    let pr = precision_recall(&outcomes)?;
    let calibration = calibration(&outcomes, 10)?;
    let (ms_median, ms_p90) = median_and_p90(&latencies);
    Ok(ConfigResult {
        name,
        mna: metrics.mna,
        oha: metrics.oha,
        r_at_1: evaluator.recall_at_n(1),
        r_at_5: evaluator.recall_at_n(5),
        average_precision: pr.average_precision,
        r_at_100p: pr.recall_at_full_precision,
        ece: calibration.expected_calibration_error,
        off_map_rate: off_map as f64 / predictions.len().max(1) as f64,
        off_world: None,
        ms_median,
        ms_p90,
        predicted: predictions
            .iter()
            .map(|p| p.top1().unwrap_or(PlaceId::MAX))
            .collect(),
    })
}
