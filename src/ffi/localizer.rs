//! C functions of the localizer: create, process a frame, reset, free.

use super::boundary::{optional_string, slice};
use super::convert::{expected_descriptor, optional_camera, optional_pose, pose_to_row_major};
use super::describer::describer_options;
use super::error::FfiError;
use super::handles::{castable, free_exclusive, new_exclusive, run_on_mut, Opaque};
use super::images::{
    backend_kind, image_view, topoloc_backend, topoloc_image, TOPOLOC_BACKEND_AUTO,
    TOPOLOC_BACKEND_NONE,
};
use super::map::{new_on_map, topoloc_map};
use super::topoloc_status;
use super::versioned::{init_versioned, read_versioned, versioned, write_versioned};
use crate::localize::{
    Frame, GrnnOptions, Localization, Localizer, LocalizerOptions, MetricOptions, Mode,
};
use crate::verify::{LocateOptions, VerificationOptions};
use nalgebra::Isometry3;
use std::ffi::c_char;

/// How a localizer estimates the place: one of the `TOPOLOC_MODE_*` values.
pub type topoloc_mode = u32;

/// Filter mode: forward filter over the graph (default).
pub const TOPOLOC_MODE_FILTER: topoloc_mode = 0;
/// Single-frame mode: every frame judged on its own.
pub const TOPOLOC_MODE_SINGLE_FRAME: topoloc_mode = 1;
/// Metric mode (ABI 1.3): Monte Carlo localization of the camera pose in the map frame, moved
/// by the frames' odometry and weighed by appearance; the place is the one nearest to the
/// particles. Needs a map with every place's position and every view's pose.
pub const TOPOLOC_MODE_METRIC: topoloc_mode = 2;
/// Learned mode (ABI 1.16): the seed's graph recurrent network (GRNN) run through ONNX Runtime
/// on a window of the map's views; the model is `grnn_model_path`'s, or the one built into the
/// library. Needs ONNX Runtime (`onnx_runtime_path`, else `TOPOLOC_ORT_LIBRARY`, the cache; else
/// `_BACKEND_UNAVAILABLE`) and a map with edges (else `_INVALID_OPTION`); a model file that is
/// not ONNX or breaks the contract is `_MODEL`. Odometry is not used.
pub const TOPOLOC_MODE_GRNN: topoloc_mode = 3;

/// Follows one camera through a map. Created by `topoloc_localizer_new`, released by
/// `topoloc_localizer_free`. Holds per-camera state: use it from one thread at a time (it may
/// move between threads). It keeps its own reference to the map. A call made while another call uses it
/// (another thread, or a callback re-entering it) fails with `TOPOLOC_ERR_CONCURRENT_USE` and
/// changes nothing (ABI 1.13).
pub struct topoloc_localizer(Opaque);

/// What a localizer handle owns: the localizer and the result buffer its frames reuse.
pub(crate) struct LocalizerState {
    localizer: Localizer,
    scratch: Localization,
}

castable!(topoloc_localizer: OwnedExclusive => LocalizerState);

