//! C functions and types for images: the image view passed in frames, and maps built from
//! image files or pixel buffers with a progress callback.

use super::boundary::{convert_each, fill_out, optional_string, run, slice, string};
use super::error::FfiError;
use super::map::{map_handle, topoloc_map};
use super::topoloc_status;
use super::versioned::{init_versioned, read_optional, versioned};
use crate::build::{
    build_from_images, read_tum, BuildStage, ImageLayout, ImageMapOptions, ImageSource,
};
use crate::describe::onnx::OnnxOptions;
use crate::describe::vlad::{LocalFeature, VladOptions};
use crate::describe::{BackendConfig, BackendKind, FitOptions, PcaPrecision};
use crate::image::{ImageView, PixelFormat};
use crate::verify::FeatureKind;
use std::ffi::{c_char, c_void};
use std::path::Path;

/// Pixel layout of a [`topoloc_image`]: one of the `TOPOLOC_PIXEL_*` values.
pub type topoloc_pixel_format = u32;
/// Descriptor backend of map building and localizer options: one of the `TOPOLOC_BACKEND_*`
/// values.
pub type topoloc_backend = u32;
/// Stage of a long operation reported to a [`topoloc_progress_fn`]: a `TOPOLOC_STAGE_*` value.
pub type topoloc_stage = u32;

/// No image (the frame carries a descriptor only).
pub const TOPOLOC_PIXEL_NONE: topoloc_pixel_format = 0;
/// 8-bit grey, one byte per pixel.
pub const TOPOLOC_PIXEL_GRAY8: topoloc_pixel_format = 1;
/// 8-bit red, green, blue.
pub const TOPOLOC_PIXEL_RGB8: topoloc_pixel_format = 2;
/// 8-bit blue, green, red (OpenCV's `CV_8UC3` order).
pub const TOPOLOC_PIXEL_BGR8: topoloc_pixel_format = 3;
/// 8-bit red, green, blue, alpha.
pub const TOPOLOC_PIXEL_RGBA8: topoloc_pixel_format = 4;
/// 8-bit blue, green, red, alpha.
pub const TOPOLOC_PIXEL_BGRA8: topoloc_pixel_format = 5;

/// Backend choice: the map's own describer when it has one (localizer), or the ONNX backend
/// (map building).
pub const TOPOLOC_BACKEND_AUTO: topoloc_backend = 0;
/// No describer: frames must carry descriptors (localizer only).
pub const TOPOLOC_BACKEND_NONE: topoloc_backend = 1;
/// ONNX multi-level CNN features (needs ONNX Runtime and the model).
pub const TOPOLOC_BACKEND_ONNX: topoloc_backend = 2;
/// VLAD of OpenCV ORB features (no learned weights).
pub const TOPOLOC_BACKEND_VLAD_ORB: topoloc_backend = 3;
/// VLAD of OpenCV SIFT features.
pub const TOPOLOC_BACKEND_VLAD_SIFT: topoloc_backend = 4;

/// How a built map stores its PCA rows (ABI 1.14, `topoloc_image_map_options.pca_precision`).
pub type topoloc_pca_precision = u32;
/// int8 rows with one scale per row (the default): a quarter of the size of f32 rows.
pub const TOPOLOC_PCA_I8: topoloc_pca_precision = 0;
/// Exact f32 rows.
pub const TOPOLOC_PCA_F32: topoloc_pca_precision = 1;

/// Build stage reported to the progress callback: describing images (`done` of `total`).
pub const TOPOLOC_STAGE_DESCRIBING: topoloc_stage = 0;
/// Build stage reported to the progress callback: fitting PCA/codebook and assembling (0 or 1 of 1).
pub const TOPOLOC_STAGE_FITTING: topoloc_stage = 1;

/// A borrowed image: `height` rows of `stride` bytes, each starting with `width` pixels.
/// Plain data, embedded in other structs; all-zero means "no image".
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_image {
    /// First byte of the first row; read only during the call it is passed to.
    pub data: *const u8,
    /// Bytes readable at `data` (at least `stride * (height - 1) + width * channels`).
    pub data_len: usize,
    /// Width in pixels (1..8192).
    pub width: u32,
    /// Height in pixels (1..8192).
    pub height: u32,
    /// Bytes from one row to the next (>= width * channels).
    pub stride: usize,
    /// One of the `TOPOLOC_PIXEL_*` formats; `TOPOLOC_PIXEL_NONE` means no image.
    pub format: topoloc_pixel_format,
}

