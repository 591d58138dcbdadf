//! `topoloc loops`: loop-closure hints over an image sequence, as a SLAM host would get them.
//!
//! ```text
//! topoloc loops --images DIR [--every N] [--keyframe-rate HZ] [--poses TUM.txt] [--intrinsics FILE] [--map MAP] --out HINTS.csv [--json]
//! ```
//! `--images` is a folder of images in file-name order, or a KITTI, TUM RGB-D or EuRoC
//! sequence folder ([`crate::sequence`]); its frames are numbered 0, 1, 2 ... in that order
//! (the *frame index*). `--every N` / `--keyframe-rate HZ` thin them to keyframes, numbered
//! 0, 1, 2 ... among themselves (the *keyframe index*): every Nth frame, and with a rate R the
//! first frame at or after each due time `t0 + k / R` by the layout's timestamps (a plain
//! folder's are its frame indices), which keeps R per second on average
//! ([`sequence::keyframes`]); the rate kept, keyframes over the time the frames cover
//! ([`sequence::effective_rate`]), is printed on stderr and reported. The keyframes' timestamps
//! are then those of `--poses`, else of the layout. Without `--map` the graph grows from
//! nothing: the describer (PCA) is fitted on the sequence's own images first, as `build-map`
//! does, then the sequence is replayed online. With `--map` (a map built from images with keypoints) the
//! map's views are the first session's keyframes and the hints name their keyframe ids.
//!
//! `HINTS.csv` has a header line, then one row per accepted hint, in query order (a hint a
//! later keyframe confirmed included, [`topoloc::loops::Processed::confirmed`]):
//! `query_index,matched_index,inliers,confidence,scale_known,tx,ty,tz,qx,qy,qz,qw,query_frame,matched_frame`.
//! `query_index` and `matched_index` are keyframe indices, `query_frame` and `matched_frame`
//! the frame indices of the same keyframes (the position of their image in `--images`). With
//! `--map`, a match in the map has the map's keyframe id as `matched_index` and an empty
//! `matched_frame` (the first session's frames are unknown); a match among this run's own
//! keyframes has both. The pose columns (`matched_T_query`: the query camera in the matched
//! camera's optical frame, translation then unit quaternion) are empty for hints without a
//! pose. `--intrinsics FILE` holds `fx fy cx cy` (pixels, whitespace-separated); `--depth DIR`
//! gives keyframes 3D points and hints metric poses. `--json` prints the hints, the median and p90 time per keyframe (and
//! the median of its describing part: global descriptor and local features), the count of
//! each keyframe's own gate and of the confirmed hints, and under `sequence` the layout, the
//! frame and keyframe counts, the asked and effective keyframe rates and every keyframe's frame
//! index; with `--aligned-tolerance T` (a frame-aligned second session, such as Gardens Point)
//! also precision and recall, and with `--truth` those against the ground truth (under
//! `truth`). A precision or recall whose denominator is 0 (no hint, no possible loop, no posed
//! hint) is `null`, not 0.

use crate::backend_args::{progress_bar, BackendArgs, LocalFeatures};
use crate::plot::{write_precision_recall_png, Series};
use crate::process::median_and_p90;
use crate::sequence::{self, Frame};
use crate::stages::StageLog;
use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion};
use serde_json::json;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;
use topoloc::build::{
    build_from_images, read_tum, BuildStage, ImageLayout, ImageMapOptions, ImageSource, TimedPose,
};
use topoloc::describe::Describer;
use topoloc::image::{read_rgb, read_u16, ImageView, PixelFormat};
use topoloc::loops::{
    DatabaseOptions, Gate, HintOptions, KeyframeDatabase, KeyframeDescriber, KeyframeEntry,
    KeyframeFeatures, LoopDetector, LoopHint, OdometryGate, Work,
};
use topoloc::verify::{
    camera_points_from_depth, DepthImage, FundamentalEstimator, Keypoints, PairOptions,
    PinholeCamera, RelativePose, RelativePoseOptions,
};
use topoloc::{LoadOptions, Map};

