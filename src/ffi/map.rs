//! C functions on maps: load, save, free and read-only accessors.

use super::boundary::{
    check_out, copy_c_string, fill_out, run, slice, string, write_array, write_out,
};
use super::convert::{expected_descriptor, pose_to_row_major};
use super::error::FfiError;
use super::handles::{
    castable, clone_arc, free_arc, handle_value, new_arc, run_on, try_ref, Opaque,
};
use super::topoloc_status;
use super::versioned::{init_versioned, read_optional, versioned, write_versioned, Versioned};
use crate::map::{Edge, LoadOptions, Map};
use std::ffi::c_char;
use std::sync::Arc;

/// An immutable map. Created by `topoloc_map_load`, `topoloc_map_load_from_memory`,
/// `topoloc_map_builder_build` or `topoloc_map_from_keyframes`; released with
/// `topoloc_map_free`. Thread safety: a `const topoloc_map*` may be used from many threads at
/// once, and localizers keep their own reference, so a map may be freed while localizers that
/// were created from it are still in use.
pub struct topoloc_map(Opaque);

castable!(topoloc_map: OwnedArc => Map);

/// Gives C a new map handle holding the only reference to `map`.
pub(crate) fn map_handle(map: Map) -> *mut topoloc_map {
    new_arc(Arc::new(map))
}

/// The body of the functions that make a handle on a map with versioned options
/// (`topoloc_localizer_new`, `topoloc_describer_new`): checks `map`, then `out`, then reads the
/// options (NULL: defaults) and writes the handle `make` returns, which may keep the map.
pub(crate) fn new_on_map<O: Versioned, H>(
    map: *const topoloc_map,
    options: *const O,
    out: *mut *mut H,
    make: impl FnOnce(Arc<Map>, O) -> Result<*mut H, FfiError>,
) -> topoloc_status {
    run(|| {
        let map = clone_arc(map, "map")?;
        fill_out(out, "out", || make(map, read_optional(options, "options")?))
    })
}

/// Options of `topoloc_map_load`. Initialise with `topoloc_map_load_options_default`.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_map_load_options {
    /// `sizeof(topoloc_map_load_options)`, set by the `_default` function.
    pub struct_size: usize,
    /// Refuse maps whose descriptor kind differs (`TOPOLOC_ERR_DESCRIPTOR_MISMATCH`); NULL or "" = any.
    pub expected_descriptor_kind: *const c_char,
    /// Refuse maps whose descriptor model differs; NULL or "" = any.
    pub expected_descriptor_model: *const c_char,
    /// Refuse maps whose descriptor dimension differs; 0 = any.
    pub expected_descriptor_dim: u32,
}

versioned! {
    topoloc_map_load_options {
        Self {
            expected_descriptor_kind: std::ptr::null(),
            expected_descriptor_model: std::ptr::null(),
            expected_descriptor_dim: 0,
        }
    }
}

/// Fills the first `size` bytes of `*options` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_map_load_options_default(options)`, which passes `sizeof *(options)`.
#[no_mangle]
pub extern "C" fn topoloc_map_load_options_init(
    options: *mut topoloc_map_load_options,
    size: usize,
) -> topoloc_status {
    init_versioned(options, size, "options")
}

/// The Rust options a C caller's options stand for (NULL: defaults).
fn load_options(options: *const topoloc_map_load_options) -> Result<LoadOptions, FfiError> {
    let o = read_optional(options, "options")?;
    Ok(LoadOptions {
        expected: expected_descriptor(
            o.expected_descriptor_kind,
            o.expected_descriptor_model,
            o.expected_descriptor_dim,
        )?,
    })
}

/// Loads and validates a map file (memory-mapped; the file must not be modified while the map
/// lives). `options` may be NULL. On success `*out` owns a new map: free it with
/// `topoloc_map_free`. Errors: `TOPOLOC_ERR_IO`, `_NOT_A_MAP`, `_TRUNCATED`, `_CORRUPT`,
/// `_UNSUPPORTED_VERSION`, `_DESCRIPTOR_MISMATCH`.
#[no_mangle]
pub extern "C" fn topoloc_map_load(
    path: *const c_char,
    options: *const topoloc_map_load_options,
    out: *mut *mut topoloc_map,
) -> topoloc_status {
    run(|| {
        let path = string(path, "path")?;
        fill_out(out, "out", || {
            Ok(map_handle(Map::load(path, &load_options(options)?)?))
        })
    })
}

/// Loads and validates a map from `len` bytes in the map file format (copied; the buffer may be
/// released afterwards). Same errors and ownership as `topoloc_map_load`.
#[no_mangle]
pub extern "C" fn topoloc_map_load_from_memory(
    data: *const u8,
    len: usize,
    options: *const topoloc_map_load_options,
    out: *mut *mut topoloc_map,
) -> topoloc_status {
    run(|| {
        let bytes = slice(data, len, "data")?;
        fill_out(out, "out", || {
            Ok(map_handle(Map::from_bytes(bytes, &load_options(options)?)?))
        })
    })
}

