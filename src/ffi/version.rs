//! Version and error-text functions.

use super::boundary::copy_last_error;
use super::status::topoloc_status;
use std::ffi::{c_char, CStr};

/// ABI version: bumped only when an existing C signature or struct layout changes
/// incompatibly (which the project avoids: it adds functions and appends struct fields).
pub const TOPOLOC_ABI_VERSION: u32 = 1;

/// ABI minor version: bumped when functions, struct fields or constants are added. The header
/// marks additions "ABI 1.N"; a host that uses one checks `topoloc_abi_version_minor() >= N`
/// at run time (the library it loaded may be older than the header it was built with).
/// 1.1: image maps; 1.2: verification; 1.3: metric mode; 1.4: `topoloc_abi_version_minor`,
/// `topoloc_status_name`; 1.5: loop closure (`topoloc_loop_detector_*`); 1.6: pose fixes
/// (camera intrinsics in the localizer options, `topoloc_map_with_keypoint_points`); 1.7:
/// metric hints (the odometry bound's drift rate, the pose fit's reprojection threshold); 1.8:
/// loop candidates from the odometry (`odometry_candidates`, `odometry_search_m`); 1.9:
/// off-map evidence from verification (`verify_off_map_inliers`, `_inlier_scale`); 1.10:
/// confirmed loop hints (`topoloc_loop_detector_confirmed_count`, `_confirmed`); 1.11:
/// trajectory metrics (`topoloc_trajectory_evaluate`, `_evaluate_files`); 1.12: describers
/// (`topoloc_describer_*`: images to a map's global descriptors); 1.13: host logging
/// (`topoloc_set_log_callback`) and `TOPOLOC_ERR_CONCURRENT_USE` for a handle used by two calls
/// at once; 1.14: `pca_precision` in the image map options (`TOPOLOC_PCA_I8`, `_F32`); 1.15:
/// image keyframes (`topoloc_keyframe_describer_*`, `topoloc_loop_detector_add_image`), ranked
/// candidates (`topoloc_loop_detector_candidates`), sessions
/// (`topoloc_loop_detector_begin_session`), local features of image maps
/// (`verification_keypoints`, `local_features`); 1.16: the learned estimator
/// (`TOPOLOC_MODE_GRNN`, `grnn_model_path`); 1.17: the loop options the CLI had alone
/// (`refine_keyframes`, `pose_min_inliers`, `pair_*`, `cells_pair_*`), the hint's
/// `translation` (`TOPOLOC_TRANSLATION_*`), `TOPOLOC_GATE_SELF_MATCH`,
/// `topoloc_loop_detector_next_id`; 1.18: `TOPOLOC_PAIR_ESTIMATOR_USAC_FAST`.
pub const TOPOLOC_ABI_VERSION_MINOR: u32 = 18;

static VERSION: &CStr =
    match CStr::from_bytes_with_nul(concat!(env!("CARGO_PKG_VERSION"), "\0").as_bytes()) {
        Ok(v) => v,
        Err(_) => panic!("version string has no interior NUL"),
    };

/// Library version "MAJOR.MINOR.PATCH" as a static NUL-terminated string (never free it).
/// Compare with the `TOPOLOC_VERSION_*` macros of the header the program was built against.
#[no_mangle]
pub extern "C" fn topoloc_version() -> *const c_char {
    VERSION.as_ptr()
}

/// ABI version of the loaded library; must equal `TOPOLOC_ABI_VERSION` of the header.
#[no_mangle]
pub extern "C" fn topoloc_abi_version() -> u32 {
    TOPOLOC_ABI_VERSION
}

/// ABI minor version of the loaded library (ABI 1.4; see `TOPOLOC_ABI_VERSION_MINOR`): fields
/// and functions marked "ABI 1.N" in the header exist when this is at least N. Thread-safe.
#[no_mangle]
pub extern "C" fn topoloc_abi_version_minor() -> u32 {
    TOPOLOC_ABI_VERSION_MINOR
}

/// Static English description of a status code (never free it); unknown codes give
/// "unknown status code". Thread-safe.
#[no_mangle]
pub extern "C" fn topoloc_status_str(status: u32) -> *const c_char {
    topoloc_status::from_code(status)
        .map_or(c"unknown status code", |s| s.entry().1)
        .as_ptr()
}

/// Static C name of a status code, e.g. `"TOPOLOC_ERR_IO"` (ABI 1.4; never free it), or NULL
/// for a code this library does not know. Language bindings use it to check that they map
/// every code. Thread-safe.
#[no_mangle]
pub extern "C" fn topoloc_status_name(status: u32) -> *const c_char {
    topoloc_status::from_code(status).map_or(std::ptr::null(), |s| s.entry().0.as_ptr())
}

/// Copies the message of the most recent failed call on this thread (NUL-terminated; "" if
/// none) into `buf` of `len` bytes. `*needed` (if not NULL) receives the size required
/// including the NUL, also when the buffer is too small. Returns `TOPOLOC_OK`,
/// `TOPOLOC_ERR_BUFFER_TOO_SMALL`, or `TOPOLOC_ERR_NULL_ARGUMENT` (NULL `buf` with `len` large
/// enough); never changes the stored message. Thread-safe: each thread
/// has its own last error.
#[no_mangle]
pub extern "C" fn topoloc_last_error_message(
    buf: *mut c_char,
    len: usize,
    needed: *mut usize,
) -> topoloc_status {
    copy_last_error(buf, len, needed)
}
