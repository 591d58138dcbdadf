//! `topoloc eval`: localizes a query image folder against a map built from images and reports
//! place-recognition quality, single-frame and with the temporal filter.
//!
//! Query frame i is correct when the predicted map image lies within `--tolerance` frames of
//! map image i (frame-aligned sets such as Gardens Point or Nordland). The predicted map image
//! is the source image of the best view of the predicted place (views record their image index
//! as keyframe id). With `--gt-nodes`, MNA, OHA and R@N over the map graph are reported too.
//!
//! With `--dataset` (a folder written by `topoloc simulate`, topoloc-sim format) the truth is the
//! dataset's place per frame instead: the seed's graph metrics MNA, OHA and R@1..R@10, for the
//! single-frame localizer, the filter and (with `--odometry`) the filter given the dataset's
//! odometry increments.

use crate::backend_args::{image_files, progress_bar, Backend, RuntimeArgs};
use crate::plot::{write_evaluation_png, Series};
use crate::process::median_and_p90;
use anyhow::{bail, Context, Result};
use clap::{ArgGroup, Args};
use nalgebra::Isometry3;
use rayon::prelude::*;
use serde_json::{json, Map as JsonMap, Value};
use std::fmt::Display;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use topoloc::describe::Describer;
use topoloc::errors::VisionError;
use topoloc::eval::{
    precision_recall, recall_at_n_frames, FrameRanking, GraphEvaluator, GraphMetrics, HopDistances,
    PrCurve, Prediction, ScoredOutcome,
};
use topoloc::image::{read_rgb, ImageView, PixelFormat};
use topoloc::map::PlaceId;
use topoloc::{
    Frame, GrnnOptions, LoadOptions, Localization, Localizer, LocalizerOptions, Map, Mode,
};
use topoloc_sim::dataset::{Dataset, GRAPH_FILE, RECALL_DEPTHS};

/// Options of `eval`.
#[derive(Args, Clone, Debug)]
#[command(group(ArgGroup::new("queries").required(true).args(["images", "dataset"])))]
pub struct EvalArgs {
    /// Map built by `topoloc build-map`.
    #[arg(long)]
    pub map: PathBuf,
    /// Folder of query images, in frame order.
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Dataset folder written by `topoloc simulate` (instead of --images): its images are the
    /// queries, its ground-truth nodes the truth; reports MNA, OHA and R@1..R@10. The map must
    /// be the one of the dataset's world.
    #[arg(long, conflicts_with_all = ["gt_nodes", "tolerance", "plot"])]
    pub dataset: Option<PathBuf>,
    /// With --dataset: also run the filter given the dataset's odometry (`filter_odometry`).
    #[arg(long, conflicts_with_all = ["images", "single_frame"])]
    pub odometry: bool,
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
    /// Places verified geometrically per frame with the local features the map stores (0: no
    /// verification); the off-map decision then reads their inliers
    /// (`VerificationOptions::off_map_inliers`).
    #[arg(long, default_value_t = 0)]
    pub verify: usize,
    /// With --verify: the most inliers at which a frame is as likely off the map as on it (0:
    /// the off-map decision stays with appearance); default the map's feature kind's.
    #[arg(long)]
    pub off_map_inliers: Option<f32>,
    /// With --verify: inliers per e-fold of the off-map likelihood ratio; default the library's.
    #[arg(long)]
    pub off_map_inlier_scale: Option<f32>,
    /// Write one CSV row per query frame: `query_index,predicted_index,confidence`, then the
    /// next candidates as `index:probability` (with --dataset: `frame,predicted_place,
    /// confidence`, then `place:probability`).
    #[arg(long)]
    pub predictions: Option<PathBuf>,
    /// Write a PNG: similarity matrix with ground truth and predictions, precision-recall curves.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Also run the learned GRNN (`Mode::Grnn`; with --verify, verifying as the others do).
    #[arg(long)]
    pub grnn: bool,
    /// With --grnn: its ONNX model (default: the one built into the library).
    #[arg(long, requires = "grnn")]
    pub grnn_model: Option<PathBuf>,
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
    /// Ranked candidates per frame as (map image, probability).
    candidates: Vec<Vec<(usize, f32)>>,
    /// Ranked candidates per frame as (place, probability).
    places: Vec<Vec<(PlaceId, f32)>>,
    /// Confidence per frame; `correct` is frame-aligned (image folders only).
    outcomes: Vec<ScoredOutcome>,
    /// Whether each frame was flagged off the map.
    off_map: Vec<bool>,
    localize_ms: Vec<f64>,
}

