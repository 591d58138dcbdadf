//! C functions that build maps: the incremental builder and the keyframe path.

use super::boundary::{convert_each, fill_out, optional_string, run, slice, string};
use super::convert::optional_pose;
use super::error::FfiError;
use super::handles::{castable, free_exclusive, new_exclusive, run_on, run_on_mut, Opaque};
use super::map::{map_handle, topoloc_map};
use super::topoloc_status;
use super::versioned::{init_versioned, read_optional, versioned};
use crate::build::{from_keyframes, Keyframe, KeyframeOptions};
use crate::descriptor::DescriptorIdentity;
use crate::map::{MapBuilder, ViewAttributes};
use nalgebra::Point3;
use std::ffi::c_char;

/// Collects places, views and edges for a new map. Created by `topoloc_map_builder_new`,
/// released by `topoloc_map_builder_free`. Not thread-safe: use from one thread at a time. A call made while another call uses it
/// (another thread, or a callback re-entering it) fails with `TOPOLOC_ERR_CONCURRENT_USE` and
/// changes nothing (ABI 1.13).
pub struct topoloc_map_builder(Opaque);

castable!(topoloc_map_builder: OwnedExclusive => MapBuilder);

/// Starts a map whose vectors come from descriptor `kind` / `model` with dimension `dim`
/// (`model` may be NULL). On success `*out` owns a new builder.
/// Errors: `_INVALID_ARGUMENT` (empty kind, dim 0 or above 65,536).
#[no_mangle]
pub extern "C" fn topoloc_map_builder_new(
    kind: *const c_char,
    model: *const c_char,
    dim: u32,
    out: *mut *mut topoloc_map_builder,
) -> topoloc_status {
    run(|| {
        let identity = identity(kind, model, dim)?;
        fill_out(out, "out", || {
            Ok(new_exclusive::<topoloc_map_builder>(MapBuilder::new(
                identity,
            )))
        })
    })
}

fn identity(
    kind: *const c_char,
    model: *const c_char,
    dim: u32,
) -> Result<DescriptorIdentity, FfiError> {
    let kind = string(kind, "kind")?;
    let model = optional_string(model, "model")?.unwrap_or_default();
    Ok(DescriptorIdentity::new(kind, model, dim)?)
}

/// Releases a builder. `NULL` is a no-op.
#[no_mangle]
pub extern "C" fn topoloc_map_builder_free(builder: *mut topoloc_map_builder) {
    free_exclusive(builder)
}

/// Adds a place; `position` (3 doubles, metres) may be NULL. `*place_out` receives its id.
#[no_mangle]
pub extern "C" fn topoloc_map_builder_add_place(
    builder: *mut topoloc_map_builder,
    position: *const f64,
    place_out: *mut u32,
) -> topoloc_status {
    run_on_mut(builder, "builder", |builder| {
        fill_out(place_out, "place_out", || {
            let position = match position.is_null() {
                true => None,
                false => {
                    let p = slice(position, 3, "position")?;
                    Some(Point3::new(p[0], p[1], p[2]))
                }
            };
            Ok(builder.add_place(position)?)
        })
    })
}

/// Optional attributes of a view. Initialise with `topoloc_view_attributes_default`.
#[repr(C)]
#[derive(Clone, Copy)]
#[allow(non_snake_case)]
pub struct topoloc_view_attributes {
    /// `sizeof(topoloc_view_attributes)`, set by the `_default` function.
    pub struct_size: usize,
    /// Whether `keyframe_id` is set.
    pub has_keyframe_id: bool,
    /// Host keyframe id.
    pub keyframe_id: u64,
    /// Camera pose, 16 doubles row-major 4x4; NULL = none.
    pub world_T_camera: *const f64,
    /// Image reference (path or URI), NUL-terminated UTF-8; NULL = none.
    pub image: *const c_char,
}

versioned! {
    topoloc_view_attributes {
        Self {
            has_keyframe_id: false,
            keyframe_id: 0,
            world_T_camera: std::ptr::null(),
            image: std::ptr::null(),
        }
    }
}

/// Fills the first `size` bytes of `*attributes` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_view_attributes_default(attributes)`, which passes `sizeof *(attributes)`.
#[no_mangle]
pub extern "C" fn topoloc_view_attributes_init(
    attributes: *mut topoloc_view_attributes,
    size: usize,
) -> topoloc_status {
    init_versioned(attributes, size, "attributes")
}

/// Adds a view with `descriptor` (`len` floats, normalised here) to `place`; `attributes` may be
/// NULL. `*view_out` receives its id. On error the builder is unchanged.
/// Errors: `_UNKNOWN_PLACE`, `_DIMENSION_MISMATCH`, `_NON_FINITE`, `_ZERO_DESCRIPTOR`, `_INVALID_ARGUMENT`.
#[no_mangle]
pub extern "C" fn topoloc_map_builder_add_view(
    builder: *mut topoloc_map_builder,
    place: u32,
    descriptor: *const f32,
    len: usize,
    attributes: *const topoloc_view_attributes,
    view_out: *mut u32,
) -> topoloc_status {
    run_on_mut(builder, "builder", |builder| {
        let descriptor = slice(descriptor, len, "descriptor")?;
        fill_out(view_out, "view_out", || {
            let a = read_optional(attributes, "attributes")?;
            let attributes = ViewAttributes {
                keyframe_id: a.has_keyframe_id.then_some(a.keyframe_id),
                world_t_camera: optional_pose(a.world_T_camera, "attributes.world_T_camera")?,
                image: optional_string(a.image, "attributes.image")?,
            };
            Ok(builder.add_view(place, descriptor, attributes)?)
        })
    })
}