impl Default for topoloc_image {
    fn default() -> Self {
        Self {
            data: std::ptr::null(),
            data_len: 0,
            width: 0,
            height: 0,
            stride: 0,
            format: TOPOLOC_PIXEL_NONE,
        }
    }
}

/// Reads a C image: `None` for `TOPOLOC_PIXEL_NONE`, a validated view otherwise.
pub(crate) fn image_view<'a>(
    image: &topoloc_image,
    name: &str,
) -> Result<Option<ImageView<'a>>, FfiError> {
    let format = match image.format {
        TOPOLOC_PIXEL_NONE => return Ok(None),
        TOPOLOC_PIXEL_GRAY8 => PixelFormat::Gray8,
        TOPOLOC_PIXEL_RGB8 => PixelFormat::Rgb8,
        TOPOLOC_PIXEL_BGR8 => PixelFormat::Bgr8,
        TOPOLOC_PIXEL_RGBA8 => PixelFormat::Rgba8,
        TOPOLOC_PIXEL_BGRA8 => PixelFormat::Bgra8,
        other => {
            return Err(FfiError::new(
                topoloc_status::TOPOLOC_ERR_INVALID_IMAGE,
                format!("'{name}.format' is {other}, not a TOPOLOC_PIXEL_* format"),
            ))
        }
    };
    if image.data_len == 0 {
        return Err(FfiError::new(
            topoloc_status::TOPOLOC_ERR_INVALID_IMAGE,
            format!("'{name}.data_len' is 0"),
        ));
    }
    let data = slice(image.data, image.data_len, &format!("{name}.data"))?;
    let view = ImageView {
        width: image.width,
        height: image.height,
        stride: image.stride,
        format,
        data,
    };
    view.validate().map_err(|e| {
        FfiError::new(
            topoloc_status::TOPOLOC_ERR_INVALID_IMAGE,
            format!("{name}: {e}"),
        )
    })?;
    Ok(Some(view))
}

/// Progress of a long operation: `stage` is a `TOPOLOC_STAGE_*` value, `done` of `total` units.
/// Called on the thread that called the building function, about ten times a second. Return
/// `true` to go on, `false` to cancel (the function then returns `TOPOLOC_ERR_CANCELLED`).
/// The callback must return normally: it must not unwind (a C++ exception, a Rust panic) or
/// `longjmp` through topoloc, which would skip its clean-up and leave the process undefined;
/// catch inside the callback and return `false` instead.
pub type topoloc_progress_fn = Option<
    unsafe extern "C" fn(
        user_data: *mut c_void,
        stage: topoloc_stage,
        done: usize,
        total: usize,
    ) -> bool,
>;

