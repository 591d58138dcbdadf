//! The mechanics every entry point shares: status codes, the thread-local last error, the panic
//! boundary, and checked conversions of raw pointers. All unsafe pointer handling of the C ABI
//! goes through the helpers here.

use crate::build::ImageMapError;
use crate::descriptor::{DescriptorError, IdentityError};
use crate::errors::VisionError;
use crate::localize::LocalizeError;
use crate::map::MapError;
use crate::skeleton::SkeletonError;
use std::cell::RefCell;
use std::ffi::{c_char, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// Result of every fallible C function. Values are grouped in ranges and never renumbered;
/// retired codes stay reserved.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[allow(non_camel_case_types)]
pub enum topoloc_status {
    /// Success.
    TOPOLOC_OK = 0,
    // 1..99: arguments
    /// A required pointer argument was NULL.
    TOPOLOC_ERR_NULL_ARGUMENT = 1,
    /// An argument is out of its valid range; the last error message names it.
    TOPOLOC_ERR_INVALID_ARGUMENT = 2,
    /// A caller buffer is too small; the `needed`/`count` out-parameter holds the size required.
    TOPOLOC_ERR_BUFFER_TOO_SMALL = 3,
    /// An options or result struct has a `struct_size` this library does not know.
    TOPOLOC_ERR_STRUCT_SIZE = 4,
    /// A string argument is not valid UTF-8.
    TOPOLOC_ERR_INVALID_UTF8 = 5,
    // 100..199: maps and map files
    /// Reading or writing a file failed.
    TOPOLOC_ERR_IO = 100,
    /// The file is not a topoloc map.
    TOPOLOC_ERR_NOT_A_MAP = 101,
    /// The map file ends early.
    TOPOLOC_ERR_TRUNCATED = 102,
    /// The map file is damaged (checksum, inconsistent arrays, invalid values).
    TOPOLOC_ERR_CORRUPT = 103,
    /// The map file has a newer major format version.
    TOPOLOC_ERR_UNSUPPORTED_VERSION = 104,
    /// The map was built with another descriptor than the caller uses.
    TOPOLOC_ERR_DESCRIPTOR_MISMATCH = 105,
    /// The map (or the input to a builder) has no places.
    TOPOLOC_ERR_EMPTY_MAP = 106,
    /// The map being built is inconsistent (e.g. a place without views).
    TOPOLOC_ERR_INVALID_MAP = 107,
    /// A place index is out of range.
    TOPOLOC_ERR_UNKNOWN_PLACE = 108,
    /// A view index is out of range.
    TOPOLOC_ERR_UNKNOWN_VIEW = 109,
    // 200..299: frames and descriptors
    /// A descriptor has the wrong number of values.
    TOPOLOC_ERR_DIMENSION_MISMATCH = 200,
    /// A descriptor, pose or number is NaN or infinite.
    TOPOLOC_ERR_NON_FINITE = 201,
    /// A descriptor is all zeros.
    TOPOLOC_ERR_ZERO_DESCRIPTOR = 202,
    /// A frame timestamp is earlier than the previous frame's.
    TOPOLOC_ERR_TIMESTAMP = 203,
    /// A localizer option is out of range.
    TOPOLOC_ERR_INVALID_OPTION = 204,
    // 300..399: images and descriptor backends
    /// An image buffer is unusable (size, stride, length, pixel format); the message says why.
    TOPOLOC_ERR_INVALID_IMAGE = 300,
    /// The image carries no place information (blank, constant, no local feature): the frame
    /// was not localized and the localizer state is unchanged.
    TOPOLOC_ERR_UNINFORMATIVE_IMAGE = 301,
    /// A runtime or model file is missing or cannot be loaded; the message names every path tried.
    TOPOLOC_ERR_BACKEND_UNAVAILABLE = 302,
    /// The model file loaded but does not work (corrupt, missing outputs, run error).
    TOPOLOC_ERR_MODEL = 303,
    /// The frame has an image but the localizer cannot describe images (the map stores no
    /// describer, or the localizer was created with `TOPOLOC_BACKEND_NONE`).
    TOPOLOC_ERR_NO_DESCRIBER = 304,
    /// The progress callback asked to stop.
    TOPOLOC_ERR_CANCELLED = 305,
    // 900..999: internal
    /// A bug inside topoloc was caught at the boundary; the object involved should be freed.
    TOPOLOC_ERR_PANIC = 900,
}

use topoloc_status::*;

impl topoloc_status {
    /// Short static description of a status code.
    pub(crate) fn description(code: u32) -> &'static CStr {
        match code {
            0 => c"ok",
            1 => c"a required pointer argument is NULL",
            2 => c"invalid argument",
            3 => c"buffer too small",
            4 => c"unknown struct_size",
            5 => c"string is not valid UTF-8",
            100 => c"I/O error",
            101 => c"not a topoloc map",
            102 => c"truncated map file",
            103 => c"corrupt map file",
            104 => c"unsupported map format version",
            105 => c"descriptor mismatch",
            106 => c"empty map",
            107 => c"invalid map",
            108 => c"unknown place",
            109 => c"unknown view",
            200 => c"descriptor dimension mismatch",
            201 => c"NaN or infinite value",
            202 => c"all-zero descriptor",
            203 => c"timestamp goes backwards",
            204 => c"invalid localizer option",
            300 => c"invalid image",
            301 => c"uninformative image",
            302 => c"descriptor backend unavailable",
            303 => c"model error",
            304 => c"no describer for images",
            305 => c"cancelled",
            900 => c"internal error (panic caught)",
            _ => c"unknown status code",
        }
    }
}

