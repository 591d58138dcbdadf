//! `topoloc eval`: localizes a query image folder against a map built from images and reports
//! place-recognition quality, single-frame and with the temporal filter.
//!
//! Query frame i is correct when the predicted map image lies within `--tolerance` frames of
//! map image i (frame-aligned sets such as Gardens Point or Nordland). The predicted map image
//! is the source image of the best view of the predicted place (views record their image index
//! as keyframe id). With `--gt-nodes`, MNA, OHA and R@N over the map graph are reported too.

use crate::backend_args::{image_files, progress_bar, Backend, RuntimeArgs};
use crate::plot::{write_evaluation_png, Series};
use crate::process::median_and_p90;
use anyhow::{bail, Context, Result};
use clap::Args;
use rayon::prelude::*;
use serde_json::{json, Map as JsonMap, Value};
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;
use topoloc::describe::image::{read_rgb, ImageView, PixelFormat};
use topoloc::describe::{DescribeError, Describer};
use topoloc::eval::{
    precision_recall, recall_at_n_frames, FrameRanking, GraphEvaluator, HopDistances, Prediction,
    ScoredOutcome,
};
use topoloc::map::PlaceId;
use topoloc::{Frame, LoadOptions, Localization, Localizer, LocalizerOptions, Map, Mode};

/// Options of `eval`.
#[derive(Args, Clone, Debug)]
pub struct EvalArgs {
    /// Map built by `topoloc build-map`.
    #[arg(long)]
    pub map: PathBuf,
    /// Folder of query images, in frame order.
    #[arg(long)]
    pub images: PathBuf,
    /// Frame tolerance for a correct match (frame-aligned sets).
    #[arg(long, default_value_t = 2)]
    pub tolerance: usize,
    /// Only evaluate single-frame localization (no temporal filter).
    #[arg(long)]
    pub single_frame: bool,
    /// Ground-truth place per query frame, CSV `query_index,place`: adds MNA, OHA and R@N.
    #[arg(long)]
    pub gt_nodes: Option<PathBuf>,
    /// Refuse the map unless it was built with this backend.
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    #[command(flatten)]
    pub runtime: RuntimeArgs,
    /// Localizer temperature (default: the library's).
    #[arg(long)]
    pub temperature: Option<f32>,
    /// Write one CSV row per query frame: `query_index,predicted_index,confidence`, then the
    /// next candidates as `index:probability`.
    #[arg(long)]
    pub predictions: Option<PathBuf>,
    /// Write a PNG: similarity matrix with ground truth and predictions, precision-recall curves.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Describing threads (0: one per core); latency figures are per image on one thread each.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Print one JSON object on stdout instead of text.
    #[arg(long)]
    pub json: bool,
}

/// One configuration's per-frame answers.
struct ModeRun {
    name: &'static str,
    /// Predicted map image per query frame (`None`: no answer, e.g. an uninformative image).
    predicted: Vec<Option<usize>>,
    rankings: Vec<FrameRanking>,
    candidates: Vec<Vec<(usize, f32)>>,
    places: Vec<Vec<PlaceId>>,
    outcomes: Vec<ScoredOutcome>,
    localize_ms: Vec<f64>,
}

