//! `topoloc eval-verify`: does geometric verification tell the true place from look-alikes on
//! real images? For every query image (every `--step`-th of a frame-aligned folder, such as
//! Gardens Point day_right against a day_left map), the map's places are ranked by appearance
//! (single frame, best view per place), the top `--top` are verified with the local features
//! the map stores, and the report gives:
//! - the inlier medians of correct candidates (within `--tolerance` frames) and wrong ones;
//! - the share of queries whose correct candidate out-scores every wrong one;
//! - R@1 by appearance alone and after re-ranking the top candidates by inliers (ties by
//!   appearance);
//! - the medians of describe, detect and per-candidate check times (this thread alone).

use crate::backend_args::{image_files, RuntimeArgs};
use crate::eval::view_image_indices;
use crate::process::median_and_p90;
use anyhow::{bail, Context, Result};
use clap::Args;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;
use topoloc::describe::Describer;
use topoloc::image::{read_rgb, ImageView, PixelFormat};
use topoloc::verify::{
    cells_from_map, check_pair, spatial_check, FeatureDetector, FeatureKind, FundamentalEstimator,
    PairOptions, CELL_TAP, DEFAULT_KEYPOINTS,
};
use topoloc::{LoadOptions, Map};

/// Options of `eval-verify`.
#[derive(Args, Clone, Debug)]
pub struct VerifyEvalArgs {
    /// Map built from images with keypoints (`topoloc build-map`).
    #[arg(long)]
    pub map: PathBuf,
    /// Query images, frame-aligned with the map's images (query i is map image i).
    #[arg(long)]
    pub images: PathBuf,
    /// Every how many-th query image is used.
    #[arg(long, default_value_t = 2)]
    pub step: usize,
    /// Candidates verified per query (appearance top places).
    #[arg(long, default_value_t = 5)]
    pub top: usize,
    /// Frames a candidate may be off and still be correct.
    #[arg(long, default_value_t = 2)]
    pub tolerance: usize,
    /// Keypoints detected per query image.
    #[arg(long, default_value_t = DEFAULT_KEYPOINTS)]
    pub query_keypoints: usize,
    /// Fit the fundamental matrix with MAGSAC++ instead of RANSAC.
    #[arg(long)]
    pub magsac: bool,
    /// RANSAC iterations at most.
    #[arg(long, default_value_t = PairOptions::default().max_iterations)]
    pub iterations: u32,
    /// Inlier threshold, pixels.
    #[arg(long, default_value_t = PairOptions::default().ransac_threshold_px)]
    pub threshold: f64,
    /// Where the ONNX files are.
    #[command(flatten)]
    pub runtime: RuntimeArgs,
    /// Also write every verified pair as CSV (query, candidate map image, similarity, inliers).
    #[arg(long)]
    pub pairs: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// One verified candidate.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    /// Map image index.
    image: usize,
    /// Appearance similarity.
    similarity: f32,
    /// GC: fundamental-matrix inliers.
    inliers: u32,
    /// s-GC: the sampling-free spatial score.
    spatial: f32,
}

/// One query's verified candidates, in appearance order.
type Checked = Vec<Candidate>;

/// Runs the command.
pub fn run(args: &VerifyEvalArgs) -> Result<()> {
    if args.step == 0 || args.top == 0 {
        bail!("--step and --top must be at least 1");
    }
    let map = Map::load(&args.map, &LoadOptions::default())
        .with_context(|| format!("loading {}", args.map.display()))?;
    let keypoints = map.keypoints().with_context(|| {
        format!(
            "{} stores no keypoints: build it with --verification-keypoints > 0",
            args.map.display()
        )
    })?;
    let model = map
        .describer()
        .cloned()
        .with_context(|| format!("{} stores no describer", args.map.display()))?;
    let mut describer = Describer::new(model, &args.runtime.describer_options(None))?;
    let kind = keypoints.kind();
    let mut detector = match kind {
        FeatureKind::Cells => None,
        _ => Some(FeatureDetector::new(
            kind,
            args.query_keypoints,
            &args.runtime.xfeat_options(),
        )?),
    };
    let view_image = view_image_indices(&map);
    let files = image_files(&args.images)?;
    let pair = PairOptions {
        estimator: if args.magsac {
            FundamentalEstimator::Magsac
        } else {
            FundamentalEstimator::Ransac
        },
        max_iterations: args.iterations,
        ransac_threshold_px: args.threshold,
        ..PairOptions::default()
    };
    pair.validate().map_err(anyhow::Error::msg)?;
    let (mut times_describe, mut times_detect) = (vec![], vec![]);
    let (mut times_check, mut times_spatial) = (vec![], vec![]);
    let mut results: Vec<(usize, Checked)> = Vec::new();
    for (q, path) in files.iter().enumerate().step_by(args.step) {
        let (w, h, rgb) = read_rgb(path)?;
        let image = ImageView::packed(w, h, PixelFormat::Rgb8, &rgb);
        let start = Instant::now();
        let mut descriptor = Vec::new();
        let query = match &mut detector {
            Some(detector) => {
                describer.describe(&image, &mut descriptor)?;
                times_describe.push(ms(start));
                let start = Instant::now();
                let query = detector.detect(&image)?;
                times_detect.push(ms(start));
                query
            }
            None => {
                let tap = describer.describe_with_tap(&image, &mut descriptor, CELL_TAP)?;
                times_describe.push(ms(start));
                let start = Instant::now();
                let query = cells_from_map(
                    &tap.values,
                    [tap.channels, tap.height, tap.width],
                    tap.cell_size,
                    args.query_keypoints,
                )?;
                times_detect.push(ms(start));
                query
            }
        };
        let mut scored: Vec<(usize, f32)> = (0..map.view_count())
            .map(|v| {
                let row = map.view_descriptor(v as u32).expect("view in range");
                (v, dot(row, &descriptor))
            })
            .collect();
        scored.sort_by(|a, b| b.1.total_cmp(&a.1));
        let mut checked = Checked::new();
        for &(v, similarity) in scored.iter().take(args.top) {
            let view = keypoints.view(v).expect("view in range");
            let start = Instant::now();
            let check = check_pair(query.as_ref(), view, &pair)?;
            times_check.push(ms(start));
            let start = Instant::now();
            let spatial = spatial_check(query.as_ref(), view, pair.max_hamming)?;
            times_spatial.push(ms(start));
            checked.push(Candidate {
                image: view_image[v],
                similarity,
                inliers: check.inliers,
                spatial: spatial.score,
            });
        }
        results.push((q, checked));
    }
    if let Some(path) = &args.pairs {
        let mut csv = String::from("query,candidate,similarity,inliers,spatial\n");
        for (q, checked) in &results {
            for c in checked {
                csv.push_str(&format!(
                    "{q},{},{},{},{}\n",
                    c.image, c.similarity, c.inliers, c.spatial
                ));
            }
        }
        std::fs::write(path, csv).with_context(|| format!("writing {}", path.display()))?;
    }
    report(
        args,
        &map,
        &results,
        [&times_describe, &times_detect, &times_check, &times_spatial],
    )
}

