//! `topoloc demo`: the main job on an embedded default. Generates a world (a graph of places
//! with four yaw views each, perceptual aliasing, D = 512 descriptors), saves and reloads its
//! map, flies a camera through it under a changed condition, localizes every frame with three
//! configurations, and prints the seed's metrics, precision-recall, calibration and latency.

use crate::process::{median_and_p90, resident_memory_mib};
use anyhow::Result;
use serde_json::json;
use std::sync::Arc;
use std::time::Instant;
use topoloc::eval::{calibration, precision_recall, GraphEvaluator, HopDistances, Prediction};
use topoloc::map::LoadOptions;
use topoloc::synthetic::{Sequence, SyntheticWorld, WorldParams};
use topoloc::{Frame, Localization, Localizer, LocalizerOptions, Map, Mode};

/// Demo settings (command-line options).
pub struct DemoArgs {
    /// World seed.
    pub seed: u64,
    /// Number of places in the generated world.
    pub places: usize,
    /// Frames in the query sequence.
    pub frames: usize,
    /// Print one JSON object instead of the table.
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
    pub ms_median: f64,
    pub ms_p90: f64,
}

pub fn run(args: &DemoArgs) -> Result<()> {
    let params = WorldParams {
        places: args.places,
        seed: args.seed,
        ..WorldParams::default()
    };
    let say = |text: String| {
        if !args.json {
            println!("{text}");
        }
    };
    let start = Instant::now();
    let world = SyntheticWorld::generate(&params)?;
    let generated = world.map();
    say(format!(
        "world: {} places, {} views, {} edges, D={} (seed {}), generated in {:.0} ms",
        generated.place_count(),
        generated.view_count(),
        generated.edge_count(),
        generated.dim(),
        args.seed,
        start.elapsed().as_secs_f64() * 1e3
    ));

    let dir = tempfile::tempdir()?;
    let path = dir.path().join("demo.topoloc");
    generated.save(&path)?;
    let start = Instant::now();
    let map = Arc::new(Map::load(&path, &LoadOptions::default())?);
    let load_ms = start.elapsed().as_secs_f64() * 1e3;
    let file_kib = std::fs::metadata(&path)?.len() as f64 / 1024.0;
    say(format!(
        "map file: {file_kib:.0} KiB, loaded (memory-mapped, validated) in {load_ms:.2} ms"
    ));

    let sequence = world.sequence(args.frames, args.seed.wrapping_add(1));
    say(format!(
        "query: {} frames at {} Hz, {} m/s, under a changed condition (shift {}), noise {}",
        sequence.frames.len(),
        params.frame_rate,
        params.speed,
        params.condition_shift,
        params.query_noise
    ));

    let spread = map.similarity_spread();
    say(format!(
        "similarity spread of the map (median std of a view's similarities to other places): {spread:.3}"
    ));
    let hops = HopDistances::from_map(&map);
    let configs = [
        ("single-frame", Mode::SingleFrame, false),
        ("filter", Mode::Filter, false),
        ("filter+odometry", Mode::Filter, true),
    ];
    let mut results = Vec::new();
    for (name, mode, odometry) in configs {
        let options = LocalizerOptions {
            mode,
            ..LocalizerOptions::default()
        };
        results.push(evaluate(name, &map, &sequence, &hops, options, odometry)?);
    }
    let (_, peak_rss) = resident_memory_mib().unwrap_or((0.0, 0.0));

    if args.json {
        let configurations: serde_json::Map<String, serde_json::Value> = results
            .iter()
            .map(|r| {
                (
                    r.name.to_string(),
                    json!({
                        "mna": r.mna, "oha": r.oha, "r_at_1": r.r_at_1, "r_at_5": r.r_at_5,
                        "average_precision": r.average_precision, "r_at_100p": r.r_at_100p,
                        "expected_calibration_error": r.ece, "off_map_rate": r.off_map_rate,
                        "ms_per_frame_median": r.ms_median, "ms_per_frame_p90": r.ms_p90,
                    }),
                )
            })
            .collect();
        let best = results
            .iter()
            .find(|r| r.name == "filter")
            .expect("configured: the default localizer");
        println!(
            "{}",
            json!({
                "places": map.place_count(), "views": map.view_count(), "dim": map.dim(),
                "frames": sequence.frames.len(), "map_load_ms": load_ms, "map_file_kib": file_kib,
                "configurations": configurations,
                "mna": best.mna, "oha": best.oha, "r_at_1": best.r_at_1, "r_at_5": best.r_at_5,
                "ms_per_frame_median": best.ms_median, "peak_rss_mb": peak_rss,
            })
        );
        return Ok(());
    }

    println!();
    println!(
        "{:<16} {:>6} {:>6} {:>6} {:>6} {:>6} {:>7} {:>6} {:>8} {:>10} {:>10}",
        "configuration",
        "MNA",
        "OHA",
        "R@1",
        "R@5",
        "AP",
        "R@100P",
        "ECE",
        "off-map",
        "ms median",
        "ms p90"
    );
    for r in &results {
        println!(
            "{:<16} {:>6.3} {:>6.3} {:>6.3} {:>6.3} {:>6.3} {:>7.3} {:>6.3} {:>8.3} {:>10.3} {:>10.3}",
            r.name, r.mna, r.oha, r.r_at_1, r.r_at_5, r.average_precision, r.r_at_100p, r.ece, r.off_map_rate, r.ms_median, r.ms_p90
        );
    }
    println!();
    println!("MNA: predicted place is the true place. OHA (= R@1): within one graph hop. R@5: any of the top 5 within one hop.");
    println!("AP / R@100P: precision-recall with the confidence as score (correct = true place); R@100P is the recall at 100% precision.");
    println!("ECE: expected calibration error of the confidence (10 bins). Latency: one thread, whole localize step.");
    println!("peak resident memory: {peak_rss:.1} MiB");
    Ok(())
}

/// Localizes every frame of `sequence` with `options` and computes the metrics.
pub(crate) fn evaluate(
    name: &'static str,
    map: &Arc<Map>,
    sequence: &Sequence,
    hops: &HopDistances,
    options: LocalizerOptions,
    use_odometry: bool,
) -> Result<ConfigResult> {
    let mut localizer = Localizer::new(map.clone(), options)?;
    let mut out = Localization::default();
    let mut predictions = Vec::with_capacity(sequence.frames.len());
    let mut latencies = Vec::with_capacity(sequence.frames.len());
    let mut off_map = 0usize;
    for f in &sequence.frames {
        let frame = Frame {
            timestamp: f.timestamp,
            descriptor: &f.descriptor,
            odometry: use_odometry.then_some(f.odometry),
            image: None,
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
        ms_median,
        ms_p90,
    })
}
