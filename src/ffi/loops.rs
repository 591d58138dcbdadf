//! C functions of loop closure (ABI 1.5): a loop detector (keyframe database with each
//! keyframe's local features) that turns every added keyframe into at most one gated hint.

use super::boundary::{check_out, fill_out, run, slice, string, write_array};
use super::convert::{optional_camera, optional_pose, pose_to_row_major};
use super::error::FfiError;
use super::handles::{
    castable, free_exclusive, handle_value, new_exclusive, run_on, run_on_mut, Opaque,
};
use super::map::topoloc_map;
use super::topoloc_status;
use super::versioned::{
    check_versioned, init_versioned, read_optional, read_versioned, versioned, write_versioned,
};
use crate::descriptor::DescriptorError;
use crate::descriptor::DescriptorIdentity;
use crate::loops::{
    DatabaseOptions, Gate, HintOptions, KeyframeDatabase, KeyframeEntry, KeyframeFeatures,
    LoopDetector, LoopHint, OdometryGate,
};
use crate::verify::{
    Descriptor, FundamentalEstimator, Keypoints, PairOptions, PoseTranslation, RelativePoseOptions,
    DESCRIPTOR_BYTES, MAX_KEYPOINTS,
};
use std::ffi::c_char;

/// Finds loop closures for one SLAM run (and, from a map, against an earlier one). Created by
/// `topoloc_loop_detector_new` or `_from_map`, released by `topoloc_loop_detector_free`.
/// Single-threaded state: one thread at a time (it may move between threads). A call made while another call uses it
/// (another thread, or a callback re-entering it) fails with `TOPOLOC_ERR_CONCURRENT_USE` and
/// changes nothing (ABI 1.13).
pub struct topoloc_loop_detector(Opaque);

castable!(topoloc_loop_detector: OwnedExclusive => LoopDetector);

/// Which gate decided a hint: one of the `TOPOLOC_GATE_*` values.
pub type topoloc_gate = u32;
/// Every gate passed: the hint is a loop closure.
pub const TOPOLOC_GATE_ACCEPTED: topoloc_gate = 0;
/// No keyframe outside the exclusion window had keypoints (of the new keyframe's kind) to
/// verify, or the new keyframe has none.
pub const TOPOLOC_GATE_NO_CANDIDATE: topoloc_gate = 1;
/// The best candidate had fewer inliers than `min_inliers`.
pub const TOPOLOC_GATE_TOO_FEW_INLIERS: topoloc_gate = 2;
/// Too few consecutive keyframes agreed on the place (`consistent_keyframes`).
pub const TOPOLOC_GATE_INCONSISTENT: topoloc_gate = 3;
/// Intrinsics were given but no relative pose could be fitted (too few matches, no
/// consensus, or views that differ by a rotation only that no rotation explains). A rotation
/// only that one explains is a pose: `translation` is then `TOPOLOC_TRANSLATION_NONE`.
pub const TOPOLOC_GATE_NO_POSE: topoloc_gate = 4;
/// The pose disagrees with the host's odometry beyond the bounds.
pub const TOPOLOC_GATE_ODOMETRY: topoloc_gate = 5;
/// The candidate is the keyframe's own image (ABI 1.17): a view of the detector's map with
/// the very same keypoints, i.e. the map was built from this run's images. A live session
/// needs a map of an earlier run (`topoloc_loop_detector_from_map`) or none
/// (`topoloc_loop_detector_new`); the library also logs a warning.
pub const TOPOLOC_GATE_SELF_MATCH: topoloc_gate = 6;

/// A fundamental-matrix estimator of the loop candidates' pair checks (ABI 1.17): one of the
/// `TOPOLOC_PAIR_ESTIMATOR_*` values.
pub type topoloc_pair_estimator = u32;
/// OpenCV's classic RANSAC (`FM_RANSAC`).
pub const TOPOLOC_PAIR_ESTIMATOR_RANSAC: topoloc_pair_estimator = 0;
/// OpenCV's USAC with MAGSAC++ scoring: steadier inlier counts at low inlier ratios, at a
/// higher cost per fit.
pub const TOPOLOC_PAIR_ESTIMATOR_MAGSAC: topoloc_pair_estimator = 1;
/// OpenCV's USAC in its fast settings (`USAC_FAST`, ABI 1.18): bad models dropped after a few
/// points, so pairs that do not match cost a fraction of RANSAC's time; it finds more inliers
/// on look-alike pairs too (less precise on small images), and none for a camera that only
/// turned (its degenerate samples).
pub const TOPOLOC_PAIR_ESTIMATOR_USAC_FAST: topoloc_pair_estimator = 2;

