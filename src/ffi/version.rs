//! Version and error-text functions.

use super::boundary::{copy_last_error, topoloc_status};
use std::ffi::{c_char, CStr};

/// ABI version: bumped only when an existing C signature or struct layout changes
/// incompatibly (which the project avoids: it adds functions and appends struct fields).
pub const TOPOLOC_ABI_VERSION: u32 = 1;

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

/// Static English description of a status code (never free it); unknown codes give
/// "unknown status code".
#[no_mangle]
pub extern "C" fn topoloc_status_str(status: u32) -> *const c_char {
    topoloc_status::description(status).as_ptr()
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
