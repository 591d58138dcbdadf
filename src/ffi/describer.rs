//! C functions of the describer (ABI 1.12): a map's describer on its own, so that a host with
//! images computes the global descriptors it gives a loop detector (or a keyframe builder)
//! exactly as the map's views were described.

use super::boundary::{optional_string, slice, write_array, write_optional};
use super::error::FfiError;
use super::handles::{castable, free_exclusive, handle_value, new_exclusive, run_on_mut, Opaque};
use super::images::{backend_family, backend_kind, image_view, topoloc_backend, topoloc_image};
use super::map::{new_on_map, topoloc_map};
use super::topoloc_status;
use super::versioned::{init_versioned, versioned};
use crate::describe::onnx::OnnxOptions;
use crate::describe::{Describer, DescriberOptions};
use crate::localize::LocalizeError;
use crate::map::Map;
use std::ffi::c_char;

/// Describes images as a map's views were described. Created by `topoloc_describer_new`,
/// released by `topoloc_describer_free`; it does not keep the map alive (the describer model
/// is shared). Single-threaded state: one thread at a time (it may move between threads). A call made while another call uses it
/// (another thread, or a callback re-entering it) fails with `TOPOLOC_ERR_CONCURRENT_USE` and
/// changes nothing (ABI 1.13).
pub struct topoloc_describer(Opaque);

/// The describer and the buffer its descriptors are written to.
pub(crate) struct DescriberState {
    describer: Describer,
    scratch: Vec<f32>,
}

castable!(topoloc_describer: OwnedExclusive => DescriberState);

/// Where the describer finds its runtime files. Initialise with
/// `topoloc_describer_options_default`.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_describer_options {
    /// `sizeof(topoloc_describer_options)`, set by the `_default` function.
    pub struct_size: usize,
    /// `TOPOLOC_BACKEND_AUTO` (default) accepts the map's backend; `_ONNX` or `_VLAD_*`
    /// require it (else `_DESCRIPTOR_MISMATCH`); `_NONE` is `_INVALID_OPTION`.
    pub backend: topoloc_backend,
    /// ONNX model file; NULL or "" = the cache's default. Must be the map's model (by hash).
    pub onnx_model_path: *const c_char,
    /// ONNX Runtime library; NULL or "" = `TOPOLOC_ORT_LIBRARY`, `ORT_DYLIB_PATH`, the cache.
    pub onnx_runtime_path: *const c_char,
    /// ONNX Runtime intra-op threads.
    pub threads: u32,
}

versioned! {
    topoloc_describer_options {
        Self {
            backend: super::images::TOPOLOC_BACKEND_AUTO,
            onnx_model_path: std::ptr::null(),
            onnx_runtime_path: std::ptr::null(),
            threads: 1,
        }
    }
}

/// The Rust describer options a backend code and two optional C paths stand for (shared with
/// the localizer, whose options carry the same three fields).
pub(crate) fn describer_options(
    backend: topoloc_backend,
    onnx_model_path: *const c_char,
    onnx_runtime_path: *const c_char,
    threads: usize,
) -> Result<DescriberOptions, FfiError> {
    Ok(DescriberOptions {
        backend: backend_kind(backend, None)?,
        family: backend_family(backend).map(Into::into),
        onnx_runtime: optional_string(onnx_runtime_path, "options.onnx_runtime_path")?
            .map(Into::into),
        onnx_model: optional_string(onnx_model_path, "options.onnx_model_path")?.map(Into::into),
        threads,
    })
}

/// The describer `map` stores, loaded with the options' backend, paths and threads (shared
/// with the keyframe describer), and the describer options used.
pub(crate) fn map_describer(
    map: &Map,
    backend: topoloc_backend,
    onnx_model_path: *const c_char,
    onnx_runtime_path: *const c_char,
    threads: u32,
) -> Result<(Describer, DescriberOptions), FfiError> {
    if backend == super::images::TOPOLOC_BACKEND_NONE {
        return Err(FfiError::invalid_option(
            "a describer needs a backend: TOPOLOC_BACKEND_NONE describes nothing",
        ));
    }
    OnnxOptions::THREADS_RANGE
        .check("threads", threads)
        .map_err(FfiError::invalid_option)?;
    let model = map.describer().cloned().ok_or_else(|| {
        LocalizeError::NoDescriber(format!(
            "the map ({}) stores no describer; it was built from descriptors, not images",
            map.descriptor()
        ))
    })?;
    let options = describer_options(
        backend,
        onnx_model_path,
        onnx_runtime_path,
        threads as usize,
    )?;
    Ok((Describer::new(model, &options)?, options))
}