/// An error on its way out through the C ABI: a status and the message for
/// `topoloc_last_error_message`.
#[derive(Debug)]
pub(crate) struct FfiError {
    pub status: topoloc_status,
    pub message: String,
}

impl FfiError {
    pub fn new(status: topoloc_status, message: impl Into<String>) -> Self {
        Self {
            status,
            message: message.into(),
        }
    }

    pub fn null(name: &str) -> Self {
        Self::new(
            TOPOLOC_ERR_NULL_ARGUMENT,
            format!("argument '{name}' is NULL"),
        )
    }

    pub fn invalid(message: impl Into<String>) -> Self {
        Self::new(TOPOLOC_ERR_INVALID_ARGUMENT, message)
    }
}

impl From<DescriptorError> for FfiError {
    fn from(e: DescriptorError) -> Self {
        let status = match e {
            DescriptorError::Dimension { .. } => TOPOLOC_ERR_DIMENSION_MISMATCH,
            DescriptorError::NonFinite => TOPOLOC_ERR_NON_FINITE,
            DescriptorError::Zero => TOPOLOC_ERR_ZERO_DESCRIPTOR,
        };
        Self::new(status, e.to_string())
    }
}

impl From<MapError> for FfiError {
    fn from(e: MapError) -> Self {
        let status = match &e {
            MapError::Io { .. } => TOPOLOC_ERR_IO,
            MapError::NotAMap(_) => TOPOLOC_ERR_NOT_A_MAP,
            MapError::Truncated(_) => TOPOLOC_ERR_TRUNCATED,
            MapError::Corrupt(_) => TOPOLOC_ERR_CORRUPT,
            MapError::UnsupportedVersion { .. } => TOPOLOC_ERR_UNSUPPORTED_VERSION,
            MapError::DescriptorMismatch { .. } => TOPOLOC_ERR_DESCRIPTOR_MISMATCH,
            MapError::EmptyMap => TOPOLOC_ERR_EMPTY_MAP,
            MapError::UnknownPlace { .. } => TOPOLOC_ERR_UNKNOWN_PLACE,
            MapError::UnknownView { .. } => TOPOLOC_ERR_UNKNOWN_VIEW,
            MapError::Descriptor(d) => return FfiError::from(d.clone()),
            MapError::NonFinite(_) => TOPOLOC_ERR_NON_FINITE,
            MapError::InvalidArgument(_) => TOPOLOC_ERR_INVALID_ARGUMENT,
            MapError::Invalid(_) => TOPOLOC_ERR_INVALID_MAP,
        };
        Self::new(status, e.to_string())
    }
}

impl From<IdentityError> for FfiError {
    fn from(e: IdentityError) -> Self {
        MapError::from(e).into()
    }
}

impl From<SkeletonError> for FfiError {
    fn from(e: SkeletonError) -> Self {
        match e {
            SkeletonError::InvalidArgument(_) => Self::invalid(e.to_string()),
        }
    }
}

