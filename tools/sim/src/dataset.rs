//! The dataset folder: what `topoloc-sim` writes and `topoloc eval` reads.
//!
//! ```text
//! <root>/
//!   manifest.json      format name and version, seeds, split, style, condition, frame count,
//!                      rate, tool version, odometry noise, file list (written last)
//!   intrinsics.json    camera::Intrinsics: width, height, fx, fy, cx, cy
//!   graph.json         places (position [x, y, z], kind, view_yaws) and edges [[a, b], ...]
//!   groundtruth.txt    TUM: `timestamp tx ty tz qx qy qz qw` per frame, world_T_camera
//!   odometry.txt       TUM, same timestamps, the drifting odometry
//!   nodes.csv          header `frame,place,view,visible`, one row per frame (visible is 0 or 1)
//!   images/000000.png  one RGB PNG per frame, six-digit frame index
//!   depth/000000.png   optional (format 1.1): one 16-bit PNG per frame, the forward distance
//!                      of each pixel's surface in units of 1/depth_scale m (the manifest's
//!                      `depth_scale`, 1000: millimetres); 0 where nothing is seen
//! ```
//!
//! Views are numbered globally place by place (see [`crate::ground_truth`]). `nodes.csv` also
//! reads as the `query_index,place` table of `topoloc eval --gt-nodes`.
//!
//! [`DatasetWriter`] writes a folder (images as they are rendered, from any thread, then the
//! rest); [`Dataset::open`] reads and checks one, with errors that name the file (and line).

use crate::camera::Intrinsics;
use crate::ground_truth::{FrameTruth, PlaceGraph};
use crate::odometry::OdometryNoise;
use opencv::core::{Mat, Vec3b};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use topoloc::build::{parse_tum, TimedPose};
use topoloc::eval::{GraphEvaluator, GraphMetrics, Prediction};
use topoloc::map::PlaceId;

/// Value of the manifest's `format` key.
pub const FORMAT_NAME: &str = "topoloc-sim-dataset";
/// Major format version this build writes and the newest it reads.
pub const FORMAT_VERSION_MAJOR: u32 = 1;
/// Minor format version this build writes (newer minors only add keys and still read).
pub const FORMAT_VERSION_MINOR: u32 = 1;
/// The manifest, written last: a folder without one is incomplete.
pub const MANIFEST_FILE: &str = "manifest.json";
/// Camera intrinsics.
pub const INTRINSICS_FILE: &str = "intrinsics.json";
/// The place graph.
pub const GRAPH_FILE: &str = "graph.json";
/// Ground-truth poses (TUM).
pub const GROUND_TRUTH_FILE: &str = "groundtruth.txt";
/// Odometry poses (TUM).
pub const ODOMETRY_FILE: &str = "odometry.txt";
/// Ground-truth place and view per frame (CSV).
pub const NODES_FILE: &str = "nodes.csv";
/// Folder of the frame images.
pub const IMAGES_DIR: &str = "images";
/// Folder of the optional depth images.
pub const DEPTH_DIR: &str = "depth";
/// Depth image units per metre: millimetres, as ROS `16UC1` depth and most depth cameras
/// (TUM RGB-D uses 5000).
pub const DEPTH_SCALE: f64 = 1000.0;
/// Header row of [`NODES_FILE`].
pub const NODES_HEADER: &str = "frame,place,view,visible";
/// List depths reported by [`Dataset::evaluate`]: R@1 to R@10.
pub const RECALL_DEPTHS: [usize; 10] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10];

/// Path of frame `frame`'s image relative to the dataset root, e.g. `images/000042.png`.
pub fn image_name(frame: usize) -> String {
    format!("{IMAGES_DIR}/{frame:06}.png")
}

/// Path of frame `frame`'s depth image relative to the dataset root, e.g. `depth/000042.png`.
pub fn depth_name(frame: usize) -> String {
    format!("{DEPTH_DIR}/{frame:06}.png")
}