/// Runs the command.
pub fn run(args: &EvalArgs) -> Result<()> {
    let map = Arc::new(
        Map::load(&args.map, &LoadOptions::default())
            .with_context(|| format!("loading {}", args.map.display()))?,
    );
    let model = map.describer().cloned().with_context(|| {
        format!(
            "{} stores no describer: eval needs a map made by `topoloc build-map`",
            args.map.display()
        )
    })?;
    let describer_options = args.runtime.describer_options(args.backend);
    // Load once on this thread so that a missing or mismatching backend fails clearly.
    Describer::new(model.clone(), &describer_options)?;
    let files = image_files(&args.images)?;
    let view_image = view_image_indices(&map);
    let map_images = view_image.iter().max().map_or(0, |m| m + 1);

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads)
        .build()?;
    let bar = progress_bar(files.len(), "describing");
    let described: Vec<(Option<Vec<f32>>, f64)> = pool.install(|| {
        files
            .par_iter()
            .map_init(
                || Describer::new(model.clone(), &describer_options),
                |describer, path| -> Result<(Option<Vec<f32>>, f64)> {
                    let describer = describer.as_mut().map_err(|e| anyhow::anyhow!("{e}"))?;
                    let (w, h, rgb) = read_rgb(path)?;
                    let mut out = Vec::new();
                    let start = Instant::now();
                    let result = describer
                        .describe(&ImageView::packed(w, h, PixelFormat::Rgb8, &rgb), &mut out);
                    let ms = start.elapsed().as_secs_f64() * 1e3;
                    bar.inc(1);
                    match result {
                        Ok(()) => Ok((Some(out), ms)),
                        Err(DescribeError::Uninformative(_)) => Ok((None, ms)),
                        Err(e) => Err(anyhow::anyhow!("{}: {e}", path.display())),
                    }
                },
            )
            .collect::<Result<Vec<_>>>()
    })?;
    bar.finish_and_clear();
    let describe_ms: Vec<f64> = described.iter().map(|d| d.1).collect();
    let uninformative: Vec<usize> = (0..described.len())
        .filter(|&i| described[i].0.is_none())
        .collect();

    let gt_nodes = match &args.gt_nodes {
        Some(path) => Some(read_gt_nodes(path, files.len(), map.place_count())?),
        None => None,
    };
    let modes: &[(&str, Mode)] = if args.single_frame {
        &[("single_frame", Mode::SingleFrame)]
    } else {
        &[
            ("single_frame", Mode::SingleFrame),
            ("filter", Mode::Filter),
        ]
    };
    let mut similarity = vec![f32::NAN; files.len() * map_images];
    let mut runs = Vec::new();
    let mut report_temperature = 0.0;
    for &(name, mode) in modes {
        let mut options = LocalizerOptions {
            mode,
            top_k: 10,
            ..LocalizerOptions::default()
        };
        if let Some(t) = args.temperature {
            options.temperature = t;
        }
        let mut localizer = Localizer::new(map.clone(), options)?;
        report_temperature = localizer.options().temperature;
        let run = localize_all(
            name,
            &mut localizer,
            &described,
            &view_image,
            args.tolerance,
            (mode == Mode::SingleFrame).then_some((&mut similarity, map_images)),
        )?;
        runs.push(run);
    }

    let mut report = JsonMap::new();
    report.insert("map".into(), json!(args.map.display().to_string()));
    report.insert("descriptor".into(), json!(map.descriptor().to_string()));
    report.insert("frames".into(), json!(files.len()));
    report.insert("map_images".into(), json!(map_images));
    report.insert("tolerance".into(), json!(args.tolerance));
    report.insert("uninformative_frames".into(), json!(uninformative.len()));
    report.insert("similarity_spread".into(), json!(map.similarity_spread()));
    report.insert("temperature".into(), json!(report_temperature));
    let describe_median = median_and_p90(&describe_ms).0;
    report.insert("describe_ms_median".into(), json!(describe_median));
    let mut curves = Vec::new();
    for run in &runs {
        let (summary, curve) = summarize(run, args.tolerance, gt_nodes.as_deref(), &map)?;
        report.insert(run.name.into(), summary);
        curves.push(curve);
    }
    // The headline figures are those of the last configuration: the filter unless
    // --single-frame; ms per frame is describe + localize of each frame.
    let primary = runs.last().expect("at least one mode");
    if let Value::Object(fields) = report[primary.name].clone() {
        for (k, v) in fields {
            report.insert(k, v);
        }
    }
    let per_frame: Vec<f64> = describe_ms
        .iter()
        .zip(&primary.localize_ms)
        .map(|(d, l)| d + l)
        .collect();
    report.insert(
        "ms_per_frame_median".into(),
        json!(median_and_p90(&per_frame).0),
    );
    report.insert("mode".into(), json!(primary.name));

    if let Some(path) = &args.predictions {
        write_predictions(path, primary)?;
    }
    if let Some(path) = &args.plot {
        let predicted: Vec<Vec<usize>> = runs
            .iter()
            .map(|r| {
                r.predicted
                    .iter()
                    .map(|p| p.unwrap_or(usize::MAX))
                    .collect()
            })
            .collect();
        let series: Vec<Series> = runs
            .iter()
            .zip(&predicted)
            .zip(&curves)
            .map(|((r, p), c)| Series {
                name: r.name,
                predicted: p,
                precision_recall: c,
            })
            .collect();
        let truth: Vec<usize> = (0..files.len()).collect();
        let title = format!("{} vs {}", args.images.display(), args.map.display());
        write_evaluation_png(
            path,
            &title,
            &similarity,
            files.len(),
            map_images,
            Some(&truth),
            &series,
        )?;
    }

    if args.json {
        println!("{}", Value::Object(report));
    } else {
        print_table(&report, &runs, describe_median);
    }
    Ok(())
}