/// Options of `loops`.
#[derive(Args, Clone, Debug)]
pub struct LoopsArgs {
    /// Keyframe images: a folder of images in file-name order (timestamped by index), or a
    /// KITTI, TUM RGB-D or EuRoC sequence folder (timestamped as the layout says; TUM's
    /// associations give depth).
    #[arg(long)]
    pub images: PathBuf,
    /// Keep every Nth frame as a keyframe.
    #[arg(long, default_value_t = 1)]
    pub every: usize,
    /// Keep this many keyframes per second on average, as a SLAM front end does: the first
    /// frame (at t0), then the first frame at or after each due time t0 + k / HZ (k = 1, 2,
    /// ...), by the layout's timestamps (a plain folder's: its frame indices). Never more than
    /// HZ, fewer only where frames are further apart than 1 / HZ (3 of KITTI's 10 Hz: frames 0,
    /// 4, 7, 10, ...). The rate kept is printed on stderr and reported (`effective_rate_hz`).
    #[arg(long)]
    pub keyframe_rate: Option<f64>,
    /// Resize every image to WxH (for example 320x240) after decoding it, as a host with
    /// smaller images would give them; intrinsics are scaled with it. Not with `--depth`.
    #[arg(long, value_parser = parse_size)]
    pub resize: Option<(u32, u32)>,
    /// TUM trajectory, one pose per image: odometry (world_T_camera) and timestamps.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// Camera intrinsics file: `fx fy cx cy`; hints then carry relative poses.
    #[arg(long)]
    pub intrinsics: Option<PathBuf>,
    /// Depth images registered to the keyframe images (16-bit PNG, same file names; as
    /// `topoloc simulate --depth` writes and RGB-D cameras give): keyframes get 3D points and
    /// hints metric poses (`scale_known = 1`). Needs `--intrinsics`.
    #[arg(long, requires = "intrinsics")]
    pub depth: Option<PathBuf>,
    /// Depth image units per metre: 1000 for millimetres (ROS 16UC1), 5000 for TUM RGB-D.
    #[arg(long, default_value_t = 1000.0)]
    pub depth_scale: f64,
    /// A map of a first session (built from images with keypoints).
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Where the accepted hints are written (CSV
    /// `query_index,matched_index,inliers,confidence,scale_known,tx,ty,tz,qx,qy,qz,qw,query_frame,matched_frame`):
    /// `query_index` / `matched_index` are keyframe indices (with `--map`, `matched_index` is
    /// the map's keyframe id for a match in the map); `query_frame` / `matched_frame` are the
    /// same keyframes' frame indices in `--images` (`matched_frame` empty for a match in the
    /// map).
    #[arg(long)]
    pub out: PathBuf,
    /// Local features without `--map` (with one, the map's kind). XFeat by default: its hints
    /// carry a pose where intrinsics are given, which dense cells cannot (BENCHMARKS.md says
    /// which data chose it).
    #[arg(long, value_enum, default_value_t = LocalFeatures::from(topoloc::loops::DEFAULT_LOOP_FEATURES))]
    pub local_features: LocalFeatures,
    /// Descriptor backend without `--map`.
    #[command(flatten)]
    pub backend: BackendArgs,
    /// How `--poses` and `--truth` name the camera: `optical` (z forward, x right, y down, as
    /// TUM RGB-D and OpenCV) or `x-forward` (x forward, y left, z up, as ROS bodies and
    /// topoloc-sim).
    #[arg(long, value_enum, default_value_t = CameraFrame::Optical)]
    pub camera_frame: CameraFrame,
    /// Ground-truth camera poses (TUM, one per image) for evaluation: precision, recall and
    /// the hints' pose error go in the report.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// With `--truth`: a hint is correct when the two cameras are this close (metres) ...
    #[arg(long, default_value_t = 2.0)]
    pub truth_radius_m: f64,
    /// With `--truth`: ... and their orientations differ by at most this (degrees): cameras
    /// facing apart see different things, which no appearance check can match.
    #[arg(long, default_value_t = 45.0)]
    pub truth_max_angle_deg: f64,
    /// Also write every keyframe's best candidate, accepted or not, with the gate that decided
    /// (CSV `query_index,gate,matched_index,inliers,confidence,detail`, keyframe indices as in
    /// `--out`; `detail` is the agreeing streak, the pose refusal, or the odometry differences
    /// `deg/m`): what a host logs.
    #[arg(long)]
    pub decisions: Option<PathBuf>,
    /// With `--truth`: also draw the accepted hints' precision against recall as their
    /// confidence threshold falls (PNG); the report gives the points and the recall at
    /// precision 1.
    #[arg(long)]
    pub pr_curve: Option<PathBuf>,
    /// Keyframes this many ids before the query or closer are never loop candidates.
    #[arg(long, default_value_t = HintOptions::default().exclude_recent_ids)]
    pub exclude_ids: u64,
    /// Keyframes less than this many seconds before the query are never loop candidates.
    #[arg(long, default_value_t = HintOptions::default().exclude_recent_s)]
    pub exclude_seconds: f64,
    /// Candidates closer than this in id to a more similar one are skipped (0 = off).
    #[arg(long, default_value_t = HintOptions::default().candidate_id_gap)]
    pub candidate_id_gap: u64,
    /// Fewest inliers of an accepted hint.
    #[arg(long, default_value_t = HintOptions::default().min_inliers)]
    pub min_inliers: u32,
    /// Consecutive keyframes that must agree on the place.
    #[arg(long, default_value_t = HintOptions::default().consistent_keyframes)]
    pub consistent_keyframes: usize,
    /// The pace rule: consecutive keyframes agree only when their candidates' times differ
    /// by at most this many times their own step plus `--match-pace-slack-s` (0 = off).
    #[arg(long, default_value_t = HintOptions::default().max_match_pace)]
    pub max_match_pace: f64,
    /// The pace rule's slack, seconds.
    #[arg(long, default_value_t = HintOptions::default().match_pace_slack_s)]
    pub match_pace_slack_s: f64,
    /// With `--poses`: largest rotation difference between a hint and the odometry, degrees.
    #[arg(long, default_value_t = OdometryGate::default().max_rotation_deg)]
    pub odometry_max_rotation_deg: f64,
    /// With `--poses`: largest translation difference, metres (an unscaled hint's direction
    /// scaled by the odometry's baseline).
    #[arg(long, default_value_t = OdometryGate::default().max_translation_m)]
    pub odometry_max_translation_m: f64,
    /// With `--poses`: the translation bound grows by this much per metre the odometry
    /// travelled between the two keyframes (its drift rate).
    #[arg(long, default_value_t = OdometryGate::default().max_translation_per_m)]
    pub odometry_max_translation_per_m: f64,
    /// The candidates' fundamental-matrix fit [default: ransac for XFeat and ORB, magsac for
    /// cells].
    #[arg(long, value_enum)]
    pub pair_estimator: Option<PairEstimator>,
    /// Iterations of the candidates' fundamental-matrix fit [default: 100 for XFeat and ORB,
    /// 1000 for cells].
    #[arg(long)]
    pub pair_iterations: Option<u32>,
    /// Smallest cosine of a kept XFeat or cells match (-1: every mutual match) [default: 0.82
    /// for XFeat, -1 for cells].
    #[arg(long, allow_hyphen_values = true)]
    pub pair_min_cosine: Option<f32>,
    /// With `--poses`: candidates proposed by the odometry (the keyframes nearest the new
    /// one's odometry pose that could pass the odometry gate) besides appearance's.
    #[arg(long, default_value_t = HintOptions::default().odometry_candidates)]
    pub odometry_candidates: usize,
    /// With `--poses`: how much farther than the odometry bound an odometry candidate may be,
    /// metres.
    #[arg(long, default_value_t = HintOptions::default().odometry_search_m)]
    pub odometry_search_m: f64,
    /// Keyframes of the best candidate's group checked to refine it (0: none).
    #[arg(long, default_value_t = HintOptions::default().refine_keyframes)]
    pub refine_keyframes: usize,
    /// Fewest inliers of a hint's relative pose.
    #[arg(long, default_value_t = RelativePoseOptions::default().min_inliers)]
    pub pose_min_inliers: u32,
    /// With `--depth`: reprojection threshold of the metric pose fit, pixels.
    #[arg(long, default_value_t = RelativePoseOptions::default().reprojection_px)]
    pub pose_reprojection_px: f64,
    /// With `--map` on a frame-aligned second session: a hint is correct when its matched id
    /// is within this many of the query index; precision and recall go in the report.
    #[arg(long)]
    pub aligned_tolerance: Option<u64>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// A fundamental-matrix estimator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PairEstimator {
    /// OpenCV's classic RANSAC.
    Ransac,
    /// MAGSAC++ (OpenCV's USAC).
    Magsac,
    /// OpenCV's USAC in its fast settings (a quarter of RANSAC's time; see BENCHMARKS.md).
    UsacFast,
}

impl PairEstimator {
    fn estimator(self) -> FundamentalEstimator {
        match self {
            PairEstimator::Ransac => FundamentalEstimator::Ransac,
            PairEstimator::Magsac => FundamentalEstimator::Magsac,
            PairEstimator::UsacFast => FundamentalEstimator::UsacFast,
        }
    }
}

/// `defaults` with the estimator and iterations given on the command line.
fn pair_options(args: &LoopsArgs, defaults: PairOptions) -> PairOptions {
    PairOptions {
        estimator: args
            .pair_estimator
            .map_or(defaults.estimator, PairEstimator::estimator),
        max_iterations: args.pair_iterations.unwrap_or(defaults.max_iterations),
        min_cosine: args.pair_min_cosine.unwrap_or(defaults.min_cosine),
        ..defaults
    }
}

/// The frame convention of given camera poses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum CameraFrame {
    /// z forward, x right, y down.
    Optical,
    /// x forward, y left, z up.
    XForward,
}

