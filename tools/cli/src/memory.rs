//! `topoloc bench-memory`: map file size, load time and resident memory of a loaded map, its
//! localizer (with the map's describer: ONNX Runtime and the model, for maps built from images)
//! and frames, measured stage by stage in a fresh child process so that nothing the parent did
//! (generating a map, parsing arguments) counts.

use crate::backend_args::RuntimeArgs;
use crate::frames::{open_images, Clock, StemUnit};
use crate::process::{median_and_p90, resident_memory_mib};
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;
use topoloc::map::LoadOptions;
use topoloc::{Frame, Localization, Localizer, LocalizerOptions, Map};

/// Options of `bench-memory`.
#[derive(Args, Clone, Debug)]
pub struct BenchMemoryArgs {
    /// Views in the generated map (4 per place); not used with --map.
    #[arg(long, default_value_t = 10_000)]
    pub views: usize,
    /// Descriptor dimension of the generated map; not used with --map.
    #[arg(long, default_value_t = 512)]
    pub dim: usize,
    /// Measure this map built from images instead of a generated one: its localizer describes
    /// the frames of --images with the map's stored describer (for ONNX maps: ONNX Runtime and
    /// the model are loaded and counted).
    #[arg(long, requires = "images")]
    pub map: Option<PathBuf>,
    /// Folder of query images for --map (file-name order).
    #[arg(long, requires = "map")]
    pub images: Option<PathBuf>,
    /// Frames localized before the last reading (generated maps: view descriptors).
    #[arg(long, default_value_t = 50)]
    pub frames: usize,
    #[command(flatten)]
    pub runtime: RuntimeArgs,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of the hidden child command `measure-map`.
#[derive(Args, Clone, Debug)]
pub struct MeasureArgs {
    /// The map to measure.
    pub map: PathBuf,
    /// Query images (maps built from images); without them, frames are view descriptors.
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Frames localized before the last reading.
    #[arg(long, default_value_t = 50)]
    pub frames: usize,
    #[command(flatten)]
    pub runtime: RuntimeArgs,
}

/// Generates a map (or takes `--map`), then measures it in a child process.
pub fn run(args: &BenchMemoryArgs) -> Result<()> {
    let dir = tempfile::tempdir()?;
    let path = match &args.map {
        Some(map) => map.clone(),
        None => {
            let path = dir.path().join("bench.topoloc");
            topoloc_synthetic::random_map(args.views, 4, args.dim, 11).save(&path)?;
            path
        }
    };
    let file_bytes = std::fs::metadata(&path)
        .with_context(|| format!("--map {}", path.display()))?
        .len();
    let mut child = std::process::Command::new(std::env::current_exe()?);
    child
        .arg("measure-map")
        .arg(&path)
        .arg("--frames")
        .arg(args.frames.to_string());
    if let Some(images) = &args.images {
        child.arg("--images").arg(images);
    }
    if let Some(model) = &args.runtime.onnx_model {
        child.arg("--onnx-model").arg(model);
    }
    if let Some(runtime) = &args.runtime.onnx_runtime {
        child.arg("--onnx-runtime").arg(runtime);
    }
    let output = child.output()?;
    if !output.status.success() {
        bail!(
            "measure-map failed: {}",
            String::from_utf8_lossy(&output.stderr)
        );
    }
    let mut report: serde_json::Value =
        serde_json::from_slice(&output.stdout).context("measure-map output")?;
    let file_mib = file_bytes as f64 / (1 << 20) as f64;
    let extra = serde_json::json!({
        "map": path,
        "generated": args.map.is_none(),
        "file_bytes": file_bytes,
        "file_mib": file_mib,
    });
    for (key, value) in extra.as_object().expect("an object") {
        report[key] = value.clone();
    }
    if args.json {
        println!("{report}");
    } else {
        print_report(&report);
    }
    Ok(())
}

fn print_report(r: &serde_json::Value) {
    let f = |key: &str| r[key].as_f64().unwrap_or(f64::NAN);
    println!(
        "map {} ({} places, {} views, D = {}{})",
        r["map"].as_str().unwrap_or("?"),
        r["places"],
        r["views"],
        r["dim"],
        r["describer"]
            .as_str()
            .map_or(String::new(), |d| format!(", {d}"))
    );
    println!(
        "  file size           {:.1} MiB ({} bytes)",
        f("file_mib"),
        r["file_bytes"]
    );
    println!("  load time (median)  {:.2} ms", f("load_ms_median"));
    println!("  resident memory, MiB (stage: total, added)");
    println!("    bare process      {:.1}", f("rss_start_mib"));
    println!(
        "    + map             {:.1}  +{:.1} ({:.2} x the file)",
        f("rss_map_mib"),
        f("map_mib"),
        f("map_mib") / f("file_mib")
    );
    println!(
        "    + localizer       {:.1}  +{:.1}{}",
        f("rss_localizer_mib"),
        f("localizer_mib"),
        if r["describer"].is_string() {
            " (describer: runtime and model)"
        } else {
            ""
        }
    );
    println!(
        "    + {} frames      {:.1}  +{:.1}",
        r["frames"],
        f("rss_frames_mib"),
        f("frames_mib")
    );
    println!("    peak              {:.1}", f("peak_rss_mib"));
    println!("  frame time (median) {:.2} ms", f("frame_ms_median"));
}

fn resident() -> Result<(f64, f64)> {
    resident_memory_mib().context("needs /proc/self/status")
}

/// Child side: loads the map once (the map's cost), then 10 more times for the load time,
/// makes a localizer (with the map's describer when frames are images), localizes the frames,
/// and prints every stage's resident memory as JSON.
pub fn measure(args: &MeasureArgs) -> Result<()> {
    let (rss_start, _) = resident()?;
    let map = Arc::new(Map::load(&args.map, &LoadOptions::default())?);
    let (rss_map, _) = resident()?;
    let mut load_ms = Vec::new();
    for _ in 0..10 {
        let start = Instant::now();
        let again = Map::load(&args.map, &LoadOptions::default())?;
        load_ms.push(start.elapsed().as_secs_f64() * 1e3);
        drop(again);
    }
    let (rss_after_loads, _) = resident()?;

    let mut localizer = match &args.images {
        Some(_) => Localizer::with_describer(
            map.clone(),
            LocalizerOptions::default(),
            &args.runtime.describer_options(None),
        )?,
        None => Localizer::new(map.clone(), LocalizerOptions::default())?,
    };
    let (rss_localizer, _) = resident()?;

    let mut out = Localization::default();
    let mut frame_ms = Vec::new();
    match &args.images {
        Some(dir) => {
            let clock = Clock {
                fps: Some(10.0),
                start: 0.0,
                stem_unit: StemUnit::S,
            };
            let mut source = open_images(dir, &clock)?.source;
            while frame_ms.len() < args.frames {
                let Some(frame) = source.next_frame()? else {
                    break;
                };
                let pixels = frame.pixels.map_err(anyhow::Error::msg)?;
                let start = Instant::now();
                localizer.process(
                    &Frame {
                        timestamp: frame.timestamp,
                        descriptor: &[],
                        odometry: None,
                        image: Some(pixels.view()),
                    },
                    &mut out,
                )?;
                frame_ms.push(start.elapsed().as_secs_f64() * 1e3);
            }
        }
        None => {
            for i in 0..args.frames {
                let view = (i * 97 % map.view_count()) as u32;
                let descriptor = map.view_descriptor(view)?.to_vec();
                let start = Instant::now();
                localizer.process(
                    &Frame {
                        timestamp: i as f64,
                        descriptor: &descriptor,
                        odometry: None,
                        image: None,
                    },
                    &mut out,
                )?;
                frame_ms.push(start.elapsed().as_secs_f64() * 1e3);
            }
        }
    }
    let (rss_frames, peak) = resident()?;
    let (load_median, _) = median_and_p90(&load_ms);
    let (frame_median, _) = median_and_p90(&frame_ms);
    println!(
        "{}",
        serde_json::json!({
            "places": map.place_count(),
            "views": map.view_count(),
            "dim": map.dim(),
            "describer": map.describer().map(|_| map.descriptor().to_string()),
            "load_ms_median": load_median,
            "frames": frame_ms.len(),
            "frame_ms_median": frame_median,
            "rss_start_mib": rss_start,
            "rss_map_mib": rss_map,
            "rss_after_loads_mib": rss_after_loads,
            "rss_localizer_mib": rss_localizer,
            "rss_frames_mib": rss_frames,
            "peak_rss_mib": peak,
            "map_mib": rss_map - rss_start,
            "localizer_mib": rss_localizer - rss_after_loads,
            "frames_mib": rss_frames - rss_localizer,
        })
    );
    Ok(())
}