/// A query frame's descriptor (`None`: the image has no content) and its describe time, ms.
type Described = (Option<Vec<f32>>, f64);

/// Decodes query image `i` at `path` to packed RGB8: (width, height, bytes).
type ReadImage<'a> = dyn Fn(usize, &Path) -> Result<(u32, u32, Vec<u8>)> + Sync + 'a;

/// Runs the command.
pub fn run(args: &EvalArgs) -> Result<()> {
    if args.verify == 0 && (args.off_map_inliers.is_some() || args.off_map_inlier_scale.is_some()) {
        bail!("--off-map-inliers and --off-map-inlier-scale shape verification's evidence: give --verify N too");
    }
    let map = Arc::new(
        Map::load(&args.map, &LoadOptions::default())
            .with_context(|| format!("loading {}", args.map.display()))?,
    );
    match (&args.dataset, &args.images) {
        (Some(dataset), _) => run_dataset(args, dataset, &map),
        (None, Some(images)) => run_images(args, images, &map),
        (None, None) => bail!("give --images DIR or --dataset DIR"),
    }
}

/// Describes the query images in parallel (`--threads`) with the map's stored describer, with a
/// progress bar; `read` decodes image `i` at `paths[i]`. Errors name the image.
fn describe_frames(
    args: &EvalArgs,
    map: &Map,
    paths: &[PathBuf],
    read: &ReadImage<'_>,
) -> Result<Vec<Described>> {
    let model = map.describer().cloned().with_context(|| {
        format!(
            "{} stores no describer: eval needs a map made by `topoloc build-map` or `topoloc simulate`",
            args.map.display()
        )
    })?;
    let describer_options = args.runtime.describer_options(args.backend);
    // Load once on this thread so that a missing or mismatching backend fails clearly.
    Describer::new(model.clone(), &describer_options)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads)
        .build()?;
    let bar = progress_bar(paths.len(), "describing");
    let described = pool.install(|| {
        paths
            .par_iter()
            .enumerate()
            .map_init(
                || Describer::new(model.clone(), &describer_options),
                |describer, (i, path)| -> Result<Described> {
                    let describer = describer.as_mut().map_err(|e| anyhow::anyhow!("{e}"))?;
                    let (w, h, rgb) = read(i, path)?;
                    let mut out = Vec::new();
                    let start = Instant::now();
                    let result = describer
                        .describe(&ImageView::packed(w, h, PixelFormat::Rgb8, &rgb), &mut out);
                    let ms = start.elapsed().as_secs_f64() * 1e3;
                    bar.inc(1);
                    match result {
                        Ok(()) => Ok((Some(out), ms)),
                        Err(VisionError::Uninformative(_)) => Ok((None, ms)),
                        Err(e) => Err(anyhow::anyhow!("{}: {e}", path.display())),
                    }
                },
            )
            .collect::<Result<Vec<_>>>()
    })?;
    bar.finish_and_clear();
    Ok(described)
}