fn ms(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}

fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Median of counts, NaN when there are none.
fn median(values: &[f64]) -> f64 {
    if values.is_empty() {
        f64::NAN
    } else {
        median_and_p90(values).0
    }
}

/// The candidate ranked first by `key` (ties: the earlier in appearance order).
fn best_by<K: PartialOrd>(checked: &Checked, key: impl Fn(&Candidate) -> K) -> Option<usize> {
    let mut best: Option<&Candidate> = None;
    for c in checked {
        if best.is_none_or(|b| key(c) > key(b)) {
            best = Some(c);
        }
    }
    best.map(|c| c.image)
}

/// Prints the figures described in the module documentation.
fn report(
    args: &VerifyEvalArgs,
    map: &Map,
    results: &[(usize, Checked)],
    times: [&[f64]; 4],
) -> Result<()> {
    let correct = |q: usize, image: usize| q.abs_diff(image) <= args.tolerance;
    let (mut right, mut wrong, mut far) = (Vec::new(), Vec::new(), Vec::new());
    let mut hits = [0usize; 3];
    let (mut discriminated, mut with_correct) = (0, 0);
    for (q, checked) in results {
        for c in checked {
            let inliers = f64::from(c.inliers);
            match q.abs_diff(c.image) {
                d if d <= args.tolerance => right.push(inliers),
                d if d >= FAR_FRAMES => {
                    wrong.push(inliers);
                    far.push(inliers);
                }
                _ => wrong.push(inliers),
            }
        }
        let rankings = [
            checked.first().map(|c| c.image),
            best_by(checked, |c| c.inliers),
            best_by(checked, |c| c.spatial),
        ];
        for (hit, best) in hits.iter_mut().zip(rankings) {
            *hit += usize::from(best.is_some_and(|image| correct(*q, image)));
        }
        let best_right = checked
            .iter()
            .filter(|c| correct(*q, c.image))
            .map(|c| c.inliers)
            .max();
        let best_wrong = checked
            .iter()
            .filter(|c| !correct(*q, c.image))
            .map(|c| c.inliers)
            .max();
        if let Some(r) = best_right {
            with_correct += 1;
            discriminated += usize::from(best_wrong.is_none_or(|w| r > w));
        }
    }
    let n = results.len().max(1) as f64;
    let [r1_appearance, r1_gc, r1_sgc] = hits.map(|h| h as f64 / n);
    let (right_median, wrong_median, far_median) = (median(&right), median(&wrong), median(&far));
    let [describe, detect, check, spatial] = times.map(|t| median_and_p90(t).0);
    let kind = map.keypoints().map(|k| k.kind().name()).unwrap_or("none");
    let out = json!({
        "map": args.map.display().to_string(),
        "images": args.images.display().to_string(),
        "features": kind,
        "queries": results.len(),
        "top": args.top,
        "tolerance": args.tolerance,
        "query_keypoints": args.query_keypoints,
        "estimator": if args.magsac { "magsac" } else { "ransac" },
        "r1_appearance": r1_appearance,
        "r1_reranked_gc": r1_gc,
        "r1_reranked_sgc": r1_sgc,
        "correct_in_top": with_correct,
        "discrimination": discriminated as f64 / (with_correct.max(1) as f64),
        "inliers_correct_median": right_median,
        "inliers_wrong_median": wrong_median,
        "inliers_far_median": far_median,
        "far_candidates": far.len(),
        "describe_ms_median": describe,
        "detect_ms_median": detect,
        "gc_ms_median": check,
        "sgc_ms_median": spatial,
    });
    if args.json {
        println!("{out}");
    } else {
        println!(
            "{kind}: {} queries, top {}: R@1 appearance {r1_appearance:.3}, re-ranked by GC {r1_gc:.3}, by s-GC {r1_sgc:.3}; inliers correct {right_median} vs wrong {wrong_median} (vs {far_median} at {FAR_FRAMES}+ frames, {} such); correct out-scores every wrong in {discriminated} of {with_correct}; describe {describe:.1} ms, detect {detect:.1} ms, GC {check:.2} ms, s-GC {spatial:.3} ms per candidate (medians)",
            results.len(),
            args.top,
            far.len(),
        );
    }
    Ok(())
}

/// Candidates at least this many frames from the query count as far (the look-alikes of
/// another part of the route rather than the next frames of the same place).
const FAR_FRAMES: usize = 10;