impl CameraFrame {
    /// `given_T_optical`: the optical frame in the given camera frame.
    fn to_optical(self) -> Isometry3<f64> {
        match self {
            CameraFrame::Optical => Isometry3::identity(),
            CameraFrame::XForward => Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_matrix(&Matrix3::new(
                    0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0,
                )),
            ),
        }
    }
}

/// Runs the command.
pub fn run(args: &LoopsArgs) -> Result<()> {
    let sequence = sequence::open(&args.images)?;
    let kept = sequence::keyframes(&sequence.frames, args.every, args.keyframe_rate)?;
    let effective_rate = sequence::effective_rate(&sequence.frames, kept.len());
    eprintln!(
        "{} keyframes of {} frames{}: {} per second{}",
        kept.len(),
        sequence.frames.len(),
        match (args.every, args.keyframe_rate) {
            (1, None) => String::new(),
            (every, None) => format!(" (every {every})"),
            (1, Some(rate)) => format!(" (--keyframe-rate {rate})"),
            (every, Some(rate)) => format!(" (every {every}, --keyframe-rate {rate})"),
        },
        effective_rate.map_or("n/a".to_string(), |r| format!("{r:.3}")),
        sequence::duration_s(&sequence.frames).map_or(String::new(), |d| format!(" over {d:.3} s")),
    );
    let frames: Vec<&Frame> = kept.iter().map(|&i| &sequence.frames[i]).collect();
    let files: Vec<PathBuf> = frames.iter().map(|f| f.image.clone()).collect();
    // Pose files hold one pose per frame of the whole sequence; the keyframes take theirs.
    let per_keyframe = |path: &Path| -> Result<Vec<TimedPose>> {
        let poses = sequence::poses_at_frames(&sequence, read_tum(path)?, path)?;
        Ok(kept.iter().map(|&i| poses[i]).collect())
    };
    let poses = args.poses.as_deref().map(per_keyframe).transpose()?;
    if args.resize.is_some() && args.depth.is_some() {
        bail!("--resize and --depth together are not supported: depth images keep their size");
    }
    let camera = match (args.intrinsics.as_deref(), args.resize) {
        (None, _) => None,
        (Some(path), None) => Some(read_intrinsics(path)?),
        (Some(path), Some(size)) => {
            let (w, h, _) = read_rgb(&files.first().context("no keyframes")?.clone())?;
            Some(scale_camera(read_intrinsics(path)?, (w, h), size))
        }
    };
    let truth: Option<Vec<Isometry3<f64>>> = args
        .truth
        .as_deref()
        .map(per_keyframe)
        .transpose()?
        .map(|poses| {
            let to_optical = args.camera_frame.to_optical();
            poses
                .iter()
                .map(|p| p.world_t_camera * to_optical)
                .collect()
        });
    let options = HintOptions {
        camera,
        exclude_recent_ids: args.exclude_ids,
        exclude_recent_s: args.exclude_seconds,
        candidate_id_gap: args.candidate_id_gap,
        min_inliers: args.min_inliers,
        consistent_keyframes: args.consistent_keyframes,
        max_match_pace: args.max_match_pace,
        match_pace_slack_s: args.match_pace_slack_s,
        odometry: Some(OdometryGate {
            max_rotation_deg: args.odometry_max_rotation_deg,
            max_translation_m: args.odometry_max_translation_m,
            max_translation_per_m: args.odometry_max_translation_per_m,
        }),
        pair: pair_options(args, HintOptions::default().pair),
        cells_pair: pair_options(args, HintOptions::default().cells_pair),
        odometry_candidates: args.odometry_candidates,
        odometry_search_m: args.odometry_search_m,
        refine_keyframes: args.refine_keyframes,
        pose: RelativePoseOptions {
            min_inliers: args.pose_min_inliers,
            reprojection_px: args.pose_reprojection_px,
            ..RelativePoseOptions::default()
        },
        ..HintOptions::default()
    };
    let (mut detector, map, first_id) = match &args.map {
        Some(path) => {
            let map = Map::load(path, &LoadOptions::default())
                .with_context(|| format!("loading {}", path.display()))?;
            let detector = LoopDetector::from_map(&map, DatabaseOptions::default(), options)?;
            let first_id = map
                .views()
                .iter()
                .filter_map(|v| v.keyframe_id)
                .max()
                .map_or(0, |m| m + 1);
            (detector, map, first_id)
        }
        None => {
            let map = fit_describer(args, &files)?;
            let db = KeyframeDatabase::new(map.descriptor().clone(), DatabaseOptions::default())?;
            (LoopDetector::new(db, options)?, map, 0)
        }
    };
    let kind = match (&args.map, map.keypoints()) {
        (Some(_), Some(k)) => k.kind(),
        (Some(path), None) => bail!(
            "{} stores no keypoints: build it with --verification-keypoints > 0",
            path.display()
        ),
        (None, _) => args.local_features.into(),
    };
    let model = map
        .describer()
        .cloned()
        .context("the map stores no describer")?;
    let runtime = &args.backend.runtime;
    let describer = Describer::new(model, &runtime.describer_options(None))?;
    let mut describer = KeyframeDescriber::new(describer, kind, &runtime.xfeat_options())?;
    let timestamps: Vec<f64> = (0..frames.len())
        .map(|i| {
            poses
                .as_ref()
                .map_or(frames[i].timestamp, |p| p[i].timestamp)
        })
        .collect();
    let bar = progress_bar(files.len(), "keyframes");
    let (mut hints, mut gates, mut times) = (Vec::new(), BTreeMap::new(), Vec::new());
    let mut describe_times = Vec::new();
    let mut work = Work::default();
    let mut confirmed = 0;
    let mut decisions = String::from("query_index,gate,matched_index,inliers,confidence,detail\n");
    let mut stages = StageLog::default();
    for (index, path) in files.iter().enumerate() {
        let decode = Instant::now();
        let (w, h, rgb) = decode_image(path, args.resize)?;
        let decode = decode.elapsed();
        let image = ImageView::packed(w, h, PixelFormat::Rgb8, &rgb);
        let _ = topoloc::profile::take();
        let start = Instant::now();
        let mut descriptor = Vec::new();
        let KeyframeFeatures { keypoints, .. } = describer
            .describe(&image, &mut descriptor)
            .with_context(|| path.display().to_string())?;
        describe_times.push(start.elapsed().as_secs_f64() * 1e3);
        let entry = KeyframeEntry {
            id: first_id + index as u64,
            timestamp: timestamps[index],
            descriptor: &descriptor,
            world_t_body: poses.as_ref().map(|p| p[index].world_t_camera),
            body_t_camera: Some(args.camera_frame.to_optical()),
        };
        let depth = match &args.depth {
            Some(dir) => Some(dir.join(path.file_name().context("image path without file name")?)),
            None => frames[index].depth.clone(),
        };
        let camera_points = match (depth, &camera) {
            (Some(depth), Some(camera)) => {
                Some(depth_points(&depth, (w, h), &keypoints, camera, args)?)
            }
            _ => None,
        };
        let done = detector.process(
            &entry,
            KeyframeFeatures {
                keypoints,
                camera_points,
            },
        )?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
        stages.record(decode, topoloc::profile::take(), times[times.len() - 1]);
        work.pair_checks += done.work.pair_checks;
        work.pose_fits += done.work.pose_fits;
        *gates.entry(done.gate().name()).or_insert(0usize) += 1;
        write_decision(&mut decisions, index, done.hint.as_ref(), first_id);
        for hint in &done.confirmed {
            hints.push(((hint.query_id - first_id) as usize, *hint));
        }
        confirmed += done.confirmed.len();
        if let Some(hint) = done.accepted() {
            hints.push((index, *hint));
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    hints.sort_by_key(|(index, _)| *index);
    write_csv(&args.out, &hints, first_id, &kept)?;
    if let Some(path) = &args.decisions {
        std::fs::write(path, decisions).with_context(|| format!("writing {}", path.display()))?;
    }
    let mut out = report(
        args,
        &hints,
        &gates,
        [&times, &describe_times],
        work,
        first_id,
        &kept,
    );
    out["confirmed"] = json!(confirmed);
    out["stages"] = stages.to_json();
    out["resize"] = json!(args.resize.map(|(w, h)| format!("{w}x{h}")));
    out["sequence"] = json!({
        "layout": format!("{:?}", sequence.layout),
        "frames": sequence.frames.len(),
        "keyframes": kept.len(),
        "every": args.every,
        "keyframe_rate_hz": args.keyframe_rate,
        "duration_s": sequence::duration_s(&sequence.frames),
        "effective_rate_hz": effective_rate,
        "keyframe_frames": kept,
    });
    if let Some(truth) = &truth {
        add_truth(&mut out, args, &hints, truth, &timestamps, first_id)?;
    }
    print_report(args, &out);
    Ok(())
}

/// Precision and recall against ground-truth camera poses, the hints per kilometre driven where
/// no loop could be closed ([`without_revisit`]), and the hints' pose errors.
/// A keyframe could have closed a loop when an earlier keyframe outside the exclusion window
/// (the detector's: `--exclude-ids` and `--exclude-seconds` by the keyframes' `timestamps`)
/// lies within the radius and the angle; a hint is correct when its matched keyframe does.
/// The precision-recall points sweep the hints' confidence from the highest down
/// ([`precision_recall`]); `--pr-curve` draws them.
/// The pose errors' medians are over the correct hints; `pose_precision` is the share of
/// posed hints whose relative pose is right ([`PoseError::is_small`]), wherever they match;
/// `precision_place_or_pose` counts a hint right when it is correct by place or its pose is
/// right (a constraint a pose graph can take, though the cameras are beyond the radius).
/// Each precision and recall is null where its denominator is 0 (no hint, no possible loop,
/// no posed hint), and so are the curve's recalls and `recall_at_full_precision` without a
/// possible loop.
fn add_truth(
    out: &mut serde_json::Value,
    args: &LoopsArgs,
    hints: &[(usize, LoopHint)],
    truth: &[Isometry3<f64>],
    timestamps: &[f64],
    first_id: u64,
) -> Result<()> {
    let max_angle = args.truth_max_angle_deg.to_radians();
    let near = |a: usize, b: usize| {
        (truth[a].translation.vector - truth[b].translation.vector).norm() <= args.truth_radius_m
            && truth[a].rotation.angle_to(&truth[b].rotation) <= max_angle
    };
    let window = args.exclude_ids.max(1) as usize;
    let outside_window = |q: usize, m: usize| {
        m + window <= q && timestamps[q] - timestamps[m] >= args.exclude_seconds
    };
    let revisits: Vec<bool> = (0..truth.len())
        .map(|q| (0..q).any(|m| outside_window(q, m) && near(q, m)))
        .collect();
    let possible = revisits.iter().filter(|&&r| r).count();
    let queries: Vec<usize> = hints.iter().map(|(q, _)| *q).collect();
    let (no_revisit_km, no_revisit_hints) = without_revisit(truth, &revisits, &queries);
    let mut correct = 0;
    let mut judged = Vec::with_capacity(hints.len());
    // Right by place, or by a relative pose a pose graph can take (whatever the distance).
    let mut right_constraints = 0;
    let (mut posed, mut pose_correct, mut rotation_only) = (0, 0, 0);
    let (mut rotation, mut translation, mut direction) = (vec![], vec![], vec![]);
    for (q, hint) in hints {
        let m = matched_index(hint, first_id) as usize;
        if m >= truth.len() {
            continue;
        }
        let loop_correct = near(*q, m);
        correct += usize::from(loop_correct);
        judged.push((hint.confidence, loop_correct));
        let Some(pose) = &hint.pose else {
            right_constraints += usize::from(loop_correct);
            continue;
        };
        let error = PoseError::of(pose, &(truth[m].inverse() * truth[*q]));
        posed += 1;
        rotation_only +=
            usize::from(!pose.scale_known && pose.matched_t_query.translation.vector.norm() == 0.0);
        pose_correct += usize::from(error.is_small());
        right_constraints += usize::from(loop_correct || error.is_small());
        if !loop_correct {
            continue;
        }
        rotation.push(error.rotation_deg);
        match error.translation {
            Translation::Metres(m) => translation.push(m),
            Translation::DirectionDeg(d) => direction.push(d),
            Translation::NoBaseline => {}
        }
    }
    let median = |v: &[f64]| {
        if v.is_empty() {
            f64::NAN
        } else {
            median_and_p90(v).0
        }
    };
    out["truth"] = json!({
        "radius_m": args.truth_radius_m,
        "max_angle_deg": args.truth_max_angle_deg,
        "possible": possible,
        "correct": correct,
        "precision": ratio(correct, hints.len()),
        "recall": ratio(correct, possible),
        "precision_place_or_pose": ratio(right_constraints, hints.len()),
        "rotation_error_deg_median": median(&rotation),
        "translation_error_m_median": median(&translation),
        "direction_error_deg_median": median(&direction),
        "posed_hints": posed,
        "rotation_only_hints": rotation_only,
        "pose_correct": pose_correct,
        "pose_precision": ratio(pose_correct, posed),
        "no_revisit_km": no_revisit_km,
        "no_revisit_hints": no_revisit_hints,
        "hints_per_km_without_revisit": (no_revisit_km > 0.0)
            .then(|| no_revisit_hints as f64 / no_revisit_km),
    });
    let curve = precision_recall(&mut judged, possible);
    // Without a possible loop, recall (and the best one at precision 1) is undefined: null.
    let defined = |recall: f64| (possible > 0).then_some(recall);
    out["truth"]["recall_at_full_precision"] = json!(defined(recall_at_full_precision(&curve)));
    out["truth"]["precision_recall"] = json!(curve
        .iter()
        .map(|p| json!({
            "confidence": p.confidence,
            "recall": defined(p.recall),
            "precision": p.precision,
        }))
        .collect::<Vec<_>>());
    if let Some(path) = &args.pr_curve {
        let points: Vec<(f64, f64)> = curve.iter().map(|p| (p.recall, p.precision)).collect();
        let title = format!("loop hints: {}", args.images.display());
        let series = Series {
            name: "hints by confidence",
            predicted: &[],
            precision_recall: &points,
        };
        write_precision_recall_png(path, &title, &[series])?;
    }
    Ok(())
}

/// One point of a precision-recall curve over the hints' confidence.
#[derive(Clone, Copy, Debug, PartialEq)]
struct PrPoint {
    /// The threshold: hints at least this confident are kept.
    confidence: f32,
    recall: f64,
    precision: f64,
}

/// The curve of the hints kept as the confidence threshold falls: `judged` holds each hint's
/// confidence and whether it is correct (sorted here, most confident first); one point per
/// distinct confidence; recall is over the `possible` keyframes.
fn precision_recall(judged: &mut [(f32, bool)], possible: usize) -> Vec<PrPoint> {
    judged.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut curve: Vec<PrPoint> = Vec::new();
    let mut correct = 0usize;
    for (k, &(confidence, right)) in judged.iter().enumerate() {
        correct += usize::from(right);
        let point = PrPoint {
            confidence,
            recall: correct as f64 / possible.max(1) as f64,
            precision: correct as f64 / (k + 1) as f64,
        };
        match curve.last_mut() {
            Some(last) if last.confidence == confidence => *last = point,
            _ => curve.push(point),
        }
    }
    curve
}

/// The largest recall of a curve's points at precision 1 (0 when none).
fn recall_at_full_precision(curve: &[PrPoint]) -> f64 {
    curve
        .iter()
        .filter(|p| p.precision >= 1.0)
        .map(|p| p.recall)
        .fold(0.0, f64::max)
}

/// The length (km) of the stretches where no keyframe could close a loop (`revisits[q]`
/// false: no earlier keyframe near it outside the window), the way into each such keyframe
/// counted, and how many hints (`queries`: the hints' keyframe indices) were given there: every
/// one of them false.
fn without_revisit(truth: &[Isometry3<f64>], revisits: &[bool], queries: &[usize]) -> (f64, usize) {
    let metres: f64 = (1..truth.len())
        .filter(|&q| !revisits[q])
        .map(|q| (truth[q].translation.vector - truth[q - 1].translation.vector).norm())
        .sum();
    let hints = queries
        .iter()
        .filter(|&&q| q < revisits.len() && !revisits[q])
        .count();
    (metres / 1000.0, hints)
}

/// How far a hint's relative pose is from the true one.
struct PoseError {
    rotation_deg: f64,
    translation: Translation,
}

/// The translation part of a [`PoseError`].
enum Translation {
    /// Metric hints: metres.
    Metres(f64),
    /// Unscaled hints: the angle between the directions, degrees.
    DirectionDeg(f64),
    /// Unscaled, and the cameras are within 0.2 m (the direction means nothing), or the hint
    /// is a rotation only (zero translation: the views showed no baseline).
    NoBaseline,
}

impl PoseError {
    fn of(pose: &RelativePose, true_rel: &Isometry3<f64>) -> Self {
        let error = true_rel.inverse() * pose.matched_t_query;
        let (t, t_true) = (
            pose.matched_t_query.translation.vector,
            true_rel.translation.vector,
        );
        let translation = match pose.scale_known {
            true => Translation::Metres((t - t_true).norm()),
            false if t_true.norm() < 0.2 || t.norm() == 0.0 => Translation::NoBaseline,
            false => Translation::DirectionDeg(t.angle(&t_true).to_degrees()),
        };
        Self {
            rotation_deg: error.rotation.angle().to_degrees(),
            translation,
        }
    }

    /// A constraint a pose graph can take: rotation within 5 degrees, and translation within
    /// 0.5 m (metric) or direction within 20 degrees (unscaled, with a baseline).
    fn is_small(&self) -> bool {
        self.rotation_deg <= 5.0
            && match self.translation {
                Translation::Metres(m) => m <= 0.5,
                Translation::DirectionDeg(d) => d <= 20.0,
                Translation::NoBaseline => true,
            }
    }
}

/// The describer fitted on the sequence itself (no keypoints stored), for a run without map.
fn fit_describer(args: &LoopsArgs, files: &[PathBuf]) -> Result<Map> {
    let options = ImageMapOptions {
        backend: args.backend.config()?,
        keypoints: 0,
        ..ImageMapOptions::default()
    };
    let sources: Vec<ImageSource> = files.iter().map(|f| ImageSource::File(f)).collect();
    let bar = progress_bar(files.len(), "fitting the describer");
    let mut progress = |stage: BuildStage, done: usize, _: usize| {
        if stage == BuildStage::Describing {
            bar.set_position(done as u64);
        }
        true
    };
    let (map, _) = build_from_images(&sources, ImageLayout::Sequence, &options, &mut progress)?;
    bar.finish_and_clear();
    Ok(map)
}

/// The keypoints' 3D points from the depth image at `path` (registered to an image of `size`
/// pixels).
fn depth_points(
    path: &Path,
    size: (u32, u32),
    keypoints: &Keypoints,
    camera: &PinholeCamera,
    args: &LoopsArgs,
) -> Result<Vec<[f32; 3]>> {
    let (width, height, values) = read_u16(path)?;
    if (width, height) != size {
        bail!(
            "--depth {}: {width}x{height}, the image is {}x{}",
            path.display(),
            size.0,
            size.1
        );
    }
    let depth = DepthImage {
        width,
        height,
        values: &values,
        units_per_metre: args.depth_scale,
    };
    camera_points_from_depth(&keypoints.points, &depth, camera)
        .with_context(|| format!("--depth {}", path.display()))
}

/// `fx fy cx cy` from a file, validated.
pub(crate) fn read_intrinsics(path: &Path) -> Result<PinholeCamera> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let values: Vec<f64> = text
        .split_whitespace()
        .map(|v| v.parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("{}: expected four numbers fx fy cx cy", path.display()))?;
    let [fx, fy, cx, cy] = values[..] else {
        bail!(
            "{}: expected four numbers fx fy cx cy, found {}",
            path.display(),
            values.len()
        );
    };
    let camera = PinholeCamera { fx, fy, cx, cy };
    camera
        .validate()
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(camera)
}

/// Appends keyframe `index`'s decision row (see `--decisions`).
fn write_decision(csv: &mut String, index: usize, hint: Option<&LoopHint>, first_id: u64) {
    let Some(hint) = hint else {
        let _ = writeln!(csv, "{index},no_candidate,,,,");
        return;
    };
    let detail = match hint.gate {
        Gate::Inconsistent { agreeing } => agreeing.to_string(),
        Gate::NoPose(refusal) => format!("{refusal:?}"),
        Gate::Odometry {
            rotation_deg,
            translation_m,
        } => format!("{rotation_deg:.1}/{translation_m:.2}"),
        _ => String::new(),
    };
    let _ = writeln!(
        csv,
        "{index},{},{},{},{:.4},{detail}",
        hint.gate.name(),
        matched_index(hint, first_id),
        hint.inliers,
        hint.confidence
    );
}

/// The hints file's header (see the module documentation): keyframe indices first, the
/// same keyframes' frame indices last (after the columns older readers know by position).
const HINTS_HEADER: &str = concat!(
    "query_index,matched_index,inliers,confidence,scale_known,tx,ty,tz,qx,qy,qz,qw,",
    "query_frame,matched_frame"
);

/// The hints file: header, then one row per accepted hint. `kept` holds the keyframes' frame
/// indices.
fn write_csv(
    path: &Path,
    hints: &[(usize, LoopHint)],
    first_id: u64,
    kept: &[usize],
) -> Result<()> {
    let mut csv = format!("{HINTS_HEADER}\n");
    for (index, hint) in hints {
        let _ = write!(
            csv,
            "{index},{},{},{:.4}",
            matched_index(hint, first_id),
            hint.inliers,
            hint.confidence
        );
        match &hint.pose {
            Some(pose) => {
                let t = pose.matched_t_query.translation.vector;
                let q = pose.matched_t_query.rotation.coords;
                let _ = write!(
                    csv,
                    ",{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6}",
                    u8::from(pose.scale_known),
                    t.x,
                    t.y,
                    t.z,
                    q.x,
                    q.y,
                    q.z,
                    q.w
                );
            }
            None => csv.push_str(",,,,,,,,"),
        }
        let matched = matched_frame(hint, first_id, kept).map_or(String::new(), |f| f.to_string());
        let _ = writeln!(csv, ",{},{matched}", kept[*index]);
    }
    std::fs::write(path, csv).with_context(|| format!("writing {}", path.display()))
}

/// The matched keyframe's frame index in this run's sequence: None for a map's keyframe.
fn matched_frame(hint: &LoopHint, first_id: u64, kept: &[usize]) -> Option<usize> {
    let own = hint.matched_id.checked_sub(first_id)?;
    usize::try_from(own).ok().and_then(|k| kept.get(k).copied())
}

/// The matched keyframe as the CSV names it: a map's keyframe id, or a keyframe index of this
/// run.
fn matched_index(hint: &LoopHint, first_id: u64) -> u64 {
    if hint.matched_id >= first_id {
        hint.matched_id - first_id
    } else {
        hint.matched_id
    }
}

fn report(
    args: &LoopsArgs,
    hints: &[(usize, LoopHint)],
    gates: &BTreeMap<&str, usize>,
    [times, describe_times]: [&[f64]; 2],
    work: Work,
    first_id: u64,
    kept: &[usize],
) -> serde_json::Value {
    let frames = kept.len();
    let (median, p90) = median_and_p90(times);
    let (describe_median, _) = median_and_p90(describe_times);
    let mut out = json!({
        "keyframes": frames,
        "hints": hints.len(),
        "gates": gates,
        "keyframe_ms_median": median,
        "keyframe_ms_p90": p90,
        "describe_ms_median": describe_median,
        "pair_checks_mean": f64::from(work.pair_checks) / frames.max(1) as f64,
        "pose_fits_mean": f64::from(work.pose_fits) / frames.max(1) as f64,
        "out": args.out.display().to_string(),
        "accepted": hints.iter().map(|(i, h)| json!({
            "query_index": i,
            "matched_index": matched_index(h, first_id),
            "query_frame": kept[*i],
            "matched_frame": matched_frame(h, first_id, kept),
            "inliers": h.inliers,
            "confidence": h.confidence,
            "has_pose": h.pose.is_some(),
        })).collect::<Vec<_>>(),
    });
    if let (Some(tolerance), Some(_)) = (args.aligned_tolerance, &args.map) {
        let correct = hints
            .iter()
            .filter(|(i, h)| {
                h.matched_id < first_id && h.matched_id.abs_diff(*i as u64) <= tolerance
            })
            .count();
        out["precision"] = json!(ratio(correct, hints.len()));
        out["recall"] = json!(ratio(correct, frames));
        out["correct"] = json!(correct);
    }
    out
}

/// `part / whole`, None (JSON null) when `whole` is 0: a precision without hints, a recall
/// without possible loops, is undefined rather than 0.
fn ratio(part: usize, whole: usize) -> Option<f64> {
    (whole > 0).then(|| part as f64 / whole as f64)
}

fn print_report(args: &LoopsArgs, out: &serde_json::Value) {
    if args.json {
        println!("{out}");
        return;
    }
    let figure =
        |v: &serde_json::Value| v.as_f64().map_or("n/a".to_string(), |x| format!("{x:.3}"));
    let figures = |v: &serde_json::Value| {
        format!(
            "; precision {}, recall {}",
            figure(&v["precision"]),
            figure(&v["recall"])
        )
    };
    println!(
        "{} keyframes, {} hints (gates {}); {:.1} ms per keyframe (p90 {:.1}){}{}; hints in {}",
        out["keyframes"],
        out["hints"],
        out["gates"],
        out["keyframe_ms_median"].as_f64().unwrap_or(0.0),
        out["keyframe_ms_p90"].as_f64().unwrap_or(0.0),
        out.get("precision").map_or(String::new(), |_| figures(out)),
        out.get("truth").map_or(String::new(), |t| format!(
            "{}, rotation error {:.2} deg, translation {:.3} m, direction {:.1} deg (medians)",
            figures(t),
            t["rotation_error_deg_median"].as_f64().unwrap_or(f64::NAN),
            t["translation_error_m_median"].as_f64().unwrap_or(f64::NAN),
            t["direction_error_deg_median"].as_f64().unwrap_or(f64::NAN)
        )),
        args.out.display()
    );
}

/// `WxH` (for example `320x240`), both at least 32.
fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let parsed = text
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)));
    match parsed {
        Some((w, h)) if w >= 32 && h >= 32 => Ok((w, h)),
        _ => Err(format!(
            "'{text}' is not WxH with both at least 32 (e.g. 320x240)"
        )),
    }
}