/// `eval --images`: frame-aligned truth (query i matches map image i), graph metrics with
/// `--gt-nodes`.
fn run_images(args: &EvalArgs, images: &Path, map: &Arc<Map>) -> Result<()> {
    let files = image_files(images)?;
    let view_image = view_image_indices(map);
    let map_images = view_image.iter().max().map_or(0, |m| m + 1);
    let read: &ReadImage<'_> = &|_, path| Ok(read_rgb(path)?);
    let described = describe_frames(args, map, &files, read)?;
    let gt_nodes = match &args.gt_nodes {
        Some(path) => Some(read_gt_nodes(path, files.len(), map.place_count())?),
        None => None,
    };
    let timestamps: Vec<f64> = (0..files.len()).map(|i| i as f64).collect();
    let mut similarity = vec![f32::NAN; files.len() * map_images];
    let queries = Queries {
        described: &described,
        timestamps: &timestamps,
        odometry: None,
        images: (args.verify > 0).then_some((files.as_slice(), read)),
    };
    let mut runs = Vec::new();
    for (name, mode, _) in configurations(args) {
        let similarity = (mode == Mode::SingleFrame).then_some((&mut similarity, map_images));
        let mut localizer = localizer(args, map, mode)?;
        let run = localize_all(
            name,
            &mut localizer,
            &queries,
            &view_image,
            args.tolerance,
            similarity,
        )?;
        runs.push(run);
    }

    let mut report = report_head(args, map, &described)?;
    report.insert("map_images".into(), json!(map_images));
    report.insert("tolerance".into(), json!(args.tolerance));
    let mut curves = Vec::new();
    for run in &runs {
        let (summary, curve) = summarize(run, args.tolerance, gt_nodes.as_deref(), map)?;
        report.insert(run.name.into(), summary);
        curves.push(curve);
    }
    let primary = add_headline(&mut report, &runs, &described);

    if let Some(path) = &args.predictions {
        let header = "query_index,predicted_index,confidence,candidates...";
        write_predictions(path, header, &primary.outcomes, &primary.candidates)?;
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
        let title = format!("{} vs {}", images.display(), args.map.display());
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
    print_report(args, report, &runs);
    Ok(())
}

/// `eval --dataset`: the dataset's place per frame is the truth; MNA, OHA and R@1..R@10 over the
/// map's graph, which must be the dataset's.
fn run_dataset(args: &EvalArgs, root: &Path, map: &Arc<Map>) -> Result<()> {
    let dataset = Dataset::open(root)
        .with_context(|| format!("--dataset {}: not a readable dataset", root.display()))?;
    check_same_graph(map, &args.map, &dataset)?;
    let n = dataset.frame_count();
    let paths: Vec<PathBuf> = (0..n).map(|i| dataset.image_path(i)).collect();
    let (width, height) = (dataset.intrinsics.width, dataset.intrinsics.height);
    let read: &ReadImage<'_> = &|i, _| Ok((width, height, dataset.read_image(i)?));
    let described = describe_frames(args, map, &paths, read)?;
    let timestamps: Vec<f64> = dataset.ground_truth.iter().map(|p| p.timestamp).collect();
    // previous_T_current of every frame from the odometry poses (identity for the first).
    let increments: Vec<Isometry3<f64>> = (0..n)
        .map(|i| match i {
            0 => Isometry3::identity(),
            _ => {
                let (a, b) = (&dataset.odometry[i - 1], &dataset.odometry[i]);
                a.world_t_camera.inverse() * b.world_t_camera
            }
        })
        .collect();
    let view_image = view_image_indices(map);
    let truth: Vec<PlaceId> = dataset.nodes.iter().map(|t| t.place).collect();
    let hops = HopDistances::from_map(map);
    let mut report = report_head(args, map, &described)?;
    report.insert("dataset".into(), json!(root.display().to_string()));
    let info = &dataset.manifest.info;
    report.insert("split".into(), json!(info.split));
    report.insert("world_seed".into(), json!(info.world_seed));
    report.insert("trajectory_seed".into(), json!(info.trajectory_seed));
    report.insert("condition".into(), json!(info.condition));
    report.insert("places".into(), json!(map.place_count()));
    let with_odometry = Queries {
        described: &described,
        timestamps: &timestamps,
        odometry: Some(&increments),
        images: (args.verify > 0).then_some((paths.as_slice(), read)),
    };
    let mut runs = Vec::new();
    for (name, mode, odometry) in configurations(args) {
        let queries = Queries {
            odometry: with_odometry.odometry.filter(|_| odometry),
            ..with_odometry
        };
        let mut localizer = localizer(args, map, mode)?;
        let run = localize_all(name, &mut localizer, &queries, &view_image, 0, None)?;
        let (metrics, pr) = graph_metrics(&run, &truth, &hops, &RECALL_DEPTHS)?;
        let mut summary = json!({
            "mna": metrics.mna,
            "oha": metrics.oha,
            "average_precision": pr.average_precision,
            "r_at_100p": pr.recall_at_full_precision,
            "localize_ms_median": median_and_p90(&run.localize_ms).0,
            "off_map_rate": share(&run.off_map),
            "off_map_rate_after_10": share(run.off_map.get(OFF_MAP_SETTLE..).unwrap_or_default()),
        });
        for r in &metrics.recall_at_n {
            summary[format!("r_at_{}", r.n)] = json!(r.recall);
        }
        report.insert(name.into(), summary);
        runs.push(run);
    }
    let primary = add_headline(&mut report, &runs, &described);
    if let Some(path) = &args.predictions {
        let header = "frame,predicted_place,confidence,candidates...";
        write_predictions(path, header, &primary.outcomes, &primary.places)?;
    }
    print_report(args, report, &runs);
    Ok(())
}

/// The localizer configurations `(name, mode, with odometry)` asked for: single-frame, the
/// filter unless `--single-frame`, the filter with odometry with `--odometry`, the GRNN with
/// `--grnn`. The last one that is not given odometry gives the headline figures.
fn configurations(args: &EvalArgs) -> Vec<(&'static str, Mode, bool)> {
    let mut configurations = vec![("single_frame", Mode::SingleFrame, false)];
    if !args.single_frame {
        configurations.push(("filter", Mode::Filter, false));
    }
    if args.grnn {
        configurations.push(("grnn", Mode::Grnn, false));
    }
    if args.odometry {
        configurations.push(("filter_odometry", Mode::Filter, true));
    }
    configurations
}

/// A localizer in `mode` keeping the top 10 candidates, at `--temperature` if given, verifying
/// `--verify` places per frame (with the map's describer, for dense cells).
fn localizer(args: &EvalArgs, map: &Arc<Map>, mode: Mode) -> Result<Localizer> {
    let mut options = LocalizerOptions {
        mode,
        top_k: 10,
        grnn: GrnnOptions {
            model: args.grnn_model.clone(),
            runtime: args.runtime.onnx_runtime.clone(),
            ..GrnnOptions::default()
        },
        ..LocalizerOptions::default()
    };
    if let Some(t) = args.temperature {
        options.temperature = t;
    }
    if args.verify == 0 {
        return Ok(Localizer::new(map.clone(), options)?);
    }
    let verification = &mut options.verification;
    verification.candidates = args.verify;
    verification.xfeat = args.runtime.xfeat_options();
    if let Some(n) = args.off_map_inliers {
        verification.off_map_inliers = Some(n);
    }
    if let Some(scale) = args.off_map_inlier_scale {
        verification.off_map_inlier_scale = scale;
    }
    let describer = args.runtime.describer_options(args.backend);
    Ok(Localizer::with_describer(map.clone(), options, &describer)?)
}

/// The report's keys common to both inputs: map, descriptor, frames, uninformative frames,
/// similarity spread, filter temperature, describe time.
fn report_head(
    args: &EvalArgs,
    map: &Arc<Map>,
    described: &[Described],
) -> Result<JsonMap<String, Value>> {
    let describe_ms: Vec<f64> = described.iter().map(|d| d.1).collect();
    let uninformative = described.iter().filter(|d| d.0.is_none()).count();
    let temperature = localizer(args, map, Mode::Filter)?.options().temperature;
    let mut report = JsonMap::new();
    report.insert("map".into(), json!(args.map.display().to_string()));
    report.insert("descriptor".into(), json!(map.descriptor().to_string()));
    report.insert("frames".into(), json!(described.len()));
    report.insert("uninformative_frames".into(), json!(uninformative));
    report.insert("similarity_spread".into(), json!(map.similarity_spread()));
    report.insert("temperature".into(), json!(temperature));
    report.insert(
        "describe_ms_median".into(),
        json!(median_and_p90(&describe_ms).0),
    );
    Ok(report)
}

/// Copies the primary configuration's figures to the top level (the filter unless
/// --single-frame; a filter given odometry is reported beside it) with `ms_per_frame_median`
/// (describe + localize of each frame) and `mode`; returns the primary run.
fn add_headline<'a>(
    report: &mut JsonMap<String, Value>,
    runs: &'a [ModeRun],
    described: &[Described],
) -> &'a ModeRun {
    let primary = runs
        .iter()
        .rev()
        .find(|r| r.name != "filter_odometry")
        .expect("single_frame is always run");
    if let Value::Object(fields) = report[primary.name].clone() {
        for (k, v) in fields {
            report.insert(k, v);
        }
    }
    let per_frame: Vec<f64> = described
        .iter()
        .zip(&primary.localize_ms)
        .map(|(d, l)| d.1 + l)
        .collect();
    report.insert(
        "ms_per_frame_median".into(),
        json!(median_and_p90(&per_frame).0),
    );
    report.insert("mode".into(), json!(primary.name));
    primary
}

