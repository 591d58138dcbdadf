//! Frame sources of `topoloc localize`: an image folder in file-name order or a video decoded
//! with OpenCV videoio, each frame with its index, a source name and a timestamp.
//!
//! Timestamps:
//! - images with `--fps`: frame i at `start + i / fps`;
//! - images otherwise: when every file stem is a finite number, that number times the stem
//!   unit (TUM RGB-D names such as `1305031102.175304.png` are seconds, EuRoC's nanoseconds);
//!   else frame i at `start + i` (1 Hz: the localizer only needs times that do not decrease);
//! - video: with `--fps` as for images, else `start + (time of frame i - time of frame 0)`
//!   from the container (CAP_PROP_POS_MSEC; where the backend gives no increasing time, the
//!   previous frame's plus one container frame period).

use crate::backend_args::{has_image_extension, IMAGE_EXTENSIONS};
use anyhow::{bail, Context, Result};
use opencv::core::Mat;
use opencv::prelude::*;
use opencv::videoio;
use std::path::{Path, PathBuf};
use topoloc::image::{read_rgb, ImageView, PixelFormat};

/// Unit of numeric file stems.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum StemUnit {
    /// Seconds (TUM RGB-D).
    S,
    /// Milliseconds.
    Ms,
    /// Microseconds.
    Us,
    /// Nanoseconds (EuRoC).
    Ns,
}

impl StemUnit {
    /// Seconds per unit.
    pub fn seconds(self) -> f64 {
        match self {
            StemUnit::S => 1.0,
            StemUnit::Ms => 1e-3,
            StemUnit::Us => 1e-6,
            StemUnit::Ns => 1e-9,
        }
    }
}

/// How frame times are found (see the module docs).
#[derive(Clone, Copy, Debug)]
pub struct Clock {
    /// Frame rate overriding file names and container times.
    pub fps: Option<f64>,
    /// Time of the first frame for relative clocks (`--fps`, video, unnumbered names).
    pub start: f64,
    /// Unit of numeric file stems.
    pub stem_unit: StemUnit,
}

/// Decoded pixels of one frame, tightly packed.
pub struct Pixels {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixel layout.
    pub format: PixelFormat,
    /// `width x height x channels` bytes.
    pub data: Vec<u8>,
}

impl Pixels {
    /// A view for the localizer.
    pub fn view(&self) -> ImageView<'_> {
        ImageView::packed(self.width, self.height, self.format, &self.data)
    }
}

/// One input frame; `pixels` holds why it could not be decoded.
pub struct RawFrame {
    /// 0-based position in the input (file list or video).
    pub index: usize,
    /// File name, or `frame N` of the video.
    pub source: String,
    /// Seconds.
    pub timestamp: f64,
    /// The image, or the decoding error.
    pub pixels: Result<Pixels, String>,
}

/// Where frames come from.
pub enum FrameSource {
    /// Image files with their timestamps, read one by one.
    Images {
        /// Files in name order.
        files: Vec<PathBuf>,
        /// Timestamp per file.
        times: Vec<f64>,
        /// Next file.
        next: usize,
    },
    /// An open video.
    Video(Box<VideoFrames>),
}

impl FrameSource {
    /// The next frame, `None` at the end; errors are fatal (the video cannot be read on).
    pub fn next_frame(&mut self) -> Result<Option<RawFrame>> {
        match self {
            FrameSource::Images { files, times, next } => {
                let Some(path) = files.get(*next) else {
                    return Ok(None);
                };
                let index = *next;
                *next += 1;
                let pixels = read_rgb(path)
                    .map(|(width, height, data)| Pixels {
                        width,
                        height,
                        format: PixelFormat::Rgb8,
                        data,
                    })
                    .map_err(|e| e.to_string());
                Ok(Some(RawFrame {
                    index,
                    source: file_name(path),
                    timestamp: times[index],
                    pixels,
                }))
            }
            FrameSource::Video(video) => video.next_frame(),
        }
    }
}

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into(),
    )
}

