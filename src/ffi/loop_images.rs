//! C functions of image keyframes (ABI 1.15): a keyframe describer gives a keyframe image's
//! global descriptor and its local features in one pass (`loops::KeyframeDescriber`), so a
//! host that has images, not its own keypoints, reaches the verification that refuses
//! look-alikes; and the ranked candidates of the last keyframe, for hosts that run their own
//! check.

use super::boundary::{check_out, optional_string, run, slice, write_array};
use super::convert::optional_pose;
use super::describer::map_describer;
use super::error::FfiError;
use super::handles::{
    castable, enter, free_exclusive, handle_value, new_exclusive, run_on, Opaque,
};
use super::images::{
    feature_code, feature_kind, image_view, topoloc_backend, topoloc_image, topoloc_local_features,
    TOPOLOC_BACKEND_AUTO,
};
use super::loops::{c_hint_of, topoloc_loop_detector, topoloc_loop_hint, topoloc_loop_keyframe};
use super::map::{new_on_map, topoloc_map};
use super::topoloc_status;
use super::versioned::{
    check_versioned, init_versioned, read_versioned, versioned, write_versioned,
};
use crate::loops::{KeyframeDescriber, KeyframeEntry, LoopHint, DEFAULT_LOOP_FEATURES};
use crate::verify::{camera_points_from_depth, DepthImage, XFeatOptions, DEFAULT_XFEAT_MAX_PIXELS};
use std::ffi::c_char;

/// Describes keyframe images for a loop detector: a map's describer (the global descriptor)
/// and local features of one kind. Created by `topoloc_keyframe_describer_new`, released by
/// `topoloc_keyframe_describer_free`; it does not keep the map alive. Single-threaded state:
/// one thread at a time (it may move between threads); a call made while another uses it fails
/// with `TOPOLOC_ERR_CONCURRENT_USE` and changes nothing.
pub struct topoloc_keyframe_describer(Opaque);

castable!(topoloc_keyframe_describer: OwnedExclusive => KeyframeDescriber);

/// How a keyframe describer is made. Initialise with
/// `topoloc_keyframe_describer_options_default`.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_keyframe_describer_options {
    /// `sizeof(topoloc_keyframe_describer_options)`, set by the `_default` function.
    pub struct_size: usize,
    /// Local features: `TOPOLOC_LOCAL_FEATURES_XFEAT` (default: its hints carry a pose where
    /// intrinsics are given; BENCHMARKS.md says which data chose it), `_ORB`, or `_CELLS`
    /// (the describer's own CNN pass; no pose). A detector reloaded from a map takes the map's
    /// kind: give the same here.
    pub local_features: topoloc_local_features,
    /// `TOPOLOC_BACKEND_AUTO` (default) accepts the map's backend; `_ONNX` or `_VLAD_*`
    /// require it (else `_DESCRIPTOR_MISMATCH`); `_NONE` is `_INVALID_OPTION`.
    pub backend: topoloc_backend,
    /// ONNX model file; NULL or "" = the cache's default. Must be the map's model (by hash).
    pub onnx_model_path: *const c_char,
    /// ONNX Runtime library; NULL or "" = `TOPOLOC_ORT_LIBRARY`, `ORT_DYLIB_PATH`, the cache.
    pub onnx_runtime_path: *const c_char,
    /// XFeat model file; NULL or "" = the cache's export (scripts/setup-models.sh).
    pub xfeat_model_path: *const c_char,
    /// XFeat: largest network input in pixels; larger images are scaled down first. 0 = the
    /// image's own size up to 4,194,304 (2048 x 2048, the most XFeat ever runs on); otherwise
    /// 16,384 to 4,194,304, else `_INVALID_OPTION`.
    pub xfeat_max_pixels: u32,
    /// ONNX Runtime intra-op threads of each network.
    pub threads: u32,
}

versioned! {
    topoloc_keyframe_describer_options {
        Self {
            local_features: feature_code(DEFAULT_LOOP_FEATURES),
            backend: TOPOLOC_BACKEND_AUTO,
            onnx_model_path: std::ptr::null(),
            onnx_runtime_path: std::ptr::null(),
            xfeat_model_path: std::ptr::null(),
            xfeat_max_pixels: DEFAULT_XFEAT_MAX_PIXELS,
            threads: 1,
        }
    }
}

/// Fills the first `size` bytes of `*options` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_keyframe_describer_options_default(options)`, which
/// passes `sizeof *(options)`.
#[no_mangle]
pub extern "C" fn topoloc_keyframe_describer_options_init(
    options: *mut topoloc_keyframe_describer_options,
    size: usize,
) -> topoloc_status {
    init_versioned(options, size, "options")
}