fn print_report(args: &EvalArgs, report: JsonMap<String, Value>, runs: &[ModeRun]) {
    if args.json {
        println!("{}", Value::Object(report));
    } else {
        print_table(&report, runs);
    }
}

/// Fails unless `map` holds the dataset's graph: as many places, the same edges, and places
/// within 1 cm of the dataset's (when the map stores positions). The error says what differs.
fn check_same_graph(map: &Map, map_path: &Path, dataset: &Dataset) -> Result<()> {
    let graph_path = dataset.root.join(GRAPH_FILE);
    let mismatch = |what: String| {
        anyhow::anyhow!(
            "{} does not hold the graph of {}: {what}; evaluate a dataset with the map of its world (`topoloc simulate` writes both)",
            map_path.display(),
            graph_path.display()
        )
    };
    let (places, graph_places) = (map.place_count(), dataset.graph.places.len());
    if places != graph_places {
        return Err(mismatch(format!(
            "the map has {places} places, the dataset's graph {graph_places}"
        )));
    }
    let mut map_edges: Vec<(PlaceId, PlaceId)> = map.edges().iter().map(|e| (e.a, e.b)).collect();
    let mut graph_edges: Vec<(PlaceId, PlaceId)> = dataset
        .graph
        .edges
        .iter()
        .map(|&(a, b)| (a.min(b), a.max(b)))
        .collect();
    map_edges.sort_unstable();
    graph_edges.sort_unstable();
    graph_edges.dedup();
    if map_edges != graph_edges {
        return Err(mismatch(format!(
            "the map has {} edges, the dataset's graph {} and they differ",
            map_edges.len(),
            graph_edges.len()
        )));
    }
    for (p, place) in dataset.graph.places.iter().enumerate() {
        let position = map.place_position(p as PlaceId)?;
        if let Some(position) = position.filter(|q| (q - place.point()).norm() > 0.01) {
            return Err(mismatch(format!(
                "place {p} is at {:?} in the map, {:?} in the dataset's graph",
                [position.x, position.y, position.z],
                place.position
            )));
        }
    }
    Ok(())
}