/// Localizer parameters. Initialise with `topoloc_localizer_options_default`; the defaults and
/// meaning of each field are those of the Rust `LocalizerOptions`.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_localizer_options {
    /// `sizeof(topoloc_localizer_options)`, set by the `_default` function.
    pub struct_size: usize,
    /// `TOPOLOC_MODE_FILTER`, `TOPOLOC_MODE_SINGLE_FRAME`, (ABI 1.3) `TOPOLOC_MODE_METRIC`
    /// (on a map without positions or view poses: `_INVALID_OPTION`) or (ABI 1.16)
    /// `TOPOLOC_MODE_GRNN`.
    pub mode: topoloc_mode,
    /// Softmax temperature of the observation likelihood.
    pub temperature: f32,
    /// Probability that the off-map state persists from one frame to the next.
    pub stay_probability: f32,
    /// Probability of a jump anywhere per frame (kidnap recovery).
    pub jump_probability: f32,
    /// Probability of entering the off-map state per frame; 0 disables off-map.
    pub off_map_probability: f32,
    /// Absolute floor of the off-map hypothesis' score (cosine similarity).
    pub off_map_similarity: f32,
    /// Standard deviations above the expected best background score a place must reach to
    /// beat the off-map hypothesis (may be negative).
    pub off_map_margin: f32,
    /// Candidates reported per frame.
    pub top_k: u32,
    /// Refuse maps built with another descriptor kind; NULL or "" = any.
    pub expected_descriptor_kind: *const c_char,
    /// Refuse maps built with another descriptor model; NULL or "" = any.
    pub expected_descriptor_model: *const c_char,
    // ABI 1.1 (topoloc 0.1): images.
    /// Describing image frames: `TOPOLOC_BACKEND_AUTO` (default) loads the map's describer when
    /// the map has one; `_NONE` never (descriptor frames only, no runtime needed); `_ONNX` or
    /// `_VLAD_*` also require the map to use that backend (else `_DESCRIPTOR_MISMATCH`).
    pub image_backend: topoloc_backend,
    /// ONNX model file; NULL or "" = the cache's default. Must be the map's model (by hash).
    pub onnx_model_path: *const c_char,
    /// ONNX Runtime library; NULL or "" = `TOPOLOC_ORT_LIBRARY`, `ORT_DYLIB_PATH`, the cache.
    pub onnx_runtime_path: *const c_char,
    // ABI 1.2 (topoloc 0.1): geometric verification.
    /// Most probable places verified geometrically per frame against the frame's image
    /// (matches of the local features the map stores, ORB, XFeat or dense cells, and a RANSAC
    /// geometric model; the result's `verified` / `inliers`). 0 = off (default). Needs a
    /// map storing keypoints (maps built from images do; else `_INVALID_OPTION`) and frames
    /// with images (else `_INVALID_IMAGE`). Costs a pair check per view checked (BENCHMARKS.md).
    pub verify_candidates: u32,
    /// Views checked per candidate place, those most similar to the frame.
    pub verify_views_per_candidate: u32,
    /// Log-likelihood of one inlier: a checked place's belief is multiplied by
    /// `exp(verify_inlier_weight * inliers)`.
    pub verify_inlier_weight: f32,
    // ABI 1.3 (topoloc 0.1): metric mode.
    /// Particles of `TOPOLOC_MODE_METRIC`.
    pub metric_particles: u32,
    /// Temperature of a particle's appearance likelihood in metric mode.
    pub metric_temperature: f32,
    /// Seed of metric mode's random generator (results are deterministic).
    pub metric_seed: u64,
    // ABI 1.6 (topoloc 0.1): pose fixes.
    /// Pinhole intrinsics of the frames' camera (undistorted images, pixels of the image as
    /// passed); `camera_fx == 0` = none (default). With them, verification on
    /// (`verify_candidates` > 0) and a map whose keypoints carry scene points
    /// (`topoloc_map_with_keypoint_points`; else `_INVALID_OPTION`), each result may carry a
    /// pose fix. Focal lengths must be finite and > 0, the principal point finite.
    pub camera_fx: f64,
    /// Focal length y, pixels.
    pub camera_fy: f64,
    /// Principal point x, pixels.
    pub camera_cx: f64,
    /// Principal point y, pixels.
    pub camera_cy: f64,
    /// Fewest PnP RANSAC inliers for a pose fix.
    pub pose_min_inliers: u32,
    // ABI 1.9 (topoloc 0.1): off-map evidence from verification.
    /// With verification on: the most inliers among the checked places at which a frame is as
    /// likely off the map as on it; the frame's off-map update then reads the inliers instead
    /// of appearance (the likelihood ratio `exp((verify_off_map_inliers - most) /
    /// verify_off_map_inlier_scale)`). Negative: the map's feature kind's default (XFeat and
    /// cells 26, ORB 0), the default -1; 0: appearance decides; NaN: `_INVALID_OPTION`.
    pub verify_off_map_inliers: f64,
    /// Inliers per e-fold of that likelihood ratio.
    pub verify_off_map_inlier_scale: f64,
    // ABI 1.16 (topoloc 0.1): the learned estimator.
    /// ONNX model of `TOPOLOC_MODE_GRNN` (written by `python/train/export.py`); NULL or "" = the
    /// model built into the library. Read when the localizer is created.
    pub grnn_model_path: *const c_char,
}