/// Joins places `a` and `b` (different, existing, not yet joined) with weight > 0.
#[no_mangle]
pub extern "C" fn topoloc_map_builder_add_edge(
    builder: *mut topoloc_map_builder,
    a: u32,
    b: u32,
    weight: f32,
) -> topoloc_status {
    run_on_mut(builder, "builder", |builder| {
        builder.add_edge(a, b, weight)?;
        Ok(())
    })
}

/// Validates and produces a map from what was added; the builder stays usable. On success
/// `*out` owns a new map. Errors: `_EMPTY_MAP`, `_INVALID_MAP` (e.g. a place without views).
#[no_mangle]
pub extern "C" fn topoloc_map_builder_build(
    builder: *const topoloc_map_builder,
    out: *mut *mut topoloc_map,
) -> topoloc_status {
    run_on(builder, "builder", |builder| {
        fill_out(out, "out", || Ok(map_handle(builder.build()?)))
    })
}

/// One keyframe for `topoloc_map_from_keyframes`. Array element: its layout never changes.
#[repr(C)]
#[derive(Clone, Copy)]
#[allow(non_snake_case)]
pub struct topoloc_keyframe {
    /// Host keyframe id, stored with the view it becomes.
    pub id: u64,
    /// Global descriptor.
    pub descriptor: *const f32,
    /// Number of floats at `descriptor` (must equal the map's D).
    pub descriptor_len: usize,
    /// Camera pose, 16 doubles row-major 4x4; NULL = none (then NULL for every keyframe).
    pub world_T_camera: *const f64,
}

/// Parameters of `topoloc_map_from_keyframes`. Initialise with `topoloc_keyframe_options_default`.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_keyframe_options {
    /// `sizeof(topoloc_keyframe_options)`, set by the `_default` function.
    pub struct_size: usize,
    /// Distance (m) within which a keyframe joins an existing place.
    pub place_spacing_m: f64,
    /// Cosine similarity below which a keyframe's appearance is novel.
    pub novelty_similarity: f32,
    /// Places closer than this (m) are joined by an edge.
    pub neighbour_radius_m: f64,
    /// Most views per place.
    pub max_views_per_place: u32,
}

versioned! {
    topoloc_keyframe_options {
        let d = KeyframeOptions::default();
        Self {
            place_spacing_m: d.place_spacing_m,
            novelty_similarity: d.novelty_similarity,
            neighbour_radius_m: d.neighbour_radius_m,
            max_views_per_place: d.max_views_per_place,
        }
    }
}

/// Fills the first `size` bytes of `*options` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_keyframe_options_default(options)`, which passes `sizeof *(options)`.
#[no_mangle]
pub extern "C" fn topoloc_keyframe_options_init(
    options: *mut topoloc_keyframe_options,
    size: usize,
) -> topoloc_status {
    init_versioned(options, size, "options")
}

/// Builds a map from `count` keyframes in order (places by spacing and appearance novelty, edges
/// between consecutive and nearby places). `options` may be NULL. On success `*out` owns a new map.
/// Errors: `_EMPTY_MAP`, `_INVALID_ARGUMENT` (bad keyframe or option; the message names it).
#[no_mangle]
pub extern "C" fn topoloc_map_from_keyframes(
    kind: *const c_char,
    model: *const c_char,
    dim: u32,
    keyframes: *const topoloc_keyframe,
    count: usize,
    options: *const topoloc_keyframe_options,
    out: *mut *mut topoloc_map,
) -> topoloc_status {
    run(|| {
        let identity = identity(kind, model, dim)?;
        let raw = slice(keyframes, count, "keyframes")?;
        fill_out(out, "out", || {
            let o = read_optional(options, "options")?;
            let options = KeyframeOptions {
                place_spacing_m: o.place_spacing_m,
                novelty_similarity: o.novelty_similarity,
                neighbour_radius_m: o.neighbour_radius_m,
                max_views_per_place: o.max_views_per_place,
            };
            let keyframes = convert_each(raw, "keyframes", |k, name| {
                Ok(Keyframe {
                    id: k.id,
                    descriptor: slice(
                        k.descriptor,
                        k.descriptor_len,
                        &format!("{name}.descriptor"),
                    )?,
                    world_t_camera: optional_pose(
                        k.world_T_camera,
                        &format!("{name}.world_T_camera"),
                    )?,
                })
            })?;
            Ok(map_handle(from_keyframes(identity, &keyframes, &options)?))
        })
    })
}