impl From<LocalizeError> for FfiError {
    fn from(e: LocalizeError) -> Self {
        match e {
            LocalizeError::Descriptor(d) => d.into(),
            LocalizeError::Map(m) => m.into(),
            LocalizeError::InvalidOption(_) => Self::new(TOPOLOC_ERR_INVALID_OPTION, e.to_string()),
            LocalizeError::Timestamp(ref msg) if msg.contains("not finite") => {
                Self::new(TOPOLOC_ERR_NON_FINITE, e.to_string())
            }
            LocalizeError::Timestamp(_) => Self::new(TOPOLOC_ERR_TIMESTAMP, e.to_string()),
            LocalizeError::Odometry(_) => Self::new(TOPOLOC_ERR_NON_FINITE, e.to_string()),
            LocalizeError::Describe(d) => d.into(),
            LocalizeError::NoDescriber(_) => Self::new(TOPOLOC_ERR_NO_DESCRIBER, e.to_string()),
            // verify_candidates > 0 on a map without keypoints.
            LocalizeError::Verification(_) | LocalizeError::Metric(_) => {
                Self::new(TOPOLOC_ERR_INVALID_OPTION, e.to_string())
            }
        }
    }
}

impl From<VisionError> for FfiError {
    fn from(e: VisionError) -> Self {
        let status = match &e {
            VisionError::InvalidImage(_) => TOPOLOC_ERR_INVALID_IMAGE,
            VisionError::InvalidArgument(_) => TOPOLOC_ERR_INVALID_ARGUMENT,
            VisionError::BackendUnavailable { .. } => TOPOLOC_ERR_BACKEND_UNAVAILABLE,
            VisionError::Model(_) | VisionError::OpenCv(_) => TOPOLOC_ERR_MODEL,
            VisionError::Uninformative(_) => TOPOLOC_ERR_UNINFORMATIVE_IMAGE,
            VisionError::Mismatch(_) => TOPOLOC_ERR_DESCRIPTOR_MISMATCH,
        };
        Self::new(status, e.to_string())
    }
}

impl From<ImageMapError> for FfiError {
    fn from(e: ImageMapError) -> Self {
        let message = e.to_string();
        let status = match e {
            ImageMapError::Image { error, .. } | ImageMapError::Describe(error) => {
                FfiError::from(error).status
            }
            ImageMapError::Map(m) => FfiError::from(m).status,
            ImageMapError::Cancelled => TOPOLOC_ERR_CANCELLED,
        };
        Self::new(status, message)
    }
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_last_error(message: &str) {
    let text = CString::new(message.replace('\0', " ")).expect("NULs replaced");
    LAST_ERROR.with(|e| *e.borrow_mut() = text);
}

/// Copies the calling thread's last error message into `buf` (see `topoloc_last_error_message`).
/// Does not itself change the last error.
pub(crate) fn copy_last_error(buf: *mut c_char, len: usize, needed: *mut usize) -> topoloc_status {
    LAST_ERROR.with(
        |e| match copy_c_string(e.borrow().to_bytes(), buf, len, needed) {
            Ok(()) => TOPOLOC_OK,
            Err(err) => err.status,
        },
    )
}

/// Runs an entry point's body: converts its error into a status and the thread's last error
/// message, and turns a panic into `TOPOLOC_ERR_PANIC` so that no unwinding crosses the ABI.
pub(crate) fn run(body: impl FnOnce() -> Result<(), FfiError>) -> topoloc_status {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => TOPOLOC_OK,
        Ok(Err(e)) => {
            set_last_error(&e.message);
            e.status
        }
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            set_last_error(&format!("internal error (panic): {what}"));
            TOPOLOC_ERR_PANIC
        }
    }
}

/// Like [`run`] for functions that return nothing (the `_free` functions): a panic is swallowed
/// after recording the message.
pub(crate) fn run_void(body: impl FnOnce()) {
    let _ = run(|| {
        body();
        Ok(())
    });
}

/// Borrows `*ptr`, or fails naming the NULL argument.
pub(crate) fn borrow<'a, T>(ptr: *const T, name: &str) -> Result<&'a T, FfiError> {
    // SAFETY: the C caller guarantees a non-NULL pointer points to a valid, live T.
    unsafe { ptr.as_ref() }.ok_or_else(|| FfiError::null(name))
}

/// Mutably borrows `*ptr`, or fails naming the NULL argument.
pub(crate) fn borrow_mut<'a, T>(ptr: *mut T, name: &str) -> Result<&'a mut T, FfiError> {
    // SAFETY: as for `borrow`, and the caller does not alias the object during the call.
    unsafe { ptr.as_mut() }.ok_or_else(|| FfiError::null(name))
}

/// Checks that an out-parameter is non-NULL; write through it with [`write_out`] on success only.
pub(crate) fn check_out<T>(ptr: *mut T, name: &str) -> Result<(), FfiError> {
    if ptr.is_null() {
        Err(FfiError::null(name))
    } else {
        Ok(())
    }
}

