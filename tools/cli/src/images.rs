//! `topoloc eval-images`: place recognition on real, frame-aligned image sequences with the
//! ONNX multi-level backend. The map folder's frames become a sequence map (one place per frame,
//! edges between consecutive frames, PCA fitted on the map frames); every query frame is then
//! localized single-frame and with the graph filter. Query frame i is correct when the predicted
//! map frame lies within `tolerance` frames of i.

use crate::process::median_and_p90;
use anyhow::{bail, Context, Result};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use topoloc::describe::image::{read_rgb, ImageView, PixelFormat};
use topoloc::describe::onnx::{OnnxMlf, OnnxOptions};
use topoloc::describe::pca::Pca;
use topoloc::eval::{precision_recall, recall_at_n_frames, FrameRanking, ScoredOutcome};
use topoloc::{
    DescriptorIdentity, Frame, Localization, Localizer, LocalizerOptions, MapBuilder, Mode,
};

/// Options of the command.
pub struct EvalImagesArgs {
    pub map_images: PathBuf,
    pub images: PathBuf,
    pub tolerance: usize,
    pub dim: usize,
    pub taps: Vec<String>,
    pub grid: (usize, usize),
    pub temperature: f32,
    pub pca_samples: usize,
    pub json: bool,
}

fn image_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading image folder {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
                ["jpg", "jpeg", "png", "bmp"].contains(&e.to_ascii_lowercase().as_str())
            })
        })
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("no images (jpg, png, bmp) in {}", dir.display());
    }
    Ok(files)
}