/// Source image index of every view (its keyframe id; the view index when absent).
pub fn view_image_indices(map: &Map) -> Vec<usize> {
    map.views()
        .iter()
        .enumerate()
        .map(|(v, r)| r.keyframe_id.map_or(v, |k| k as usize))
        .collect()
}

/// The query frames as the localizer sees them.
struct Queries<'a> {
    described: &'a [Described],
    /// Timestamp per frame, seconds.
    timestamps: &'a [f64],
    /// Odometry per frame, `previous_T_current` (the first frame's is ignored); `None`: the
    /// localizer gets no odometry.
    odometry: Option<&'a [Isometry3<f64>]>,
    /// With verification: the frames' image files and their reader (the images are read again
    /// as each frame is localized, since verification needs them).
    images: Option<(&'a [PathBuf], &'a ReadImage<'a>)>,
}

/// Localizes every frame; frames without a descriptor get no answer (and their odometry is
/// carried to the next frame). `similarity` (matrix, columns) collects the best similarity of
/// each query frame to each map image.
fn localize_all(
    name: &'static str,
    localizer: &mut Localizer,
    queries: &Queries<'_>,
    view_image: &[usize],
    tolerance: usize,
    mut similarity: Option<(&mut Vec<f32>, usize)>,
) -> Result<ModeRun> {
    let described = queries.described;
    let mut run = ModeRun {
        name,
        predicted: Vec::with_capacity(described.len()),
        rankings: Vec::with_capacity(described.len()),
        candidates: Vec::with_capacity(described.len()),
        places: Vec::with_capacity(described.len()),
        outcomes: Vec::with_capacity(described.len()),
        off_map: Vec::with_capacity(described.len()),
        localize_ms: Vec::with_capacity(described.len()),
    };
    let mut out = Localization::default();
    // previous_T_current since the last frame given to the localizer.
    let mut motion: Option<Isometry3<f64>> = None;
    for (i, (descriptor, _)) in described.iter().enumerate() {
        if let Some(odometry) = queries.odometry.filter(|_| i > 0) {
            motion = Some(motion.map_or(odometry[i], |m| m * odometry[i]));
        }
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
            run.off_map.push(false);
            run.localize_ms.push(0.0);
            continue;
        };
        let image = match queries.images {
            Some((paths, read)) => Some(read(i, &paths[i])?),
            None => None,
        };
        let image = image
            .as_ref()
            .map(|(w, h, rgb)| ImageView::packed(*w, *h, PixelFormat::Rgb8, rgb));
        // Dense cells come from the localizer's own forward pass: it describes the image.
        let descriptor = match localizer.wants_image_only() {
            true => &[][..],
            false => descriptor.as_slice(),
        };
        let start = Instant::now();
        localizer.process(
            &Frame {
                timestamp: queries.timestamps[i],
                descriptor,
                odometry: motion.take(),
                image,
            },
            &mut out,
        )?;
        run.localize_ms.push(start.elapsed().as_secs_f64() * 1e3);
        run.off_map.push(out.off_map);
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
        run.places.push(
            out.candidates
                .iter()
                .map(|c| (c.place, c.probability))
                .collect(),
        );
        run.rankings.push(FrameRanking { truth: i, ranked });
    }
    Ok(run)
}

