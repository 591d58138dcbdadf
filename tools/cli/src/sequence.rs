//! Image sequences as SLAM hosts have them, each frame with its timestamp in seconds:
//!
//! - a KITTI odometry sequence: `image_0/` (or `image_2/`) with `times.txt` beside it (the
//!   sequence folder or its image folder may be given);
//! - a TUM RGB-D sequence: `rgb.txt` (`timestamp file` lines), with `associations.txt`
//!   (`rgb_time rgb_file depth_time depth_file ...`, as TUM's `associate.py` writes) giving
//!   each frame its registered depth image; frames without an association are left out;
//! - an EuRoC MAV sequence: `mav0/cam0/data.csv` (`timestamp_ns,filename`) and `data/`
//!   (the `mav0` or `cam0` folder may be given too);
//! - else a folder of images in file-name order, timestamped by their index (0, 1, 2 ... s).
//!
//! [`keyframes`] thins a sequence to keyframes as a SLAM front end does: every Nth frame, and
//! with a rate R, one frame per due time `t0 + k / R` (R per second on average; see there);
//! [`effective_rate`] says how many per second were kept.

use crate::backend_args::image_files;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use topoloc::build::TimedPose;

/// Where a sequence's frames and timestamps come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// A folder of images; timestamps are the frame indices.
    Folder,
    /// KITTI odometry: an image folder and `times.txt`.
    Kitti,
    /// TUM RGB-D: `rgb.txt`, optionally `associations.txt`.
    TumRgbd,
    /// EuRoC MAV: `cam0/data.csv` and `cam0/data/`.
    Euroc,
}

/// One frame of a sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// The image file.
    pub image: PathBuf,
    /// Seconds (KITTI: from the sequence start; TUM: Unix time; EuRoC: nanoseconds / 1e9).
    pub timestamp: f64,
    /// The registered depth image, where the layout has one (TUM with associations).
    pub depth: Option<PathBuf>,
}

/// The frames of a sequence, in time order.
#[derive(Clone, Debug)]
pub struct Sequence {
    /// How the folder was read.
    pub layout: Layout,
    /// Its frames, timestamps strictly increasing.
    pub frames: Vec<Frame>,
}

/// True when `path` holds a KITTI, TUM RGB-D or EuRoC layout (not a plain image folder).
pub fn has_layout(path: &Path) -> bool {
    kitti_files(path).is_some() || path.join("rgb.txt").is_file() || euroc_camera(path).is_some()
}

/// Reads the sequence at `path` (see the module documentation for the layouts recognised).
pub fn open(path: &Path) -> Result<Sequence> {
    let (layout, frames) = if let Some((images, times)) = kitti_files(path) {
        (Layout::Kitti, kitti(&images, &times)?)
    } else if path.join("rgb.txt").is_file() {
        (Layout::TumRgbd, tum(path)?)
    } else if let Some(cam) = euroc_camera(path) {
        (Layout::Euroc, euroc(&cam)?)
    } else {
        let frames = image_files(path)?
            .into_iter()
            .enumerate()
            .map(|(i, image)| Frame {
                image,
                timestamp: i as f64,
                depth: None,
            })
            .collect();
        (Layout::Folder, frames)
    };
    if frames.is_empty() {
        bail!("{}: the sequence has no frames", path.display());
    }
    if let Some(i) = frames
        .windows(2)
        .position(|w| w[1].timestamp <= w[0].timestamp)
    {
        bail!(
            "{}: frame {} ({}) is not later than frame {i} ({}): timestamps must increase",
            path.display(),
            i + 1,
            frames[i + 1].timestamp,
            frames[i].timestamp
        );
    }
    Ok(Sequence { layout, frames })
}

/// Largest gap between a frame's timestamp and the pose given to it by [`poses_at_frames`],
/// seconds: TUM's `associate.py` default.
pub const POSE_MAX_GAP_S: f64 = 0.02;