/// What a hint's translation holds (ABI 1.17): one of the `TOPOLOC_TRANSLATION_*` values.
pub type topoloc_translation = u32;
/// No translation: the hint has no pose, or the views differ by a rotation only (the cameras
/// about one place relative to the scene's depth): `matched_T_query`'s translation is exactly
/// zero, its rotation holds, and the covariance gives each translation axis 1 m^2.
pub const TOPOLOC_TRANSLATION_NONE: topoloc_translation = 0;
/// A unit-length direction (`scale_known` 0): the host finds the scale.
pub const TOPOLOC_TRANSLATION_DIRECTION: topoloc_translation = 1;
/// Metres (`scale_known` 1): the matched keyframe's scene points fixed the scale.
pub const TOPOLOC_TRANSLATION_METRIC: topoloc_translation = 2;

/// Loop detector parameters. Initialise with `topoloc_loop_options_default`; the defaults
/// and meaning of each field are those of the Rust `HintOptions` and `DatabaseOptions`.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_loop_options {
    /// `sizeof(topoloc_loop_options)`, set by the `_default` function.
    pub struct_size: usize,
    /// Loop candidates verified per keyframe.
    pub candidates: u32,
    /// Keyframes with an id within this many of the new one's are never candidates (DBoW2's
    /// `max_id`; an earlier session's keyframes always may be).
    pub exclude_recent_ids: u64,
    /// Keyframes less than this many seconds older than the new one are never candidates.
    pub exclude_recent_s: f64,
    /// Fewest fundamental-matrix inliers of an accepted hint.
    pub min_inliers: u32,
    /// Consecutive keyframes whose best candidates must agree on the place.
    pub consistent_keyframes: u32,
    /// Check hints with a pose against the host's odometry when both keyframes have poses.
    /// Default true.
    pub odometry_gate: bool,
    /// Largest rotation difference to the odometry, degrees.
    pub odometry_max_rotation_deg: f64,
    /// Largest translation difference to the odometry, metres (an unscaled hint's direction
    /// is scaled by the odometry's baseline), plus
    /// `odometry_max_translation_per_m` per metre travelled (ABI 1.7).
    pub odometry_max_translation_m: f64,
    /// Pinhole intrinsics of the camera (undistorted images, pixels); `fx == 0` = none: hints
    /// then carry no pose. Default none.
    pub fx: f64,
    /// Focal length y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// A keyframe starts a new place when its similarity to its predecessor's place is below
    /// this, in (-1, 1].
    pub novelty_similarity: f32,
    /// With poses, a keyframe closer than this to the previous place joins it (metres).
    pub place_spacing_m: f64,
    /// With poses, a new place is linked to places within this distance (metres).
    pub neighbour_radius_m: f64,
    // ABI 1.6 (topoloc 0.1): candidates from different stretches.
    /// A candidate whose id is less than this from a more similar candidate's is skipped (its
    /// stretch is still searched when the better one is refined); 0 = off.
    pub candidate_id_gap: u64,
    // ABI 1.7 (topoloc 0.1): metric hints.
    /// The odometry translation bound grows by this much per metre the odometry travelled
    /// between the two keyframes (its drift rate; 0: a fixed bound).
    pub odometry_max_translation_per_m: f64,
    /// Reprojection threshold of the metric pose fit against a keyframe's 3D points,
    /// pixels.
    pub pose_reprojection_px: f64,
    // ABI 1.8 (topoloc 0.1): candidates from the odometry.
    /// How much farther than the odometry translation bound an odometry candidate may lie,
    /// metres.
    pub odometry_search_m: f64,
    /// Candidates proposed by the odometry besides appearance's: the keyframes nearest the new
    /// one's odometry pose that could pass the odometry gate (this session's; needs poses and
    /// `odometry_gate`); 0 = none.
    pub odometry_candidates: u32,
    // ABI 1.15 (topoloc 0.1): the consistency gate's pace rule.
    /// Consecutive keyframes agree only when their candidates' timestamps differ by at most
    /// this many times the keyframes' own time step plus `match_pace_slack_s`, unless their
    /// poses lie within `neighbour_radius_m` of each other; 0 = off.
    pub max_match_pace: f64,
    /// The pace rule's slack, seconds.
    pub match_pace_slack_s: f64,
    // ABI 1.17 (topoloc 0.1): the options the CLI had alone.
    /// Keyframes of a candidate's group (its place, the linked places, its stretch of
    /// `candidate_id_gap` ids) checked to refine it, nearest in id first; 0 = no refinement
    /// (ABI 1.17, as the seven fields after it).
    pub refine_keyframes: u32,
    /// Fewest inliers of a hint's relative pose.
    pub pose_min_inliers: u32,
    /// Estimator of the pair checks of point features (XFeat, ORB/BRIEF):
    /// `TOPOLOC_PAIR_ESTIMATOR_*`.
    pub pair_estimator: topoloc_pair_estimator,
    /// RANSAC iterations at most of the pair checks of point features.
    pub pair_iterations: u32,
    /// Smallest cosine of a kept XFeat match (-1: every mutual match; ORB/BRIEF matches are
    /// kept by Hamming distance instead).
    pub pair_min_cosine: f32,
    /// Estimator of the pair checks of dense cells: `TOPOLOC_PAIR_ESTIMATOR_*`.
    pub cells_pair_estimator: topoloc_pair_estimator,
    /// RANSAC iterations at most of the pair checks of dense cells.
    pub cells_pair_iterations: u32,
    /// Smallest cosine of a kept dense-cell match (-1: every mutual match).
    pub cells_pair_min_cosine: f32,
}