/// How `topoloc_map_build_from_image_files` / `_from_images` build a map. Initialise with
/// `topoloc_image_map_options_default`.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_image_map_options {
    /// `sizeof(topoloc_image_map_options)`, set by the `_default` function.
    pub struct_size: usize,
    /// `TOPOLOC_BACKEND_ONNX` (also for `_AUTO`, the default), `_VLAD_ORB` or `_VLAD_SIFT`.
    pub backend: topoloc_backend,
    /// Descriptor dimension D; with fewer than D + 1 images it becomes the number of images
    /// minus one (`topoloc_map_dim` tells).
    pub dim: u32,
    /// Without poses: consecutive images per place (1, or 4 for yaw views); with poses: most
    /// views per place.
    pub views_per_place: u32,
    /// Describing threads; 0 = one per core (beyond the range: `TOPOLOC_ERR_INVALID_ARGUMENT`).
    /// They are joined before the build returns.
    pub threads: u32,
    /// ONNX model file; NULL or "" = the cache's default (scripts/setup-models.sh).
    pub onnx_model_path: *const c_char,
    /// ONNX Runtime library; NULL or "" = `TOPOLOC_ORT_LIBRARY`, `ORT_DYLIB_PATH`, the cache.
    pub onnx_runtime_path: *const c_char,
    /// ONNX outputs to pool, comma-separated; NULL or "" = "f6,f13,f17,f18".
    pub onnx_taps: *const c_char,
    /// ONNX pooling grid rows and columns (1 = global pooling).
    pub grid_rows: u32,
    /// See `grid_rows`.
    pub grid_cols: u32,
    /// VLAD codebook size.
    pub vlad_clusters: u32,
    /// VLAD keypoints on a dense grid (true, default) or detected by ORB/SIFT (false).
    pub vlad_dense: bool,
    /// TUM trajectory with one pose per image (same order); NULL or "" = none (a sequence map).
    pub poses_tum_path: *const c_char,
    /// Place spacing in metres when poses are given.
    pub place_spacing_m: f64,
    /// (ABI 1.14) How the map stores its PCA rows: `TOPOLOC_PCA_I8` (default; map format 1.5,
    /// which readers before it refuse) or `TOPOLOC_PCA_F32` (exact, four times larger).
    pub pca_precision: topoloc_pca_precision,
    // ABI 1.15 (topoloc 0.1): local features.
    /// Keypoints stored per view for geometric verification and loop hints (0: none).
    pub verification_keypoints: u32,
    /// Which local features those keypoints are: a `TOPOLOC_LOCAL_FEATURES_*` value; XFeat by
    /// default (its model from `xfeat_model_path`), `_CELLS` needs the ONNX backend.
    pub local_features: topoloc_local_features,
    /// XFeat model file, when `local_features` is XFeat; NULL or "" = the cache's export
    /// (scripts/setup-models.sh). A missing model fails the build with
    /// `TOPOLOC_ERR_BACKEND_UNAVAILABLE`.
    pub xfeat_model_path: *const c_char,
}

/// Local features: which keypoints a map stores or a keyframe describer extracts.
pub type topoloc_local_features = u32;
/// ORB (OpenCV), 32-byte binary descriptors.
pub const TOPOLOC_LOCAL_FEATURES_ORB: topoloc_local_features = 1;
/// XFeat (ONNX Runtime, the cache's export), 64-byte learned descriptors.
pub const TOPOLOC_LOCAL_FEATURES_XFEAT: topoloc_local_features = 2;
/// Dense cells of the describer's CNN, from the same forward pass (ONNX backend).
pub const TOPOLOC_LOCAL_FEATURES_CELLS: topoloc_local_features = 3;

/// The feature kind a C code names.
pub(crate) fn feature_kind(
    code: topoloc_local_features,
    field: &str,
) -> Result<FeatureKind, FfiError> {
    match code {
        TOPOLOC_LOCAL_FEATURES_ORB => Ok(FeatureKind::Orb),
        TOPOLOC_LOCAL_FEATURES_XFEAT => Ok(FeatureKind::XFeat),
        TOPOLOC_LOCAL_FEATURES_CELLS => Ok(FeatureKind::Cells),
        other => Err(FfiError::invalid_option(format!(
            "{field} is {other}, not a TOPOLOC_LOCAL_FEATURES_* value"
        ))),
    }
}

/// The C code of a feature kind.
pub(crate) fn feature_code(kind: FeatureKind) -> topoloc_local_features {
    match kind {
        FeatureKind::Orb => TOPOLOC_LOCAL_FEATURES_ORB,
        FeatureKind::XFeat => TOPOLOC_LOCAL_FEATURES_XFEAT,
        FeatureKind::Cells => TOPOLOC_LOCAL_FEATURES_CELLS,
    }
}

// ABI 1.0 to 1.13 ended before `pca_precision`, ABI 1.14 before `verification_keypoints`.
versioned! {
    topoloc_image_map_options [pca_precision, verification_keypoints] {
        let onnx = OnnxOptions::default();
        Self {
            backend: TOPOLOC_BACKEND_AUTO,
            dim: FitOptions::default().dim as u32,
            views_per_place: 1,
            threads: 0,
            onnx_model_path: std::ptr::null(),
            onnx_runtime_path: std::ptr::null(),
            onnx_taps: std::ptr::null(),
            grid_rows: onnx.grid.0 as u32,
            grid_cols: onnx.grid.1 as u32,
            vlad_clusters: VladOptions::default().clusters as u32,
            vlad_dense: VladOptions::default().dense,
            poses_tum_path: std::ptr::null(),
            place_spacing_m: 2.0,
            pca_precision: TOPOLOC_PCA_I8,
            verification_keypoints: ImageMapOptions::default().keypoints as u32,
            local_features: feature_code(ImageMapOptions::default().features),
            xfeat_model_path: std::ptr::null(),
        }
    }
}