/// Frames after which an off-map stream (queries from elsewhere) should be flagged: the
/// localizer's off-map target is "flagged within 10 frames".
const OFF_MAP_SETTLE: usize = 10;

/// Share of true values (0 for none).
fn share(flags: &[bool]) -> f64 {
    flags.iter().filter(|&&f| f).count() as f64 / flags.len().max(1) as f64
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
        "off_map_rate": share(&run.off_map),
        "off_map_rate_after_10": share(run.off_map.get(OFF_MAP_SETTLE..).unwrap_or_default()),
    });
    if let Some(truth) = gt_nodes {
        let hops = HopDistances::from_map(map);
        let (metrics, _) = graph_metrics(run, truth, &hops, &[1, 5, 10])?;
        summary["mna"] = json!(metrics.mna);
        summary["oha"] = json!(metrics.oha);
        for r in metrics.recall_at_n {
            summary[format!("graph_r_at_{}", r.n)] = json!(r.recall);
        }
    }
    let curve = pr.points.iter().map(|p| (p.recall, p.precision)).collect();
    Ok((summary, curve))
}

/// The seed's graph metrics of a run against the true place of every frame: MNA, OHA and R@N
/// for each of `depths`, and the precision-recall curve of the confidence with "correct" = the
/// true place.
fn graph_metrics(
    run: &ModeRun,
    truth: &[PlaceId],
    hops: &HopDistances,
    depths: &[usize],
) -> Result<(GraphMetrics, PrCurve)> {
    let predictions: Vec<Prediction> = truth
        .iter()
        .zip(&run.places)
        .zip(&run.outcomes)
        .map(|((&truth, ranked), o)| Prediction {
            truth,
            ranked: ranked.iter().map(|c| c.0).collect(),
            confidence: o.confidence,
            frames: None,
        })
        .collect();
    let evaluator = GraphEvaluator::new(hops, &predictions)?;
    let pr = precision_recall(&evaluator.scored_outcomes(0))?;
    Ok((evaluator.metrics(depths), pr))
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

/// Writes `header`, then per frame `frame,best,confidence` and the next candidates as
/// `candidate:probability` (`frame,-1,0` for a frame without an answer).
fn write_predictions<T: Display>(
    path: &Path,
    header: &str,
    outcomes: &[ScoredOutcome],
    candidates: &[Vec<(T, f32)>],
) -> Result<()> {
    let mut file = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
    );
    writeln!(file, "{header}")?;
    for (i, (ranked, outcome)) in candidates.iter().zip(outcomes).enumerate() {
        match ranked.first() {
            Some((p, _)) => write!(file, "{i},{p},{:.6}", outcome.confidence)?,
            None => write!(file, "{i},-1,0")?,
        }
        for (index, score) in ranked.iter().skip(1) {
            write!(file, ",{index}:{score:.6}")?;
        }
        writeln!(file)?;
    }
    file.flush()?;
    Ok(())
}