// ABI 1.5 ended before `candidate_id_gap`, ABI 1.6 before `odometry_max_translation_per_m`,
// ABI 1.7 before `odometry_search_m`, ABI 1.14 before `max_match_pace`, ABI 1.16 before
// `refine_keyframes`.
versioned! {
    topoloc_loop_options [
        candidate_id_gap,
        odometry_max_translation_per_m,
        odometry_search_m,
        max_match_pace,
        refine_keyframes,
    ] {
        let (h, d) = (HintOptions::default(), DatabaseOptions::default());
        let gate = h.odometry.unwrap_or_default();
        Self {
            candidates: h.candidates as u32,
            exclude_recent_ids: h.exclude_recent_ids,
            exclude_recent_s: h.exclude_recent_s,
            min_inliers: h.min_inliers,
            consistent_keyframes: h.consistent_keyframes as u32,
            odometry_gate: h.odometry.is_some(),
            odometry_max_rotation_deg: gate.max_rotation_deg,
            odometry_max_translation_m: gate.max_translation_m,
            fx: 0.0,
            fy: 0.0,
            cx: 0.0,
            cy: 0.0,
            novelty_similarity: d.novelty_similarity,
            place_spacing_m: d.place_spacing_m,
            neighbour_radius_m: d.neighbour_radius_m,
            candidate_id_gap: h.candidate_id_gap,
            odometry_max_translation_per_m: gate.max_translation_per_m,
            pose_reprojection_px: h.pose.reprojection_px,
            odometry_search_m: h.odometry_search_m,
            odometry_candidates: h.odometry_candidates as u32,
            max_match_pace: h.max_match_pace,
            match_pace_slack_s: h.match_pace_slack_s,
            refine_keyframes: h.refine_keyframes as u32,
            pose_min_inliers: h.pose.min_inliers,
            pair_estimator: estimator_code(h.pair.estimator),
            pair_iterations: h.pair.max_iterations,
            pair_min_cosine: h.pair.min_cosine,
            cells_pair_estimator: estimator_code(h.cells_pair.estimator),
            cells_pair_iterations: h.cells_pair.max_iterations,
            cells_pair_min_cosine: h.cells_pair.min_cosine,
        }
    }
}

/// The C code of an estimator.
fn estimator_code(estimator: FundamentalEstimator) -> topoloc_pair_estimator {
    match estimator {
        FundamentalEstimator::Ransac => TOPOLOC_PAIR_ESTIMATOR_RANSAC,
        FundamentalEstimator::Magsac => TOPOLOC_PAIR_ESTIMATOR_MAGSAC,
        FundamentalEstimator::UsacFast => TOPOLOC_PAIR_ESTIMATOR_USAC_FAST,
    }
}

/// The estimator a C code stands for; `_INVALID_OPTION` naming `field` for another value.
fn estimator(code: topoloc_pair_estimator, field: &str) -> Result<FundamentalEstimator, FfiError> {
    match code {
        TOPOLOC_PAIR_ESTIMATOR_RANSAC => Ok(FundamentalEstimator::Ransac),
        TOPOLOC_PAIR_ESTIMATOR_MAGSAC => Ok(FundamentalEstimator::Magsac),
        TOPOLOC_PAIR_ESTIMATOR_USAC_FAST => Ok(FundamentalEstimator::UsacFast),
        other => Err(FfiError::invalid_option(format!(
            "{field} is {other}: TOPOLOC_PAIR_ESTIMATOR_RANSAC (0), _MAGSAC (1) or _USAC_FAST (2)"
        ))),
    }
}

/// Fills the first `size` bytes of `*options` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_loop_options_default(options)`, which passes `sizeof *(options)`.
#[no_mangle]
pub extern "C" fn topoloc_loop_options_init(
    options: *mut topoloc_loop_options,
    size: usize,
) -> topoloc_status {
    init_versioned(options, size, "options")
}

