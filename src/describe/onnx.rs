//! The ONNX backend: a CNN run by ONNX Runtime (loaded at run time, so the library works without
//! it until an ONNX model is asked for), whose selected feature maps become a multi-level vector.

use super::mlf::{multi_level, FeatureMap};
use crate::bounds::Bounds;
use crate::errors::VisionError;
use crate::image::ImageView;
pub use crate::onnx_runtime::cache_dir;
use crate::onnx_runtime::session;
use crate::profile::{self, measure, Stage};
use opencv::core::Size;
use opencv::prelude::*;
use ort::session::Session;
use ort::value::TensorRef;
use std::path::PathBuf;

/// ImageNet normalisation of the default backbone (torchvision MobileNetV2), RGB order.
const MEAN: [f32; 3] = [0.485, 0.456, 0.406];
const STD: [f32; 3] = [0.229, 0.224, 0.225];
/// File name of the default model in the cache (made by scripts/setup-models.sh).
pub const DEFAULT_MODEL_FILE: &str = "models/mobilenetv2-mlf.onnx";

/// Where the ONNX backend finds its files, and what it extracts.
#[derive(Clone, Debug, PartialEq)]
pub struct OnnxOptions {
    /// ONNX Runtime shared library; else `TOPOLOC_ORT_LIBRARY`, `ORT_DYLIB_PATH`, then the cache.
    pub runtime: Option<PathBuf>,
    /// Model file; else the cache's default MobileNetV2 multi-level export.
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
            "run scripts/setup-models.sh or pass the model path",
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
        for (i, px) in pixels.chunks_exact(3).enumerate() {
            for c in 0..3 {
                self.input[c * plane + i] = (f32::from(px[c]) / 255.0 - MEAN[c]) / STD[c];
            }
        }
        Ok(())
    }
}