/// Which rule gave an image folder's timestamps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeRule {
    /// `--fps`.
    Fps,
    /// Numeric file stems.
    Names,
    /// Frame index at 1 Hz (names not numeric, no `--fps`).
    Index,
    /// A KITTI, TUM RGB-D or EuRoC sequence folder: the timestamps its layout gives.
    Layout,
}

/// An image folder as a frame source: files with an image extension in name order, with
/// timestamps by `clock`.
pub struct ImageFolder {
    /// The source.
    pub source: FrameSource,
    /// Files without an image extension (not frames).
    pub ignored: Vec<String>,
    /// The timestamp rule used.
    pub rule: TimeRule,
    /// That rule in words, for the start-up message.
    pub describe: String,
}

/// Lists `dir` and gives every image file its timestamp: a KITTI, TUM RGB-D or EuRoC sequence
/// folder ([`crate::sequence`]) gives its frames with the layout's timestamps (unless `--fps`
/// is given), any other folder its image files by `clock`. Fails when the folder cannot be
/// read, holds no image file, numeric names decrease in name order, or a layout's files are
/// malformed (the file and line are named).
pub fn open_images(dir: &Path, clock: &Clock) -> Result<ImageFolder> {
    if clock.fps.is_none() && crate::sequence::has_layout(dir) {
        let sequence = crate::sequence::open(dir)?;
        return Ok(ImageFolder {
            source: FrameSource::Images {
                files: sequence.frames.iter().map(|f| f.image.clone()).collect(),
                times: sequence.frames.iter().map(|f| f.timestamp).collect(),
                next: 0,
            },
            ignored: Vec::new(),
            rule: TimeRule::Layout,
            describe: format!("from the {:?} sequence's timestamps", sequence.layout),
        });
    }
    let mut files = Vec::new();
    let mut ignored = Vec::new();
    for entry in std::fs::read_dir(dir)
        .with_context(|| format!("--images {}: cannot read the folder", dir.display()))?
    {
        let path = entry?.path();
        if !path.is_file() {
            continue;
        }
        if has_image_extension(&path) {
            files.push(path);
        } else {
            ignored.push(file_name(&path));
        }
    }
    files.sort();
    ignored.sort();
    if files.is_empty() {
        bail!(
            "--images {}: no image files (extensions {})",
            dir.display(),
            IMAGE_EXTENSIONS.join(", ")
        );
    }
    let stems: Option<Vec<f64>> = files
        .iter()
        .map(|f| {
            f.file_stem()
                .and_then(|s| s.to_str())
                .and_then(|s| s.parse::<f64>().ok())
                .filter(|t| t.is_finite())
        })
        .collect();
    let (times, rule, describe) = match (clock.fps, stems) {
        (Some(fps), _) => (
            (0..files.len())
                .map(|i| clock.start + i as f64 / fps)
                .collect(),
            TimeRule::Fps,
            format!("frame i at {} + i / {fps} s (--fps)", clock.start),
        ),
        (None, Some(stems)) => {
            let times: Vec<f64> = stems
                .iter()
                .map(|s| s * clock.stem_unit.seconds())
                .collect();
            for k in 1..times.len() {
                if times[k] < times[k - 1] {
                    bail!(
                        "--images {}: file names are timestamps but decrease in name order ({} after {}); zero-pad the names to one width, or give --fps",
                        dir.display(),
                        file_name(&files[k]),
                        file_name(&files[k - 1])
                    );
                }
            }
            let unit = format!("{:?}", clock.stem_unit).to_lowercase();
            (
                times,
                TimeRule::Names,
                format!("from the file names (unit {unit})"),
            )
        }
        (None, None) => (
            (0..files.len()).map(|i| clock.start + i as f64).collect(),
            TimeRule::Index,
            format!(
                "frame i at {} + i s (file names are not all numbers; give --fps for the true rate)",
                clock.start
            ),
        ),
    };
    Ok(ImageFolder {
        source: FrameSource::Images {
            files,
            times,
            next: 0,
        },
        ignored,
        rule,
        describe,
    })
}