// ABI 1.0 ended before `image_backend`; 1.1 added the image fields, 1.2 verification, 1.3
// metric mode, 1.6 pose fixes, 1.9 off-map evidence from verification (its fields are 8 bytes
// wide so that the 1.6 layout, padded after `pose_min_inliers`, still ends where they start),
// 1.16 the learned estimator's model.
versioned! {
    topoloc_localizer_options [
        image_backend,
        verify_candidates,
        metric_particles,
        camera_fx,
        verify_off_map_inliers,
        grnn_model_path,
    ] {
        let d = LocalizerOptions::default();
        Self {
            mode: TOPOLOC_MODE_FILTER,
            temperature: d.temperature,
            stay_probability: d.stay_probability,
            jump_probability: d.jump_probability,
            off_map_probability: d.off_map_probability,
            off_map_similarity: d.off_map_similarity,
            off_map_margin: d.off_map_margin,
            top_k: d.top_k as u32,
            expected_descriptor_kind: std::ptr::null(),
            expected_descriptor_model: std::ptr::null(),
            image_backend: TOPOLOC_BACKEND_AUTO,
            onnx_model_path: std::ptr::null(),
            onnx_runtime_path: std::ptr::null(),
            verify_candidates: d.verification.candidates as u32,
            verify_views_per_candidate: d.verification.views_per_candidate as u32,
            verify_inlier_weight: d.verification.inlier_weight,
            metric_particles: d.metric.particles as u32,
            metric_temperature: d.metric.temperature,
            metric_seed: d.metric.seed,
            camera_fx: 0.0,
            camera_fy: 0.0,
            camera_cx: 0.0,
            camera_cy: 0.0,
            pose_min_inliers: d.verification.locate.min_inliers,
            verify_off_map_inliers: -1.0,
            verify_off_map_inlier_scale: f64::from(d.verification.off_map_inlier_scale),
            grnn_model_path: std::ptr::null(),
        }
    }
}

/// Fills the first `size` bytes of `*options` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_localizer_options_default(options)`, which passes `sizeof *(options)`.
#[no_mangle]
pub extern "C" fn topoloc_localizer_options_init(
    options: *mut topoloc_localizer_options,
    size: usize,
) -> topoloc_status {
    init_versioned(options, size, "options")
}

/// Creates a localizer on `map` (which it keeps alive; the caller may free its own handle).
/// `options` may be NULL for defaults. With `image_backend` `TOPOLOC_BACKEND_AUTO` and a map
/// built from images, the map's describer is loaded now (for ONNX: the runtime and model).
/// On success `*out` owns a new localizer.
/// Errors: `_INVALID_OPTION`, `_DESCRIPTOR_MISMATCH` (also another backend or model file than the
/// map's), `_BACKEND_UNAVAILABLE` (paths tried in the message; pass `TOPOLOC_BACKEND_NONE` to
/// localize descriptors only), `_MODEL`, `_NO_DESCRIBER` (a backend was required but the map stores
/// none).
#[no_mangle]
pub extern "C" fn topoloc_localizer_new(
    map: *const topoloc_map,
    options: *const topoloc_localizer_options,
    out: *mut *mut topoloc_localizer,
) -> topoloc_status {
    new_on_map(map, options, out, |map, o| {
        let options = localizer_options(&o)?;
        let has_describer = map.describer().is_some();
        // Unknown backend codes are refused before the map is looked at.
        backend_kind(o.image_backend, None)?;
        let localizer = match (o.image_backend, has_describer) {
            (TOPOLOC_BACKEND_NONE, _) | (TOPOLOC_BACKEND_AUTO, false) => {
                Localizer::new(map, options)?
            }
            _ => {
                let describer =
                    describer_options(o.image_backend, o.onnx_model_path, o.onnx_runtime_path, 1)?;
                Localizer::with_describer(map, options, &describer)?
            }
        };
        Ok(new_exclusive::<topoloc_localizer>(LocalizerState {
            localizer,
            scratch: Localization::default(),
        }))
    })
}

