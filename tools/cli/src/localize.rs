//! `topoloc localize`: localizes a stream of frames (an image folder or a video) against a map
//! and prints one result per frame as it goes, flushed line by line, for robots and shell
//! pipelines.
//!
//! ```text
//! topoloc localize --map MAP (--images DIR | --video FILE) [--odometry TUM] [--json-lines]
//! ```
//! Frames are described with the map's stored describer. With `--odometry` each frame takes
//! the TUM pose nearest its timestamp within `--odometry-tolerance`; a frame whose pose and
//! the previous localized frame's pose are both known gets their relative motion
//! (`previous_T_current`) as the localizer's odometry, any other frame none. Frame times:
//! [`crate::frames`]. Per-frame failures (undecodable image, size other than the first
//! frame's, uninformative image) are result lines with an `error` field and the stream goes
//! on; bad input (map, odometry file, folder, options) stops with a message on stderr and a
//! non-zero exit. stdout carries results only; the start-up line and the summary go to stderr.

use crate::backend_args::{Backend, RuntimeArgs, IMAGE_EXTENSIONS};
use crate::frames::{
    open_images, open_video, Clock, FrameSource, Pixels, RawFrame, StemUnit, TimeRule,
};
use crate::loops::read_intrinsics;
use crate::odometry::Odometry;
use crate::process::median_and_p90;
use anyhow::{bail, Context, Result};
use clap::{ArgGroup, Args, ValueEnum};
use nalgebra::Isometry3;
use serde_json::Value;
use std::fmt::Write as _;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;
use topoloc::{
    Frame, GrnnOptions, LoadOptions, Localization, Localizer, LocalizerOptions, Map, Mode,
};