/// Saves a map to `path` atomically (temporary file, fsync, rename). Errors: `TOPOLOC_ERR_IO`.
#[no_mangle]
pub extern "C" fn topoloc_map_save(map: *const topoloc_map, path: *const c_char) -> topoloc_status {
    run_on(map, "map", |map| {
        map.save(string(path, "path")?)?;
        Ok(())
    })
}

/// Releases a map handle. Localizers created from it keep working. `NULL` is a no-op.
#[no_mangle]
pub extern "C" fn topoloc_map_free(map: *mut topoloc_map) {
    free_arc(map)
}

/// Number of places (`*out`).
#[no_mangle]
pub extern "C" fn topoloc_map_place_count(
    map: *const topoloc_map,
    out: *mut usize,
) -> topoloc_status {
    handle_value(map, "map", out, "out", |m| m.place_count())
}

/// Number of views (`*out`).
#[no_mangle]
pub extern "C" fn topoloc_map_view_count(
    map: *const topoloc_map,
    out: *mut usize,
) -> topoloc_status {
    handle_value(map, "map", out, "out", |m| m.view_count())
}

/// Number of undirected edges (`*out`).
#[no_mangle]
pub extern "C" fn topoloc_map_edge_count(
    map: *const topoloc_map,
    out: *mut usize,
) -> topoloc_status {
    handle_value(map, "map", out, "out", |m| m.edge_count())
}

/// Descriptor dimension D (`*out`).
#[no_mangle]
pub extern "C" fn topoloc_map_descriptor_dim(
    map: *const topoloc_map,
    out: *mut u32,
) -> topoloc_status {
    handle_value(map, "map", out, "out", |m| m.descriptor().dim)
}

/// Copies the descriptor kind (NUL-terminated) into `buf` of `len` bytes. `*needed` (if not
/// NULL) receives the size required including the NUL, also on `TOPOLOC_ERR_BUFFER_TOO_SMALL`.
#[no_mangle]
pub extern "C" fn topoloc_map_descriptor_kind(
    map: *const topoloc_map,
    buf: *mut c_char,
    len: usize,
    needed: *mut usize,
) -> topoloc_status {
    map_string(map, buf, len, needed, |m| m.descriptor().kind.clone())
}

/// Copies the descriptor model identity; same contract as `topoloc_map_descriptor_kind`.
#[no_mangle]
pub extern "C" fn topoloc_map_descriptor_model(
    map: *const topoloc_map,
    buf: *mut c_char,
    len: usize,
    needed: *mut usize,
) -> topoloc_status {
    map_string(map, buf, len, needed, |m| m.descriptor().model.clone())
}

fn map_string(
    map: *const topoloc_map,
    buf: *mut c_char,
    len: usize,
    needed: *mut usize,
    read: impl FnOnce(&Map) -> String,
) -> topoloc_status {
    run(|| {
        let text = read(try_ref(map, "map")?);
        copy_c_string(text.as_bytes(), buf, len, needed)
    })
}

/// Copies the neighbours of `place` into `buf` (capacity `len`). `*count` (if not NULL) receives
/// the number of neighbours, also on `TOPOLOC_ERR_BUFFER_TOO_SMALL`. Errors: `_UNKNOWN_PLACE`.
#[no_mangle]
pub extern "C" fn topoloc_map_neighbours(
    map: *const topoloc_map,
    place: u32,
    buf: *mut u32,
    len: usize,
    count: *mut usize,
) -> topoloc_status {
    run_on(map, "map", |map| {
        let (ids, _) = map.neighbours(place)?;
        write_array(ids, buf, len, count)
    })
}

/// Copies the view ids of `place`; same contract as `topoloc_map_neighbours`.
#[no_mangle]
pub extern "C" fn topoloc_map_place_views(
    map: *const topoloc_map,
    place: u32,
    buf: *mut u32,
    len: usize,
    count: *mut usize,
) -> topoloc_status {
    run_on(map, "map", |map| {
        let views = map.place_views(place)?;
        write_array(views, buf, len, count)
    })
}

/// Position of `place` in metres: `*has_position` says whether the map has one; `xyz` (3
/// doubles) receives it, or zeros. Errors: `_UNKNOWN_PLACE`.
#[no_mangle]
pub extern "C" fn topoloc_map_place_position(
    map: *const topoloc_map,
    place: u32,
    xyz: *mut f64,
    has_position: *mut bool,
) -> topoloc_status {
    run_on(map, "map", |map| {
        let position = map.place_position(place)?;
        check_out(xyz, "xyz")?;
        check_out(has_position, "has_position")?;
        let p = position.map_or([0.0; 3], |p| [p.x, p.y, p.z]);
        write_array(&p, xyz, 3, std::ptr::null_mut())?;
        write_out(has_position, position.is_some());
        Ok(())
    })
}