/// The Rust options a C caller's options stand for (NULL: defaults).
fn loop_options(
    options: *const topoloc_loop_options,
) -> Result<(HintOptions, DatabaseOptions), FfiError> {
    let o = read_optional(options, "options")?;
    let camera = optional_camera(o.fx, o.fy, o.cx, o.cy);
    let gate = OdometryGate {
        max_rotation_deg: o.odometry_max_rotation_deg,
        max_translation_m: o.odometry_max_translation_m,
        max_translation_per_m: o.odometry_max_translation_per_m,
    };
    // The bounds are checked with the gate off too: the header gives their ranges.
    gate.validate()?;
    let defaults = HintOptions::default();
    let hints = HintOptions {
        candidates: o.candidates as usize,
        candidate_id_gap: o.candidate_id_gap,
        exclude_recent_ids: o.exclude_recent_ids,
        exclude_recent_s: o.exclude_recent_s,
        min_inliers: o.min_inliers,
        consistent_keyframes: o.consistent_keyframes as usize,
        odometry: o.odometry_gate.then_some(gate),
        camera,
        odometry_candidates: o.odometry_candidates as usize,
        odometry_search_m: o.odometry_search_m,
        max_match_pace: o.max_match_pace,
        match_pace_slack_s: o.match_pace_slack_s,
        refine_keyframes: o.refine_keyframes as usize,
        pose: RelativePoseOptions {
            reprojection_px: o.pose_reprojection_px,
            min_inliers: o.pose_min_inliers,
            ..RelativePoseOptions::default()
        },
        pair: PairOptions {
            estimator: estimator(o.pair_estimator, "options.pair_estimator")?,
            max_iterations: o.pair_iterations,
            min_cosine: o.pair_min_cosine,
            ..defaults.pair
        },
        cells_pair: PairOptions {
            estimator: estimator(o.cells_pair_estimator, "options.cells_pair_estimator")?,
            max_iterations: o.cells_pair_iterations,
            min_cosine: o.cells_pair_min_cosine,
            ..defaults.cells_pair
        },
    };
    let database = DatabaseOptions {
        novelty_similarity: o.novelty_similarity,
        place_spacing_m: o.place_spacing_m,
        neighbour_radius_m: o.neighbour_radius_m,
    };
    Ok((hints, database))
}

/// Creates an empty loop detector for descriptors of `descriptor_kind` (a non-empty string),
/// `descriptor_model` (may be empty) and dimension `dim`: the place graph grows from nothing.
/// `options` may be NULL for defaults. On success `*out` owns the detector.
/// Errors: `_INVALID_OPTION`, `_INVALID_ARGUMENT` (empty kind, a kind above 256 bytes or a
/// model above 4,096, dim 0 or above 65,536, refused before anything is allocated).
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_new(
    descriptor_kind: *const c_char,
    descriptor_model: *const c_char,
    dim: u32,
    options: *const topoloc_loop_options,
    out: *mut *mut topoloc_loop_detector,
) -> topoloc_status {
    run(|| {
        fill_out(out, "out", || {
            let identity = DescriptorIdentity::new(
                string(descriptor_kind, "descriptor_kind")?,
                string(descriptor_model, "descriptor_model")?,
                dim,
            )?;
            let (hints, database) = loop_options(options)?;
            let detector = LoopDetector::new(KeyframeDatabase::new(identity, database)?, hints)?;
            Ok(new_exclusive::<topoloc_loop_detector>(detector))
        })
    })
}

/// Creates a loop detector whose first session is `map`'s views (with their stored keypoints
/// and, where known, scene points): new keyframes (ids above the map's) close loops against
/// it. The map must come from an earlier run: `topoloc_loop_detector_save`d by a detector, or
/// built from another run's images; a map of this run's own images makes every keyframe match
/// itself (`TOPOLOC_GATE_SELF_MATCH`). The map's keyframes are an earlier session's, as after
/// `topoloc_loop_detector_begin_session`: never inside the exclusion window, and their poses
/// (in the map's world frame) never compared with the new keyframes' by the odometry gate.
/// The map handle is not kept. On success `*out` owns the detector.
/// Errors: `_INVALID_OPTION` (also a view without keyframe id), `_INVALID_ARGUMENT` (ids not
/// increasing).
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_from_map(
    map: *const topoloc_map,
    options: *const topoloc_loop_options,
    out: *mut *mut topoloc_loop_detector,
) -> topoloc_status {
    run_on(map, "map", |map| {
        fill_out(out, "out", || {
            let (hints, database) = loop_options(options)?;
            let detector = LoopDetector::from_map(map, database, hints)?;
            Ok(new_exclusive::<topoloc_loop_detector>(detector))
        })
    })
}