/// Options of `localize`.
#[derive(Args, Clone, Debug)]
#[command(group(ArgGroup::new("input").required(true).args(["images", "video"])))]
#[command(after_help = "\
Frame times: --fps F puts frame i at START + i/F. Without it, images whose file stems are all \
numbers are timed by their names (times --stem-unit: s for TUM RGB-D's 1305031102.175304.png, \
ns for EuRoC); other names give frame i the time START + i (1 Hz); a video's frames take the \
container's times (CAP_PROP_POS_MSEC) relative to its first frame, plus START. START is \
--start-time, else the first odometry pose's time, else 0.

Odometry: each frame takes the TUM pose nearest its time if it lies within \
--odometry-tolerance (default 0.02 s, TUM's associate.py). A frame with a pose, localized right \
after a frame with a pose, gets the relative motion previous_T_current between the two; a frame \
without a pose (or after one) gets no odometry and the localizer predicts with its motion prior. \
Frames that fail are skipped by the localizer: the next motion spans them.

Output: one line per frame on stdout, flushed. With --json-lines: {\"frame\", \"source\", \
\"timestamp\", \"place\", \"view\", \"keyframe\", \"view_image\", \"confidence\", \"similarity\", \
\"off_map\", \"off_map_probability\", \"candidates\": [{\"place\", \"view\", \"probability\", \
\"similarity\", \"verified\", \"inliers\"}], \"pose_fix\": null | {\"view\", \"keyframe\", \"inliers\", \
\"translation\": [x, y, z], \"quaternion\": [qx, qy, qz, qw]} (world_T_optical in the map frame, \
with --verify and --intrinsics), \"odometry\": bool (a motion was given), \
\"odometry_timestamp\": number | null, \"ms\": describe + localize time}; a frame that fails: {\"frame\", \"source\", \
\"timestamp\", \"error_kind\": \"decode\" | \"size\" | \"localize\", \"error\"}. Exit status 0 when the \
stream ends (or stdout closes), 1 on bad input or when no frame could be localized.")]
pub struct LocalizeArgs {
    /// Map built from images (`topoloc build-map` or `topoloc simulate`); its stored describer
    /// describes the frames.
    #[arg(long)]
    pub map: PathBuf,
    /// Folder of frames in file-name order: files ending .png .jpg .jpeg .bmp .pgm .ppm (any
    /// case; other files are not frames); or a KITTI, TUM RGB-D or EuRoC sequence folder,
    /// its frames timed by the layout.
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Video file, decoded with OpenCV videoio (e.g. MJPG AVI; MP4/H.264 through FFmpeg).
    #[arg(long)]
    pub video: Option<PathBuf>,
    /// TUM odometry `timestamp tx ty tz qx qy qz qw` (world_T_camera, metres; in metric mode
    /// the convention of the map's view poses), poses matched to frames by time.
    #[arg(long)]
    pub odometry: Option<PathBuf>,
    /// Largest time difference, seconds, between a frame and the pose it takes.
    #[arg(long, default_value_t = 0.02)]
    pub odometry_tolerance: f64,
    /// Frame rate: frame i at START + i / FPS (overrides numeric names and container times).
    #[arg(long)]
    pub fps: Option<f64>,
    /// START, the time of the first frame for --fps, unnumbered names and video (default: the
    /// first odometry pose's time, else 0).
    #[arg(long)]
    pub start_time: Option<f64>,
    /// Unit of numeric image file names.
    #[arg(long, value_enum, default_value_t = StemUnit::S)]
    pub stem_unit: StemUnit,
    /// Localizer mode: the graph filter, frames one by one, metric (particles; needs
    /// odometry and a map with poses) or the learned GRNN (the built-in model; ONNX Runtime).
    #[arg(long, value_enum, default_value_t = ModeArg::Filter)]
    pub mode: ModeArg,
    /// Candidates per frame.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..))]
    pub top_k: u64,
    /// Places verified geometrically per frame with the map's stored keypoints (0: none).
    #[arg(long, default_value_t = 0)]
    pub verify: usize,
    /// With --verify: camera intrinsics file `fx fy cx cy` (pixels, of the frames' size); on a
    /// map storing keypoint scene points, results then carry a metric pose fix.
    #[arg(long)]
    pub intrinsics: Option<PathBuf>,
    /// Localizer temperature (default: the library's).
    #[arg(long)]
    pub temperature: Option<f32>,
    /// Localize every Nth input frame only (frame indices stay the input's).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub stride: u64,
    /// Stop after this many output lines (results and errors).
    #[arg(long)]
    pub max_frames: Option<u64>,
    /// Refuse the map unless it was built with this backend.
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
    #[command(flatten)]
    pub runtime: RuntimeArgs,
    /// One JSON object per line instead of text.
    #[arg(long)]
    pub json_lines: bool,
}

/// `--mode`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// Forward filter over the graph.
    Filter,
    /// Every frame on its own.
    SingleFrame,
    /// Particle filter over the camera pose (map with positions and view poses).
    Metric,
    /// The learned GRNN (the model built into the library; needs ONNX Runtime).
    Grnn,
}

impl From<ModeArg> for Mode {
    fn from(m: ModeArg) -> Self {
        match m {
            ModeArg::Filter => Mode::Filter,
            ModeArg::SingleFrame => Mode::SingleFrame,
            ModeArg::Metric => Mode::Metric,
            ModeArg::Grnn => Mode::Grnn,
        }
    }
}

/// Why a frame has no result.
#[derive(Clone, Copy, Debug)]
enum FrameErrorKind {
    /// The image did not decode.
    Decode,
    /// Its size differs from the stream's.
    Size,
    /// The localizer refused it (uninformative image, describer error, bad timestamp).
    Localize,
}

impl FrameErrorKind {
    fn name(self) -> &'static str {
        match self {
            FrameErrorKind::Decode => "decode",
            FrameErrorKind::Size => "size",
            FrameErrorKind::Localize => "localize",
        }
    }
}

/// Counts for the summary.
#[derive(Default)]
struct Tally {
    lines: u64,
    localized: u64,
    with_odometry: u64,
    with_pose: u64,
    errors: u64,
    ms: Vec<f64>,
}

