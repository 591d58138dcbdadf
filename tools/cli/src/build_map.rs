//! `topoloc build-map`: a map from an image folder or an image sequence (optionally with a TUM
//! trajectory), with the describer stored in it.
//!
//! `--images` is read as `topoloc loops --images` reads it ([`crate::sequence::open`]): a KITTI,
//! TUM RGB-D or EuRoC sequence folder gives its frames in the layout's order (`times.txt` beside
//! the image folder, `rgb.txt` or `associations.txt`, `data.csv`), any other folder its images
//! in file-name order. The map's views are those frames, in that order. `--poses` gives one pose
//! per frame: as many poses as frames are taken in order; otherwise, for a sequence layout, each
//! frame takes the pose nearest its timestamp ([`crate::sequence::poses_at_frames`]).

use crate::backend_args::{progress_bar, BackendArgs, LocalFeatures};
use crate::sequence;
use anyhow::Result;
use clap::{Args, ValueEnum};
use serde_json::json;
use std::path::PathBuf;
use topoloc::build::{
    build_from_images, read_tum, BuildStage, ImageLayout, ImageMapOptions, ImageSource,
    KeyframeOptions,
};
use topoloc::describe::{FitOptions, PcaPrecision};

/// Options of `build-map`.
#[derive(Args, Clone, Debug)]
pub struct BuildMapArgs {
    /// Folder of images, taken in file-name order, or a KITTI, TUM RGB-D or EuRoC sequence
    /// folder, taken in the layout's order (as `loops --images`).
    #[arg(long)]
    pub images: PathBuf,
    /// TUM trajectory (`t tx ty tz qx qy qz qw`), one pose per image in the same order (for a
    /// sequence layout, else the pose nearest each frame's timestamp, within 20 ms): places are
    /// then made by spacing and revisits merged.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    #[command(flatten)]
    pub backend: BackendArgs,
    /// Without poses: consecutive images per place (4 for yaw views); with poses: most views
    /// per place.
    #[arg(long, default_value_t = 1)]
    pub views_per_place: usize,
    /// Place spacing in metres (with poses).
    #[arg(long, default_value_t = 2.0)]
    pub place_spacing: f64,
    /// Descriptor dimension D; with fewer than D + 1 images, the number of images minus one.
    #[arg(long, default_value_t = 512)]
    pub dim: usize,
    /// Most images the PCA is fitted on (evenly spaced).
    #[arg(long, default_value_t = 1000)]
    pub pca_samples: usize,
    /// Whiten the PCA (unit variance per component; see FitOptions::whiten).
    #[arg(long)]
    pub whiten: bool,
    /// How the PCA rows are stored: i8 (a quarter of the size; the views are projected with
    /// the stored rows) or f32 (exact).
    #[arg(long, value_enum, default_value_t = PcaPrecisionArg::I8)]
    pub pca_precision: PcaPrecisionArg,
    /// Describing threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Keypoints stored per view for geometric verification (0: none).
    #[arg(long, default_value_t = topoloc::verify::DEFAULT_KEYPOINTS)]
    pub verification_keypoints: usize,
    /// Which local features those keypoints are (xfeat runs the cache's XFeat export).
    #[arg(long, value_enum, default_value_t = LocalFeatures::from(topoloc::build::DEFAULT_MAP_FEATURES))]
    pub local_features: LocalFeatures,
    /// Output map file.
    #[arg(long)]
    pub out: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `--pca-precision`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PcaPrecisionArg {
    /// Exact, 4 bytes per value.
    F32,
    /// 1 byte per value and one scale per row.
    I8,
}

impl From<PcaPrecisionArg> for PcaPrecision {
    fn from(p: PcaPrecisionArg) -> Self {
        match p {
            PcaPrecisionArg::F32 => PcaPrecision::F32,
            PcaPrecisionArg::I8 => PcaPrecision::I8,
        }
    }
}

/// Runs the command.
pub fn run(args: &BuildMapArgs) -> Result<()> {
    let sequence = sequence::open(&args.images)?;
    let files: Vec<PathBuf> = sequence.frames.iter().map(|f| f.image.clone()).collect();
    let poses = match &args.poses {
        Some(path) => Some(
            sequence::poses_at_frames(&sequence, read_tum(path)?, path)?
                .into_iter()
                .map(|p| p.world_t_camera)
                .collect::<Vec<_>>(),
        ),
        None => None,
    };
    let options = ImageMapOptions {
        backend: args.backend.config()?,
        fit: FitOptions {
            dim: args.dim,
            pca_samples: args.pca_samples,
            whiten: args.whiten,
            pca_precision: args.pca_precision.into(),
            ..FitOptions::default()
        },
        views_per_place: args.views_per_place,
        keyframes: KeyframeOptions {
            place_spacing_m: args.place_spacing,
            neighbour_radius_m: 1.5 * args.place_spacing,
            ..KeyframeOptions::default()
        },
        threads: args.threads,
        keypoints: args.verification_keypoints,
        features: args.local_features.into(),
        xfeat: args.backend.runtime.xfeat_options(),
    };
    let sources: Vec<ImageSource> = files.iter().map(|f| ImageSource::File(f)).collect();
    let bar = progress_bar(files.len(), "describing");
    let mut report_progress = |stage: BuildStage, done: usize, _total: usize| {
        match stage {
            BuildStage::Describing => bar.set_position(done as u64),
            BuildStage::Fitting => bar.set_message("fitting"),
        }
        true
    };
    let (map, report) = build_from_images(
        &sources,
        poses
            .as_deref()
            .map_or(ImageLayout::Sequence, ImageLayout::Keyframes),
        &options,
        &mut report_progress,
    )?;
    bar.finish_and_clear();
    map.save(&args.out)?;
    let summary = json!({
        "map": args.out.display().to_string(),
        "images": report.images,
        "sequence": {
            "layout": format!("{:?}", sequence.layout),
            "frames": sequence.frames.len(),
        },
        "places": map.place_count(),
        "views": map.view_count(),
        "edges": map.edge_count(),
        "descriptor": map.descriptor().to_string(),
        "uninformative_images": report.uninformative,
        "describe_seconds": report.describe_seconds,
        "fit_seconds": report.fit_seconds,
    });
    if args.json {
        println!("{summary}");
    } else {
        println!(
            "{}: {} places, {} views, {} edges from {} images",
            args.out.display(),
            map.place_count(),
            map.view_count(),
            map.edge_count(),
            report.images
        );
        println!("descriptor: {}", map.descriptor());
        println!(
            "describe {:.1} s ({:.1} ms per image, all threads), fit {:.1} s",
            report.describe_seconds,
            report.describe_seconds * 1e3 / report.images as f64,
            report.fit_seconds
        );
        if !report.uninformative.is_empty() {
            println!(
                "warning: {} images without content (blank/constant or no local feature) kept as views: {:?}",
                report.uninformative.len(),
                report.uninformative
            );
        }
    }
    Ok(())
}