/// Loads the describer `map` stores and the local features `options` name (for XFeat: its
/// network). `options` may be NULL for defaults. On success `*out` owns a new keyframe
/// describer.
/// Errors: `_NO_DESCRIBER` (the map was built from descriptors), `_BACKEND_UNAVAILABLE` (a
/// missing runtime or model: the message names the paths tried and what to install),
/// `_DESCRIPTOR_MISMATCH`, `_MODEL` (a file that is not the expected network),
/// `_INVALID_OPTION` (an unknown local-features or backend value, threads or xfeat_max_pixels out of range, cells
/// on a VLAD map).
#[no_mangle]
pub extern "C" fn topoloc_keyframe_describer_new(
    map: *const topoloc_map,
    options: *const topoloc_keyframe_describer_options,
    out: *mut *mut topoloc_keyframe_describer,
) -> topoloc_status {
    new_on_map(
        map,
        options,
        out,
        |map, o: topoloc_keyframe_describer_options| {
            let kind = feature_kind(o.local_features, "options.local_features")?;
            let (describer, options) = map_describer(
                &map,
                o.backend,
                o.onnx_model_path,
                o.onnx_runtime_path,
                o.threads,
            )?;
            let xfeat = XFeatOptions {
                runtime: options.onnx_runtime.clone(),
                model: optional_string(o.xfeat_model_path, "options.xfeat_model_path")?
                    .map(Into::into),
                threads: o.threads as usize,
                max_pixels: o.xfeat_max_pixels,
            };
            xfeat
                .validate()
                .map_err(|e| FfiError::invalid_option(format!("options.xfeat_max_pixels: {e}")))?;
            let keyframes = KeyframeDescriber::new(describer, kind, &xfeat)?;
            Ok(new_exclusive::<topoloc_keyframe_describer>(keyframes))
        },
    )
}

/// Releases a keyframe describer; NULL is a no-op.
#[no_mangle]
pub extern "C" fn topoloc_keyframe_describer_free(describer: *mut topoloc_keyframe_describer) {
    free_exclusive(describer)
}

/// The local features a keyframe describer extracts (`*out`, a `TOPOLOC_LOCAL_FEATURES_*`
/// value).
#[no_mangle]
pub extern "C" fn topoloc_keyframe_describer_local_features(
    describer: *const topoloc_keyframe_describer,
    out: *mut topoloc_local_features,
) -> topoloc_status {
    handle_value(describer, "describer", out, "out", |d| {
        feature_code(d.kind())
    })
}

/// A keyframe's depth image, registered to its image (same size): `width * height` row-major
/// values, `units_per_metre` of them per metre (1000 for millimetres, 5000 for TUM RGB-D), 0 =
/// no depth. Plain data, read only during the call it is passed to.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_depth_image {
    /// First value of the first row (NULL = no depth).
    pub values: *const u16,
    /// Values at `values`: `width * height` of the image.
    pub values_len: usize,
    /// Depth units per metre (> 0).
    pub units_per_metre: f64,
}