/// Writes an out-parameter checked with [`check_out`].
pub(crate) fn write_out<T>(ptr: *mut T, value: T) {
    // SAFETY: checked non-NULL by `check_out`; the caller provides writable storage for a T.
    unsafe { ptr.write(value) }
}

/// Views `(ptr, len)` as a slice; `len == 0` gives an empty slice whatever `ptr` is.
pub(crate) fn slice<'a, T>(ptr: *const T, len: usize, name: &str) -> Result<&'a [T], FfiError> {
    if len == 0 {
        return Ok(&[]);
    }
    if ptr.is_null() {
        return Err(FfiError::null(name));
    }
    if len
        .checked_mul(std::mem::size_of::<T>())
        .is_none_or(|bytes| bytes > isize::MAX as usize)
    {
        return Err(FfiError::invalid(format!(
            "length of '{name}' is too large"
        )));
    }
    // SAFETY: the caller guarantees `len` readable, initialised Ts at `ptr`.
    Ok(unsafe { std::slice::from_raw_parts(ptr, len) })
}

/// Reads a required NUL-terminated UTF-8 string.
pub(crate) fn string<'a>(ptr: *const c_char, name: &str) -> Result<&'a str, FfiError> {
    if ptr.is_null() {
        return Err(FfiError::null(name));
    }
    // SAFETY: the caller guarantees a NUL-terminated string.
    unsafe { CStr::from_ptr(ptr) }.to_str().map_err(|_| {
        FfiError::new(
            topoloc_status::TOPOLOC_ERR_INVALID_UTF8,
            format!("'{name}' is not valid UTF-8"),
        )
    })
}

/// Reads an optional string: NULL and "" both mean "not given".
pub(crate) fn optional_string(ptr: *const c_char, name: &str) -> Result<Option<String>, FfiError> {
    if ptr.is_null() {
        return Ok(None);
    }
    let s = string(ptr, name)?;
    Ok((!s.is_empty()).then(|| s.to_string()))
}

/// Copies `text` plus a NUL into `buf` of `len` bytes. `needed` (if non-NULL) always receives
/// the size required including the NUL; a too-small buffer gives `TOPOLOC_ERR_BUFFER_TOO_SMALL`.
pub(crate) fn copy_c_string(
    text: &[u8],
    buf: *mut c_char,
    len: usize,
    needed: *mut usize,
) -> Result<(), FfiError> {
    let required = text.len() + 1;
    if !needed.is_null() {
        write_out(needed, required);
    }
    if len < required {
        return Err(FfiError::new(
            TOPOLOC_ERR_BUFFER_TOO_SMALL,
            format!("buffer of {len} bytes, {required} needed"),
        ));
    }
    check_out(buf, "buf")?;
    // SAFETY: `buf` has room for `len >= required` bytes per the caller's contract.
    unsafe {
        std::ptr::copy_nonoverlapping(text.as_ptr().cast::<c_char>(), buf, text.len());
        buf.add(text.len()).write(0);
    }
    Ok(())
}

/// Copies `values` into the caller's `(buf, len)`. `count` (if non-NULL) always receives
/// `values.len()`; a too-small buffer fails with `TOPOLOC_ERR_BUFFER_TOO_SMALL`.
pub(crate) fn write_array<T: Copy>(
    values: &[T],
    buf: *mut T,
    len: usize,
    count: *mut usize,
) -> Result<(), FfiError> {
    if !count.is_null() {
        write_out(count, values.len());
    }
    if len < values.len() {
        return Err(FfiError::new(
            TOPOLOC_ERR_BUFFER_TOO_SMALL,
            format!("buffer holds {len} elements, {} needed", values.len()),
        ));
    }
    if values.is_empty() {
        return Ok(());
    }
    check_out(buf, "buf")?;
    // SAFETY: `buf` has room for `len >= values.len()` elements per the caller's contract.
    unsafe { std::ptr::copy_nonoverlapping(values.as_ptr(), buf, values.len()) };
    Ok(())
}

/// Structs passed across the ABI whose first field is `struct_size`, so that fields can be
/// appended in later versions.
pub(crate) trait Versioned: Copy {
    /// Sizes of the published layouts, oldest first; the last is `size_of::<Self>()`.
    const LAYOUTS: &'static [usize];
}

