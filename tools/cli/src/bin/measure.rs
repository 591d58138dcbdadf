//! `topoloc-measure`, the child process of `topoloc bench-memory`: loads a map, makes its
//! localizer (with the map's describer when frames are images), localizes frames, and prints
//! the resident memory of every stage as one JSON object. It links only the library and what
//! the measurement needs, so its bare process costs what a host linking libtopoloc pays.
//!
//! `topoloc-measure MAP [--images DIR] [--frames N] [--onnx-runtime LIB] [--onnx-model FILE]`

#[path = "../process.rs"]
mod process;

use anyhow::{Context, Result};
use clap::Parser;
use process::{median_and_p90, resident_memory_mib};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;
use topoloc::describe::DescriberOptions;
use topoloc::image::{read_rgb, ImageView, PixelFormat};
use topoloc::map::LoadOptions;
use topoloc::{Frame, Localization, Localizer, LocalizerOptions, Map};

/// Arguments (see the module documentation).
#[derive(Parser, Debug)]
#[command(name = "topoloc-measure", about = "Child of `topoloc bench-memory`")]
struct MeasureArgs {
    /// The map to measure.
    map: PathBuf,
    /// Query images (maps built from images), in file-name order; without them, frames are
    /// view descriptors.
    #[arg(long)]
    images: Option<PathBuf>,
    /// Frames localized before the last reading.
    #[arg(long, default_value_t = 50)]
    frames: usize,
    /// ONNX Runtime library (default: the library's search).
    #[arg(long)]
    onnx_runtime: Option<PathBuf>,
    /// ONNX model file (default: the cache's).
    #[arg(long)]
    onnx_model: Option<PathBuf>,
}

fn main() -> Result<()> {
    measure(&MeasureArgs::parse())
}

fn resident() -> Result<(f64, f64)> {
    resident_memory_mib().context("needs /proc/self/status")
}

/// Loads the map (the map's cost), makes a localizer (with the map's describer when frames
/// are images), localizes the frames, reads the peak, then times 10 more loads, and prints
/// every stage's resident memory as JSON.
fn measure(args: &MeasureArgs) -> Result<()> {
    let (rss_start, _) = resident()?;
    let map = Arc::new(Map::load(&args.map, &LoadOptions::default())?);
    let (rss_map, _) = resident()?;

    let mut localizer = match &args.images {
        Some(_) => Localizer::with_describer(
            map.clone(),
            LocalizerOptions::default(),
            &DescriberOptions {
                onnx_runtime: args.onnx_runtime.clone(),
                onnx_model: args.onnx_model.clone(),
                ..DescriberOptions::default()
            },
        )?,
        None => Localizer::new(map.clone(), LocalizerOptions::default())?,
    };
    let (rss_localizer, _) = resident()?;

    let mut out = Localization::default();
    let mut frame_ms = Vec::new();
    match &args.images {
        Some(dir) => {
            let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
                .with_context(|| format!("--images {}", dir.display()))?
                .map(|e| e.map(|e| e.path()))
                .collect::<Result<_, _>>()?;
            files.sort();
            for (i, file) in files.iter().take(args.frames).enumerate() {
                let (width, height, rgb) = read_rgb(file)
                    .with_context(|| format!("--images: {} is not an image", file.display()))?;
                let start = Instant::now();
                localizer.process(
                    &Frame {
                        timestamp: i as f64 * 0.1,
                        descriptor: &[],
                        odometry: None,
                        image: Some(ImageView::packed(width, height, PixelFormat::Rgb8, &rgb)),
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
    // The load time last, so that its extra maps count in no reading.
    let mut load_ms = Vec::new();
    for _ in 0..10 {
        let start = Instant::now();
        let again = Map::load(&args.map, &LoadOptions::default())?;
        load_ms.push(start.elapsed().as_secs_f64() * 1e3);
        drop(again);
    }
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
            "rss_localizer_mib": rss_localizer,
            "rss_frames_mib": rss_frames,
            "peak_rss_mib": peak,
            "map_mib": rss_map - rss_start,
            "localizer_mib": rss_localizer - rss_map,
            "frames_mib": rss_frames - rss_localizer,
        })
    );
    Ok(())
}