/// The Rust options a C caller's options stand for.
fn localizer_options(o: &topoloc_localizer_options) -> Result<LocalizerOptions, FfiError> {
    let mode = match o.mode {
        TOPOLOC_MODE_FILTER => Mode::Filter,
        TOPOLOC_MODE_SINGLE_FRAME => Mode::SingleFrame,
        TOPOLOC_MODE_METRIC => Mode::Metric,
        TOPOLOC_MODE_GRNN => Mode::Grnn,
        other => return Err(FfiError::invalid_option(format!("unknown mode {other}"))),
    };
    Ok(LocalizerOptions {
        mode,
        temperature: o.temperature,
        stay_probability: o.stay_probability,
        jump_probability: o.jump_probability,
        off_map_probability: o.off_map_probability,
        off_map_similarity: o.off_map_similarity,
        off_map_margin: o.off_map_margin,
        top_k: o.top_k as usize,
        expected: expected_descriptor(o.expected_descriptor_kind, o.expected_descriptor_model, 0)?,
        verification: VerificationOptions {
            candidates: o.verify_candidates as usize,
            views_per_candidate: o.verify_views_per_candidate as usize,
            inlier_weight: o.verify_inlier_weight,
            camera: optional_camera(o.camera_fx, o.camera_fy, o.camera_cx, o.camera_cy),
            locate: LocateOptions {
                min_inliers: o.pose_min_inliers,
                ..LocateOptions::default()
            },
            // Negative: the kind's default; NaN stays NaN, for validation to refuse.
            off_map_inliers: match o.verify_off_map_inliers {
                n if n < 0.0 => None,
                n => Some(n as f32),
            },
            off_map_inlier_scale: o.verify_off_map_inlier_scale as f32,
            ..VerificationOptions::default()
        },
        metric: MetricOptions {
            particles: o.metric_particles as usize,
            temperature: o.metric_temperature,
            seed: o.metric_seed,
            ..MetricOptions::default()
        },
        grnn: GrnnOptions {
            model: optional_string(o.grnn_model_path, "options.grnn_model_path")?.map(Into::into),
            runtime: optional_string(o.onnx_runtime_path, "options.onnx_runtime_path")?
                .map(Into::into),
            ..GrnnOptions::default()
        },
        // The motion model's speed classes are not in the C options yet: defaults.
        ..LocalizerOptions::default()
    })
}

/// Releases a localizer. `NULL` is a no-op.
#[no_mangle]
pub extern "C" fn topoloc_localizer_free(localizer: *mut topoloc_localizer) {
    free_exclusive(localizer)
}

/// Forgets all history; the next frame is treated as the first.
#[no_mangle]
pub extern "C" fn topoloc_localizer_reset(localizer: *mut topoloc_localizer) -> topoloc_status {
    run_on_mut(localizer, "localizer", |state| {
        state.localizer.reset();
        Ok(())
    })
}

/// One camera frame. Initialise with `topoloc_frame_default`.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_frame {
    /// `sizeof(topoloc_frame)`, set by the `_default` function.
    pub struct_size: usize,
    /// Time in seconds; must not decrease in filter mode (reset to start a new sequence).
    pub timestamp: f64,
    /// Global descriptor of the frame (normalised internally).
    pub descriptor: *const f32,
    /// Number of floats at `descriptor`; must equal the map's D.
    pub descriptor_len: usize,
    /// Motion since the previous frame `previous_T_current`, 16 doubles row-major 4x4; NULL = none.
    pub odometry: *const f64,
    // ABI 1.1 (topoloc 0.1): images.
    /// The camera image, described with the map's backend when `descriptor_len` is 0 (the
    /// localizer must have a describer). Default: no image (`TOPOLOC_PIXEL_NONE`).
    pub image: topoloc_image,
}