fn print_table(report: &JsonMap<String, Value>, runs: &[ModeRun]) {
    let text = |key: &str| report[key].as_str().unwrap_or_default().to_string();
    let number = |key: &str| report[key].as_f64().unwrap_or(0.0);
    match report.get("dataset") {
        Some(_) => println!(
            "map {} ({}), dataset {} ({} split, '{}' light), {} frames; truth: its place per frame",
            text("map"),
            text("descriptor"),
            text("dataset"),
            text("split"),
            text("condition"),
            report["frames"]
        ),
        None => println!(
            "map {} ({}), {} query frames, tolerance +-{}",
            text("map"),
            text("descriptor"),
            report["frames"],
            report["tolerance"]
        ),
    }
    println!(
        "similarity spread {:.3}, filter temperature {:.3}",
        number("similarity_spread"),
        number("temperature")
    );
    if report["uninformative_frames"].as_u64() != Some(0) {
        println!(
            "{} query frames without content were not localized (counted wrong)",
            report["uninformative_frames"]
        );
    }
    println!(
        "\n{:<16} {:>6} {:>6} {:>6} {:>7} {:>6} {:>6} {:>6} {:>8} {:>9} {:>12}",
        "mode",
        "R@1",
        "R@5",
        "R@10",
        "R@100P",
        "AP",
        "MNA",
        "OHA",
        "off-map",
        "off@10+",
        "localize ms"
    );
    let f = |v: &Value| v.as_f64().map_or("-".to_string(), |x| format!("{x:.3}"));
    for run in runs {
        let s = &report[run.name];
        println!(
            "{:<16} {:>6} {:>6} {:>6} {:>7} {:>6} {:>6} {:>6} {:>8} {:>9} {:>12.3}",
            run.name.replace('_', "-"),
            f(&s["r_at_1"]),
            f(&s["r_at_5"]),
            f(&s["r_at_10"]),
            f(&s["r_at_100p"]),
            f(&s["average_precision"]),
            f(&s["mna"]),
            f(&s["oha"]),
            f(&s["off_map_rate"]),
            f(&s["off_map_rate_after_10"]),
            s["localize_ms_median"].as_f64().unwrap_or(0.0)
        );
    }
    println!(
        "\ndescribe {:.1} ms per image (median, one thread each); describe + localize {:.1} ms per frame",
        number("describe_ms_median"),
        number("ms_per_frame_median")
    );
}