/// A dataset that cannot be written or read; every variant names the file or folder.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// Reading or writing failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// File or folder involved.
        path: PathBuf,
        /// Underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A folder or file the dataset needs is not there.
    #[error("{}: {what} is missing", path.display())]
    Missing {
        /// Expected path.
        path: PathBuf,
        /// What it should have been.
        what: &'static str,
    },
    /// A JSON file does not parse, or lacks a key (serde names the key, line and column).
    #[error("{}: {source}", path.display())]
    Json {
        /// The JSON file.
        path: PathBuf,
        /// Parser error.
        #[source]
        source: serde_json::Error,
    },
    /// A file's content is wrong: a bad value, a wrong count, an inconsistency.
    #[error("{}{}: {message}", path.display(), line.map(|l| format!(" line {l}")).unwrap_or_default())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// 1-based line, for text files.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// The dataset was written by a newer, incompatible format version.
    #[error("{}: format version {found} is newer than the supported {supported}.x; upgrade topoloc-sim", path.display())]
    UnsupportedVersion {
        /// The manifest.
        path: PathBuf,
        /// Version found.
        found: String,
        /// Newest major version supported.
        supported: u32,
    },
    /// The writer refuses a folder that already holds files (stale frames would mix in).
    #[error("{}: folder is not empty; write a dataset into a new or empty folder", path.display())]
    NotEmpty {
        /// The folder.
        path: PathBuf,
    },
    /// Predictions handed to [`Dataset::evaluate`] do not fit the dataset.
    #[error("evaluation: {0}")]
    Evaluation(String),
}

fn invalid(path: &Path, line: Option<usize>, message: impl Into<String>) -> DatasetError {
    DatasetError::Invalid {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> DatasetError + '_ {
    move |source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// What a dataset is, as the generator knows it (recorded in the manifest).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetInfo {
    /// Seed of the world.
    pub world_seed: u64,
    /// Seed of the trajectory.
    pub trajectory_seed: u64,
    /// Split name, e.g. `"train"`, `"test"`.
    pub split: String,
    /// Visual style of the world.
    pub style: String,
    /// Lighting / appearance condition of the images.
    pub condition: String,
    /// Frame rate, Hz.
    pub rate_hz: f64,
    /// Seed of the odometry noise.
    pub odometry_seed: u64,
    /// How the odometry drifts.
    pub odometry_noise: OdometryNoise,
}

/// `manifest.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`FORMAT_NAME`].
    pub format: String,
    /// `"major.minor"`.
    pub format_version: String,
    /// Name of the writing tool (`topoloc-sim`).
    pub tool: String,
    /// Version of the writing tool.
    pub tool_version: String,
    /// Seeds, split, style, condition, rate and odometry noise.
    #[serde(flatten)]
    pub info: DatasetInfo,
    /// Number of frames (images, poses, node rows).
    pub frame_count: usize,
    /// Depth image units per metre when the dataset has depth images (format 1.1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_scale: Option<f64>,
    /// Files of the dataset relative to its root, the manifest excepted (images included).
    pub files: Vec<String>,
}

/// Writes a dataset folder (see the module documentation).
#[derive(Debug)]
pub struct DatasetWriter {
    root: PathBuf,
    intrinsics: Intrinsics,
    /// Whether a depth image was written.
    depth: std::sync::atomic::AtomicBool,
}

/// What [`DatasetWriter`] is given for one image, as its errors name it.
struct BufferKind {
    /// The buffer's name.
    name: &'static str,
    /// What its values are.
    units: &'static str,
    /// Values per pixel.
    per_pixel: usize,
    /// The image it becomes.
    image: &'static str,
}

/// Packed RGB8 rows of a frame's image.
const RGB8_BUFFER: BufferKind = BufferKind {
    name: "image",
    units: "bytes",
    per_pixel: 3,
    image: "RGB8 image",
};

/// A frame's depth in metres, one value per pixel.
const DEPTH_BUFFER: BufferKind = BufferKind {
    name: "depth",
    units: "values",
    per_pixel: 1,
    image: "image",
};

impl DatasetWriter {
    /// Creates `root` (and `root/images`); refuses a folder that already holds anything and
    /// invalid intrinsics (naming the field).
    pub fn create(root: &Path, intrinsics: Intrinsics) -> Result<Self, DatasetError> {
        intrinsics
            .validate()
            .map_err(|m| invalid(&root.join(INTRINSICS_FILE), None, m))?;
        if root.exists() {
            let mut entries = std::fs::read_dir(root).map_err(io(root))?;
            if entries.next().is_some() {
                return Err(DatasetError::NotEmpty {
                    path: root.to_path_buf(),
                });
            }
        }
        let images = root.join(IMAGES_DIR);
        std::fs::create_dir_all(&images).map_err(io(&images))?;
        Ok(Self {
            root: root.to_path_buf(),
            intrinsics,
            depth: false.into(),
        })
    }