// ABI 1.0 ended before `image`; 1.1 added it.
versioned! {
    topoloc_frame [image] {
        Self {
            timestamp: 0.0,
            descriptor: std::ptr::null(),
            descriptor_len: 0,
            odometry: std::ptr::null(),
            image: topoloc_image::default(),
        }
    }
}

/// Fills the first `size` bytes of `*frame` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_frame_default(frame)`, which passes `sizeof *(frame)`.
#[no_mangle]
pub extern "C" fn topoloc_frame_init(frame: *mut topoloc_frame, size: usize) -> topoloc_status {
    init_versioned(frame, size, "frame")
}

/// One ranked hypothesis. Array element: its layout never changes.
#[repr(C)]
#[derive(Clone, Copy, Default)]
pub struct topoloc_candidate {
    /// Place id.
    pub place: u32,
    /// Best-matching view of the place.
    pub view: u32,
    /// Posterior probability of the place.
    pub probability: f32,
    /// Cosine similarity of the frame to `view`.
    pub similarity: f32,
}

/// The answer for one frame, written by `topoloc_localizer_process`. The caller sets
/// `struct_size` (with `topoloc_result_default`) and, to receive candidates, `candidates` and
/// `candidates_capacity`; topoloc writes the other fields.
#[repr(C)]
#[derive(Clone, Copy)]
#[allow(non_snake_case)]
pub struct topoloc_result {
    /// `sizeof(topoloc_result)`, set by the `_default` function.
    pub struct_size: usize,
    /// 0-based frame count since creation or reset.
    pub frame_index: u64,
    /// Most probable place.
    pub place: u32,
    /// Best-matching view of that place.
    pub view: u32,
    /// Posterior probability that the robot is at `place` (place belief x on-map probability).
    pub confidence: f32,
    /// Cosine similarity of the frame to `view`.
    pub similarity: f32,
    /// Posterior probability of the off-map state.
    pub off_map_probability: f32,
    /// True when the robot is more likely off the map than on it.
    pub off_map: bool,
    /// Caller-owned array receiving the top candidates, best first; may be NULL if capacity is 0.
    pub candidates: *mut topoloc_candidate,
    /// Capacity of `candidates` in elements.
    pub candidates_capacity: usize,
    /// Number of candidates written: min(top_k, places, capacity).
    pub candidates_len: usize,
    // ABI 1.2 (topoloc 0.1): geometric verification.
    /// True when `place` was verified geometrically in this frame (`verify_candidates` > 0).
    pub verified: bool,
    /// RANSAC inliers between the frame and `view` (0 unless `verified`): with `place` and
    /// `view`, the evidence for a loop closure.
    pub inliers: u32,
    // ABI 1.6 (topoloc 0.1): pose fixes.
    /// True when `world_T_camera` holds a pose fix of this frame (camera intrinsics in the
    /// options, a map with keypoint scene points, and at least `pose_min_inliers` agreeing
    /// keypoints against the best-verified view).
    pub has_pose_fix: bool,
    /// The view the camera was placed against (0 unless `has_pose_fix`).
    pub pose_fix_view: u32,
    /// PnP inliers of the pose fix (0 unless `has_pose_fix`).
    pub pose_fix_inliers: u32,
    /// The camera in the map frame, `world_T_camera`, 16 doubles row-major 4x4, camera axes
    /// optical (z forward, x right, y down); identity unless `has_pose_fix`. A pose graph adds
    /// it as a prior or loop constraint on the frame's pose.
    pub world_T_camera: [f64; 16],
}