/// Runs the command.
pub fn run(args: &LocalizeArgs) -> Result<()> {
    check_options(args)?;
    let odometry = args.odometry.as_deref().map(Odometry::read).transpose()?;
    let map = Arc::new(
        Map::load(&args.map, &LoadOptions::default())
            .with_context(|| format!("--map {}: cannot load the map", args.map.display()))?,
    );
    if map.describer().is_none() {
        bail!(
            "--map {}: the map has no describer (it was built from descriptors, not images), so frames cannot be described; build one from images with `topoloc build-map --images DIR --out MAP` (or `topoloc simulate`)",
            args.map.display()
        );
    }
    let mut localizer = localizer(args, &map)?;
    let clock = Clock {
        fps: args.fps,
        start: args
            .start_time
            .or(odometry.as_ref().map(|o| o.span().0))
            .unwrap_or(0.0),
        stem_unit: args.stem_unit,
    };
    let (mut source, input, describe) = open_source(args, &clock, odometry.as_ref())?;
    eprintln!(
        "topoloc localize: {} ({} places, {} views, {}); {input}: {describe}",
        args.map.display(),
        map.place_count(),
        map.view_count(),
        map.descriptor()
    );
    if args.mode == ModeArg::Metric && odometry.is_none() {
        eprintln!("note: metric mode without --odometry: its particles only diffuse");
    }

    let mut stream = Stream {
        args,
        map: &map,
        odometry: odometry.as_ref(),
        localizer: &mut localizer,
        size: None,
        last_pose: None,
        out: Localization::default(),
        tally: Tally::default(),
    };
    let mut stdout = std::io::stdout().lock();
    while args.max_frames.is_none_or(|m| stream.tally.lines < m) {
        let Some(frame) = source.next_frame()? else {
            break;
        };
        if !(frame.index as u64).is_multiple_of(args.stride) {
            continue;
        }
        let line = stream.line(&frame);
        let written = writeln!(stdout, "{line}").and_then(|()| stdout.flush());
        match written {
            Ok(()) => {}
            // The reader is gone (`| head`): the stream ends normally.
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => return Ok(()),
            Err(e) => return Err(e).context("writing to stdout"),
        }
    }
    summarize(&stream.tally, odometry.as_ref())
}

/// The state of a stream between frames.
struct Stream<'a> {
    args: &'a LocalizeArgs,
    map: &'a Map,
    odometry: Option<&'a Odometry>,
    localizer: &'a mut Localizer,
    /// Size of the stream's frames (the first decoded frame's).
    size: Option<(u32, u32)>,
    /// Pose of the last localized frame (None: it had none, or no frame yet).
    last_pose: Option<Isometry3<f64>>,
    out: Localization,
    tally: Tally,
}

impl Stream<'_> {
    /// Localizes one frame and returns its output line (a result or an error).
    fn line(&mut self, frame: &RawFrame) -> String {
        self.tally.lines += 1;
        let pose = self
            .odometry
            .and_then(|o| o.pose_at(frame.timestamp, self.args.odometry_tolerance))
            .copied();
        let pixels = match &frame.pixels {
            Ok(pixels) => pixels,
            Err(e) => return self.error(frame, FrameErrorKind::Decode, e),
        };
        if let Err(e) = check_size(&mut self.size, pixels) {
            return self.error(frame, FrameErrorKind::Size, &e);
        }
        let motion = match (self.last_pose, pose) {
            (Some(a), Some(b)) => Some(a.inverse() * b.world_t_camera),
            _ => None,
        };
        let start = Instant::now();
        let result = self.localizer.process(
            &Frame {
                timestamp: frame.timestamp,
                descriptor: &[],
                image: Some(pixels.view()),
                odometry: motion,
            },
            &mut self.out,
        );
        let ms = start.elapsed().as_secs_f64() * 1e3;
        if let Err(e) = result {
            return self.error(frame, FrameErrorKind::Localize, &e.to_string());
        }
        self.last_pose = pose.map(|p| p.world_t_camera);
        let tally = &mut self.tally;
        tally.localized += 1;
        tally.with_odometry += u64::from(motion.is_some());
        tally.with_pose += u64::from(self.out.pose_fix.is_some());
        tally.ms.push(ms);
        let odometry = Applied {
            motion: motion.is_some(),
            pose_time: pose.map(|p| p.timestamp),
        };
        result_line(self.args, self.map, frame, &self.out, odometry, ms)
    }

    fn error(&mut self, frame: &RawFrame, kind: FrameErrorKind, error: &str) -> String {
        self.tally.errors += 1;
        error_line(self.args, frame, kind, error)
    }
}

