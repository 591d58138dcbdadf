//! The describer: one object that turns an image into the map's D-dimensional descriptor, and
//! the model it needs (backend configuration, PCA, VLAD codebook) as stored in a map.
//!
//! Building a map: an [`Extractor`] per thread turns images into [`RawFeatures`]; [`fit`] learns
//! the [`DescriberModel`] (codebook and PCA) from all of them and returns every image's
//! descriptor. Localizing: [`Describer::new`] loads the backend named by a map's model, checks
//! that it is the very same (model file hash, taps, preprocessing), and describes query images.

use super::limits;
use super::onnx::{DenseTap, OnnxMlf, OnnxOptions};
use super::pca::{Components, Pca, PcaPrecision};
use super::vlad::{Codebook, LocalExtractor, LocalFeature, LocalFeatures, VladOptions};
use crate::bounds::Bounds;
use crate::descriptor::DescriptorIdentity;
use crate::errors::VisionError;
use crate::image::ImageView;
use crate::profile::{measure, Stage};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::sync::Arc;

/// Preprocessing of the ONNX backend, recorded in its identity.
pub const ONNX_PREPROCESSING: &str = "rgb/255 imagenet-mean-std";

/// The descriptor backends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendKind {
    /// A CNN run by ONNX Runtime, multi-level pooled (the seed's MLF).
    Onnx,
    /// VLAD over OpenCV local features; needs no learned weights.
    Vlad,
}

impl BackendKind {
    /// Lower-case name, as used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            BackendKind::Onnx => "onnx",
            BackendKind::Vlad => "vlad",
        }
    }
}

/// A backend and its options, for building a map.
#[derive(Clone, Debug, PartialEq)]
pub enum BackendConfig {
    /// ONNX multi-level CNN features.
    Onnx(OnnxOptions),
    /// VLAD of local features.
    Vlad(VladOptions),
}

impl BackendConfig {
    /// Which backend this is.
    pub fn kind(&self) -> BackendKind {
        match self {
            BackendConfig::Onnx(_) => BackendKind::Onnx,
            BackendConfig::Vlad(_) => BackendKind::Vlad,
        }
    }
}

/// The backend as recorded in a map: everything that defines the descriptor except the learned
/// arrays (PCA, codebook), which are stored as tensors. Serialised into the map's metadata.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "backend", rename_all = "lowercase")]
pub enum BackendSpec {
    /// ONNX multi-level features.
    Onnx {
        /// SHA-256 (hex) of the model file.
        model_sha256: String,
        /// Output names pooled, in order.
        taps: Vec<String>,
        /// Pooling grid, rows and columns.
        grid: [usize; 2],
        /// Network input, width and height.
        input_size: [u32; 2],
        /// Colour order and normalisation ([`ONNX_PREPROCESSING`]).
        preprocessing: String,
    },
    /// VLAD of local features.
    Vlad(VladOptions),
}

impl BackendSpec {
    /// Which backend this is.
    pub fn kind(&self) -> BackendKind {
        match self {
            BackendSpec::Onnx { .. } => BackendKind::Onnx,
            BackendSpec::Vlad(_) => BackendKind::Vlad,
        }
    }