/// Fills the first `size` bytes of `*options` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_image_map_options_default(options)`.
#[no_mangle]
pub extern "C" fn topoloc_image_map_options_init(
    options: *mut topoloc_image_map_options,
    size: usize,
) -> topoloc_status {
    init_versioned(options, size, "options")
}

/// The descriptor family a C backend code requires, if it names one precisely.
pub(crate) fn backend_family(code: topoloc_backend) -> Option<&'static str> {
    match code {
        TOPOLOC_BACKEND_ONNX => Some("onnx-mlf"),
        TOPOLOC_BACKEND_VLAD_ORB => Some("vlad-orb"),
        TOPOLOC_BACKEND_VLAD_SIFT => Some("vlad-sift"),
        _ => None,
    }
}

/// The backend kind a C backend code names (`_AUTO` maps to `default`).
pub(crate) fn backend_kind(
    code: topoloc_backend,
    default: Option<BackendKind>,
) -> Result<Option<BackendKind>, FfiError> {
    match code {
        TOPOLOC_BACKEND_AUTO => Ok(default),
        TOPOLOC_BACKEND_NONE => Ok(None),
        TOPOLOC_BACKEND_ONNX => Ok(Some(BackendKind::Onnx)),
        TOPOLOC_BACKEND_VLAD_ORB | TOPOLOC_BACKEND_VLAD_SIFT => Ok(Some(BackendKind::Vlad)),
        other => Err(FfiError::invalid_option(format!(
            "backend {other} is not a TOPOLOC_BACKEND_* value"
        ))),
    }
}

fn image_map_options(
    options: *const topoloc_image_map_options,
) -> Result<(ImageMapOptions, Option<String>), FfiError> {
    let o = read_optional(options, "options")?;
    let backend = match o.backend {
        TOPOLOC_BACKEND_AUTO | TOPOLOC_BACKEND_ONNX => {
            let mut onnx = OnnxOptions {
                runtime: optional_string(o.onnx_runtime_path, "options.onnx_runtime_path")?
                    .map(Into::into),
                model: optional_string(o.onnx_model_path, "options.onnx_model_path")?
                    .map(Into::into),
                grid: (o.grid_rows as usize, o.grid_cols as usize),
                ..OnnxOptions::default()
            };
            if let Some(taps) = optional_string(o.onnx_taps, "options.onnx_taps")? {
                onnx.taps = taps.split(',').map(|t| t.trim().to_string()).collect();
            }
            BackendConfig::Onnx(onnx)
        }
        TOPOLOC_BACKEND_VLAD_ORB | TOPOLOC_BACKEND_VLAD_SIFT => BackendConfig::Vlad(VladOptions {
            feature: if o.backend == TOPOLOC_BACKEND_VLAD_ORB {
                LocalFeature::Orb
            } else {
                LocalFeature::Sift
            },
            clusters: o.vlad_clusters as usize,
            dense: o.vlad_dense,
            ..VladOptions::default()
        }),
        other => {
            return Err(FfiError::invalid(format!(
                "options.backend is {other}: use TOPOLOC_BACKEND_ONNX, _VLAD_ORB or _VLAD_SIFT"
            )))
        }
    };
    let pca_precision = match o.pca_precision {
        TOPOLOC_PCA_I8 => PcaPrecision::I8,
        TOPOLOC_PCA_F32 => PcaPrecision::F32,
        other => {
            return Err(FfiError::invalid(format!(
                "options.pca_precision is {other}: use TOPOLOC_PCA_I8 or TOPOLOC_PCA_F32"
            )))
        }
    };
    let mut built = ImageMapOptions {
        backend,
        fit: FitOptions {
            dim: o.dim as usize,
            pca_precision,
            ..FitOptions::default()
        },
        views_per_place: o.views_per_place as usize,
        threads: o.threads as usize,
        keypoints: o.verification_keypoints as usize,
        features: feature_kind(o.local_features, "options.local_features")?,
        ..ImageMapOptions::default()
    };
    built.xfeat.model =
        optional_string(o.xfeat_model_path, "options.xfeat_model_path")?.map(Into::into);
    built.keyframes.place_spacing_m = o.place_spacing_m;
    built.keyframes.neighbour_radius_m = 1.5 * o.place_spacing_m;
    let poses = optional_string(o.poses_tum_path, "options.poses_tum_path")?;
    Ok((built, poses))
}