/// Adds a keyframe given as an image: `describer` gives its global descriptor and local
/// features in one pass, then it is verified and gated as `topoloc_loop_detector_add` does.
/// `keyframe` gives the id, timestamp and poses; its descriptor and keypoint fields must be
/// empty (NULL, 0). `depth` may be NULL; with one, the detector's options must have
/// intrinsics, and each keypoint gets its scene point (later hints matched to this keyframe
/// are metric). `*hint` receives the best verified candidate (as `_add`). On any error the
/// detector, the describer's state and `*hint` are unchanged.
/// Errors: those of `topoloc_loop_detector_add`; `_INVALID_IMAGE` (a bad image buffer);
/// `_INVALID_ARGUMENT` (descriptor or keypoints given, a depth image of another size than the
/// image, local features of another kind than earlier keyframes'); `_INVALID_OPTION` (depth
/// without intrinsics); `_DIMENSION_MISMATCH` (a describer of another map than the detector's
/// descriptors).
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_add_image(
    detector: *mut topoloc_loop_detector,
    describer: *mut topoloc_keyframe_describer,
    keyframe: *const topoloc_loop_keyframe,
    image: *const topoloc_image,
    depth: *const topoloc_depth_image,
    hint: *mut topoloc_loop_hint,
) -> topoloc_status {
    run(|| {
        let mut detector = enter(detector, "detector")?;
        let mut describer = enter(describer, "describer")?;
        let k = read_versioned(keyframe, "keyframe")?;
        check_versioned(hint, "hint")?;
        if !k.descriptor.is_null()
            || k.descriptor_len != 0
            || k.keypoint_count != 0
            || !k.keypoints.is_null()
            || !k.keypoint_descriptors.is_null()
            || !k.camera_points.is_null()
        {
            return Err(FfiError::invalid(
                "an image keyframe's descriptor, keypoints and scene points come from the image: leave keyframe.descriptor, keypoints, keypoint_descriptors and camera_points empty",
            ));
        }
        // SAFETY: a non-NULL image is a valid topoloc_image for the call (C contract).
        let image = unsafe { image.as_ref() }.ok_or_else(|| FfiError::null("image"))?;
        let view = image_view(image, "image")?.ok_or_else(|| {
            FfiError::new(
                topoloc_status::TOPOLOC_ERR_INVALID_IMAGE,
                "image has format TOPOLOC_PIXEL_NONE",
            )
        })?;
        // SAFETY: a non-NULL depth is a valid topoloc_depth_image for the call (C contract).
        let depth = unsafe { depth.as_ref() }.filter(|d| !d.values.is_null());
        if depth.is_some() && detector.options().camera.is_none() {
            return Err(FfiError::invalid_option(
                "a depth image needs the camera intrinsics in the detector's options (fx, fy, cx, cy)",
            ));
        }
        let mut descriptor = Vec::new();
        let mut features = describer.describe(&view, &mut descriptor)?;
        if let (Some(d), Some(camera)) = (depth, detector.options().camera) {
            let pixels = view.width as usize * view.height as usize;
            if d.values_len != pixels {
                return Err(FfiError::invalid(format!(
                    "depth.values_len is {}, the {}x{} image needs {pixels}",
                    d.values_len, view.width, view.height
                )));
            }
            let values = slice(d.values, d.values_len, "depth.values")?;
            let depth = DepthImage {
                width: view.width,
                height: view.height,
                values,
                units_per_metre: d.units_per_metre,
            };
            features.camera_points = Some(camera_points_from_depth(
                &features.keypoints.points,
                &depth,
                &camera,
            )?);
        }
        let entry = KeyframeEntry {
            id: k.id,
            timestamp: k.timestamp,
            descriptor: &descriptor,
            world_t_body: optional_pose(k.world_T_body, "keyframe.world_T_body")?,
            body_t_camera: optional_pose(k.body_T_camera, "keyframe.body_T_camera")?,
        };
        let done = detector.process(&entry, features)?;
        let best: Option<&LoopHint> = done.hint.as_ref();
        write_versioned(hint, c_hint_of(k.id, done.added.place, best), "hint")
    })
}

/// One verified loop candidate of a keyframe. Array element: its layout never changes.
#[repr(C)]
#[derive(Clone, Copy, Default)]
pub struct topoloc_loop_candidate_check {
    /// The candidate keyframe's id.
    pub keyframe_id: u64,
    /// Its place.
    pub place: u32,
    /// Cosine similarity of the keyframe's global descriptor to the candidate's.
    pub similarity: f32,
    /// Fundamental-matrix inliers of the pair check.
    pub inliers: u32,
    /// Its share of the inliers of every verified candidate of the keyframe (0..=1).
    pub confidence: f32,
}

/// The loop candidates the last successful `topoloc_loop_detector_add` or `_add_image`
/// verified, most inliers first (accepted or not; keyframes erased since are left out; a
/// candidate that refinement swapped for a neighbouring keyframe with more inliers is listed
/// as that keyframe, so the hint's matched keyframe is always here), into
/// the caller's array `(out, capacity)`; `*count` receives how many were written (at most
/// `capacity`). For hosts that run their own check on several candidates (ORB-SLAM3 takes 3
/// loop and 3 merge candidates).
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_candidates(
    detector: *const topoloc_loop_detector,
    out: *mut topoloc_loop_candidate_check,
    capacity: usize,
    count: *mut usize,
) -> topoloc_status {
    run_on(detector, "detector", |detector| {
        check_out(count, "count")?;
        let found: Vec<topoloc_loop_candidate_check> = detector
            .candidates()
            .take(capacity)
            .map(|c| topoloc_loop_candidate_check {
                keyframe_id: c.id,
                place: c.place,
                similarity: c.similarity,
                inliers: c.inliers,
                confidence: c.confidence,
            })
            .collect();
        write_array(&found, out, capacity, count)
    })
}