    /// The descriptor family name stored in [`DescriptorIdentity::kind`].
    pub fn family(&self) -> &'static str {
        match self {
            BackendSpec::Onnx { .. } => "onnx-mlf",
            BackendSpec::Vlad(VladOptions {
                feature: LocalFeature::Orb,
                ..
            }) => "vlad-orb",
            BackendSpec::Vlad(VladOptions {
                feature: LocalFeature::Sift,
                ..
            }) => "vlad-sift",
        }
    }

    /// Checks every size and string the spec declares against the bounds of
    /// [`super::limits`] (taps, grid, input size, model hash; VLAD options by
    /// [`VladOptions::validate`]), before anything is allocated from them.
    pub fn validate(&self) -> Result<(), VisionError> {
        match self {
            BackendSpec::Onnx {
                model_sha256,
                taps,
                grid,
                input_size,
                preprocessing,
            } => {
                limits::check_onnx_config(taps, *grid, *input_size)?;
                let hex = |c: char| c.is_ascii_digit() || ('a'..='f').contains(&c);
                if model_sha256.len() != limits::SHA256_HEX_LEN || !model_sha256.chars().all(hex) {
                    return Err(VisionError::InvalidArgument(format!(
                        "ONNX model hash must be {} lower-case hex digits",
                        limits::SHA256_HEX_LEN
                    )));
                }
                if preprocessing.len() > limits::MAX_TAP_NAME_BYTES || preprocessing.contains('\0')
                {
                    return Err(VisionError::InvalidArgument(format!(
                        "ONNX preprocessing must be at most {} bytes without NUL",
                        limits::MAX_TAP_NAME_BYTES
                    )));
                }
                Ok(())
            }
            BackendSpec::Vlad(o) => o.validate(),
        }
    }

    fn summary(&self) -> String {
        match self {
            BackendSpec::Onnx {
                model_sha256,
                taps,
                grid,
                input_size,
                preprocessing,
            } => format!(
                "sha256:{} taps={} grid={}x{} input={}x{} {preprocessing}",
                model_sha256.get(..16).unwrap_or(model_sha256),
                taps.join(","),
                grid[0],
                grid[1],
                input_size[0],
                input_size[1]
            ),
            BackendSpec::Vlad(o) => format!(
                "k={} {} input={}x{} signed-sqrt intra-l2",
                o.clusters,
                if o.dense {
                    format!(
                        "dense step={} size={}",
                        super::vlad::DENSE_STEP,
                        super::vlad::DENSE_SIZE
                    )
                } else {
                    format!("max_features={}", o.max_features)
                },
                o.input_size.0,
                o.input_size.1
            ),
        }
    }
}

/// Everything a map stores to describe new images exactly as its views were described.
#[derive(Clone, Debug, PartialEq)]
pub struct DescriberModel {
    /// Backend and its configuration.
    pub spec: BackendSpec,
    /// Projection from raw vectors to the map's D dimensions.
    pub pca: Pca,
    /// VLAD vocabulary (VLAD backend only).
    pub codebook: Option<Codebook>,
}

impl DescriberModel {
    /// Checks that the parts fit together (codebook present exactly for VLAD, dimensions agree)
    /// and that every declared size lies within [`super::limits`]: the spec
    /// ([`BackendSpec::validate`]), the PCA dimensions (1..=[`limits::MAX_PCA_INPUT_DIM`] in,
    /// 1..=[`limits::MAX_PCA_OUTPUT_DIM`] out), the codebook against the VLAD options, and for
    /// ONNX a PCA input that is a whole number of pooled grids, at least one per tap.
    pub fn validate(&self) -> Result<(), VisionError> {
        let bad = |m: String| Err(VisionError::InvalidArgument(m));
        self.spec.validate()?;
        let pca = &self.pca;
        if !(1..=limits::MAX_PCA_INPUT_DIM).contains(&pca.input_dim)
            || !(1..=limits::MAX_PCA_OUTPUT_DIM).contains(&pca.output_dim)
        {
            return bad(format!(
                "PCA is {}x{}, must be at most {}x{} and not empty",
                pca.output_dim,
                pca.input_dim,
                limits::MAX_PCA_OUTPUT_DIM,
                limits::MAX_PCA_INPUT_DIM
            ));
        }
        if pca.mean.len() != pca.input_dim
            || pca.output_dim.checked_mul(pca.input_dim) != Some(pca.components.len())
        {
            return bad(format!(
                "PCA arrays do not match {}x{}",
                pca.output_dim, pca.input_dim
            ));
        }
        let finite = match &pca.components {
            Components::F32(rows) => pca.mean.iter().chain(rows).all(|x| x.is_finite()),
            Components::I8 { scales, .. } => {
                if scales.len() != pca.output_dim {
                    return bad(format!(
                        "PCA has {} row scales for {} rows",
                        scales.len(),
                        pca.output_dim
                    ));
                }
                if scales.iter().any(|&s| s < 0.0) {
                    return bad("PCA row scales must not be negative".into());
                }
                if let Some(&s) = scales
                    .iter()
                    .find(|&&s| s.is_finite() && !limits::PCA_ROW_SCALE_RANGE.contains(s.into()))
                {
                    return bad(format!(
                        "a PCA row scale is {s}, must be in {}",
                        limits::PCA_ROW_SCALE_RANGE
                    ));
                }
                if scales.iter().all(|&s| s == 0.0) {
                    return bad("PCA row scales are all 0: every descriptor would be zero".into());
                }
                pca.mean.iter().chain(scales).all(|x| x.is_finite())
            }
        };
        if !finite {
            return bad("PCA holds NaN or infinite values".into());
        }
        match (&self.spec, &self.codebook) {
            (BackendSpec::Vlad(o), Some(c)) => {
                if c.clusters != o.clusters
                    || c.dim != o.feature.dim()
                    || c.clusters.checked_mul(c.dim) != Some(pca.input_dim)
                    || c.centres.len() != pca.input_dim
                {
                    return bad(format!(
                        "codebook {}x{} does not match {} clusters of {}-d features and PCA input {}",
                        c.clusters,
                        c.dim,
                        o.clusters,
                        o.feature.dim(),
                        pca.input_dim
                    ));
                }
                Ok(())
            }
            (BackendSpec::Onnx { taps, grid, .. }, None) => {
                let cells = grid[0] * grid[1]; // both bounded by MAX_POOL_GRID above
                if !pca.input_dim.is_multiple_of(cells) || pca.input_dim / cells < taps.len() {
                    return bad(format!(
                        "PCA input {} is not a whole number of {}x{} grids, at least one per tap ({})",
                        pca.input_dim,
                        grid[0],
                        grid[1],
                        taps.len()
                    ));
                }
                Ok(())
            }
            (BackendSpec::Vlad(_), None) => bad("VLAD model without a codebook".into()),
            (BackendSpec::Onnx { .. }, Some(_)) => bad("ONNX model with a codebook".into()),
        }
    }