/// What odometry a frame had: whether a motion went to the localizer, and the time of the
/// pose the frame took.
#[derive(Clone, Copy)]
struct Applied {
    motion: bool,
    pose_time: Option<f64>,
}

/// Option values clap cannot check.
fn check_options(args: &LocalizeArgs) -> Result<()> {
    if let Some(fps) = args.fps {
        if !(fps.is_finite() && fps > 0.0) {
            bail!("--fps {fps}: must be a finite rate > 0");
        }
    }
    if let Some(t) = args.start_time {
        if !t.is_finite() {
            bail!("--start-time {t}: must be finite");
        }
    }
    if !(args.odometry_tolerance.is_finite() && args.odometry_tolerance >= 0.0) {
        bail!(
            "--odometry-tolerance {}: must be finite and >= 0 seconds",
            args.odometry_tolerance
        );
    }
    if args.intrinsics.is_some() && args.verify == 0 {
        bail!("--intrinsics gives pose fixes of verified places: give --verify N too");
    }
    Ok(())
}

/// The localizer the options ask for, describing frames with the map's describer.
fn localizer(args: &LocalizeArgs, map: &Arc<Map>) -> Result<Localizer> {
    let mut options = LocalizerOptions {
        mode: args.mode.into(),
        top_k: args.top_k as usize,
        grnn: GrnnOptions {
            runtime: args.runtime.onnx_runtime.clone(),
            ..GrnnOptions::default()
        },
        ..LocalizerOptions::default()
    };
    if let Some(t) = args.temperature {
        options.temperature = t;
    }
    if args.verify > 0 {
        options.verification.candidates = args.verify;
        options.verification.xfeat = args.runtime.xfeat_options();
        options.verification.camera = args
            .intrinsics
            .as_deref()
            .map(read_intrinsics)
            .transpose()
            .context("--intrinsics")?;
    }
    Localizer::with_describer(
        map.clone(),
        options,
        &args.runtime.describer_options(args.backend),
    )
    .with_context(|| {
        format!(
            "--map {}: cannot localize with this map and these options",
            args.map.display()
        )
    })
}