/// Source image index of every view (its keyframe id; the view index when absent).
fn view_image_indices(map: &Map) -> Vec<usize> {
    map.views()
        .iter()
        .enumerate()
        .map(|(v, r)| r.keyframe_id.map_or(v, |k| k as usize))
        .collect()
}

fn localize_all(
    name: &'static str,
    localizer: &mut Localizer,
    described: &[(Option<Vec<f32>>, f64)],
    view_image: &[usize],
    tolerance: usize,
    mut similarity: Option<(&mut Vec<f32>, usize)>,
) -> Result<ModeRun> {
    let mut run = ModeRun {
        name,
        predicted: Vec::with_capacity(described.len()),
        rankings: Vec::with_capacity(described.len()),
        candidates: Vec::with_capacity(described.len()),
        places: Vec::with_capacity(described.len()),
        outcomes: Vec::with_capacity(described.len()),
        localize_ms: Vec::with_capacity(described.len()),
    };
    let mut out = Localization::default();
    for (i, (descriptor, _)) in described.iter().enumerate() {
        let Some(descriptor) = descriptor else {
            run.predicted.push(None);
            run.rankings.push(FrameRanking {
                truth: i,
                ranked: Vec::new(),
            });
            run.candidates.push(Vec::new());
            run.places.push(Vec::new());
            run.outcomes.push(ScoredOutcome {
                confidence: 0.0,
                correct: false,
            });
            run.localize_ms.push(0.0);
            continue;
        };
        let start = Instant::now();
        localizer.process(
            &Frame {
                timestamp: i as f64,
                descriptor,
                odometry: None,
                image: None,
            },
            &mut out,
        )?;
        run.localize_ms.push(start.elapsed().as_secs_f64() * 1e3);
        if let Some((matrix, columns)) = similarity.as_mut() {
            let row = &mut matrix[i * *columns..(i + 1) * *columns];
            for (v, &s) in localizer.last_view_similarities().iter().enumerate() {
                let cell = &mut row[view_image[v]];
                *cell = if cell.is_nan() { s } else { cell.max(s) };
            }
        }
        let ranked: Vec<usize> = out
            .candidates
            .iter()
            .map(|c| view_image[c.view as usize])
            .collect();
        run.predicted.push(Some(ranked[0]));
        run.outcomes.push(ScoredOutcome {
            confidence: out.confidence,
            correct: ranked[0].abs_diff(i) <= tolerance,
        });
        run.candidates.push(
            out.candidates
                .iter()
                .zip(&ranked)
                .map(|(c, &img)| (img, c.probability))
                .collect(),
        );
        run.places
            .push(out.candidates.iter().map(|c| c.place).collect());
        run.rankings.push(FrameRanking { truth: i, ranked });
    }
    Ok(run)
}

/// Metrics of one configuration, and its PR curve as (recall, precision) points.
fn summarize(
    run: &ModeRun,
    tolerance: usize,
    gt_nodes: Option<&[PlaceId]>,
    map: &Map,
) -> Result<(Value, Vec<(f64, f64)>)> {
    let pr = precision_recall(&run.outcomes)?;
    let mut summary = json!({
        "r_at_1": recall_at_n_frames(&run.rankings, tolerance, 1),
        "r_at_5": recall_at_n_frames(&run.rankings, tolerance, 5),
        "r_at_10": recall_at_n_frames(&run.rankings, tolerance, 10),
        "r_at_100p": pr.recall_at_full_precision,
        "average_precision": pr.average_precision,
        "localize_ms_median": median_and_p90(&run.localize_ms).0,
    });
    if let Some(truth) = gt_nodes {
        let predictions: Vec<Prediction> = truth
            .iter()
            .zip(&run.places)
            .zip(&run.outcomes)
            .map(|((&truth, ranked), o)| Prediction {
                truth,
                ranked: ranked.clone(),
                confidence: o.confidence,
                frames: None,
            })
            .collect();
        let hops = HopDistances::from_map(map);
        let metrics = GraphEvaluator::new(&hops, &predictions)?.metrics(&[1, 5, 10]);
        summary["mna"] = json!(metrics.mna);
        summary["oha"] = json!(metrics.oha);
        for r in metrics.recall_at_n {
            summary[format!("graph_r_at_{}", r.n)] = json!(r.recall);
        }
    }
    let curve = pr.points.iter().map(|p| (p.recall, p.precision)).collect();
    Ok((summary, curve))
}