/// Releases a loop detector. `NULL` is a no-op.
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_free(detector: *mut topoloc_loop_detector) {
    free_exclusive(detector)
}

/// One keyframe as the host gives it. Initialise with `topoloc_loop_keyframe_default`.
#[allow(non_snake_case)]
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_loop_keyframe {
    /// `sizeof(topoloc_loop_keyframe)`, set by the `_default` function.
    pub struct_size: usize,
    /// The host's keyframe id: its keyframe counter (0, 1, 2, ... or any increasing count of
    /// keyframes, as VINS-Fusion's and ORB-SLAM's `mnId` are), not a frame index or a time:
    /// `exclude_recent_ids` and `candidate_id_gap` count keyframes in these ids. Must increase
    /// from one keyframe to the next, past erased keyframes' ids too.
    pub id: u64,
    /// Time in seconds; must not decrease (within a session).
    pub timestamp: f64,
    /// Global descriptor (normalised internally).
    pub descriptor: *const f32,
    /// Floats at `descriptor`: the detector's D.
    pub descriptor_len: usize,
    /// Odometry pose of the body `world_T_body`, 16 doubles row-major 4x4; NULL = none (either
    /// every keyframe has one or none has).
    pub world_T_body: *const f64,
    /// Camera in the body frame `body_T_camera`, 16 doubles row-major; NULL = identity.
    pub body_T_camera: *const f64,
    /// Number of keypoints (0..=5000).
    pub keypoint_count: usize,
    /// Keypoint pixel positions, `2 * keypoint_count` floats (x right, y down).
    pub keypoints: *const f32,
    /// Their 32-byte binary descriptors (ORB, BRIEF), `32 * keypoint_count` bytes.
    pub keypoint_descriptors: *const u8,
    /// Each keypoint's scene point in this keyframe's camera frame (metres; NaN x3 when
    /// unknown), `3 * keypoint_count` floats; NULL = none. With intrinsics, a later hint
    /// matched to this keyframe is metric.
    pub camera_points: *const f32,
}

versioned! {
    topoloc_loop_keyframe {
        Self {
            id: 0,
            timestamp: 0.0,
            descriptor: std::ptr::null(),
            descriptor_len: 0,
            world_T_body: std::ptr::null(),
            body_T_camera: std::ptr::null(),
            keypoint_count: 0,
            keypoints: std::ptr::null(),
            keypoint_descriptors: std::ptr::null(),
            camera_points: std::ptr::null(),
        }
    }
}

/// Fills the first `size` bytes of `*keyframe` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_loop_keyframe_default(keyframe)`, which passes `sizeof *(keyframe)`.
#[no_mangle]
pub extern "C" fn topoloc_loop_keyframe_init(
    keyframe: *mut topoloc_loop_keyframe,
    size: usize,
) -> topoloc_status {
    init_versioned(keyframe, size, "keyframe")
}

/// The best verified candidate of a keyframe, written by `topoloc_loop_detector_add` (and a
/// confirmed one by `topoloc_loop_detector_confirmed`). The caller sets `struct_size` with
/// `topoloc_loop_hint_default`; topoloc writes the rest.
#[allow(non_snake_case)]
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_loop_hint {
    /// `sizeof(topoloc_loop_hint)`, set by the `_default` function.
    pub struct_size: usize,
    /// The query keyframe's id (the added one, or for a confirmed hint the earlier one).
    pub query_id: u64,
    /// The place the query keyframe joined.
    pub query_place: u32,
    /// True when a candidate was verified (the fields below describe it).
    pub has_match: bool,
    /// True when every gate passed: a loop closure for the pose graph.
    pub accepted: bool,
    /// The gate that decided (`TOPOLOC_GATE_*`): why a candidate was refused, for logs.
    pub gate: topoloc_gate,
    /// The matched keyframe's id.
    pub matched_id: u64,
    /// The matched keyframe's place.
    pub place: u32,
    /// Fundamental-matrix inliers between the two keyframes.
    pub inliers: u32,
    /// The matched keyframe's share of the inliers of all verified candidates (0..=1), as
    /// `topoloc_loop_detector_candidates` lists it (the matched keyframe is always there).
    pub confidence: f32,
    /// True when `matched_T_query` and `covariance` are set (intrinsics given, pose fitted).
    pub has_pose: bool,
    /// True when the translation is metric (the matched keyframe had scene points); else it
    /// is a unit direction or, for a rotation only, zero: `translation` says which.
    pub scale_known: bool,
    /// The query camera in the matched camera's optical frame (z forward, x right, y down),
    /// 16 doubles row-major 4x4.
    pub matched_T_query: [f64; 16],
    /// Covariance of `matched_T_query` for a right perturbation, 36 doubles row-major, in
    /// GTSAM Pose3 tangent order: rotation (rad) x y z, then translation (m) x y z.
    pub covariance: [f64; 36],
    /// What the translation of `matched_T_query` holds (ABI 1.17): `TOPOLOC_TRANSLATION_METRIC`
    /// (metres), `_DIRECTION` (unit length) or `_NONE` (no pose, or a rotation only: exactly
    /// zero). A host adds a between-factor with the translation only for `_METRIC`, a
    /// direction factor for `_DIRECTION`, and a rotation factor alone for `_NONE`.
    pub translation: topoloc_translation,
}