    /// The identity of the descriptors this model produces: backend, its configuration, and a
    /// fingerprint of the fitted arrays (two PCA fits give incompatible spaces).
    pub fn identity(&self) -> DescriptorIdentity {
        let mut hasher = crc32fast::Hasher::new();
        hash_f32s(&mut hasher, &self.pca.mean);
        // f32 rows keep the fingerprint of maps written before i8 rows existed.
        let precision = match &self.pca.components {
            Components::F32(rows) => {
                hash_f32s(&mut hasher, rows);
                ""
            }
            Components::I8 { values, scales } => {
                hasher.update(values);
                hash_f32s(&mut hasher, scales);
                "/i8"
            }
        };
        if let Some(c) = &self.codebook {
            hash_f32s(&mut hasher, &c.centres);
        }
        DescriptorIdentity {
            kind: self.spec.family().into(),
            model: format!(
                "{} pca={}x{}{precision} fit={:08x}",
                self.spec.summary(),
                self.pca.output_dim,
                self.pca.input_dim,
                hasher.finalize()
            ),
            dim: self.pca.output_dim as u32,
        }
    }
}

/// Feeds `values` to `hasher` as their little-endian bytes (in blocks, not value by value: a
/// 512 x 27,648 PCA is 14 million values).
fn hash_f32s(hasher: &mut crc32fast::Hasher, values: &[f32]) {
    let mut bytes = Vec::with_capacity(4096 * 4);
    for block in values.chunks(4096) {
        bytes.clear();
        bytes.extend(block.iter().flat_map(|x| x.to_le_bytes()));
        hasher.update(&bytes);
    }
}

/// An image's features before the learned steps (codebook, PCA).
#[derive(Clone, Debug)]
pub enum RawFeatures {
    /// The raw multi-level CNN vector.
    Mlf(Vec<f32>),
    /// Local descriptors, aggregated by VLAD once the codebook is trained.
    Local(LocalFeatures),
}

enum Engine {
    Onnx(Box<OnnxMlf>),
    Vlad(LocalExtractor),
}

/// Turns images into [`RawFeatures`]. Holds a loaded backend; one per thread (`Send`, not `Sync`).
pub struct Extractor {
    engine: Engine,
    spec: BackendSpec,
}