/// Edge number `index` (0..edge_count, sorted by (a, b)): places `*a < *b` and `*weight`.
#[no_mangle]
pub extern "C" fn topoloc_map_edge(
    map: *const topoloc_map,
    index: usize,
    a: *mut u32,
    b: *mut u32,
    weight: *mut f32,
) -> topoloc_status {
    run_on(map, "map", |map| {
        let parts = |e: Edge| (e.a, e.b, e.weight);
        write_edge(map.edges(), index, "map", parts, (a, b, weight), "weight")
    })
}

/// The body of `topoloc_map_edge` and `topoloc_graph_edge`: edge `index` of the `edges` of a
/// `what` (map, graph), split by `parts` into its two places and its value, is written to the
/// out-parameters `(a, b, value)`, the last named `value_name`; all three are checked first.
pub(crate) fn write_edge<E: Copy, T>(
    edges: &[E],
    index: usize,
    what: &str,
    parts: impl FnOnce(E) -> (u32, u32, T),
    (a, b, value): (*mut u32, *mut u32, *mut T),
    value_name: &str,
) -> Result<(), FfiError> {
    let edge = *edges.get(index).ok_or_else(|| {
        FfiError::invalid(format!(
            "edge index {index} out of range (the {what} has {} edges)",
            edges.len()
        ))
    })?;
    check_out(a, "a")?;
    check_out(b, "b")?;
    check_out(value, value_name)?;
    let (edge_a, edge_b, edge_value) = parts(edge);
    write_out(a, edge_a);
    write_out(b, edge_b);
    write_out(value, edge_value);
    Ok(())
}

/// Attributes of one view, filled by `topoloc_map_view_info`. Initialise with
/// `topoloc_view_info_default` (which sets `struct_size`) before the call.
#[repr(C)]
#[derive(Clone, Copy)]
#[allow(non_snake_case)]
pub struct topoloc_view_info {
    /// `sizeof(topoloc_view_info)`, set by the caller.
    pub struct_size: usize,
    /// Place the view belongs to.
    pub place: u32,
    /// Whether `keyframe_id` is set.
    pub has_keyframe_id: bool,
    /// Host keyframe id.
    pub keyframe_id: u64,
    /// Whether `world_T_camera` is set.
    pub has_pose: bool,
    /// Camera pose, row-major 4x4 (identity when absent).
    pub world_T_camera: [f64; 16],
}

versioned! {
    topoloc_view_info {
        Self {
            place: 0,
            has_keyframe_id: false,
            keyframe_id: 0,
            has_pose: false,
            world_T_camera: [0.0; 16],
        }
    }
}

/// Fills the first `size` bytes of `*info` with an empty view info and sets `struct_size`; call
/// it through the header macro `topoloc_view_info_default(info)`, which passes `sizeof *(info)`.
#[no_mangle]
pub extern "C" fn topoloc_view_info_init(
    info: *mut topoloc_view_info,
    size: usize,
) -> topoloc_status {
    init_versioned(info, size, "info")
}

/// Fills `*out` with the attributes of `view`. Errors: `_UNKNOWN_VIEW`.
#[no_mangle]
pub extern "C" fn topoloc_map_view_info(
    map: *const topoloc_map,
    view: u32,
    out: *mut topoloc_view_info,
) -> topoloc_status {
    run_on(map, "map", |map| {
        let record = map.view(view)?;
        let pose = record
            .world_t_camera
            .unwrap_or_else(nalgebra::Isometry3::identity);
        write_versioned(
            out,
            topoloc_view_info {
                place: record.place,
                has_keyframe_id: record.keyframe_id.is_some(),
                keyframe_id: record.keyframe_id.unwrap_or(0),
                has_pose: record.world_t_camera.is_some(),
                world_T_camera: pose_to_row_major(&pose),
                ..topoloc_view_info::default()
            },
            "out",
        )
    })
}

/// Copies the image reference of `view` (NUL-terminated, "" when none); same buffer contract as
/// `topoloc_map_descriptor_kind`.
#[no_mangle]
pub extern "C" fn topoloc_map_view_image(
    map: *const topoloc_map,
    view: u32,
    buf: *mut c_char,
    len: usize,
    needed: *mut usize,
) -> topoloc_status {
    run_on(map, "map", |map| {
        let record = map.view(view)?;
        copy_c_string(
            record.image.as_deref().unwrap_or("").as_bytes(),
            buf,
            len,
            needed,
        )
    })
}

/// Copies the unit-norm descriptor of `view` (D floats) into `buf` of capacity `len`.
/// Errors: `_UNKNOWN_VIEW`, `_BUFFER_TOO_SMALL` when `len < D`.
#[no_mangle]
pub extern "C" fn topoloc_map_view_descriptor(
    map: *const topoloc_map,
    view: u32,
    buf: *mut f32,
    len: usize,
) -> topoloc_status {
    run_on(map, "map", |map| {
        let descriptor = map.view_descriptor(view)?;
        write_array(descriptor, buf, len, std::ptr::null_mut())
    })
}