/// Opens the frame source: (source, what it is, its timestamp rule). Checks what can be
/// checked before the stream starts.
fn open_source(
    args: &LocalizeArgs,
    clock: &Clock,
    odometry: Option<&Odometry>,
) -> Result<(FrameSource, String, String)> {
    if let Some(video) = &args.video {
        let (source, describe) = open_video(video, clock)?;
        return Ok((source, format!("video {}", video.display()), describe));
    }
    let dir = args
        .images
        .as_ref()
        .expect("clap requires --images or --video");
    let folder = open_images(dir, clock)?;
    match folder.rule {
        TimeRule::Names if args.start_time.is_some() => bail!(
            "--start-time applies to --fps, --video and unnumbered file names; the files of {} are timed by their names",
            dir.display()
        ),
        TimeRule::Layout if args.start_time.is_some() => bail!(
            "--start-time applies to --fps, --video and unnumbered file names; {} is a sequence timed by its layout",
            dir.display()
        ),
        TimeRule::Index if odometry.is_some() => bail!(
            "--odometry needs frame times: the file names of {} are not all numbers, so give the frame rate with --fps",
            dir.display()
        ),
        _ => {}
    }
    if !folder.ignored.is_empty() {
        let shown: Vec<&str> = folder.ignored.iter().take(5).map(String::as_str).collect();
        eprintln!(
            "note: {} files of {} are not frames (extensions {}): {}{}",
            folder.ignored.len(),
            dir.display(),
            IMAGE_EXTENSIONS.join(", "),
            shown.join(", "),
            if folder.ignored.len() > 5 {
                ", ..."
            } else {
                ""
            }
        );
    }
    if let (Some(odometry), FrameSource::Images { times, .. }) = (odometry, &folder.source) {
        if !times
            .iter()
            .any(|&t| odometry.pose_at(t, args.odometry_tolerance).is_some())
        {
            let (first, last) = odometry.span();
            bail!(
                "--odometry: no frame time is within {} s of a pose (frames {} to {} s, {}; poses {first} to {last} s): check --fps, --start-time or --stem-unit",
                args.odometry_tolerance,
                times[0],
                times[times.len() - 1],
                folder.describe
            );
        }
    }
    let count = match &folder.source {
        FrameSource::Images { files, .. } => files.len(),
        FrameSource::Video(_) => 0,
    };
    Ok((
        folder.source,
        format!("{count} images in {}", dir.display()),
        format!("times {}", folder.describe),
    ))
}

/// Fails when `pixels` is not of the stream's size (the first frame's, recorded here).
fn check_size(size: &mut Option<(u32, u32)>, pixels: &Pixels) -> Result<(), String> {
    let this = (pixels.width, pixels.height);
    match *size {
        None => {
            *size = Some(this);
            Ok(())
        }
        Some(s) if s == this => Ok(()),
        Some((w, h)) => Err(format!(
            "image is {}x{}, this stream's frames are {w}x{h} (the first frame's size)",
            this.0, this.1
        )),
    }
}

/// A JSON object written field by field in the order given (serde_json's own maps sort their
/// keys); values are serialized as their own type, so f32 figures print at f32 precision.
struct JsonLine(String);

impl JsonLine {
    fn new() -> Self {
        Self(String::from("{"))
    }

    /// Adds `key` with the JSON text `json`.
    fn raw(mut self, key: &str, json: &str) -> Self {
        if self.0.len() > 1 {
            self.0.push(',');
        }
        self.0.push_str(&Value::from(key).to_string());
        self.0.push(':');
        self.0.push_str(json);
        self
    }

    /// Adds `key` with `value` serialized.
    fn field<T: serde::Serialize>(self, key: &str, value: T) -> Self {
        let json = serde_json::to_string(&value).expect("plain values serialize");
        self.raw(key, &json)
    }

    fn finish(mut self) -> String {
        self.0.push('}');
        self.0
    }
}

/// The keyframe id and image reference of `view` (none when the map has none).
fn view_refs(map: &Map, view: u32) -> (Option<u64>, Option<String>) {
    map.view(view)
        .map_or((None, None), |r| (r.keyframe_id, r.image.clone()))
}

/// One frame's result line.
fn result_line(
    args: &LocalizeArgs,
    map: &Map,
    frame: &RawFrame,
    out: &Localization,
    odometry: Applied,
    ms: f64,
) -> String {
    let (keyframe, view_image) = view_refs(map, out.view);
    if !args.json_lines {
        return text_line(frame, out, odometry.motion, view_image.as_deref());
    }
    let pose_fix = out.pose_fix.map_or_else(
        || "null".to_string(),
        |fix| {
            let t = fix.world_t_optical.translation.vector;
            let q = fix.world_t_optical.rotation;
            JsonLine::new()
                .field("view", fix.view)
                .field("keyframe", view_refs(map, fix.view).0)
                .field("inliers", fix.inliers)
                .field("translation", [t.x, t.y, t.z])
                .field("quaternion", [q.i, q.j, q.k, q.w])
                .finish()
        },
    );
    let candidates: Vec<String> = out
        .candidates
        .iter()
        .map(|c| {
            JsonLine::new()
                .field("place", c.place)
                .field("view", c.view)
                .field("probability", c.probability)
                .field("similarity", c.similarity)
                .field("verified", c.verified)
                .field("inliers", c.inliers)
                .finish()
        })
        .collect();
    JsonLine::new()
        .field("frame", frame.index)
        .field("source", &frame.source)
        .field("timestamp", frame.timestamp)
        .field("place", out.place)
        .field("view", out.view)
        .field("keyframe", keyframe)
        .field("view_image", view_image)
        .field("confidence", out.confidence)
        .field("similarity", out.similarity)
        .field("off_map", out.off_map)
        .field("off_map_probability", out.off_map_probability)
        .raw("candidates", &format!("[{}]", candidates.join(",")))
        .raw("pose_fix", &pose_fix)
        .field("odometry", odometry.motion)
        .field("odometry_timestamp", odometry.pose_time)
        .field("ms", (ms * 1e3).round() / 1e3)
        .finish()
}