    /// The dataset folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Checks that a `kind` buffer of `len` units for the image at `path` holds one pixel's
    /// worth for every pixel of the intrinsics' size.
    fn check_buffer(&self, path: &Path, kind: &BufferKind, len: usize) -> Result<(), DatasetError> {
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        let needed = w as usize * h as usize * kind.per_pixel;
        if len == needed {
            return Ok(());
        }
        let BufferKind {
            name, units, image, ..
        } = kind;
        let message =
            format!("{name} buffer holds {len} {units}, a {w}x{h} {image} needs {needed}");
        Err(invalid(path, None, message))
    }

    /// Writes frame `frame`'s image, packed RGB8 rows of the intrinsics' size, as PNG. Takes
    /// `&self`: frames may be written from several threads, in any order.
    pub fn write_image(&self, frame: usize, rgb: &[u8]) -> Result<PathBuf, DatasetError> {
        let path = self.root.join(image_name(frame));
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        self.check_buffer(&path, &RGB8_BUFFER, rgb.len())?;
        let cv = |e: opencv::Error| invalid(&path, None, format!("OpenCV: {e}"));
        let packed = Mat::new_rows_cols_with_bytes::<Vec3b>(h as i32, w as i32, rgb).map_err(cv)?;
        let mut bgr = Mat::default();
        opencv::imgproc::cvt_color_def(&packed, &mut bgr, opencv::imgproc::COLOR_RGB2BGR)
            .map_err(cv)?;
        if !opencv::imgcodecs::imwrite_def(&path, &bgr).map_err(cv)? {
            return Err(invalid(&path, None, "OpenCV could not write the PNG"));
        }
        Ok(path)
    }

    /// Writes frame `frame`'s depth image (metres per pixel, rows of the intrinsics' size;
    /// NaN, zero or beyond the 16-bit range for nothing seen) as a 16-bit PNG in
    /// [`DEPTH_SCALE`] units. Like images, from any thread; once one frame has depth, every
    /// frame needs it.
    pub fn write_depth(&self, frame: usize, metres: &[f32]) -> Result<PathBuf, DatasetError> {
        let path = self.root.join(depth_name(frame));
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        self.check_buffer(&path, &DEPTH_BUFFER, metres.len())?;
        let units: Vec<u16> = metres
            .iter()
            .map(|&m| {
                let u = f64::from(m) * DEPTH_SCALE;
                if u.is_finite() && u >= 0.5 && u < f64::from(u16::MAX) {
                    u.round() as u16
                } else {
                    0
                }
            })
            .collect();
        let dir = self.root.join(DEPTH_DIR);
        std::fs::create_dir_all(&dir).map_err(io(&dir))?;
        let cv = |e: opencv::Error| invalid(&path, None, format!("OpenCV: {e}"));
        let mat = Mat::new_rows_cols_with_data::<u16>(h as i32, w as i32, &units).map_err(cv)?;
        if !opencv::imgcodecs::imwrite_def(&path, &mat).map_err(cv)? {
            return Err(invalid(&path, None, "OpenCV could not write the PNG"));
        }
        self.depth.store(true, std::sync::atomic::Ordering::Relaxed);
        Ok(path)
    }