/// One pose per frame from a trajectory file's `poses` (time order): with as many poses as
/// frames, in order; otherwise, for a layout with timestamps, the pose nearest each frame in
/// time (a ground truth at 100 Hz for a camera at 30 Hz), which must lie within
/// [`POSE_MAX_GAP_S`]. `what` names the file in errors: the frame without a pose is named.
pub fn poses_at_frames(
    sequence: &Sequence,
    poses: Vec<TimedPose>,
    what: &Path,
) -> Result<Vec<TimedPose>> {
    let frames = &sequence.frames;
    if poses.len() == frames.len() {
        return Ok(poses);
    }
    if sequence.layout == Layout::Folder {
        bail!(
            "{} has {} poses for {} images: give one pose per image, in file-name order",
            what.display(),
            poses.len(),
            frames.len()
        );
    }
    if let Some(i) = poses
        .windows(2)
        .position(|w| w[1].timestamp < w[0].timestamp)
    {
        bail!(
            "{}: pose {} ({} s) is earlier than pose {i}: timestamps must not decrease",
            what.display(),
            i + 1,
            poses[i + 1].timestamp
        );
    }
    frames
        .iter()
        .map(|frame| {
            let after = poses.partition_point(|p| p.timestamp < frame.timestamp);
            let nearest = [after.checked_sub(1), Some(after)]
                .into_iter()
                .flatten()
                .filter_map(|k| poses.get(k))
                .min_by(|a, b| {
                    let gap = |p: &TimedPose| (p.timestamp - frame.timestamp).abs();
                    gap(a).total_cmp(&gap(b))
                });
            match nearest {
                Some(p) if (p.timestamp - frame.timestamp).abs() <= POSE_MAX_GAP_S => Ok(*p),
                _ => bail!(
                    "{} has no pose within {POSE_MAX_GAP_S} s of frame {} ({} s)",
                    what.display(),
                    frame.image.display(),
                    frame.timestamp
                ),
            }
        })
        .collect()
}

/// Slack of a due time in [`keyframes`], seconds: far below any frame interval, above the
/// rounding of Unix-time timestamps (about 2e-7 s at 1.7e9 s).
const DUE_SLACK_S: f64 = 1e-6;

/// The indices of the keyframes among `frames`, in order. `every` N keeps frames 0, N, 2N, ...
/// (1: all). With `rate_hz` R as well, of those the first frame (at `t0`) and then the first
/// frame at or after each due time `t0 + k / R` (k = 1, 2, ...) are kept: at most one per due
/// time, and a frame late past several due times (a gap) is kept once, the next due time being
/// the first one after it. So R keyframes per second are kept on average (never more, and fewer
/// only where the frames themselves are further apart than `1 / R`): 3 per second of KITTI's
/// 10 Hz frames are frames 0, 4, 7, 10, 14, 17, 20, ... (not every 4th, 2.5 per second).
pub fn keyframes(frames: &[Frame], every: usize, rate_hz: Option<f64>) -> Result<Vec<usize>> {
    if every == 0 {
        bail!("--every must be at least 1");
    }
    if let Some(rate) = rate_hz.filter(|r| !(r.is_finite() && *r > 0.0)) {
        bail!("--keyframe-rate is {rate}, must be finite and > 0");
    }
    let Some(t0) = frames.first().map(|f| f.timestamp) else {
        return Ok(Vec::new());
    };
    let mut kept = Vec::new();
    // The number of the next due time: frames at t0 + due / rate or later are kept.
    let mut due = 0.0f64;
    for (i, frame) in frames.iter().enumerate().step_by(every) {
        let Some(rate) = rate_hz else {
            kept.push(i);
            continue;
        };
        let periods = (frame.timestamp - t0) * rate;
        if periods >= due - DUE_SLACK_S * rate {
            kept.push(i);
            due = (periods + DUE_SLACK_S * rate).floor() + 1.0;
        }
    }
    Ok(kept)
}

/// Keyframes per second: `kept` over the time the frames cover, their last timestamp minus
/// their first plus one mean frame interval (`(last - first) * n / (n - 1)` for n frames, so
/// keeping every frame gives the frame rate). None for a single frame. A plain folder's
/// timestamps are its frame indices: keyframes per frame then.
pub fn effective_rate(frames: &[Frame], kept: usize) -> Option<f64> {
    let duration = duration_s(frames)?;
    (duration > 0.0).then(|| kept as f64 / duration)
}

/// The time `frames` cover, seconds, as [`effective_rate`] counts it (None for fewer than 2).
pub fn duration_s(frames: &[Frame]) -> Option<f64> {
    let (first, last) = (frames.first()?, frames.last()?);
    let n = frames.len();
    (n >= 2).then(|| (last.timestamp - first.timestamp) * n as f64 / (n - 1) as f64)
}

