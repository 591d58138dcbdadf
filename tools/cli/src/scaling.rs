//! `topoloc scaling`: per-frame localization time against map size, as the seed thesis'
//! Fig. 4.11 (20-300 places there; 20 to 2,000 places here by default).
//!
//! For each size it generates a synthetic corridor world ([`SyntheticWorld`]: places on a
//! lattice joined by a random spanning tree plus some loops, degree 1-4, unit descriptors) and
//! walks a query stream along its graph (descriptors interpolated between views plus noise, with
//! odometry). One localizer per configuration (single-frame, filter, filter given odometry)
//! processes the same frames, interleaved frame by frame so that load from other processes
//! affects every configuration alike, on one thread, after a warm-up. Only `Localizer::process`
//! is timed: describing the image is a constant cost per frame (see [`DESCRIBE_MS`]).
//!
//! Prints a markdown table (or one JSON object with `--json`) and writes a PNG of milliseconds
//! per frame against places, both axes logarithmic.

use crate::plot::{
    draw_light_legend, ensure_font, font, label_axes, legend_line, DrawResult, SERIES_COLORS,
};
use crate::process::median_and_p90;
use anyhow::{anyhow, bail, Result};
use plotters::prelude::*;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Instant;
use topoloc::describe::FitOptions;
use topoloc::{Frame, Localization, Localizer, LocalizerOptions, Mode};
use topoloc_synthetic::{SyntheticWorld, WorldParams};

/// Frames processed by every localizer before timing starts (caches, page faults, filter
/// settling); they precede the timed frames on the same walk.
const WARMUP_FRAMES: usize = 50;

/// Median describe time per frame in ms, `(JSON key, backend, ms)`: BENCHMARKS.md's
/// "Descriptor and describe time" (`cargo bench --bench describe`, i8 PCA rows); independent of
/// the map size.
const DESCRIBE_MS: [(&str, &str, f64); 2] = [("onnx", "ONNX MLF", 7.17), ("vlad", "VLAD", 1.49)];

/// Localizer configurations timed: JSON key, label in the table and plot, mode, odometry given.
const CONFIGURATIONS: [(&str, &str, Mode, bool); 3] = [
    ("single_frame", "single-frame", Mode::SingleFrame, false),
    ("filter", "filter", Mode::Filter, false),
    ("filter_odometry", "filter+odometry", Mode::Filter, true),
];

/// Options of `scaling`.
#[derive(clap::Args, Clone, Debug)]
pub struct ScalingArgs {
    /// Map sizes to measure, in places (comma-separated).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "20,50,100,200,300,500,1000,2000"
    )]
    pub sizes: Vec<usize>,
    /// Views (micro nodes) per place.
    #[arg(long, default_value_t = WorldParams::default().views_per_place)]
    pub views_per_place: usize,
    /// Descriptor dimension (default: the describers' PCA output dimension).
    #[arg(long, default_value_t = FitOptions::default().dim)]
    pub dim: usize,
    /// Timed query frames per size (after the warm-up frames).
    #[arg(long, default_value_t = 500)]
    pub frames: usize,
    /// Seed of the generated worlds and query walks.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// PNG of milliseconds per frame against places, one line per configuration.
    #[arg(long, default_value = "topoloc-scaling.png")]
    pub plot: PathBuf,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
}

/// Per-frame times of one configuration at one size, in ms.
#[derive(Clone, Copy, Debug)]
struct Timing {
    median: f64,
    p90: f64,
}

/// Measurements at one map size.
#[derive(Debug)]
struct SizeResult {
    places: usize,
    views: usize,
    edges: usize,
    /// Bytes of the map's descriptor matrix (views x dim f32).
    descriptor_bytes: usize,
    /// One entry per [`CONFIGURATIONS`] entry, in that order.
    timings: Vec<Timing>,
}