    /// Checks the records against each other and the images written, writes the other files
    /// and the manifest last, and returns the manifest. `ground_truth`, `odometry` and `nodes`
    /// hold one entry per frame, with equal timestamps; `nodes[k].frame` must be `k`; every
    /// frame `0..n` needs its image and no other image may be there.
    pub fn finish(
        self,
        info: &DatasetInfo,
        graph: &PlaceGraph,
        ground_truth: &[TimedPose],
        odometry: &[TimedPose],
        nodes: &[FrameTruth],
    ) -> Result<Manifest, DatasetError> {
        let root = &self.root;
        let n = ground_truth.len();
        let depth = self.depth.load(std::sync::atomic::Ordering::Relaxed);
        let manifest = Manifest {
            format: FORMAT_NAME.into(),
            format_version: format!("{FORMAT_VERSION_MAJOR}.{FORMAT_VERSION_MINOR}"),
            tool: env!("CARGO_PKG_NAME").into(),
            tool_version: env!("CARGO_PKG_VERSION").into(),
            info: info.clone(),
            frame_count: n,
            depth_scale: depth.then_some(DEPTH_SCALE),
            files: file_list(n, depth),
        };
        check_manifest(&root.join(MANIFEST_FILE), &manifest)?;
        graph
            .validate()
            .map_err(|m| invalid(&root.join(GRAPH_FILE), None, m))?;
        check_poses(&root.join(GROUND_TRUTH_FILE), ground_truth, n, None)?;
        check_poses(&root.join(ODOMETRY_FILE), odometry, n, Some(ground_truth))?;
        let rows = nodes.iter().enumerate().map(|(k, t)| (k + 2, *t));
        check_nodes(&root.join(NODES_FILE), graph, rows, n)?;
        check_images(root, n)?;
        if depth {
            check_depth(root, n)?;
        }

        write_json(&root.join(INTRINSICS_FILE), &self.intrinsics)?;
        write_json(&root.join(GRAPH_FILE), graph)?;
        write_text(&root.join(GROUND_TRUTH_FILE), &tum_text(ground_truth))?;
        write_text(&root.join(ODOMETRY_FILE), &tum_text(odometry))?;
        let mut csv = format!("{NODES_HEADER}\n");
        for t in nodes {
            let _ = writeln!(
                csv,
                "{},{},{},{}",
                t.frame,
                t.place,
                t.view,
                u8::from(t.visible)
            );
        }
        write_text(&root.join(NODES_FILE), &csv)?;
        // The manifest goes last and atomically: its presence marks a complete dataset.
        let partial = root.join(format!("{MANIFEST_FILE}.partial"));
        write_json(&partial, &manifest)?;
        let path = root.join(MANIFEST_FILE);
        std::fs::rename(&partial, &path).map_err(io(&path))?;
        Ok(manifest)
    }
}

/// The files of an `n`-frame dataset, manifest excepted.
fn file_list(n: usize, depth: bool) -> Vec<String> {
    [
        INTRINSICS_FILE,
        GRAPH_FILE,
        GROUND_TRUTH_FILE,
        ODOMETRY_FILE,
        NODES_FILE,
    ]
    .iter()
    .map(|s| s.to_string())
    .chain((0..n).map(image_name))
    .chain((0..if depth { n } else { 0 }).map(depth_name))
    .collect()
}