impl Extractor {
    /// Loads the backend: for ONNX the runtime and model (typed errors name every path tried).
    pub fn new(config: &BackendConfig) -> Result<Self, VisionError> {
        Ok(match config {
            BackendConfig::Onnx(options) => {
                let mlf = OnnxMlf::new(options.clone())?;
                let spec = BackendSpec::Onnx {
                    model_sha256: mlf.model_sha256().to_string(),
                    taps: options.taps.clone(),
                    grid: [options.grid.0, options.grid.1],
                    input_size: [options.input_size.0, options.input_size.1],
                    preprocessing: ONNX_PREPROCESSING.into(),
                };
                Self {
                    engine: Engine::Onnx(Box::new(mlf)),
                    spec,
                }
            }
            BackendConfig::Vlad(options) => Self {
                engine: Engine::Vlad(LocalExtractor::new(options)?),
                spec: BackendSpec::Vlad(options.clone()),
            },
        })
    }

    /// The backend as it will be recorded in the map.
    pub fn spec(&self) -> &BackendSpec {
        &self.spec
    }

    /// Raw features of one image. Refuses images without content (every pixel within
    /// [`CONSTANT_IMAGE_RANGE`] grey levels, or no local feature found) with
    /// [`VisionError::Uninformative`].
    pub fn extract(&mut self, image: &ImageView<'_>) -> Result<RawFeatures, VisionError> {
        image.validate()?;
        if is_constant(image) {
            return Err(constant_image());
        }
        match self.run(image)? {
            RawFeatures::Local(l) if l.count() == 0 => Err(VisionError::Uninformative(
                "no local features found in the image".into(),
            )),
            raw => Ok(raw),
        }
    }

    /// Raw features of one image, also for images without content (their CNN features, or an
    /// empty feature set), with `false` for those; for map building, where image indices must
    /// stay aligned.
    pub fn extract_keeping_uninformative(
        &mut self,
        image: &ImageView<'_>,
    ) -> Result<(RawFeatures, bool), VisionError> {
        image.validate()?;
        let constant = is_constant(image);
        let raw = self.run(image)?;
        let informative = !constant && !matches!(&raw, RawFeatures::Local(l) if l.count() == 0);
        Ok((raw, informative))
    }

    /// As [`Extractor::extract_keeping_uninformative`], and the feature map `tap` of the same
    /// forward pass (dense cells for verification). Only the ONNX backend has feature maps:
    /// VLAD gives [`VisionError::InvalidArgument`].
    pub fn extract_with_tap(
        &mut self,
        image: &ImageView<'_>,
        tap: &str,
    ) -> Result<(RawFeatures, bool, DenseTap), VisionError> {
        image.validate()?;
        let Engine::Onnx(mlf) = &mut self.engine else {
            return Err(VisionError::InvalidArgument(
                "dense cells come from a CNN feature map: they need the ONNX backend".into(),
            ));
        };
        let (raw, dense) = mlf.raw_features_and_tap(image, Some(tap))?;
        let dense = dense.expect("a tap was asked for");
        Ok((RawFeatures::Mlf(raw), !is_constant(image), dense))
    }

    fn run(&mut self, image: &ImageView<'_>) -> Result<RawFeatures, VisionError> {
        Ok(match &mut self.engine {
            Engine::Onnx(mlf) => RawFeatures::Mlf(mlf.raw_features(image)?),
            Engine::Vlad(local) => RawFeatures::Local(local.extract(image)?),
        })
    }
}

/// The error for an image without content.
fn constant_image() -> VisionError {
    VisionError::Uninformative(format!(
        "every pixel lies within {CONSTANT_IMAGE_RANGE} grey levels (blank or constant image)"
    ))
}

/// Images whose pixel values all lie within this many grey levels carry no place information.
pub const CONSTANT_IMAGE_RANGE: u8 = 2;

