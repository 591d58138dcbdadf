//! Command-line options shared by the commands that describe images: which backend, its
//! options, and where its runtime files are; plus listing an image folder.

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use std::path::{Path, PathBuf};
use topoloc::describe::onnx::OnnxOptions;
use topoloc::describe::vlad::{LocalFeature, VladOptions};
use topoloc::describe::{BackendConfig, BackendKind, DescriberOptions};

/// The descriptor backend on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Backend {
    /// MobileNetV2 multi-level features through ONNX Runtime (run scripts/setup-models.sh).
    Onnx,
    /// VLAD of OpenCV local features (no learned weights).
    Vlad,
}

impl From<Backend> for BackendKind {
    fn from(b: Backend) -> Self {
        match b {
            Backend::Onnx => BackendKind::Onnx,
            Backend::Vlad => BackendKind::Vlad,
        }
    }
}

/// Local feature of the VLAD backend.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Feature {
    /// ORB (binary, fast).
    Orb,
    /// SIFT (slower, more distinctive).
    Sift,
}

/// Where VLAD describes local features.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Keypoints {
    /// A regular grid (dense VLAD).
    Dense,
    /// The strongest keypoints of the feature's detector.
    Detected,
}

/// Local features stored for verification (`--local-features`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum LocalFeatures {
    /// ORB (OpenCV), 32-byte binary descriptors.
    Orb,
    /// XFeat (ONNX Runtime), 64-byte learned descriptors.
    Xfeat,
    /// Dense cells of the describer's CNN (ONNX backend), from the same forward pass.
    Cells,
}

impl From<topoloc::verify::FeatureKind> for LocalFeatures {
    fn from(kind: topoloc::verify::FeatureKind) -> Self {
        match kind {
            topoloc::verify::FeatureKind::Orb => Self::Orb,
            topoloc::verify::FeatureKind::XFeat => Self::Xfeat,
            topoloc::verify::FeatureKind::Cells => Self::Cells,
        }
    }
}

impl From<LocalFeatures> for topoloc::verify::FeatureKind {
    fn from(f: LocalFeatures) -> Self {
        match f {
            LocalFeatures::Orb => Self::Orb,
            LocalFeatures::Xfeat => Self::XFeat,
            LocalFeatures::Cells => Self::Cells,
        }
    }
}

/// Where the ONNX backend's files are (both commands).
#[derive(Args, Clone, Debug)]
pub struct RuntimeArgs {
    /// ONNX model file (default: the cache's MobileNetV2 export).
    #[arg(long)]
    pub onnx_model: Option<PathBuf>,
    /// ONNX Runtime library (default: TOPOLOC_ORT_LIBRARY, ORT_DYLIB_PATH, then the cache).
    #[arg(long)]
    pub onnx_runtime: Option<PathBuf>,
    /// XFeat: largest network input in pixels; larger images are scaled down first (0: the
    /// image's own size).
    #[arg(long, default_value_t = topoloc::verify::DEFAULT_XFEAT_MAX_PIXELS)]
    pub xfeat_max_pixels: u32,
}

impl RuntimeArgs {
    /// Where XFeat is: the cache's export, on the same runtime library.
    pub fn xfeat_options(&self) -> topoloc::verify::XFeatOptions {
        topoloc::verify::XFeatOptions {
            runtime: self.onnx_runtime.clone(),
            max_pixels: self.xfeat_max_pixels,
            ..Default::default()
        }
    }

    /// Options for describing query images with a map's stored describer.
    pub fn describer_options(&self, backend: Option<Backend>) -> DescriberOptions {
        DescriberOptions {
            backend: backend.map(Into::into),
            family: None,
            onnx_runtime: self.onnx_runtime.clone(),
            onnx_model: self.onnx_model.clone(),
            threads: 1,
        }
    }
}

/// Backend choice and options for building a map.
#[derive(Args, Clone, Debug)]
pub struct BackendArgs {
    /// Descriptor backend.
    #[arg(long, value_enum, default_value_t = Backend::Onnx)]
    pub backend: Backend,
    /// ONNX: network outputs to pool (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "f6,f13,f17,f18")]
    pub taps: Vec<String>,
    /// ONNX: pooling grid per tap, ROWSxCOLS (1x1 is plain global pooling).
    #[arg(long, default_value = "4x4")]
    pub grid: String,
    /// VLAD: local feature.
    #[arg(long, value_enum, default_value_t = Feature::Orb)]
    pub feature: Feature,
    /// VLAD: codebook size.
    #[arg(long, default_value_t = 64)]
    pub clusters: usize,
    /// VLAD: keypoints on a dense grid (default) or detected by the feature's detector.
    #[arg(long, value_enum, default_value_t = Keypoints::Dense)]
    pub keypoints: Keypoints,
    #[command(flatten)]
    pub runtime: RuntimeArgs,
}

impl BackendArgs {
    /// The library's backend configuration.
    pub fn config(&self) -> Result<BackendConfig> {
        Ok(match self.backend {
            Backend::Onnx => {
                let (rows, cols) = self
                    .grid
                    .split_once('x')
                    .context("--grid must look like 4x4")?;
                BackendConfig::Onnx(OnnxOptions {
                    runtime: self.runtime.onnx_runtime.clone(),
                    model: self.runtime.onnx_model.clone(),
                    taps: self.taps.clone(),
                    grid: (rows.parse()?, cols.parse()?),
                    ..OnnxOptions::default()
                })
            }
            Backend::Vlad => BackendConfig::Vlad(VladOptions {
                feature: match self.feature {
                    Feature::Orb => LocalFeature::Orb,
                    Feature::Sift => LocalFeature::Sift,
                },
                clusters: self.clusters,
                dense: self.keypoints == Keypoints::Dense,
                ..VladOptions::default()
            }),
        })
    }
}

/// File extensions (any case) taken as images in an image folder.
pub const IMAGE_EXTENSIONS: [&str; 6] = ["jpg", "jpeg", "png", "bmp", "pgm", "ppm"];

/// True when `path` has one of [`IMAGE_EXTENSIONS`].
pub fn has_image_extension(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// Image files (jpg, jpeg, png, bmp, pgm, ppm) in `dir`, sorted by name.
pub fn image_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading image folder {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| has_image_extension(p))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("no images (jpg, png, bmp, pgm, ppm) in {}", dir.display());
    }
    Ok(files)
}

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub fn progress_bar(total: usize, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(total as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{msg:>12} [{bar:40}] {pos}/{len} {per_sec} eta {eta}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}
