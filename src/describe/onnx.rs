//! The ONNX backend: a CNN run by ONNX Runtime (loaded at run time, so the library works without
//! it until an ONNX model is asked for), whose selected feature maps become a multi-level vector.

use super::mlf::{multi_level, FeatureMap};
use crate::bounds::Bounds;
use crate::errors::VisionError;
use crate::image::ImageView;
pub use crate::onnx_runtime::cache_dir;
use crate::onnx_runtime::{check_single_input, session};
use crate::profile::{self, measure, Stage};
use opencv::core::Size;
use opencv::prelude::*;
use ort::session::Session;
use ort::value::TensorRef;
use std::path::PathBuf;

/// ImageNet normalisation of the default backbone (torchvision MobileNetV2), RGB order.
const MEAN: [f32; 3] = [0.485, 0.456, 0.406];
const STD: [f32; 3] = [0.229, 0.224, 0.225];
/// Every grey level of each channel, normalised as the network expects: `(v / 255 - mean) / std`.
fn normalised_levels() -> &'static [[f32; 256]; 3] {
    static TABLE: std::sync::OnceLock<[[f32; 256]; 3]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|c| std::array::from_fn(|v| (v as f32 / 255.0 - MEAN[c]) / STD[c]))
    })
}

/// File name of the default model in the cache: MobileNetV2's multi-level export quantized to
/// int8 by `scripts/setup-models.sh` (BENCHMARKS.md, "int8 MobileNetV2", shows its time and
/// that localization and loop hints keep their accuracy).
pub const DEFAULT_MODEL_FILE: &str = "models/mobilenetv2-mlf-int8.onnx";
/// File name of the same network in f32 in the cache: the option for a host that wants it
/// (pass its path), and the model of maps built before the int8 default.
pub const F32_MODEL_FILE: &str = "models/mobilenetv2-mlf.onnx";
/// What a missing model file's error tells the caller to do.
const MODEL_HINT: &str = "run scripts/setup-models.sh or pass the model path";

/// The cache's model file for a map built with the model whose SHA-256 is `sha256`, for a
/// describer given no model path: the int8 default ([`DEFAULT_MODEL_FILE`]) or the f32 network
/// ([`F32_MODEL_FILE`]), whichever is that very file, so maps of either keep loading. Neither
/// is [`VisionError::Mismatch`] naming both files and the hash the map asks for (missing ones
/// as missing); the file is then read again, and hashed, by the session that loads it.
pub fn default_model_for(sha256: &str) -> Result<PathBuf, VisionError> {
    let mut seen = Vec::new();
    for file in [DEFAULT_MODEL_FILE, F32_MODEL_FILE] {
        let path = cache_dir().join(file);
        if !path.is_file() {
            seen.push(format!("{} (missing)", path.display()));
            continue;
        }
        let found = crate::onnx_runtime::file_sha256(&path, MODEL_HINT)?;
        if found == sha256 {
            return Ok(path);
        }
        seen.push(format!("{} (sha256:{})", path.display(), &found[..16]));
    }
    Err(VisionError::Mismatch(format!(
        "the map was built with the ONNX model sha256:{}, which is none of the cache's models: {}; \
         pass the model file the map was built with (or run scripts/setup-models.sh)",
        sha256.get(..16).unwrap_or(sha256),
        seen.join(", ")
    )))
}

/// Where the ONNX backend finds its files, and what it extracts.
#[derive(Clone, Debug, PartialEq)]
pub struct OnnxOptions {
    /// ONNX Runtime shared library; else `TOPOLOC_ORT_LIBRARY`, `ORT_DYLIB_PATH`, then the cache.
    pub runtime: Option<PathBuf>,
    /// Model file; else the cache's int8 MobileNetV2 multi-level export ([`DEFAULT_MODEL_FILE`]).
    pub model: Option<PathBuf>,
    /// Output names of the feature maps to use (the default model names them `f{block}`).
    pub taps: Vec<String>,
    /// Pooling grid (rows, columns) per tap.
    pub grid: (usize, usize),
    /// Network input size (width, height); images are resized to it.
    pub input_size: (u32, u32),
    /// ONNX Runtime intra-op threads.
    pub threads: usize,
}

impl OnnxOptions {
    /// Accepted values of [`Self::threads`].
    pub const THREADS_RANGE: Bounds = Bounds::whole(1, 64);
}

impl Default for OnnxOptions {
    fn default() -> Self {
        Self {
            runtime: None,
            model: None,
            taps: ["f6", "f13", "f17", "f18"]
                .iter()
                .map(|s| s.to_string())
                .collect(),
            grid: (4, 4),
            input_size: (320, 240),
            threads: 1,
        }
    }
}

/// One feature map of the network for one image, channel-major (`values[c][y][x]`), and the
/// size of one cell in the image's own pixels (the image was resized to the network input).
#[derive(Clone, Debug, PartialEq)]
pub struct DenseTap {
    /// Channels C.
    pub channels: usize,
    /// Rows of cells.
    pub height: usize,
    /// Columns of cells.
    pub width: usize,
    /// Width and height of one cell in image pixels.
    pub cell_size: [f32; 2],
    /// C x height x width values.
    pub values: Vec<f32>,
}

/// A loaded CNN that turns images into raw multi-level vectors (before PCA).
pub struct OnnxMlf {
    session: Session,
    options: OnnxOptions,
    model_sha256: String,
    input: Vec<f32>,
}