// ABI 1.0 and 1.1 ended before `verified`; 1.2 added verification, 1.6 pose fixes.
versioned! {
    topoloc_result [verified, has_pose_fix] {
        Self {
            frame_index: 0,
            place: 0,
            view: 0,
            confidence: 0.0,
            similarity: 0.0,
            off_map_probability: 0.0,
            off_map: false,
            candidates: std::ptr::null_mut(),
            candidates_capacity: 0,
            candidates_len: 0,
            verified: false,
            inliers: 0,
            has_pose_fix: false,
            pose_fix_view: 0,
            pose_fix_inliers: 0,
            world_T_camera: pose_to_row_major(&Isometry3::identity()),
        }
    }
}

/// Fills the first `size` bytes of `*result` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_result_default(result)`, which passes `sizeof *(result)`.
#[no_mangle]
pub extern "C" fn topoloc_result_init(result: *mut topoloc_result, size: usize) -> topoloc_status {
    init_versioned(result, size, "result")
}

/// Localizes one frame and writes the answer into `*result`. The whole frame is validated
/// first: on any error the localizer state and `*result` are unchanged.
/// A frame with `descriptor_len` 0 and an image is described first (the localizer needs a
/// describer: see `topoloc_localizer_new`).
/// Errors: `_DIMENSION_MISMATCH`, `_NON_FINITE`, `_ZERO_DESCRIPTOR`, `_TIMESTAMP`,
/// `_INVALID_ARGUMENT` (odometry not a rigid transform), `_INVALID_IMAGE`, `_UNINFORMATIVE_IMAGE`
/// (blank or featureless image: state unchanged), `_NO_DESCRIBER`, `_MODEL`. With verification on,
/// the frame needs its image (`_INVALID_IMAGE`), beside its descriptor or instead of it. Cost:
/// describing the image (if any), then one pass over the map's descriptors plus O(places + edges);
/// no allocation for descriptor frames without verification; verification adds keypoint detection
/// and a pair check per checked view (BENCHMARKS.md).
#[no_mangle]
pub extern "C" fn topoloc_localizer_process(
    localizer: *mut topoloc_localizer,
    frame: *const topoloc_frame,
    result: *mut topoloc_result,
) -> topoloc_status {
    run_on_mut(localizer, "localizer", |state| {
        let f = read_versioned(frame, "frame")?;
        // The caller's result is read through its own layout only (it may be an older one).
        let caller = read_versioned(result.cast_const(), "result")?;
        let (buffer, capacity) = (caller.candidates, caller.candidates_capacity);
        if buffer.is_null() && capacity > 0 {
            return Err(FfiError::null("result.candidates"));
        }
        let frame = Frame {
            timestamp: f.timestamp,
            descriptor: slice(f.descriptor, f.descriptor_len, "frame.descriptor")?,
            odometry: optional_pose(f.odometry, "frame.odometry")?,
            image: image_view(&f.image, "frame.image")?,
        };
        state.localizer.process(&frame, &mut state.scratch)?;
        let out = &state.scratch;
        let written = out.candidates.len().min(capacity);
        for (i, c) in out.candidates[..written].iter().enumerate() {
            let candidate = topoloc_candidate {
                place: c.place,
                view: c.view,
                probability: c.probability,
                similarity: c.similarity,
            };
            // SAFETY: the caller provides `capacity` writable elements at `buffer`; i < capacity.
            unsafe { buffer.add(i).write(candidate) };
        }
        write_versioned(
            result,
            topoloc_result {
                frame_index: out.frame_index,
                place: out.place,
                view: out.view,
                confidence: out.confidence,
                similarity: out.similarity,
                off_map_probability: out.off_map_probability,
                off_map: out.off_map,
                candidates: buffer,
                candidates_capacity: capacity,
                candidates_len: written,
                verified: out.candidates[0].verified,
                inliers: out.candidates[0].inliers,
                has_pose_fix: out.pose_fix.is_some(),
                pose_fix_view: out.pose_fix.map_or(0, |f| f.view),
                pose_fix_inliers: out.pose_fix.map_or(0, |f| f.inliers),
                world_T_camera: pose_to_row_major(
                    &out.pose_fix
                        .map_or_else(Isometry3::identity, |f| f.world_t_optical),
                ),
                ..topoloc_result::default()
            },
            "result",
        )
    })
}