/// True when every channel value of the image lies within [`CONSTANT_IMAGE_RANGE`] levels.
fn is_constant(image: &ImageView<'_>) -> bool {
    let row_bytes = image.width as usize * image.format.channels();
    let (mut lo, mut hi) = (u8::MAX, u8::MIN);
    for row in image.data.chunks(image.stride).take(image.height as usize) {
        for &v in &row[..row_bytes] {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        if hi - lo > CONSTANT_IMAGE_RANGE {
            return false;
        }
    }
    true
}

/// How [`fit`] learns the model.
#[derive(Clone, Debug, PartialEq)]
pub struct FitOptions {
    /// Descriptor dimension D (at most the number of images minus one). Default 512.
    pub dim: usize,
    /// PCA is fitted on at most this many images, evenly spaced (the SVD costs n^2 x raw size).
    /// Default 1000.
    pub pca_samples: usize,
    /// The VLAD codebook is trained on at most this many local features, evenly spaced.
    /// Default 100,000.
    pub codebook_samples: usize,
    /// Scale PCA components to unit variance. Default `false` for both backends: fitted on the
    /// map's own n images with D = n - 1 (small maps), whitening makes the map's views mutually
    /// equidistant and throws their structure away (it lowered single-frame R@1 on Gardens
    /// Point; BENCHMARKS.md, "Real images").
    pub whiten: bool,
    /// How the PCA rows are stored: `i8` (default) is a quarter of `f32`'s size; the map's own
    /// views are projected with the stored rows, so that they and the queries share one
    /// projection (BENCHMARKS.md, "Memory budget").
    pub pca_precision: PcaPrecision,
}

impl FitOptions {
    /// Accepted values of [`Self::dim`].
    pub const DIM_RANGE: Bounds = Bounds::whole(1, limits::MAX_PCA_OUTPUT_DIM as u64);
    /// Accepted values of [`Self::pca_samples`].
    pub const PCA_SAMPLES_RANGE: Bounds = Bounds::whole_at_least(2);
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            dim: 512,
            pca_samples: 1000,
            codebook_samples: 100_000,
            whiten: false,
            pca_precision: PcaPrecision::default(),
        }
    }
}

/// Learns the codebook (VLAD) and PCA from the map's raw features, and returns the model with
/// every image's D-dimensional, unit-norm descriptor (in input order).
pub fn fit(
    spec: &BackendSpec,
    raws: &[RawFeatures],
    options: &FitOptions,
) -> Result<(DescriberModel, Vec<Vec<f32>>), VisionError> {
    if raws.len() < 2 {
        return Err(VisionError::InvalidArgument(format!(
            "a describer is fitted on at least 2 images, got {}",
            raws.len()
        )));
    }
    FitOptions::DIM_RANGE
        .check("descriptor dimension", options.dim)
        .and_then(|()| FitOptions::PCA_SAMPLES_RANGE.check("PCA samples", options.pca_samples))
        .map_err(VisionError::InvalidArgument)?;
    spec.validate()?;
    let (codebook, vectors) = match spec {
        BackendSpec::Onnx { .. } => {
            let vectors = raws
                .iter()
                .map(|r| match r {
                    RawFeatures::Mlf(v) => Ok(v.clone()),
                    RawFeatures::Local(_) => Err(wrong_raw_kind()),
                })
                .collect::<Result<Vec<_>, _>>()?;
            (None, vectors)
        }
        BackendSpec::Vlad(o) => {
            let locals = raws
                .iter()
                .map(|r| match r {
                    RawFeatures::Local(l) => Ok(l),
                    RawFeatures::Mlf(_) => Err(wrong_raw_kind()),
                })
                .collect::<Result<Vec<_>, _>>()?;
            let codebook = train_codebook(&locals, o.clusters, options.codebook_samples)?;
            let vectors = locals.iter().map(|l| codebook.vlad(l)).collect();
            (Some(codebook), vectors)
        }
    };
    let raw_dim = vectors[0].len();
    if vectors.iter().any(|v| v.len() != raw_dim) {
        return Err(VisionError::InvalidArgument(
            "raw vectors differ in length (mixed backends or taps)".into(),
        ));
    }
    let step = vectors.len().div_ceil(options.pca_samples.max(2));
    let rows: Vec<f32> = vectors.iter().step_by(step).flatten().copied().collect();
    let pca = Pca::fit(&rows, raw_dim, options.dim, options.whiten)?
        .with_precision(options.pca_precision);
    let descriptors = vectors
        .iter()
        .map(|v| pca.project(v))
        .collect::<Result<Vec<_>, _>>()?;
    let model = DescriberModel {
        spec: spec.clone(),
        pca,
        codebook,
    };
    Ok((model, descriptors))
}

fn wrong_raw_kind() -> VisionError {
    VisionError::InvalidArgument("raw features come from another backend than the spec".into())
}