impl OnnxMlf {
    /// Loads the runtime and the model; fails with a typed error naming every path tried.
    pub fn new(options: OnnxOptions) -> Result<Self, VisionError> {
        OnnxOptions::THREADS_RANGE
            .check("ONNX threads", options.threads)
            .map_err(VisionError::InvalidArgument)?;
        super::limits::check_onnx_config(
            &options.taps,
            [options.grid.0, options.grid.1],
            [options.input_size.0, options.input_size.1],
        )?;
        let model = options
            .model
            .clone()
            .unwrap_or_else(|| cache_dir().join(DEFAULT_MODEL_FILE));
        let (session, model_sha256) = session(
            options.runtime.as_deref(),
            &model,
            options.threads,
            MODEL_HINT,
        )?;
        let (w, h) = options.input_size;
        check_single_input(
            &session,
            &model,
            "input",
            [None, Some(3), Some(i64::from(h)), Some(i64::from(w))],
        )?;
        let outputs: Vec<&str> = session.outputs().iter().map(|o| o.name()).collect();
        if let Some(missing) = options.taps.iter().find(|t| !outputs.contains(&t.as_str())) {
            return Err(VisionError::Model(format!(
                "{} has no output '{missing}' (it has {outputs:?})",
                model.display()
            )));
        }
        Ok(Self {
            session,
            options,
            model_sha256,
            input: Vec::new(),
        })
    }

    /// Describes the model, taps, pooling and preprocessing: the descriptor identity's model field.
    pub fn identity(&self) -> String {
        let o = &self.options;
        format!(
            "sha256:{} taps={} grid={}x{} input={}x{} rgb/255 imagenet-mean-std",
            &self.model_sha256[..16],
            o.taps.join(","),
            o.grid.0,
            o.grid.1,
            o.input_size.0,
            o.input_size.1
        )
    }

    /// SHA-256 (hex) of the model file.
    pub fn model_sha256(&self) -> &str {
        &self.model_sha256
    }

    /// The options it was created with.
    pub fn options(&self) -> &OnnxOptions {
        &self.options
    }

    /// Runs the network on one image and returns the raw multi-level vector.
    pub fn raw_features(&mut self, image: &ImageView<'_>) -> Result<Vec<f32>, VisionError> {
        Ok(self.raw_features_and_tap(image, None)?.0)
    }

    /// Runs the network once and returns the raw multi-level vector and, when `tap` names an
    /// output, that feature map whole (for dense cells: the same forward pass, never a second).
    pub fn raw_features_and_tap(
        &mut self,
        image: &ImageView<'_>,
        tap: Option<&str>,
    ) -> Result<(Vec<f32>, Option<DenseTap>), VisionError> {
        let (w, h) = self.options.input_size;
        measure(Stage::CnnInput, || self.fill_input(image))?;
        let tensor = TensorRef::from_array_view((
            [1usize, 3, h as usize, w as usize],
            self.input.as_slice(),
        ))
        .map_err(|e| VisionError::Model(e.to_string()))?;
        let outputs = measure(Stage::Cnn, || {
            self.session.run(ort::inputs!["input" => tensor])
        })
        .map_err(|e| VisionError::Model(e.to_string()))?;
        let pooling = std::time::Instant::now();
        let feature_map = |name: &str| -> Result<FeatureMap<'_>, VisionError> {
            let value = outputs
                .get(name)
                .ok_or_else(|| VisionError::Model(format!("the model has no output '{name}'")))?;
            let (shape, values) = value
                .try_extract_tensor::<f32>()
                .map_err(|e| VisionError::Model(e.to_string()))?;
            if shape.len() != 4 || shape[0] != 1 {
                return Err(VisionError::Model(format!(
                    "output '{name}' has shape {shape:?}, expected [1, C, H, W]"
                )));
            }
            Ok(FeatureMap {
                channels: shape[1] as usize,
                height: shape[2] as usize,
                width: shape[3] as usize,
                values,
            })
        };
        let maps = self
            .options
            .taps
            .iter()
            .map(|tap| feature_map(tap))
            .collect::<Result<Vec<_>, _>>()?;
        let vector = multi_level(&maps, self.options.grid.0, self.options.grid.1);
        let dense = match tap {
            None => None,
            Some(name) => {
                let map = feature_map(name)?;
                Some(DenseTap {
                    channels: map.channels,
                    height: map.height,
                    width: map.width,
                    cell_size: [
                        image.width as f32 / map.width as f32,
                        image.height as f32 / map.height as f32,
                    ],
                    values: map.values.to_vec(),
                })
            }
        };
        profile::add(Stage::Pooling, pooling.elapsed());
        Ok((vector, dense))
    }

    /// The network's input: `image` resized to the input size, RGB, ImageNet-normalised,
    /// channel-major.
    fn fill_input(&mut self, image: &ImageView<'_>) -> Result<(), VisionError> {
        let (w, h) = self.options.input_size;
        let rgb = image.to_rgb_resized(Size::new(w as i32, h as i32))?;
        let pixels = rgb.data_bytes()?;
        let plane = (w * h) as usize;
        self.input.resize(3 * plane, 0.0);
        let table = normalised_levels();
        let (red, rest) = self.input.split_at_mut(plane);
        let (green, blue) = rest.split_at_mut(plane);
        for (i, px) in pixels.chunks_exact(3).enumerate() {
            red[i] = table[0][px[0] as usize];
            green[i] = table[1][px[1] as usize];
            blue[i] = table[2][px[2] as usize];
        }
        Ok(())
    }
}