/// How many bytes of a caller's struct of `size` bytes this library reads or writes: the size of
/// the newest layout it knows when the caller's is that or larger (a newer caller), else the
/// caller's size, which must then be a published layout. Sizes below the first layout, or
/// between two layouts (they would cut a field in two), are refused with
/// `TOPOLOC_ERR_STRUCT_SIZE`.
fn layout_bytes<T: Versioned>(size: usize, name: &str) -> Result<usize, FfiError> {
    let newest = std::mem::size_of::<T>();
    if size >= newest {
        return Ok(newest);
    }
    if T::LAYOUTS.contains(&size) {
        return Ok(size);
    }
    let reason = if size < T::LAYOUTS[0] {
        format!("at least {} expected", T::LAYOUTS[0])
    } else {
        format!("not a published layout ({:?} or more)", T::LAYOUTS)
    };
    Err(FfiError::new(
        TOPOLOC_ERR_STRUCT_SIZE,
        format!(
            "'{name}'.struct_size is {size}, {reason}; initialise it with its _default() function"
        ),
    ))
}

/// Reads a versioned struct written by the caller: `struct_size` must be a published layout
/// size or larger ([`layout_bytes`]); fields beyond the caller's layout keep their values from
/// `defaults`.
pub(crate) fn read_versioned<T: Versioned>(
    ptr: *const T,
    defaults: T,
    name: &str,
) -> Result<T, FfiError> {
    let copy = struct_size_of(ptr, name)?;
    let mut value = defaults;
    // SAFETY: the caller's struct is at least `copy` bytes long (its struct_size says so), `copy`
    // ends on a field boundary of T, and `value` is a T, so the first `copy` bytes of both are
    // valid to copy.
    unsafe {
        std::ptr::copy_nonoverlapping(ptr.cast::<u8>(), (&mut value as *mut T).cast::<u8>(), copy)
    };
    Ok(value)
}

/// Reads the leading `struct_size` field of a caller's versioned struct and returns how many of
/// its bytes this library uses ([`layout_bytes`]).
pub(crate) fn struct_size_of<T: Versioned>(ptr: *const T, name: &str) -> Result<usize, FfiError> {
    if ptr.is_null() {
        return Err(FfiError::null(name));
    }
    // SAFETY: every versioned struct starts with a `size_t struct_size`.
    let size = unsafe { ptr.cast::<usize>().read_unaligned() };
    layout_bytes::<T>(size, name)
}

/// Body of the `*_init(ptr, size)` functions behind the header's `*_default(ptr)` macros:
/// writes `T::default()` up to the layout `size` allows ([`layout_bytes`]) and sets
/// `struct_size` to that count, so that a library newer than the caller's header never writes
/// past the caller's struct.
pub(crate) fn init_versioned<T: Versioned + Default>(
    ptr: *mut T,
    size: usize,
    name: &str,
) -> topoloc_status {
    run(|| {
        check_out(ptr, name)?;
        let written = layout_bytes::<T>(size, name)?;
        let value = T::default();
        // SAFETY: the caller provides `size >= written` writable bytes at `ptr`; `value` is a T of
        // at least `written` bytes; every versioned struct starts with a `size_t struct_size`.
        unsafe {
            std::ptr::copy_nonoverlapping(
                (&value as *const T).cast::<u8>(),
                ptr.cast::<u8>(),
                written,
            );
            ptr.cast::<usize>().write_unaligned(written);
        }
        Ok(())
    })
}

/// Writes an output struct into the caller's storage, up to the caller's layout
/// ([`layout_bytes`]) and keeping the caller's `struct_size`.
pub(crate) fn write_versioned<T: Versioned>(
    ptr: *mut T,
    value: T,
    name: &str,
) -> Result<(), FfiError> {
    // SAFETY: every versioned struct starts with a `size_t struct_size`.
    let size = if ptr.is_null() {
        0
    } else {
        unsafe { ptr.cast::<usize>().read_unaligned() }
    };
    let written = struct_size_of(ptr as *const T, name)?;
    // SAFETY: the caller's struct is `size >= written` bytes long (its struct_size says so).
    unsafe {
        std::ptr::copy_nonoverlapping((&value as *const T).cast::<u8>(), ptr.cast::<u8>(), written);
        ptr.cast::<usize>().write_unaligned(size);
    }
    Ok(())
}

/// Moves a handle's Rust value to the heap and gives C its pointer (freed by [`free_handle`]).
pub(crate) fn into_handle<T>(value: T) -> *mut T {
    Box::into_raw(Box::new(value))
}

/// Body of the `_free` functions: drops a handle made with `Box::into_raw`; NULL is a no-op.
pub(crate) fn free_handle<T>(ptr: *mut T) {
    run_void(|| {
        if !ptr.is_null() {
            // SAFETY: the C contract: `ptr` came from this library's `_new`/`_load` function for
            // this handle type and is freed once.
            drop(unsafe { Box::from_raw(ptr) });
        }
    })
}