fn train_codebook(
    locals: &[&LocalFeatures],
    clusters: usize,
    max_samples: usize,
) -> Result<Codebook, VisionError> {
    let dim = locals[0].dim;
    let total: usize = locals.iter().map(|l| l.count()).sum();
    let step = total.div_ceil(max_samples.max(clusters)).max(1);
    let mut samples = Vec::with_capacity(total / step * dim + dim);
    let mut index = 0usize;
    for l in locals {
        for row in l.values.chunks_exact(dim) {
            if index.is_multiple_of(step) {
                samples.extend_from_slice(row);
            }
            index += 1;
        }
    }
    Codebook::train(&samples, dim, clusters)
}

/// Where the describer finds its runtime files, and what the caller insists on.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DescriberOptions {
    /// Refuse maps built with another backend.
    pub backend: Option<BackendKind>,
    /// Refuse maps built with another descriptor family ([`BackendSpec::family`]:
    /// `"onnx-mlf"`, `"vlad-orb"`, `"vlad-sift"`), a finer demand than `backend`.
    pub family: Option<String>,
    /// ONNX Runtime library (else `TOPOLOC_ORT_LIBRARY`, `ORT_DYLIB_PATH`, the cache).
    pub onnx_runtime: Option<PathBuf>,
    /// ONNX model file; must be the very model the map was built with. Else the cache's file
    /// that is ([`super::onnx::default_model_for`]: the int8 default or the f32 network).
    pub onnx_model: Option<PathBuf>,
    /// ONNX Runtime intra-op threads; 0 means 1.
    pub threads: usize,
}

/// Describes images exactly as a map's views were described. Not `Sync`: one per localizer.
pub struct Describer {
    model: Arc<DescriberModel>,
    identity: DescriptorIdentity,
    extractor: Extractor,
}

impl Describer {
    /// Loads the backend the model names and checks that it is the same one: the same backend
    /// as `options.backend` asks for, and for ONNX the same model file (by SHA-256). Mismatches
    /// give [`VisionError::Mismatch`]; missing files [`VisionError::BackendUnavailable`].
    pub fn new(
        model: Arc<DescriberModel>,
        options: &DescriberOptions,
    ) -> Result<Self, VisionError> {
        model.validate()?;
        if let Some(kind) = options.backend {
            if kind != model.spec.kind() {
                return Err(VisionError::Mismatch(format!(
                    "the map was built with the {} backend, the caller asked for {}",
                    model.spec.kind().name(),
                    kind.name()
                )));
            }
        }
        if let Some(family) = &options.family {
            if family != model.spec.family() {
                return Err(VisionError::Mismatch(format!(
                    "the map was built with the {} backend, the caller asked for {family}",
                    model.spec.family()
                )));
            }
        }
        let config = match &model.spec {
            BackendSpec::Onnx {
                model_sha256,
                taps,
                grid,
                input_size,
                preprocessing,
            } => {
                if preprocessing != ONNX_PREPROCESSING {
                    return Err(VisionError::Mismatch(format!(
                        "the map's preprocessing '{preprocessing}' is not supported by this build ('{ONNX_PREPROCESSING}')"
                    )));
                }
                let model_file = match &options.onnx_model {
                    Some(path) => path.clone(),
                    None => super::onnx::default_model_for(model_sha256)?,
                };
                BackendConfig::Onnx(OnnxOptions {
                    runtime: options.onnx_runtime.clone(),
                    model: Some(model_file),
                    taps: taps.clone(),
                    grid: (grid[0], grid[1]),
                    input_size: (input_size[0], input_size[1]),
                    threads: options.threads.max(1),
                })
            }
            BackendSpec::Vlad(o) => BackendConfig::Vlad(o.clone()),
        };
        let extractor = Extractor::new(&config)?;
        if extractor.spec() != &model.spec {
            return Err(VisionError::Mismatch(format!(
                "the map was built with {}, the loaded backend is {}",
                model.spec.summary(),
                extractor.spec().summary()
            )));
        }
        Ok(Self {
            identity: model.identity(),
            model,
            extractor,
        })
    }

    /// The identity of the descriptors produced (equal to the map's).
    pub fn identity(&self) -> &DescriptorIdentity {
        &self.identity
    }

    /// The model used.
    pub fn model(&self) -> &Arc<DescriberModel> {
        &self.model
    }

    /// Describes one image into `out` (D values, unit norm).
    pub fn describe(
        &mut self,
        image: &ImageView<'_>,
        out: &mut Vec<f32>,
    ) -> Result<(), VisionError> {
        let raw = self.extractor.extract(image)?;
        self.project(&raw, out)
    }