// ABI 1.16 ended before `translation`.
versioned! {
    topoloc_loop_hint [translation] {
        Self {
            query_id: 0,
            query_place: 0,
            has_match: false,
            accepted: false,
            gate: TOPOLOC_GATE_NO_CANDIDATE,
            matched_id: 0,
            place: 0,
            inliers: 0,
            confidence: 0.0,
            has_pose: false,
            scale_known: false,
            matched_T_query: pose_to_row_major(&nalgebra::Isometry3::identity()),
            covariance: [0.0; 36],
            translation: TOPOLOC_TRANSLATION_NONE,
        }
    }
}

/// Fills the first `size` bytes of `*hint` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_loop_hint_default(hint)`, which passes `sizeof *(hint)`.
#[no_mangle]
pub extern "C" fn topoloc_loop_hint_init(
    hint: *mut topoloc_loop_hint,
    size: usize,
) -> topoloc_status {
    init_versioned(hint, size, "hint")
}

/// The C code of a gate.
fn gate_code(gate: &Gate) -> topoloc_gate {
    match gate {
        Gate::Accepted => TOPOLOC_GATE_ACCEPTED,
        Gate::NoCandidate => TOPOLOC_GATE_NO_CANDIDATE,
        Gate::TooFewInliers => TOPOLOC_GATE_TOO_FEW_INLIERS,
        Gate::Inconsistent { .. } => TOPOLOC_GATE_INCONSISTENT,
        Gate::NoPose(_) => TOPOLOC_GATE_NO_POSE,
        Gate::Odometry { .. } => TOPOLOC_GATE_ODOMETRY,
        Gate::SelfMatch => TOPOLOC_GATE_SELF_MATCH,
    }
}

/// A caller's descriptor of `len` floats at `ptr`: `_DIMENSION_MISMATCH` before anything is
/// read when `len` is not the detector's D (whatever its size).
fn descriptor_of<'a>(
    detector: &LoopDetector,
    ptr: *const f32,
    len: usize,
    name: &str,
) -> Result<&'a [f32], FfiError> {
    let expected = detector.database().identity().dim as usize;
    if len != expected {
        return Err(DescriptorError::Dimension { got: len, expected }.into());
    }
    slice(ptr, len, name)
}