/// Shared body of the two building functions.
fn build(
    sources: &[ImageSource<'_>],
    options: *const topoloc_image_map_options,
    progress: topoloc_progress_fn,
    user_data: *mut c_void,
    out: *mut *mut topoloc_map,
) -> Result<(), FfiError> {
    fill_out(out, "out", || {
        let (options, poses_path) = image_map_options(options)?;
        let poses = match poses_path {
            Some(path) => Some(
                read_tum(Path::new(&path))?
                    .into_iter()
                    .map(|p| p.world_t_camera)
                    .collect::<Vec<_>>(),
            ),
            None => None,
        };
        let mut report = |stage: BuildStage, done: usize, total: usize| match progress {
            // SAFETY: the caller passes a valid callback and its user data.
            Some(callback) => unsafe {
                callback(
                    user_data,
                    match stage {
                        BuildStage::Describing => TOPOLOC_STAGE_DESCRIBING,
                        BuildStage::Fitting => TOPOLOC_STAGE_FITTING,
                    },
                    done,
                    total,
                )
            },
            None => true,
        };
        let (map, _) = build_from_images(
            sources,
            poses
                .as_deref()
                .map_or(ImageLayout::Sequence, ImageLayout::Keyframes),
            &options,
            &mut report,
        )?;
        Ok(map_handle(map))
    })
}

/// Builds a map from `count` image files (any format OpenCV reads), describing them in
/// parallel; the map stores its describer, so localizers on it accept image frames. Views
/// record their image's index (as keyframe id) and path. `options` may be NULL for defaults
/// (ONNX backend); `progress` may be NULL. On success `*out` owns a new map.
/// Errors: `_INVALID_ARGUMENT` (fewer than 2 images, bad options, pose count), `_INVALID_IMAGE` (an
/// unreadable file; the message names it), `_BACKEND_UNAVAILABLE`, `_MODEL`, `_IO` (poses file),
/// `_CANCELLED`.
#[no_mangle]
pub extern "C" fn topoloc_map_build_from_image_files(
    paths: *const *const c_char,
    count: usize,
    options: *const topoloc_image_map_options,
    progress: topoloc_progress_fn,
    user_data: *mut c_void,
    out: *mut *mut topoloc_map,
) -> topoloc_status {
    run(|| {
        let sources = convert_each(slice(paths, count, "paths")?, "paths", |&path, name| {
            Ok(ImageSource::File(Path::new(string(path, name)?)))
        })?;
        build(&sources, options, progress, user_data, out)
    })
}

/// Builds a map from `count` images in memory (see `topoloc_map_build_from_image_files`; the
/// views have no path). The pixels are only read during the call.
/// Errors: as `topoloc_map_build_from_image_files`, with `_INVALID_IMAGE` for a bad buffer.
#[no_mangle]
pub extern "C" fn topoloc_map_build_from_images(
    images: *const topoloc_image,
    count: usize,
    options: *const topoloc_image_map_options,
    progress: topoloc_progress_fn,
    user_data: *mut c_void,
    out: *mut *mut topoloc_map,
) -> topoloc_status {
    run(|| {
        let sources = convert_each(slice(images, count, "images")?, "images", |image, name| {
            image_view(image, name)?
                .map(ImageSource::Pixels)
                .ok_or_else(|| {
                    FfiError::new(
                        topoloc_status::TOPOLOC_ERR_INVALID_IMAGE,
                        format!("{name} has format TOPOLOC_PIXEL_NONE"),
                    )
                })
        })?;
        build(&sources, options, progress, user_data, out)
    })
}