    /// Describes one image into `out` and returns the feature map `tap` of the same forward
    /// pass (ONNX backend only; see [`Extractor::extract_with_tap`]). Images without content
    /// are [`VisionError::Uninformative`], as for [`Describer::describe`].
    pub fn describe_with_tap(
        &mut self,
        image: &ImageView<'_>,
        out: &mut Vec<f32>,
        tap: &str,
    ) -> Result<DenseTap, VisionError> {
        let (raw, informative, dense) = self.extractor.extract_with_tap(image, tap)?;
        if !informative {
            return Err(constant_image());
        }
        self.project(&raw, out)?;
        Ok(dense)
    }

    /// The model's descriptor of raw features.
    fn project(&self, raw: &RawFeatures, out: &mut Vec<f32>) -> Result<(), VisionError> {
        let vlad;
        let vector = match raw {
            RawFeatures::Mlf(v) => v,
            RawFeatures::Local(l) => {
                let codebook = self
                    .model
                    .codebook
                    .as_ref()
                    .expect("validated: VLAD models have a codebook");
                vlad = codebook.vlad(l);
                &vlad
            }
        };
        *out = measure(Stage::Pooling, || self.model.pca.project(vector))?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::PixelFormat;

    #[test]
    fn constant_images_are_detected_through_padding() {
        let view = |data: &[u8]| {
            is_constant(&ImageView {
                width: 3,
                height: 4,
                stride: 8,
                format: PixelFormat::Gray8,
                data,
            })
        };
        let mut data = vec![100u8; 4 * 8];
        assert!(view(&data));
        data[7] = 0; // padding byte: ignored
        assert!(view(&data));
        data[8 + 2] = 103; // a pixel 3 levels away
        assert!(!view(&data));
    }

    #[test]
    fn vlad_models_describe_and_identify_themselves() {
        let options = VladOptions::default();
        let spec = BackendSpec::Vlad(options.clone());
        let mut extractor = Extractor::new(&BackendConfig::Vlad(options)).unwrap();
        let images: Vec<Vec<u8>> = (0..6).map(|seed| textured(320, 240, seed)).collect();
        let raws: Vec<RawFeatures> = images
            .iter()
            .map(|d| {
                extractor
                    .extract(&ImageView::packed(320, 240, PixelFormat::Gray8, d))
                    .unwrap()
            })
            .collect();
        let (model, descriptors) = fit(&spec, &raws, &FitOptions::default()).unwrap();
        assert_eq!(model.pca.output_dim, 5, "n - 1 components");
        let identity = model.identity();
        assert_eq!(identity.kind, "vlad-orb");
        assert_eq!(identity.dim, 5);
        let mut describer = Describer::new(Arc::new(model), &DescriberOptions::default()).unwrap();
        let mut out = Vec::new();
        describer
            .describe(
                &ImageView::packed(320, 240, PixelFormat::Gray8, &images[3]),
                &mut out,
            )
            .unwrap();
        let diff: f32 = out
            .iter()
            .zip(&descriptors[3])
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(
            diff < 1e-5,
            "describing a map image again gives its view: {diff}"
        );
        let blank = vec![7u8; 320 * 240];
        assert!(matches!(
            describer.describe(
                &ImageView::packed(320, 240, PixelFormat::Gray8, &blank),
                &mut out
            ),
            Err(VisionError::Uninformative(_))
        ));
        let wrong = DescriberOptions {
            backend: Some(BackendKind::Onnx),
            ..Default::default()
        };
        assert!(matches!(
            Describer::new(describer.model().clone(), &wrong),
            Err(VisionError::Mismatch(_))
        ));
    }

    /// A deterministic textured grey image: overlapping rectangles of pseudo-random shades.
    pub(crate) fn textured(width: usize, height: usize, seed: u64) -> Vec<u8> {
        let mut state = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut next = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as usize
        };
        let mut data = vec![128u8; width * height];
        for _ in 0..120 {
            let (x0, y0) = (next() % width, next() % height);
            let (w, h) = (8 + next() % 40, 8 + next() % 40);
            let shade = (next() % 256) as u8;
            for y in y0..(y0 + h).min(height) {
                for x in x0..(x0 + w).min(width) {
                    data[y * width + x] = shade;
                }
            }
        }
        data
    }
}