/// Runs the command.
pub fn run(args: &ScalingArgs) -> Result<()> {
    if args.sizes.is_empty() || args.sizes.contains(&0) {
        bail!("--sizes needs one or more place counts >= 1");
    }
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let mut sizes = args.sizes.clone();
    sizes.sort_unstable();
    sizes.dedup();
    let mut results = Vec::with_capacity(sizes.len());
    for &places in &sizes {
        let result = measure(args, places)?;
        if !args.json {
            eprintln!(
                "{places} places: single-frame {:.4} ms, filter {:.4} ms (medians)",
                result.timings[0].median, result.timings[1].median
            );
        }
        results.push(result);
    }
    write_plot(&args.plot, args, &results)?;
    if args.json {
        println!("{}", report(args, &results));
    } else {
        print_table(args, &results);
        println!("plot written to {}", args.plot.display());
    }
    Ok(())
}

/// Generates the world of `places` places and times every configuration on one walk.
fn measure(args: &ScalingArgs, places: usize) -> Result<SizeResult> {
    let world = SyntheticWorld::generate(&WorldParams {
        places,
        views_per_place: args.views_per_place,
        dim: args.dim,
        seed: args.seed,
        ..WorldParams::default()
    })?;
    let map = world.map();
    let sequence = world.sequence(WARMUP_FRAMES + args.frames, args.seed.wrapping_add(1));
    let mut localizers = CONFIGURATIONS
        .iter()
        .map(|&(_, _, mode, _)| {
            Localizer::new(
                map.clone(),
                LocalizerOptions {
                    mode,
                    ..LocalizerOptions::default()
                },
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut out = Localization::default();
    let mut samples = vec![Vec::with_capacity(args.frames); CONFIGURATIONS.len()];
    for (i, f) in sequence.frames.iter().enumerate() {
        for ((localizer, times), &(_, _, _, odometry)) in
            localizers.iter_mut().zip(&mut samples).zip(&CONFIGURATIONS)
        {
            let frame = Frame {
                timestamp: f.timestamp,
                descriptor: &f.descriptor,
                odometry: odometry.then_some(f.odometry),
                image: None,
            };
            let start = Instant::now();
            localizer.process(&frame, &mut out)?;
            let ms = start.elapsed().as_secs_f64() * 1e3;
            if i >= WARMUP_FRAMES {
                times.push(ms);
            }
        }
    }
    let timings = samples
        .iter()
        .map(|times| {
            let (median, p90) = median_and_p90(times);
            Timing { median, p90 }
        })
        .collect();
    Ok(SizeResult {
        places: map.place_count(),
        views: map.view_count(),
        edges: map.edge_count(),
        descriptor_bytes: std::mem::size_of_val(map.descriptors()),
        timings,
    })
}

/// The JSON report: settings, describe times for reference, and one object per size.
fn report(args: &ScalingArgs, results: &[SizeResult]) -> Value {
    let sizes: Vec<Value> = results
        .iter()
        .map(|r| {
            let mut size = json!({
                "places": r.places,
                "views": r.views,
                "edges": r.edges,
                "descriptor_bytes": r.descriptor_bytes,
            });
            for (&(key, ..), t) in CONFIGURATIONS.iter().zip(&r.timings) {
                size[key] = json!({"ms_median": t.median, "ms_p90": t.p90});
            }
            size
        })
        .collect();
    let describe: serde_json::Map<String, Value> = DESCRIBE_MS
        .iter()
        .map(|&(key, _, ms)| (key.to_string(), json!(ms)))
        .collect();
    json!({
        "views_per_place": args.views_per_place,
        "dim": args.dim,
        "frames": args.frames,
        "warmup_frames": WARMUP_FRAMES,
        "seed": args.seed,
        "describe_ms_median": describe,
        "plot": args.plot.display().to_string(),
        "sizes": sizes,
    })
}

/// Prints the markdown table and what it leaves out.
fn print_table(args: &ScalingArgs, results: &[SizeResult]) {
    println!(
        "Per-frame localization, one thread, D = {}, {} views per place, {} timed frames per size \
         after {WARMUP_FRAMES} warm-up frames (synthetic corridor worlds, seed {}):",
        args.dim, args.views_per_place, args.frames, args.seed
    );
    println!();
    let mut header = "| places | views | edges | descriptors |".to_string();
    let mut rule = "|---|---|---|---|".to_string();
    for &(_, label, ..) in &CONFIGURATIONS {
        header.push_str(&format!(" {label} median | {label} p90 |"));
        rule.push_str("---|---|");
    }
    println!("{header}");
    println!("{rule}");
    for r in results {
        let mut row = format!(
            "| {} | {} | {} | {:.2} MiB |",
            r.places,
            r.views,
            r.edges,
            r.descriptor_bytes as f64 / (1 << 20) as f64
        );
        for t in &r.timings {
            row.push_str(&format!(" {:.4} ms | {:.4} ms |", t.median, t.p90));
        }
        println!("{row}");
    }
    println!();
    let describe: Vec<String> = DESCRIBE_MS
        .iter()
        .map(|(_, backend, ms)| format!("~{ms} ms ({backend})"))
        .collect();
    println!(
        "Localization only: describing each frame adds {} whatever the map size \
         (BENCHMARKS.md, `cargo bench --bench describe`).",
        describe.join(" / ")
    );
}

/// Writes the PNG: median (solid, with markers) and p90 (dashed) ms per frame against places,
/// one colour per configuration, logarithmic axes.
fn write_plot(path: &Path, args: &ScalingArgs, results: &[SizeResult]) -> Result<()> {
    ensure_font()?;
    let root = BitMapBackend::new(path, (1000, 650)).into_drawing_area();
    draw_plot(&root, args, results)
        .map_err(|e| anyhow!("drawing scaling plot {}: {e}", path.display()))?;
    root.present()
        .map_err(|e| anyhow!("writing scaling plot {}: {e}", path.display()))?;
    Ok(())
}

/// Draws the scaling chart onto `root`.
fn draw_plot<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    args: &ScalingArgs,
    results: &[SizeResult],
) -> DrawResult<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let places = |r: &SizeResult| r.places as f64;
    let x_min = results.iter().map(places).fold(f64::INFINITY, f64::min);
    let x_max = results.iter().map(places).fold(0.0, f64::max);
    let all = results.iter().flat_map(|r| &r.timings);
    let y_min = all.clone().map(|t| t.median).fold(f64::INFINITY, f64::min);
    let y_max = all.map(|t| t.p90).fold(0.0, f64::max);
    // Log axes need positive bounds; a timer cannot resolve below a nanosecond anyway.
    let y_min = y_min.max(1e-6);
    let y_max = y_max.max(y_min * 10.0);
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!(
                "per-frame localization vs map size (D = {}, {} views/place, one thread; \
                 solid: median, dashed: p90)",
                args.dim, args.views_per_place
            ),
            font(20),
        )
        .margin(15)
        .margin_right(30)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (x_min / 1.2..x_max * 1.2).log_scale(),
            (y_min / 1.5..y_max * 1.5).log_scale(),
        )?;
    let ticks = |v: &f64| tick(*v);
    let mut mesh = chart.configure_mesh();
    label_axes(&mut mesh, "places", "ms per frame (localize only)", &ticks);
    mesh.light_line_style(RGBColor(235, 235, 235)).draw()?;
    for (k, &(_, label, ..)) in CONFIGURATIONS.iter().enumerate() {
        let color = SERIES_COLORS[k % SERIES_COLORS.len()];
        let medians: Vec<(f64, f64)> = results
            .iter()
            .map(|r| (places(r), r.timings[k].median))
            .collect();
        chart
            .draw_series(LineSeries::new(medians.clone(), color.stroke_width(2)))?
            .label(label)
            .legend(legend_line(color.stroke_width(2)));
        chart.draw_series(medians.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
        chart.draw_series(DashedLineSeries::new(
            results.iter().map(|r| (places(r), r.timings[k].p90)),
            6,
            4,
            color.mix(0.7).stroke_width(1),
        ))?;
    }
    draw_light_legend(&mut chart, SeriesLabelPosition::UpperLeft)
}

/// Axis label of a logarithmic tick: at most three significant digits, no trailing zeros.
fn tick(v: f64) -> String {
    if !(v.is_finite() && v > 0.0) {
        return format!("{v}");
    }
    let decimals = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    let text = format!("{v:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

#[cfg(test)]
mod tests {
    use super::tick;

    #[test]
    fn ticks_are_short() {
        assert_eq!(tick(2000.0), "2000");
        assert_eq!(tick(20.0), "20");
        assert_eq!(tick(0.5), "0.5");
        assert_eq!(tick(0.030000000000000002), "0.03");
        assert_eq!(tick(0.00123456), "0.00123");
    }
}
