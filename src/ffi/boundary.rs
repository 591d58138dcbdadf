//! The mechanics every entry point shares: the panic boundary, the thread-local last error, and
//! checked views of caller memory (pointers, slices, strings, output buffers). Handles are in
//! `handles.rs`, versioned structs in `versioned.rs`.

use super::error::FfiError;
use super::status::topoloc_status::{self, *};
use std::cell::RefCell;
use std::ffi::{c_char, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_last_error(message: &str) {
    let text = CString::new(message.replace('\0', " ")).expect("NULs replaced");
    LAST_ERROR.with(|e| *e.borrow_mut() = text);
}

/// Records `error` as the calling thread's last error, for entry points that return no status.
pub(crate) fn record_error(error: &FfiError) {
    set_last_error(&error.message);
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

/// Checks that an out-parameter is non-NULL; write through it with [`write_out`] on success only.
pub(crate) fn check_out<T>(ptr: *mut T, name: &str) -> Result<(), FfiError> {
    if ptr.is_null() {
        Err(FfiError::null(name))
    } else {
        Ok(())
    }
}

/// Writes an optional out-parameter (a size the caller may not want): NULL is skipped.
pub(crate) fn write_optional<T>(ptr: *mut T, value: T) {
    if !ptr.is_null() {
        write_out(ptr, value);
    }
}

/// Writes an out-parameter checked with [`check_out`].
pub(crate) fn write_out<T>(ptr: *mut T, value: T) {
    // SAFETY: checked non-NULL by `check_out`; the caller provides writable storage for a T.
    unsafe { ptr.write(value) }
}

/// The body of an out-parameter: checks that `ptr` is non-NULL, then computes `value` and
/// writes it only when that succeeds.
pub(crate) fn fill_out<T>(
    ptr: *mut T,
    name: &str,
    value: impl FnOnce() -> Result<T, FfiError>,
) -> Result<(), FfiError> {
    check_out(ptr, name)?;
    write_out(ptr, value()?);
    Ok(())
}

/// Converts each element of the C array `items` named `name`, passing `convert` the element's
/// name for messages (`name[i]`); the first error stops.
pub(crate) fn convert_each<'a, T, U>(
    items: &'a [T],
    name: &str,
    mut convert: impl FnMut(&'a T, &str) -> Result<U, FfiError>,
) -> Result<Vec<U>, FfiError> {
    items
        .iter()
        .enumerate()
        .map(|(i, element)| convert(element, &format!("{name}[{i}]")))
        .collect()
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
    write_optional(needed, required);
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
    write_optional(count, values.len());
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