/// Raw multi-level vectors of every image in `files`, and the per-image time in ms.
fn describe_all(backend: &mut OnnxMlf, files: &[PathBuf]) -> Result<(Vec<Vec<f32>>, Vec<f64>)> {
    let mut out = Vec::with_capacity(files.len());
    let mut times = Vec::with_capacity(files.len());
    for f in files {
        let (w, h, rgb) = read_rgb(f)?;
        let start = Instant::now();
        out.push(backend.raw_features(&ImageView::packed(w, h, PixelFormat::Rgb8, &rgb))?);
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    Ok((out, times))
}

pub fn run(args: &EvalImagesArgs) -> Result<()> {
    let options = OnnxOptions {
        taps: args.taps.clone(),
        grid: args.grid,
        ..OnnxOptions::default()
    };
    let mut backend = OnnxMlf::new(options)?;
    let map_files = image_files(&args.map_images)?;
    let query_files = image_files(&args.images)?;
    let (map_raw, _) = describe_all(&mut backend, &map_files)?;
    let (query_raw, describe_ms) = describe_all(&mut backend, &query_files)?;

    let raw_dim = map_raw[0].len();
    // PCA on at most `pca_samples` map frames, evenly spaced (the thin SVD costs n^2 x raw_dim).
    let stride = map_raw.len().div_ceil(args.pca_samples.max(2));
    let fit_rows: Vec<f32> = map_raw.iter().step_by(stride).flatten().copied().collect();
    let pca = Pca::fit(&fit_rows, raw_dim, args.dim, false)?;
    let identity = DescriptorIdentity::new(
        "onnx-mlf",
        format!("{} pca={}", backend.identity(), pca.output_dim),
        pca.output_dim as u32,
    )?;
    let mut builder = MapBuilder::new(identity);
    for (i, raw) in map_raw.iter().enumerate() {
        let place = builder.add_place(None)?;
        builder.add_view(place, &pca.project(raw)?, Default::default())?;
        if i > 0 {
            builder.add_edge(place - 1, place, 1.0)?;
        }
    }
    let map = Arc::new(builder.build()?);
    let queries: Vec<Vec<f32>> = query_raw
        .iter()
        .map(|r| pca.project(r))
        .collect::<Result<_, _>>()?;

    let mut report = serde_json::Map::new();
    report.insert("frames".into(), json!(queries.len()));
    report.insert("map_frames".into(), json!(map.place_count()));
    report.insert("raw_dim".into(), json!(raw_dim));
    report.insert("dim".into(), json!(pca.output_dim));
    report.insert("descriptor".into(), json!(map.descriptor().model));
    report.insert(
        "describe_ms_median".into(),
        json!(median_and_p90(&describe_ms).0),
    );
    report.insert(
        "similarity_std_median".into(),
        json!(similarity_spread(&map, &queries)),
    );
    if !args.json {
        println!(
            "map: {} frames from {}; query: {} frames from {}",
            map.place_count(),
            args.map_images.display(),
            queries.len(),
            args.images.display()
        );
        println!(
            "descriptor: {} (raw {raw_dim} -> PCA {})",
            map.descriptor().model,
            pca.output_dim
        );
        println!(
            "describe: {:.1} ms per image (median, one thread)",
            median_and_p90(&describe_ms).0
        );
        println!(
            "\n{:<14} {:>6} {:>6} {:>7} {:>6} {:>10}",
            "mode", "R@1", "R@5", "R@100P", "AP", "ms median"
        );
    }
    for (name, mode) in [
        ("single-frame", Mode::SingleFrame),
        ("filter", Mode::Filter),
    ] {
        let options = LocalizerOptions {
            mode,
            temperature: args.temperature,
            top_k: 5,
            ..Default::default()
        };
        let mut localizer = Localizer::new(map.clone(), options)?;
        let mut out = Localization::default();
        let mut rankings = Vec::with_capacity(queries.len());
        let mut outcomes = Vec::with_capacity(queries.len());
        let mut times = Vec::with_capacity(queries.len());
        for (i, q) in queries.iter().enumerate() {
            let start = Instant::now();
            localizer.process(
                &Frame {
                    timestamp: i as f64,
                    descriptor: q,
                    odometry: None,
                },
                &mut out,
            )?;
            times.push(start.elapsed().as_secs_f64() * 1e3);
            let ranked: Vec<usize> = out.candidates.iter().map(|c| c.place as usize).collect();
            outcomes.push(ScoredOutcome {
                confidence: out.confidence,
                correct: ranked[0].abs_diff(i) <= args.tolerance,
            });
            rankings.push(FrameRanking { truth: i, ranked });
        }
        let r1 = recall_at_n_frames(&rankings, args.tolerance, 1);
        let r5 = recall_at_n_frames(&rankings, args.tolerance, 5);
        let pr = precision_recall(&outcomes)?;
        let ms = median_and_p90(&times).0;
        if !args.json {
            println!(
                "{name:<14} {r1:>6.3} {r5:>6.3} {:>7.3} {:>6.3} {ms:>10.3}",
                pr.recall_at_full_precision, pr.average_precision
            );
        }
        report.insert(
            name.replace('-', "_"),
            json!({"r_at_1": r1, "r_at_5": r5, "r_at_100p": pr.recall_at_full_precision, "average_precision": pr.average_precision, "localize_ms_median": ms}),
        );
    }
    if args.json {
        println!("{}", serde_json::Value::Object(report));
    } else {
        println!("\ntolerance: +-{} frames", args.tolerance);
    }
    Ok(())
}

/// Median over queries of the standard deviation of a query's similarities to all map views:
/// the scale that the localizer temperature is relative to.
pub(crate) fn similarity_spread(map: &topoloc::Map, queries: &[Vec<f32>]) -> f64 {
    let d = map.dim();
    let stds: Vec<f64> = queries
        .iter()
        .map(|q| {
            let sims: Vec<f64> = map
                .descriptors()
                .chunks_exact(d)
                .map(|v| v.iter().zip(q).map(|(a, b)| f64::from(a * b)).sum())
                .collect();
            let mean = sims.iter().sum::<f64>() / sims.len() as f64;
            (sims.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / sims.len() as f64).sqrt()
        })
        .collect();
    median_and_p90(&stds).0
}