fn write_text(path: &Path, text: &str) -> Result<(), DatasetError> {
    std::fs::write(path, text).map_err(io(path))
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<(), DatasetError> {
    let text = serde_json::to_string_pretty(value).map_err(|source| DatasetError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    write_text(path, &(text + "\n"))
}

/// TUM text: a header comment, then `timestamp tx ty tz qx qy qz qw` per pose, each number in
/// the shortest form that reads back exactly.
fn tum_text(poses: &[TimedPose]) -> String {
    let mut text = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for p in poses {
        let t = p.world_t_camera.translation.vector;
        let q = p.world_t_camera.rotation.coords; // [qx, qy, qz, qw]
        let _ = writeln!(
            text,
            "{} {} {} {} {} {} {} {}",
            p.timestamp, t.x, t.y, t.z, q.x, q.y, q.z, q.w
        );
    }
    text
}

fn check_manifest(path: &Path, m: &Manifest) -> Result<(), DatasetError> {
    let rate = m.info.rate_hz;
    if !(rate.is_finite() && rate > 0.0) {
        return Err(invalid(
            path,
            None,
            format!("rate_hz is {rate}, must be finite and positive"),
        ));
    }
    m.info
        .odometry_noise
        .validate()
        .map_err(|msg| invalid(path, None, format!("odometry_noise: {msg}")))
}

/// Checks that the file (or folder) at `path` holds `count` `what`, one for each of `n` frames.
fn check_count(path: &Path, count: usize, what: &str, n: usize) -> Result<(), DatasetError> {
    if count == n {
        return Ok(());
    }
    Err(invalid(
        path,
        None,
        format!("{count} {what} for {n} frames"),
    ))
}

/// Checks a pose list: `n` poses, finite non-decreasing timestamps, and (for odometry) the
/// timestamps of `reference`.
fn check_poses(
    path: &Path,
    poses: &[TimedPose],
    n: usize,
    reference: Option<&[TimedPose]>,
) -> Result<(), DatasetError> {
    check_count(path, poses.len(), "poses", n)?;
    for (k, p) in poses.iter().enumerate() {
        let t = p.timestamp;
        let earlier = k > 0 && t < poses[k - 1].timestamp;
        if !t.is_finite() || earlier {
            return Err(invalid(
                path,
                None,
                format!("pose {k}: timestamp {t} is not finite or goes backwards"),
            ));
        }
        if let Some(r) = reference.and_then(|r| r.get(k)) {
            if (r.timestamp - t).abs() > 1e-6 {
                return Err(invalid(
                    path,
                    None,
                    format!(
                        "pose {k}: timestamp {t} differs from the ground truth's {}",
                        r.timestamp
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Checks node rows `(line, truth)`: frames `0..n` in order, places and views of the graph.
fn check_nodes(
    path: &Path,
    graph: &PlaceGraph,
    rows: impl ExactSizeIterator<Item = (usize, FrameTruth)>,
    n: usize,
) -> Result<(), DatasetError> {
    check_count(path, rows.len(), "rows", n)?;
    let offsets = graph.view_offsets();
    let places = graph.places.len();
    for (k, (line, t)) in rows.enumerate() {
        let bad = |message: String| Err(invalid(path, Some(line), message));
        if t.frame != k {
            return bad(format!(
                "frame {} where frame {k} was expected (one row per frame, in order)",
                t.frame
            ));
        }
        let p = t.place as usize;
        if p >= places {
            return bad(format!("place {p}, the graph has {places} places"));
        }
        if !(offsets[p]..offsets[p + 1]).contains(&t.view) {
            return bad(format!(
                "view {} is not a view of place {p} (its views are {}..{})",
                t.view,
                offsets[p],
                offsets[p + 1]
            ));
        }
    }
    Ok(())
}

/// Checks that `images/` holds exactly the PNGs of frames `0..n`.
fn check_images(root: &Path, n: usize) -> Result<(), DatasetError> {
    check_frame_pngs(
        root,
        IMAGES_DIR,
        image_name,
        n,
        ["the image folder", "the image of a frame"],
    )
}

/// Exactly one depth PNG per frame in [`DEPTH_DIR`].
fn check_depth(root: &Path, n: usize) -> Result<(), DatasetError> {
    check_frame_pngs(
        root,
        DEPTH_DIR,
        depth_name,
        n,
        ["the depth folder", "the depth image of a frame"],
    )
}

/// Exactly one PNG per frame in `root/folder`, named by `name`; `what` names the folder and a
/// file in errors.
fn check_frame_pngs(
    root: &Path,
    folder: &str,
    name: fn(usize) -> String,
    n: usize,
    what: [&'static str; 2],
) -> Result<(), DatasetError> {
    let dir = root.join(folder);
    if !dir.is_dir() {
        return Err(DatasetError::Missing {
            path: dir,
            what: what[0],
        });
    }
    let entries = std::fs::read_dir(&dir).map_err(io(&dir))?;
    let mut count = 0;
    for entry in entries {
        let entry = entry.map_err(io(&dir))?;
        let is_png = entry
            .path()
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("png"));
        count += usize::from(is_png);
    }
    check_count(&dir, count, "PNG images", n)?;
    for frame in 0..n {
        let path = root.join(name(frame));
        if !path.is_file() {
            return Err(DatasetError::Missing {
                path,
                what: what[1],
            });
        }
    }
    Ok(())
}

/// A dataset read from its folder (images stay on disk; see [`Dataset::read_image`]).
#[derive(Clone, Debug)]
pub struct Dataset {
    /// The folder.
    pub root: PathBuf,
    /// `manifest.json`.
    pub manifest: Manifest,
    /// `intrinsics.json`.
    pub intrinsics: Intrinsics,
    /// `graph.json`.
    pub graph: PlaceGraph,
    /// `groundtruth.txt`.
    pub ground_truth: Vec<TimedPose>,
    /// `odometry.txt`.
    pub odometry: Vec<TimedPose>,
    /// `nodes.csv`.
    pub nodes: Vec<FrameTruth>,
}

impl Dataset {
    /// Reads and checks the dataset at `root`: every file present and well-formed, the format
    /// known and not newer than this build, and the counts of images, poses and node rows
    /// equal to the manifest's frame count. Errors name the file (and line for text files).
    pub fn open(root: &Path) -> Result<Self, DatasetError> {
        if !root.is_dir() {
            return Err(DatasetError::Missing {
                path: root.to_path_buf(),
                what: "the dataset folder",
            });
        }
        let manifest = read_manifest(&root.join(MANIFEST_FILE))?;
        for name in file_list(0, false).iter().chain(&manifest.files) {
            let path = root.join(name);
            if !path.is_file() {
                return Err(DatasetError::Missing {
                    path,
                    what: "a file of the dataset",
                });
            }
        }
        let n = manifest.frame_count;
        let path = root.join(INTRINSICS_FILE);
        let intrinsics: Intrinsics = read_json(&path)?;
        intrinsics.validate().map_err(|m| invalid(&path, None, m))?;
        let path = root.join(GRAPH_FILE);
        let graph: PlaceGraph = read_json(&path)?;
        graph.validate().map_err(|m| invalid(&path, None, m))?;
        let ground_truth = read_poses(&root.join(GROUND_TRUTH_FILE))?;
        check_poses(&root.join(GROUND_TRUTH_FILE), &ground_truth, n, None)?;
        let odometry = read_poses(&root.join(ODOMETRY_FILE))?;
        check_poses(&root.join(ODOMETRY_FILE), &odometry, n, Some(&ground_truth))?;
        let path = root.join(NODES_FILE);
        let rows = parse_nodes(&path, &read_text(&path)?)?;
        check_nodes(&path, &graph, rows.iter().copied(), n)?;
        check_images(root, n)?;
        if let Some(scale) = manifest.depth_scale {
            if !(scale.is_finite() && scale > 0.0) {
                let path = root.join(MANIFEST_FILE);
                return Err(invalid(
                    &path,
                    None,
                    format!("depth_scale is {scale}, must be > 0"),
                ));
            }
            check_depth(root, n)?;
        }
        Ok(Self {
            root: root.to_path_buf(),
            manifest,
            intrinsics,
            graph,
            ground_truth,
            odometry,
            nodes: rows.into_iter().map(|(_, t)| t).collect(),
        })
    }

    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.manifest.frame_count
    }

    /// Path of frame `frame`'s image.
    pub fn image_path(&self, frame: usize) -> PathBuf {
        self.root.join(image_name(frame))
    }

    /// Path of frame `frame`'s depth image (see the module documentation), when the dataset
    /// has depth images.
    pub fn depth_path(&self, frame: usize) -> Option<PathBuf> {
        self.manifest
            .depth_scale
            .map(|_| self.root.join(depth_name(frame)))
    }

    /// Reads frame `frame`'s image as packed RGB8 rows (width x height x 3 bytes); fails,
    /// naming the file, when it does not decode or its size differs from the intrinsics.
    pub fn read_image(&self, frame: usize) -> Result<Vec<u8>, DatasetError> {
        let path = self.image_path(frame);
        let (w, h, rgb) =
            topoloc::image::read_rgb(&path).map_err(|e| invalid(&path, None, e.to_string()))?;
        let (iw, ih) = (self.intrinsics.width, self.intrinsics.height);
        if (w, h) != (iw, ih) {
            return Err(invalid(
                &path,
                None,
                format!("image is {w}x{h}, the intrinsics say {iw}x{ih}"),
            ));
        }
        Ok(rgb)
    }

    /// The seed's graph metrics of a localizer's answers: `ranked[k]` holds frame k's predicted
    /// places, best first (empty: no answer, counted wrong). Returns MNA, OHA and R@1..R@10
    /// ([`RECALL_DEPTHS`]) as `topoloc::eval` defines them. Fails when the count differs from
    /// the frame count or a place is not in the graph.
    pub fn evaluate(&self, ranked: &[Vec<PlaceId>]) -> Result<GraphMetrics, DatasetError> {
        let n = self.frame_count();
        if ranked.len() != n {
            return Err(DatasetError::Evaluation(format!(
                "{} ranked lists for {n} frames",
                ranked.len()
            )));
        }
        let hops = self
            .graph
            .hop_distances()
            .map_err(DatasetError::Evaluation)?;
        let predictions: Vec<Prediction> = self
            .nodes
            .iter()
            .zip(ranked)
            .map(|(t, r)| Prediction {
                truth: t.place,
                ranked: r.clone(),
                ..Prediction::default()
            })
            .collect();
        let evaluator = GraphEvaluator::new(&hops, &predictions)
            .map_err(|e| DatasetError::Evaluation(e.to_string()))?;
        Ok(evaluator.metrics(&RECALL_DEPTHS))
    }
}

fn read_text(path: &Path) -> Result<String, DatasetError> {
    if !path.is_file() {
        return Err(DatasetError::Missing {
            path: path.to_path_buf(),
            what: "a file of the dataset",
        });
    }
    std::fs::read_to_string(path).map_err(io(path))
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, DatasetError> {
    serde_json::from_str(&read_text(path)?).map_err(|source| DatasetError::Json {
        path: path.to_path_buf(),
        source,
    })
}

/// Reads the manifest, checking the format name and version before the other keys (a newer
/// major version may have changed them).
fn read_manifest(path: &Path) -> Result<Manifest, DatasetError> {
    let value: serde_json::Value = read_json(path)?;
    let format = value.get("format").and_then(|v| v.as_str());
    if format != Some(FORMAT_NAME) {
        let found = format.map_or("missing".into(), |f| format!("{f:?}"));
        return Err(invalid(
            path,
            None,
            format!("format is {found}, expected \"{FORMAT_NAME}\""),
        ));
    }
    let version = value
        .get("format_version")
        .and_then(|v| v.as_str())
        .unwrap_or("");
    let major = version
        .split_once('.')
        .and_then(|(major, minor)| minor.parse::<u32>().ok().and(major.parse::<u32>().ok()));
    let Some(major) = major else {
        return Err(invalid(
            path,
            None,
            format!("format_version is {version:?}, expected \"major.minor\""),
        ));
    };
    if major > FORMAT_VERSION_MAJOR {
        return Err(DatasetError::UnsupportedVersion {
            path: path.to_path_buf(),
            found: version.into(),
            supported: FORMAT_VERSION_MAJOR,
        });
    }
    let manifest: Manifest =
        serde_json::from_value(value).map_err(|source| DatasetError::Json {
            path: path.to_path_buf(),
            source,
        })?;
    check_manifest(path, &manifest)?;
    Ok(manifest)
}

fn read_poses(path: &Path) -> Result<Vec<TimedPose>, DatasetError> {
    // parse_tum names the line in its message.
    parse_tum(&read_text(path)?).map_err(|e| invalid(path, None, e.to_string()))
}

/// Parses `nodes.csv` into `(line, truth)` rows; blank lines are skipped.
fn parse_nodes(path: &Path, text: &str) -> Result<Vec<(usize, FrameTruth)>, DatasetError> {
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    match lines.next() {
        Some((_, NODES_HEADER)) => {}
        other => {
            let found = other.map_or("", |(_, l)| l);
            return Err(invalid(
                path,
                Some(1),
                format!("header is {found:?}, expected \"{NODES_HEADER}\""),
            ));
        }
    }
    let mut rows = Vec::new();
    for (line, row) in lines.filter(|(_, l)| !l.is_empty()) {
        let bad = |message: String| invalid(path, Some(line), message);
        let fields: Vec<&str> = row.split(',').map(str::trim).collect();
        let [frame, place, view, visible] = fields[..] else {
            return Err(bad(format!(
                "{} fields, expected 4 ({NODES_HEADER})",
                fields.len()
            )));
        };
        let number = |name: &str, text: &str| {
            text.parse::<u64>()
                .map_err(|e| bad(format!("{name} {text:?}: {e}")))
        };
        let visible = match visible {
            "1" | "true" => true,
            "0" | "false" => false,
            other => return Err(bad(format!("visible {other:?}: expected 0 or 1"))),
        };
        let place = number("place", place)?;
        let view = number("view", view)?;
        let (Ok(place), Ok(view)) = (PlaceId::try_from(place), u32::try_from(view)) else {
            return Err(bad(format!("place {place} or view {view} is out of range")));
        };
        rows.push((
            line,
            FrameTruth {
                frame: number("frame", frame)? as usize,
                place,
                view,
                visible,
            },
        ));
    }
    Ok(rows)
}