/// A video read frame by frame.
pub struct VideoFrames {
    capture: videoio::VideoCapture,
    clock: Clock,
    /// Seconds per frame by the container (0 when it does not say).
    period: f64,
    /// Container time of frame 0, seconds.
    first: Option<f64>,
    /// Timestamp of the previous frame.
    last: Option<f64>,
    index: usize,
    mat: Mat,
}

/// Opens `path` with OpenCV videoio (any backend). Fails, naming the file, when it does not
/// open.
pub fn open_video(path: &Path, clock: &Clock) -> Result<(FrameSource, String)> {
    if !path.is_file() {
        bail!("--video {}: no such file", path.display());
    }
    let capture = videoio::VideoCapture::from_file(path, videoio::CAP_ANY)
        .with_context(|| format!("--video {}: OpenCV cannot open it", path.display()))?;
    if !capture.is_opened()? {
        bail!(
            "--video {}: no OpenCV videoio backend opens it (not a video, or a codec this OpenCV build lacks)",
            path.display()
        );
    }
    let fps = capture.get(videoio::CAP_PROP_FPS).unwrap_or(0.0);
    let backend = capture.get_backend_name().unwrap_or_else(|_| "?".into());
    let describe = match clock.fps {
        Some(f) => format!(
            "{backend} backend; frame i at {} + i / {f} s (--fps)",
            clock.start
        ),
        None => format!(
            "{backend} backend, {fps} fps; frame times from the container, frame 0 at {} s",
            clock.start
        ),
    };
    let video = VideoFrames {
        capture,
        clock: *clock,
        period: if fps.is_finite() && fps > 0.0 {
            1.0 / fps
        } else {
            0.0
        },
        first: None,
        last: None,
        index: 0,
        mat: Mat::default(),
    };
    Ok((FrameSource::Video(Box::new(video)), describe))
}

impl VideoFrames {
    fn next_frame(&mut self) -> Result<Option<RawFrame>> {
        if !self.capture.read(&mut self.mat)? || self.mat.empty() {
            return Ok(None);
        }
        let index = self.index;
        self.index += 1;
        let timestamp = match self.clock.fps {
            Some(fps) => self.clock.start + index as f64 / fps,
            None => {
                let container = self.capture.get(videoio::CAP_PROP_POS_MSEC)? / 1e3;
                let first = *self.first.get_or_insert(container);
                let t = self.clock.start + (container - first);
                match self.last {
                    Some(last) if !t.is_finite() || t <= last => {
                        if self.period == 0.0 {
                            bail!(
                                "the video gives neither frame times nor a frame rate: give --fps"
                            );
                        }
                        last + self.period
                    }
                    _ => t,
                }
            }
        };
        self.last = Some(timestamp);
        Ok(Some(RawFrame {
            index,
            source: format!("frame {index}"),
            timestamp,
            pixels: pixels_of(&self.mat),
        }))
    }
}

/// Copies an 8-bit Mat of 1, 3 or 4 channels (OpenCV order) into packed pixels.
fn pixels_of(mat: &Mat) -> Result<Pixels, String> {
    let format = match (mat.depth(), mat.channels()) {
        (opencv::core::CV_8U, 1) => PixelFormat::Gray8,
        (opencv::core::CV_8U, 3) => PixelFormat::Bgr8,
        (opencv::core::CV_8U, 4) => PixelFormat::Bgra8,
        (depth, channels) => {
            return Err(format!(
                "decoded frame has OpenCV depth {depth} with {channels} channels; expected 8-bit with 1, 3 or 4"
            ))
        }
    };
    let packed;
    let mat = if mat.is_continuous() {
        mat
    } else {
        packed = mat.try_clone().map_err(|e| e.to_string())?;
        &packed
    };
    let data = mat.data_bytes().map_err(|e| e.to_string())?.to_vec();
    Ok(Pixels {
        width: mat.cols() as u32,
        height: mat.rows() as u32,
        format,
        data,
    })
}