/// An image file as RGB, resized to `size` when given (OpenCV's area interpolation).
fn decode_image(path: &Path, size: Option<(u32, u32)>) -> Result<(u32, u32, Vec<u8>)> {
    let (w, h, rgb) = read_rgb(path)?;
    let Some((to_w, to_h)) = size else {
        return Ok((w, h, rgb));
    };
    use opencv::prelude::*;
    let source = Mat::new_rows_cols_with_data(h as i32, (w * 3) as i32, &rgb)?;
    let source = source.reshape(3, h as i32)?;
    let mut resized = Mat::default();
    opencv::imgproc::resize(
        &source,
        &mut resized,
        opencv::core::Size::new(to_w as i32, to_h as i32),
        0.0,
        0.0,
        opencv::imgproc::INTER_AREA,
    )
    .with_context(|| format!("resizing {}", path.display()))?;
    Ok((to_w, to_h, resized.data_bytes()?.to_vec()))
}

/// Intrinsics of images of `from` pixels for the same images resized to `to`.
fn scale_camera(camera: PinholeCamera, from: (u32, u32), to: (u32, u32)) -> PinholeCamera {
    let sx = f64::from(to.0) / f64::from(from.0);
    let sy = f64::from(to.1) / f64::from(from.1);
    PinholeCamera {
        fx: camera.fx * sx,
        fy: camera.fy * sy,
        cx: camera.cx * sx,
        cy: camera.cy * sy,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_curve_sweeps_the_confidence_down_and_ties_make_one_point() {
        // Confidences 0.9 (right), 0.8 (wrong), 0.5 twice (both right), 0.2 (wrong); 4 possible.
        let mut judged = [
            (0.5, true),
            (0.9, true),
            (0.2, false),
            (0.8, false),
            (0.5, true),
        ];
        let curve = precision_recall(&mut judged, 4);
        let points: Vec<(f32, f64, f64)> = curve
            .iter()
            .map(|p| (p.confidence, p.recall, p.precision))
            .collect();
        assert_eq!(
            points,
            [
                (0.9, 0.25, 1.0),
                (0.8, 0.25, 0.5),
                (0.5, 0.75, 0.75),
                (0.2, 0.75, 0.6)
            ]
        );
        assert_eq!(recall_at_full_precision(&curve), 0.25);
        assert_eq!(recall_at_full_precision(&curve[1..]), 0.0);
        assert!(precision_recall(&mut [], 3).is_empty());
    }

    #[test]
    fn hints_on_stretches_without_a_revisit_are_counted_per_kilometre_driven() {
        // 0..5 drive 100 m each along x; 5 and 6 come back near 0 (revisits).
        let x = [0.0, 100.0, 200.0, 300.0, 400.0, 5.0, 0.0];
        let truth: Vec<Isometry3<f64>> = x
            .iter()
            .map(|&x| Isometry3::translation(x, 0.0, 0.0))
            .collect();
        let revisits = [false, false, false, false, false, true, true];
        let (km, hints) = without_revisit(&truth, &revisits, &[2, 3, 5, 6, 99]);
        assert!((km - 0.4).abs() < 1e-12, "{km}");
        assert_eq!(hints, 2, "the hints of keyframes 2 and 3");
    }
}