/// KITTI's image folder and `times.txt`, from the sequence folder or its image folder.
fn kitti_files(path: &Path) -> Option<(PathBuf, PathBuf)> {
    let in_sequence = ["image_0", "image_2"]
        .iter()
        .map(|name| path.join(name))
        .find(|dir| dir.is_dir())
        .map(|dir| (dir, path.join("times.txt")));
    let in_images = path
        .file_name()
        .and_then(|n| n.to_str())
        .filter(|n| n.starts_with("image_"))
        .and_then(|_| path.parent())
        .map(|parent| (path.to_path_buf(), parent.join("times.txt")));
    in_sequence
        .into_iter()
        .chain(in_images)
        .find(|(_, times)| times.is_file())
}

/// The non-empty, non-comment lines of `path`, with their 1-based line numbers.
fn data_lines(path: &Path) -> Result<Vec<(usize, String)>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim().to_string()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
        .collect())
}

/// The number in `field` of line `line` of `path`.
fn number(path: &Path, line: usize, field: Option<&str>, what: &str) -> Result<f64> {
    let field = field.with_context(|| format!("{} line {line}: no {what}", path.display()))?;
    field
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .with_context(|| {
            format!(
                "{} line {line}: {what} {field:?} is not a number",
                path.display()
            )
        })
}

fn kitti(images: &Path, times_path: &Path) -> Result<Vec<Frame>> {
    let files = image_files(images)?;
    let times = data_lines(times_path)?;
    if times.len() != files.len() {
        bail!(
            "{} has {} timestamps for {} images in {}: give one per image",
            times_path.display(),
            times.len(),
            files.len(),
            images.display()
        );
    }
    files
        .into_iter()
        .zip(times)
        .map(|(image, (line, text))| {
            Ok(Frame {
                image,
                timestamp: number(times_path, line, Some(&text), "timestamp")?,
                depth: None,
            })
        })
        .collect()
}

fn tum(dir: &Path) -> Result<Vec<Frame>> {
    let associations = dir.join("associations.txt");
    let (path, with_depth) = match associations.is_file() {
        true => (associations, true),
        false => (dir.join("rgb.txt"), false),
    };
    data_lines(&path)?
        .into_iter()
        .map(|(line, text)| {
            let fields: Vec<&str> = text.split_whitespace().collect();
            let file = |at: usize, what: &str| -> Result<PathBuf> {
                let name = fields
                    .get(at)
                    .with_context(|| format!("{} line {line}: no {what}", path.display()))?;
                Ok(dir.join(name))
            };
            Ok(Frame {
                timestamp: number(&path, line, fields.first().copied(), "timestamp")?,
                image: file(1, "image file")?,
                depth: with_depth.then(|| file(3, "depth file")).transpose()?,
            })
        })
        .collect()
}

/// EuRoC's `cam0` folder, from the sequence, `mav0` or `cam0` folder.
fn euroc_camera(path: &Path) -> Option<PathBuf> {
    [
        path.join("mav0/cam0"),
        path.join("cam0"),
        path.to_path_buf(),
    ]
    .into_iter()
    .find(|cam| cam.join("data.csv").is_file() && cam.join("data").is_dir())
}

