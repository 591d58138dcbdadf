//! The ONNX backend: a CNN run by ONNX Runtime (loaded at run time, so the library works without
//! it until an ONNX model is asked for), whose selected feature maps become a multi-level vector.

use super::mlf::{multi_level, FeatureMap};
use crate::errors::VisionError;
use crate::image::ImageView;
use opencv::core::Size;
use opencv::prelude::*;
use ort::session::Session;
use ort::value::TensorRef;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

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

/// The cache folder of set-up files: `TOPOLOC_CACHE`, else `~/.cache/topoloc`.
pub fn cache_dir() -> PathBuf {
    std::env::var_os("TOPOLOC_CACHE")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(std::env::var_os("HOME").unwrap_or_default()).join(".cache/topoloc")
        })
}

/// Candidate paths of the ONNX Runtime library, in the order they are tried. A configured path
/// (the option, else `TOPOLOC_ORT_LIBRARY`, else `ORT_DYLIB_PATH`) is the only candidate: asking
/// for a library and silently getting another would hide a set-up mistake. Without one, the
/// libraries `scripts/setup-models.sh` put in the cache are tried.
fn runtime_candidates(explicit: Option<&Path>) -> Vec<PathBuf> {
    if let Some(path) = configured_runtime(explicit) {
        return vec![path];
    }
    let dir = cache_dir().join("onnxruntime");
    let mut cached: Vec<PathBuf> = std::fs::read_dir(&dir)
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("libonnxruntime.so"))
        })
        .collect();
    cached.sort();
    if cached.is_empty() {
        cached.push(dir.join("libonnxruntime.so.<version>"));
    }
    cached
}

/// The runtime library the caller configured: the option, else `TOPOLOC_ORT_LIBRARY`, else
/// `ORT_DYLIB_PATH`; `None` when none is set.
fn configured_runtime(explicit: Option<&Path>) -> Option<PathBuf> {
    explicit.map(Path::to_path_buf).or_else(|| {
        ["TOPOLOC_ORT_LIBRARY", "ORT_DYLIB_PATH"]
            .iter()
            .find_map(|var| std::env::var_os(var).filter(|v| !v.is_empty()))
            .map(PathBuf::from)
    })
}

/// The ONNX Runtime loaded in this process, and from where.
struct LoadedRuntime {
    path: PathBuf,
    environment: ort::environment::Environment,
}

/// The process-wide ONNX Runtime environment. The runtime library can be loaded once per
/// process: a later request for a different configured library fails rather than silently
/// using the first. Failed loads are not remembered, so a corrected path works on retry.
fn environment(
    explicit: Option<&Path>,
) -> Result<&'static ort::environment::Environment, VisionError> {
    static RUNTIME: OnceLock<LoadedRuntime> = OnceLock::new();
    static LOADING: Mutex<()> = Mutex::new(());
    let configured = configured_runtime(explicit);
    let tried = runtime_candidates(explicit);
    let unavailable = |hint: String| VisionError::BackendUnavailable {
        what: "ONNX Runtime".into(),
        tried: tried.clone(),
        hint,
    };
    let Some(path) = tried.iter().find(|p| p.is_file()) else {
        return Err(unavailable(if configured.is_some() {
            "the configured ONNX Runtime library does not exist (option, TOPOLOC_ORT_LIBRARY or \
             ORT_DYLIB_PATH, in that order)"
                .into()
        } else {
            "run scripts/setup-models.sh, or pass the library path (option or TOPOLOC_ORT_LIBRARY)"
                .into()
        }));
    };
    let _serialised = LOADING
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    let loaded = match RUNTIME.get() {
        Some(loaded) => loaded,
        None => {
            let environment = ort::init_from(path)
                .map_err(|e| unavailable(format!("loading {}: {e}", path.display())))?
                .build()
                .map_err(|e| {
                    unavailable(format!(
                        "creating the ONNX Runtime environment from {}: {e}",
                        path.display()
                    ))
                })?;
            RUNTIME.get_or_init(|| LoadedRuntime {
                path: path.clone(),
                environment,
            })
        }
    };
    let same_library =
        || std::fs::canonicalize(path).ok() == std::fs::canonicalize(&loaded.path).ok();
    if configured.is_none() || same_library() {
        Ok(&loaded.environment)
    } else {
        Err(unavailable(format!(
            "this process already loaded ONNX Runtime from {}; it can be loaded only once per \
             process, so {} cannot be used",
            loaded.path.display(),
            path.display()
        )))
    }
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
        super::limits::check_onnx_config(
            &options.taps,
            [options.grid.0, options.grid.1],
            [options.input_size.0, options.input_size.1],
        )?;
        let model = options
            .model
            .clone()
            .unwrap_or_else(|| cache_dir().join(DEFAULT_MODEL_FILE));
        let bytes = std::fs::read(&model).map_err(|e| VisionError::BackendUnavailable {
            what: "ONNX model".into(),
            tried: vec![model.clone()],
            hint: format!("{e}; run scripts/setup-models.sh or pass the model path"),
        })?;
        let env = environment(options.runtime.as_deref())?;
        let onnx = |e: ort::Error| VisionError::Model(format!("{}: {e}", model.display()));
        let session = Session::builder(env)
            .map_err(onnx)?
            .with_intra_threads(options.threads.max(1))
            .map_err(|e| onnx(e.into()))?
            .commit_from_memory(&bytes)
            .map_err(onnx)?;
        let outputs: Vec<&str> = session.outputs().iter().map(|o| o.name()).collect();
        if let Some(missing) = options.taps.iter().find(|t| !outputs.contains(&t.as_str())) {
            return Err(VisionError::Model(format!(
                "{} has no output '{missing}' (it has {outputs:?})",
                model.display()
            )));
        }
        let model_sha256 = format!("{:x}", Sha256::digest(&bytes));
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
        let tensor = TensorRef::from_array_view((
            [1usize, 3, h as usize, w as usize],
            self.input.as_slice(),
        ))
        .map_err(|e| VisionError::Model(e.to_string()))?;
        let outputs = self
            .session
            .run(ort::inputs!["input" => tensor])
            .map_err(|e| VisionError::Model(e.to_string()))?;
        let mut levels = Vec::with_capacity(self.options.taps.len());
        for tap in &self.options.taps {
            let (shape, values) = outputs[tap.as_str()]
                .try_extract_tensor::<f32>()
                .map_err(|e| VisionError::Model(e.to_string()))?;
            if shape.len() != 4 || shape[0] != 1 {
                return Err(VisionError::Model(format!(
                    "output '{tap}' has shape {shape:?}, expected [1, C, H, W]"
                )));
            }
            levels.push((
                shape[1] as usize,
                shape[2] as usize,
                shape[3] as usize,
                values,
            ));
        }
        let maps: Vec<FeatureMap> = levels
            .iter()
            .map(|&(channels, height, width, values)| FeatureMap {
                channels,
                height,
                width,
                values,
            })
            .collect();
        Ok(multi_level(&maps, self.options.grid.0, self.options.grid.1))
    }
}