/// Fills `*options` with the defaults. Call through the header macro
/// `topoloc_describer_options_default(options)`, which passes `sizeof *(options)`.
#[no_mangle]
pub extern "C" fn topoloc_describer_options_init(
    options: *mut topoloc_describer_options,
    size: usize,
) -> topoloc_status {
    init_versioned(options, size, "options")
}

/// Loads the describer `map` stores (for ONNX: the runtime and the model, checked by hash).
/// `options` may be NULL for defaults. On success `*out` owns a new describer.
/// Errors: `_NO_DESCRIBER` (the map was built from descriptors), `_BACKEND_UNAVAILABLE` (paths
/// tried in the message), `_DESCRIPTOR_MISMATCH`, `_MODEL`, `_INVALID_OPTION`.
#[no_mangle]
pub extern "C" fn topoloc_describer_new(
    map: *const topoloc_map,
    options: *const topoloc_describer_options,
    out: *mut *mut topoloc_describer,
) -> topoloc_status {
    new_on_map(map, options, out, |map, o: topoloc_describer_options| {
        let (describer, _) = map_describer(
            &map,
            o.backend,
            o.onnx_model_path,
            o.onnx_runtime_path,
            o.threads,
        )?;
        Ok(new_exclusive::<topoloc_describer>(DescriberState {
            describer,
            scratch: Vec::new(),
        }))
    })
}

/// Releases a describer; NULL is a no-op.
#[no_mangle]
pub extern "C" fn topoloc_describer_free(describer: *mut topoloc_describer) {
    free_exclusive(describer);
}

/// Writes the descriptor dimension D (the map's) to `*out`.
#[no_mangle]
pub extern "C" fn topoloc_describer_dim(
    describer: *const topoloc_describer,
    out: *mut usize,
) -> topoloc_status {
    handle_value(describer, "describer", out, "out", |state| {
        state.describer.identity().dim as usize
    })
}

/// Describes `image` into `descriptor` (capacity `capacity` floats): D values of unit norm,
/// comparable with the map's. `*len` (if not NULL) receives D, also on
/// `_BUFFER_TOO_SMALL`. The image is read only during the call.
/// Errors: `_INVALID_IMAGE` (also `TOPOLOC_PIXEL_NONE`), `_UNINFORMATIVE_IMAGE` (no content, e.g. a
/// constant image), `_BUFFER_TOO_SMALL`, `_MODEL`.
#[no_mangle]
pub extern "C" fn topoloc_describer_describe(
    describer: *mut topoloc_describer,
    image: *const topoloc_image,
    descriptor: *mut f32,
    capacity: usize,
    len: *mut usize,
) -> topoloc_status {
    run_on_mut(describer, "describer", |state| {
        let image = &slice(image, 1, "image")?[0];
        let view = image_view(image, "image")?.ok_or_else(|| {
            FfiError::new(
                topoloc_status::TOPOLOC_ERR_INVALID_IMAGE,
                "'image.format' is TOPOLOC_PIXEL_NONE: there is no image to describe".to_string(),
            )
        })?;
        let dim = state.describer.identity().dim as usize;
        if capacity < dim {
            // The size contract of `write_array`, checked before the forward pass is paid for.
            write_optional(len, dim);
            return Err(FfiError::new(
                topoloc_status::TOPOLOC_ERR_BUFFER_TOO_SMALL,
                format!("buffer holds {capacity} floats, {dim} needed"),
            ));
        }
        state.describer.describe(&view, &mut state.scratch)?;
        write_array(&state.scratch, descriptor, capacity, len)
    })
}
