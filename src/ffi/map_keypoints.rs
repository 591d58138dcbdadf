//! C functions on a map's keypoints (ABI 1.6): read each view's keypoint positions, and attach
//! the 3D scene point of each keypoint (from depth or a SLAM system's map points) so that a
//! localizer with camera intrinsics reports metric pose fixes.

use super::boundary::{fill_out, slice, write_array, write_optional};
use super::error::FfiError;
use super::handles::{handle_value, run_on};
use super::map::{map_handle, topoloc_map};
use super::topoloc_status;
use crate::map::{Map, MapError};
use crate::verify::ViewKeypoints;

/// The map's keypoint store, or the typed error a C caller gets for a map without one.
fn keypoints_of(map: &Map) -> Result<&ViewKeypoints, FfiError> {
    map.keypoints().ok_or_else(|| {
        MapError::InvalidArgument(
            "the map stores no keypoints (maps built from images store them)".into(),
        )
        .into()
    })
}

/// Writes into `*total` the number of keypoints of all views together (0 when the map stores
/// none): the length, in points, of the array `topoloc_map_with_keypoint_points` takes.
/// Thread safety: as every `const topoloc_map*` accessor.
#[no_mangle]
pub extern "C" fn topoloc_map_keypoint_total(
    map: *const topoloc_map,
    total: *mut usize,
) -> topoloc_status {
    handle_value(map, "map", total, "total", |m| {
        m.keypoints().map_or(0, ViewKeypoints::total)
    })
}

/// Copies the pixel positions of `view`'s keypoints, `x y` pairs (OpenCV convention: the centre
/// of the top-left pixel is (0, 0)), into `xy` of capacity `len` floats. `*count` (if non-NULL)
/// always receives the number of keypoints; `len` must be at least `2 * count`. Keypoints are in
/// the order `topoloc_map_with_keypoint_points` expects their scene points.
/// Errors: `_UNKNOWN_VIEW`, `_INVALID_ARGUMENT` (the map stores no keypoints), `_BUFFER_TOO_SMALL`.
#[no_mangle]
pub extern "C" fn topoloc_map_view_keypoints(
    map: *const topoloc_map,
    view: u32,
    xy: *mut f32,
    len: usize,
    count: *mut usize,
) -> topoloc_status {
    run_on(map, "map", |map| {
        map.view(view)?;
        let keypoints = keypoints_of(map)?;
        let points = keypoints
            .view(view as usize)
            .map(|k| k.points)
            .unwrap_or_default();
        write_optional(count, points.len());
        write_array(points.as_flattened(), xy, len, std::ptr::null_mut())
    })
}

/// Makes a copy of `map` whose keypoints carry their scene points: `xyz` holds `3 * total`
/// floats (`topoloc_map_keypoint_total`), the map-frame position (the frame of the place
/// positions and view poses, metres) of each keypoint, view after view in the order of
/// `topoloc_map_view_keypoints`; all three NaN where unknown. With such a map and camera
/// intrinsics in its options, a localizer reports pose fixes (`topoloc_result.has_pose_fix`).
/// On success `*out` owns the new map (release it with `topoloc_map_free`); `map` is unchanged
/// and remains the caller's. The copy holds its descriptors in memory, even when `map` was
/// memory-mapped from a file. Errors: `_INVALID_ARGUMENT` (no keypoints, wrong length, a point
/// neither finite nor all NaN).
#[no_mangle]
pub extern "C" fn topoloc_map_with_keypoint_points(
    map: *const topoloc_map,
    xyz: *const f32,
    len: usize,
    out: *mut *mut topoloc_map,
) -> topoloc_status {
    run_on(map, "map", |map| {
        fill_out(out, "out", || {
            let total = keypoints_of(map)?.total();
            if len != 3 * total {
                return Err(MapError::InvalidArgument(format!(
                    "xyz holds {len} floats, the map's {total} keypoints need {}",
                    3 * total
                ))
                .into());
            }
            let points = slice(xyz, len, "xyz")?
                .chunks_exact(3)
                .map(|p| [p[0], p[1], p[2]])
                .collect();
            Ok(map_handle(map.with_keypoint_world_points(points)?))
        })
    })
}