/// The keyframe's features from the C arrays.
fn keyframe_features(k: &topoloc_loop_keyframe) -> Result<KeyframeFeatures, FfiError> {
    let n = k.keypoint_count;
    if n > MAX_KEYPOINTS {
        return Err(FfiError::invalid(format!(
            "keyframe.keypoint_count is {n}, at most {MAX_KEYPOINTS}"
        )));
    }
    let points = slice(k.keypoints, 2 * n, "keyframe.keypoints")?;
    let bytes = slice(
        k.keypoint_descriptors,
        DESCRIPTOR_BYTES * n,
        "keyframe.keypoint_descriptors",
    )?;
    let descriptors: Vec<Descriptor> = bytes
        .chunks_exact(DESCRIPTOR_BYTES)
        .map(|c| c.try_into().expect("32 bytes"))
        .collect();
    let camera_points = if k.camera_points.is_null() {
        None
    } else {
        let p = slice(k.camera_points, 3 * n, "keyframe.camera_points")?;
        Some(p.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
    };
    Ok(KeyframeFeatures {
        keypoints: Keypoints {
            points: points.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
            descriptors: descriptors.into(),
        },
        camera_points,
    })
}

/// The C hint of a processed keyframe: its best candidate, or none (`has_match` 0).
pub(super) fn c_hint_of(
    query_id: u64,
    query_place: u32,
    hint: Option<&LoopHint>,
) -> topoloc_loop_hint {
    match hint {
        Some(h) => c_hint(h),
        None => topoloc_loop_hint {
            query_id,
            query_place,
            ..topoloc_loop_hint::default()
        },
    }
}

/// The C form of a verified candidate.
fn c_hint(h: &LoopHint) -> topoloc_loop_hint {
    let mut out = topoloc_loop_hint {
        query_id: h.query_id,
        query_place: h.query_place,
        ..topoloc_loop_hint::default()
    };
    out.has_match = true;
    out.accepted = h.accepted();
    out.gate = gate_code(&h.gate);
    out.matched_id = h.matched_id;
    out.place = h.place;
    out.inliers = h.inliers;
    out.confidence = h.confidence;
    if let Some(pose) = &h.pose {
        out.has_pose = true;
        out.scale_known = pose.scale_known;
        out.translation = match pose.translation() {
            PoseTranslation::Metric => TOPOLOC_TRANSLATION_METRIC,
            PoseTranslation::Direction => TOPOLOC_TRANSLATION_DIRECTION,
            PoseTranslation::RotationOnly => TOPOLOC_TRANSLATION_NONE,
        };
        out.matched_T_query = pose_to_row_major(&pose.matched_t_query);
        for r in 0..6 {
            for c in 0..6 {
                out.covariance[r * 6 + c] = pose.covariance[(r, c)];
            }
        }
    }
    out
}

/// Adds a keyframe: its loop candidates (outside the exclusion window) are verified against
/// its keypoints and gated, then it joins the place graph. `*hint` receives the best verified
/// candidate with the gate that decided (`has_match` 0 when there was none); at most one hint
/// per keyframe. The whole keyframe is validated first: on any error the detector and `*hint`
/// are unchanged.
/// Errors: `_DIMENSION_MISMATCH` (`descriptor_len` is not D, whatever its size), `_NON_FINITE`
/// (descriptor, timestamp, poses), `_ZERO_DESCRIPTOR`, `_INVALID_ARGUMENT` (duplicate id, an id
/// not above every id added before, erased or not, earlier timestamp, bad keypoints or scene
/// points, non-rigid poses), `_INVALID_OPTION` (a pose on some keyframes only: the first keyframe
/// decides whether all have one). Cost: one pass over the keyframes' descriptors and a pair check
/// per verified candidate (BENCHMARKS.md).
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_add(
    detector: *mut topoloc_loop_detector,
    keyframe: *const topoloc_loop_keyframe,
    hint: *mut topoloc_loop_hint,
) -> topoloc_status {
    run_on_mut(detector, "detector", |detector| {
        let k = read_versioned(keyframe, "keyframe")?;
        // Checks the caller's hint struct before anything changes.
        check_versioned(hint, "hint")?;
        let entry = KeyframeEntry {
            id: k.id,
            timestamp: k.timestamp,
            descriptor: descriptor_of(
                detector,
                k.descriptor,
                k.descriptor_len,
                "keyframe.descriptor",
            )?,
            world_t_body: optional_pose(k.world_T_body, "keyframe.world_T_body")?,
            body_t_camera: optional_pose(k.body_T_camera, "keyframe.body_T_camera")?,
        };
        let features = keyframe_features(&k)?;
        let done = detector.process(&entry, features)?;
        write_versioned(
            hint,
            c_hint_of(k.id, done.added.place, done.hint.as_ref()),
            "hint",
        )
    })
}

/// How many hints of earlier keyframes the last successful `topoloc_loop_detector_add`
/// confirmed (ABI 1.10), into `*count`: when a keyframe's hint is accepted because it completes
/// a consistency streak, the streak's earlier keyframes, refused as `TOPOLOC_GATE_INCONSISTENT`
/// while it was short, are accepted too. Read each with `topoloc_loop_detector_confirmed`
/// before the next `_add` replaces them (errors and `_erase` keep them). 0 after an `_add`
/// whose hint was not accepted.
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_confirmed_count(
    detector: *const topoloc_loop_detector,
    count: *mut usize,
) -> topoloc_status {
    handle_value(detector, "detector", count, "count", |d| {
        d.confirmed().len()
    })
}

/// Writes confirmed hint `index` (0 = oldest; below `topoloc_loop_detector_confirmed_count`)
/// into `*hint` (ABI 1.10), whose `struct_size` the caller set with
/// `topoloc_loop_hint_default`: `accepted` 1, `query_id` and `query_place` the earlier
/// keyframe's, at most one accepted hint per keyframe in all. Errors: `_INVALID_ARGUMENT` (index
/// out of range; `*hint` unchanged).
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_confirmed(
    detector: *const topoloc_loop_detector,
    index: usize,
    hint: *mut topoloc_loop_hint,
) -> topoloc_status {
    run_on(detector, "detector", |detector| {
        check_versioned(hint, "hint")?;
        let confirmed = detector.confirmed();
        let Some(h) = confirmed.get(index) else {
            return Err(FfiError::invalid(format!(
                "index is {index}, but {} hints were confirmed",
                confirmed.len()
            )));
        };
        write_versioned(hint, c_hint(h), "hint")
    })
}

/// One relocalization candidate. Array element: its layout never changes.
#[repr(C)]
#[derive(Clone, Copy, Default)]
pub struct topoloc_loop_candidate {
    /// Keyframe id.
    pub keyframe_id: u64,
    /// Its place.
    pub place: u32,
    /// Cosine similarity of the query to the keyframe.
    pub similarity: f32,
}

/// Relocalization candidates for a descriptor that is not added (every keyframe may match),
/// most similar first, into the caller's array `(out, capacity)`; `*count` receives how many
/// were written (at most `capacity`). Errors: `_DIMENSION_MISMATCH`, `_NON_FINITE`,
/// `_ZERO_DESCRIPTOR`.
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_query(
    detector: *const topoloc_loop_detector,
    descriptor: *const f32,
    descriptor_len: usize,
    out: *mut topoloc_loop_candidate,
    capacity: usize,
    count: *mut usize,
) -> topoloc_status {
    run_on(detector, "detector", |detector| {
        check_out(count, "count")?;
        let descriptor = descriptor_of(detector, descriptor, descriptor_len, "descriptor")?;
        let found: Vec<topoloc_loop_candidate> = detector
            .database()
            .relocalization_candidates(descriptor, capacity)?
            .iter()
            .map(|m| topoloc_loop_candidate {
                keyframe_id: m.keyframe_id,
                place: m.place,
                similarity: m.similarity,
            })
            .collect();
        write_array(&found, out, capacity, count)
    })
}

/// Removes a keyframe and its features (ORB-SLAM culls keyframes).
/// Errors: `_INVALID_ARGUMENT` (no keyframe with that id).
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_erase(
    detector: *mut topoloc_loop_detector,
    id: u64,
) -> topoloc_status {
    run_on_mut(detector, "detector", |detector| {
        detector.erase(id)?;
        Ok(())
    })
}

/// Starts a new session whose odometry is in a new world frame (ABI 1.15): ORB-SLAM3 starting
/// a new map after tracking is lost, VINS-Fusion a new sequence. The keyframes held become an
/// earlier session's, as a map's are for `topoloc_loop_detector_from_map`: never inside the
/// exclusion window (the map just lost may be found again at once), not compared by time, and
/// not by the odometry gate, which compares poses of one world frame only. The next keyframe's
/// timestamp may be earlier than the last one's; ids must still increase. The consistency
/// streak ends (hints not yet confirmed are dropped). Only the general errors.
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_begin_session(
    detector: *mut topoloc_loop_detector,
) -> topoloc_status {
    run_on_mut(detector, "detector", |detector| {
        detector.begin_session();
        Ok(())
    })
}

/// Saves the keyframes and their place graph as a topoloc map file (a view per keyframe,
/// keyframe ids kept, with the keyframes' keypoints and, where a keyframe had an odometry pose
/// and scene points, those points), for a later session: `topoloc_map_load`, then
/// `topoloc_loop_detector_from_map`, which verifies against them. Atomic (a temporary file
/// renamed over `path`).
/// Errors: `_IO`, `_EMPTY_MAP`; `_INVALID_ARGUMENT` for a map a reader would refuse (its header
/// too long), before anything is written.
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_save(
    detector: *const topoloc_loop_detector,
    path: *const c_char,
) -> topoloc_status {
    run_on(detector, "detector", |detector| {
        detector.save(string(path, "path")?)?;
        Ok(())
    })
}

/// The smallest id the next keyframe may have (`*out`, ABI 1.17): one above the largest id
/// ever added or reloaded, erased keyframes' included; 0 for an empty new detector. A host
/// whose keyframe ids restart at 0 in a new run adds this value to them after
/// `topoloc_loop_detector_from_map`.
/// Errors: `_INVALID_ARGUMENT` once id `UINT64_MAX` was added (no id can follow).
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_next_id(
    detector: *const topoloc_loop_detector,
    out: *mut u64,
) -> topoloc_status {
    run_on(detector, "detector", |d| {
        fill_out(out, "out", || {
            d.database().next_id().ok_or_else(|| {
                FfiError::invalid(format!(
                    "keyframe id {} was added: no id can follow",
                    u64::MAX
                ))
            })
        })
    })
}

/// Number of keyframes held (`*out`).
#[no_mangle]
pub extern "C" fn topoloc_loop_detector_len(
    detector: *const topoloc_loop_detector,
    out: *mut usize,
) -> topoloc_status {
    handle_value(detector, "detector", out, "out", |d| d.database().len())
}