fn euroc(cam: &Path) -> Result<Vec<Frame>> {
    let path = cam.join("data.csv");
    data_lines(&path)?
        .into_iter()
        .map(|(line, text)| {
            let mut fields = text.split(',').map(str::trim);
            let nanoseconds = number(&path, line, fields.next(), "timestamp")?;
            let name = fields
                .next()
                .with_context(|| format!("{} line {line}: no file name", path.display()))?;
            Ok(Frame {
                image: cam.join("data").join(name),
                timestamp: nanoseconds * 1e-9,
                depth: None,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(path: &Path, text: &str) {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }

    /// Empty image files named `names` in `dir` (only their names are read here).
    fn images(dir: &Path, names: &[&str]) {
        for name in names {
            write(&dir.join(name), "");
        }
    }

    #[test]
    fn poses_go_to_frames_in_order_or_by_the_nearest_timestamp() {
        let sequence = |layout, times: &[f64]| Sequence {
            layout,
            frames: times
                .iter()
                .enumerate()
                .map(|(i, &timestamp)| Frame {
                    image: PathBuf::from(format!("{i}.png")),
                    timestamp,
                    depth: None,
                })
                .collect(),
        };
        let poses = |times: &[f64]| -> Vec<TimedPose> {
            times
                .iter()
                .map(|&timestamp| TimedPose {
                    timestamp,
                    world_t_camera: nalgebra::Isometry3::translation(timestamp, 0.0, 0.0),
                })
                .collect()
        };
        let gt = Path::new("groundtruth.txt");
        // As many as frames: in order, whatever their times.
        let same = poses_at_frames(
            &sequence(Layout::Folder, &[0.0, 1.0]),
            poses(&[5.0, 6.0]),
            gt,
        );
        assert_eq!(same.unwrap()[1].timestamp, 6.0);
        // A 100 Hz ground truth for frames at 10.004 and 10.031 s: the nearest rows.
        let tum = sequence(Layout::TumRgbd, &[10.004, 10.031]);
        let fast: Vec<f64> = (0..10).map(|k| 10.0 + 0.01 * k as f64).collect();
        let near = poses_at_frames(&tum, poses(&fast), gt).unwrap();
        let picked: Vec<f64> = near.iter().map(|p| p.timestamp).collect();
        assert_eq!(picked, [10.0, 10.03]);
        // A frame farther than 20 ms from every row is named.
        let err = poses_at_frames(&tum, poses(&[9.0, 9.5, 10.0]), gt).unwrap_err();
        assert!(
            err.to_string()
                .contains("no pose within 0.02 s of frame 1.png"),
            "{err}"
        );
        // Rows out of time order, or a plain folder with another count, are refused.
        let err = poses_at_frames(&tum, poses(&[10.03, 10.0, 10.01]), gt).unwrap_err();
        assert!(
            err.to_string().contains("pose 1 (10 s) is earlier"),
            "{err}"
        );
        let folder = sequence(Layout::Folder, &[0.0, 1.0]);
        let err = poses_at_frames(&folder, poses(&[0.0, 1.0, 2.0]), gt).unwrap_err();
        assert!(err.to_string().contains("3 poses for 2 images"), "{err}");
    }

    #[test]
    fn a_kitti_sequence_is_read_from_its_folder_or_its_image_folder() {
        let dir = tempfile::tempdir().unwrap();
        images(&dir.path().join("image_0"), &["000000.png", "000001.png"]);
        write(
            &dir.path().join("times.txt"),
            "0.000000e+00\n1.037359e-01\n",
        );
        for path in [dir.path().to_path_buf(), dir.path().join("image_0")] {
            let s = open(&path).unwrap();
            assert_eq!(s.layout, Layout::Kitti);
            assert_eq!(s.frames.len(), 2);
            assert!((s.frames[1].timestamp - 0.1037359).abs() < 1e-12);
            assert!(s.frames[1].image.ends_with("image_0/000001.png"));
        }
        write(&dir.path().join("times.txt"), "0\n");
        let err = open(dir.path()).unwrap_err().to_string();
        assert!(err.contains("1 timestamps for 2 images"), "{err}");
        write(&dir.path().join("times.txt"), "0\nsoon\n");
        let err = open(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("times.txt line 2") && err.contains("soon"),
            "{err}"
        );
        write(&dir.path().join("times.txt"), "0.2\n0.1\n");
        let err = open(dir.path()).unwrap_err().to_string();
        assert!(err.contains("must increase"), "{err}");
    }

    #[test]
    fn a_tum_sequence_takes_its_depth_from_the_associations() {
        let dir = tempfile::tempdir().unwrap();
        write(
            &dir.path().join("rgb.txt"),
            "# color images\n# timestamp filename\n1305031102.175304 rgb/a.png\n1305031102.211214 rgb/b.png\n",
        );
        let s = open(dir.path()).unwrap();
        assert_eq!(s.layout, Layout::TumRgbd);
        assert_eq!(s.frames.len(), 2);
        assert_eq!(s.frames[0].depth, None);
        assert!((s.frames[1].timestamp - 1305031102.211214).abs() < 1e-6);
        write(
            &dir.path().join("associations.txt"),
            "1305031102.211214 rgb/b.png 1305031102.226738 depth/d.png 1305031102.2159\n",
        );
        let s = open(dir.path()).unwrap();
        assert_eq!(s.frames.len(), 1, "frames without depth are left out");
        assert_eq!(s.frames[0].image, dir.path().join("rgb/b.png"));
        assert_eq!(s.frames[0].depth, Some(dir.path().join("depth/d.png")));
        write(
            &dir.path().join("associations.txt"),
            "1305031102.2 rgb/b.png\n",
        );
        let err = open(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("associations.txt line 1: no depth file"),
            "{err}"
        );
    }

    #[test]
    fn an_euroc_sequence_is_timed_in_nanoseconds() {
        let dir = tempfile::tempdir().unwrap();
        let cam = dir.path().join("mav0/cam0");
        write(
            &cam.join("data.csv"),
            "#timestamp [ns],filename\n1403715273262142976,1403715273262142976.png\n1403715273312143104,1403715273312143104.png\n",
        );
        std::fs::create_dir_all(cam.join("data")).unwrap();
        for path in [
            dir.path().to_path_buf(),
            dir.path().join("mav0"),
            cam.clone(),
        ] {
            let s = open(&path).unwrap();
            assert_eq!(s.layout, Layout::Euroc);
            assert!((s.frames[1].timestamp - s.frames[0].timestamp - 0.05).abs() < 1e-6);
            assert_eq!(s.frames[0].image, cam.join("data/1403715273262142976.png"));
        }
    }

    #[test]
    fn a_plain_folder_is_timed_by_index_and_thinned_to_keyframes() {
        let dir = tempfile::tempdir().unwrap();
        let names: Vec<String> = (0..10).map(|i| format!("{i:02}.png")).collect();
        images(
            dir.path(),
            &names.iter().map(String::as_str).collect::<Vec<_>>(),
        );
        let s = open(dir.path()).unwrap();
        assert_eq!(s.layout, Layout::Folder);
        assert_eq!(s.frames[9].timestamp, 9.0);
        assert_eq!(keyframes(&s.frames, 1, None).unwrap().len(), 10);
        assert_eq!(keyframes(&s.frames, 3, None).unwrap(), [0, 3, 6, 9]);
        assert_eq!(keyframes(&s.frames, 1, Some(0.5)).unwrap(), [0, 2, 4, 6, 8]);
        // Due at 0, 4, 8 s: of frames 0, 3, 6, 9 the first at or after each.
        assert_eq!(keyframes(&s.frames, 3, Some(0.25)).unwrap(), [0, 6, 9]);
        // Due every 0.4 s: each frame reaches a due time (the frames are sparser).
        assert_eq!(keyframes(&s.frames, 1, Some(2.5)).unwrap().len(), 10);
        assert_eq!(effective_rate(&s.frames, 5), Some(0.5));
        assert_eq!(effective_rate(&s.frames[..1], 1), None);
        assert!(keyframes(&s.frames, 0, None).is_err());
        assert!(keyframes(&s.frames, 1, Some(0.0)).is_err());
    }

    #[test]
    fn a_keyframe_rate_is_kept_on_average_and_a_gap_keeps_one_frame() {
        // 10 Hz from Unix time 1.7e9 s (TUM, EuRoC), 30 s: 3 per second kept, not 2.5.
        let frames = |times: &[f64]| -> Vec<Frame> {
            times
                .iter()
                .map(|&timestamp| Frame {
                    image: PathBuf::new(),
                    timestamp,
                    depth: None,
                })
                .collect()
        };
        let times: Vec<f64> = (0..300).map(|i| 1.7e9 + i as f64 * 0.1).collect();
        let kept = keyframes(&frames(&times), 1, Some(3.0)).unwrap();
        assert_eq!(kept[..7], [0, 4, 7, 10, 14, 17, 20]);
        assert_eq!(kept.len(), 90);
        let rate = effective_rate(&frames(&times), kept.len()).unwrap();
        assert!((rate - 3.0).abs() < 1e-6, "{rate}");
        // A 2 s gap after 1.0 s: the frame after it is kept once, then the grid goes on.
        let gappy = frames(&[0.0, 0.5, 1.0, 3.05, 3.1, 3.6, 4.0]);
        assert_eq!(keyframes(&gappy, 1, Some(2.0)).unwrap(), [0, 1, 2, 3, 5, 6]);
    }
}