/// Reads `query_index,place` rows (a header line is allowed) into one place per query frame.
fn read_gt_nodes(path: &PathBuf, frames: usize, places: usize) -> Result<Vec<PlaceId>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut truth = vec![None; frames];
    for (number, line) in text.lines().enumerate() {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let (Some(Ok(query)), Some(Ok(place))) = (
            fields.first().map(|f| f.parse::<usize>()),
            fields.get(1).map(|f| f.parse::<PlaceId>()),
        ) else {
            if number == 0 {
                continue; // header
            }
            bail!(
                "{} line {}: expected query_index,place",
                path.display(),
                number + 1
            );
        };
        if query >= frames || place as usize >= places {
            bail!(
                "{} line {}: query {query} or place {place} out of range ({frames} frames, {places} places)",
                path.display(),
                number + 1
            );
        }
        truth[query] = Some(place);
    }
    truth
        .into_iter()
        .enumerate()
        .map(|(i, t)| t.with_context(|| format!("{} has no row for query {i}", path.display())))
        .collect()
}

fn write_predictions(path: &PathBuf, run: &ModeRun) -> Result<()> {
    let mut file = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
    );
    writeln!(file, "query_index,predicted_index,confidence,candidates...")?;
    for (i, (predicted, outcome)) in run.predicted.iter().zip(&run.outcomes).enumerate() {
        match predicted {
            Some(p) => write!(file, "{i},{p},{:.6}", outcome.confidence)?,
            None => write!(file, "{i},-1,0")?,
        }
        for (index, score) in run.candidates[i].iter().skip(1) {
            write!(file, ",{index}:{score:.6}")?;
        }
        writeln!(file)?;
    }
    file.flush()?;
    Ok(())
}

fn print_table(report: &JsonMap<String, Value>, runs: &[ModeRun], describe_median: f64) {
    println!(
        "map {} ({}), {} query frames, tolerance +-{}",
        report["map"].as_str().unwrap_or_default(),
        report["descriptor"].as_str().unwrap_or_default(),
        report["frames"],
        report["tolerance"]
    );
    println!(
        "similarity spread {:.3}, filter temperature {:.3}",
        report["similarity_spread"].as_f64().unwrap_or(0.0),
        report["temperature"].as_f64().unwrap_or(0.0)
    );
    if report["uninformative_frames"].as_u64() != Some(0) {
        println!(
            "{} query frames without content were not localized (counted wrong)",
            report["uninformative_frames"]
        );
    }
    println!(
        "\n{:<14} {:>6} {:>6} {:>7} {:>6} {:>6} {:>6} {:>12}",
        "mode", "R@1", "R@5", "R@100P", "AP", "MNA", "OHA", "localize ms"
    );
    let f = |v: &Value| v.as_f64().map_or("-".to_string(), |x| format!("{x:.3}"));
    for run in runs {
        let s = &report[run.name];
        println!(
            "{:<14} {:>6} {:>6} {:>7} {:>6} {:>6} {:>6} {:>12.3}",
            run.name.replace('_', "-"),
            f(&s["r_at_1"]),
            f(&s["r_at_5"]),
            f(&s["r_at_100p"]),
            f(&s["average_precision"]),
            f(&s["mna"]),
            f(&s["oha"]),
            s["localize_ms_median"].as_f64().unwrap_or(0.0)
        );
    }
    println!(
        "\ndescribe {describe_median:.1} ms per image (median, one thread each); describe + localize {:.1} ms per frame",
        report["ms_per_frame_median"].as_f64().unwrap_or(0.0)
    );
}