/// The human-readable form of a result.
fn text_line(
    frame: &RawFrame,
    out: &Localization,
    odometry: bool,
    view_image: Option<&str>,
) -> String {
    let mut line = format!(
        "{:>6} {} t={:.3} place {} view {}",
        frame.index, frame.source, frame.timestamp, out.place, out.view
    );
    if let Some(image) = view_image {
        let name = std::path::Path::new(image)
            .file_name()
            .map_or(image.into(), |n| n.to_string_lossy());
        let _ = write!(line, " ({name})");
    }
    let _ = write!(
        line,
        " conf {:.3} sim {:.3} {}",
        out.confidence,
        out.similarity,
        if out.off_map {
            format!("OFF-MAP {:.2}", out.off_map_probability)
        } else {
            "on-map".into()
        }
    );
    line.push_str(" | top");
    for c in &out.candidates {
        let _ = write!(line, " {}:{:.3}", c.place, c.probability);
        if c.verified {
            let _ = write!(line, "[{} inl]", c.inliers);
        }
    }
    if odometry {
        line.push_str(" | odometry");
    }
    if let Some(fix) = &out.pose_fix {
        let t = fix.world_t_optical.translation.vector;
        let _ = write!(
            line,
            " | pose fix view {} ({} inliers) at {:.3} {:.3} {:.3}",
            fix.view, fix.inliers, t.x, t.y, t.z
        );
    }
    line
}

/// One frame's error line.
fn error_line(args: &LocalizeArgs, frame: &RawFrame, kind: FrameErrorKind, error: &str) -> String {
    if args.json_lines {
        JsonLine::new()
            .field("frame", frame.index)
            .field("source", &frame.source)
            .field("timestamp", frame.timestamp)
            .field("error_kind", kind.name())
            .field("error", error)
            .finish()
    } else {
        format!(
            "{:>6} {} t={:.3} error ({}): {error}",
            frame.index,
            frame.source,
            frame.timestamp,
            kind.name()
        )
    }
}

/// The summary on stderr; fails when frames came but none could be localized.
fn summarize(tally: &Tally, odometry: Option<&Odometry>) -> Result<()> {
    let (median, p90) = median_and_p90(&tally.ms);
    eprintln!(
        "topoloc localize: {} frames, {} localized ({} with odometry, {} with a pose fix), {} errors; {median:.1} ms per frame median, {p90:.1} p90",
        tally.lines, tally.localized, tally.with_odometry, tally.with_pose, tally.errors
    );
    if let Some(odometry) = odometry.filter(|_| tally.localized > 1 && tally.with_odometry == 0) {
        let (first, last) = odometry.span();
        eprintln!(
            "warning: --odometry gave no frame a motion (poses {first} to {last} s): check --fps, --start-time, --stem-unit or --odometry-tolerance"
        );
    }
    if tally.lines > 0 && tally.localized == 0 {
        bail!(
            "none of the {} frames could be localized (see their error lines)",
            tally.lines
        );
    }
    Ok(())
}
