//! Status codes of the C ABI: one enum (what cbindgen writes into the header) and one table of
//! names and descriptions beside it, matched exhaustively so that a new code cannot lack
//! either. `topoloc_status_str` and `topoloc_status_name` read the table; the C++ and Python
//! layers are tested against it.

use std::ffi::CStr;

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
    /// The handle is in use by another call (ABI 1.13): two threads used one localizer, loop
    /// detector, describer or map builder at once, or a callback re-entered it. The call did
    /// nothing; the other call goes on unaffected.
    TOPOLOC_ERR_CONCURRENT_USE = 6,
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
    /// Every status, in numeric order.
    pub(crate) const ALL: &'static [topoloc_status] = &[
        TOPOLOC_OK,
        TOPOLOC_ERR_NULL_ARGUMENT,
        TOPOLOC_ERR_INVALID_ARGUMENT,
        TOPOLOC_ERR_BUFFER_TOO_SMALL,
        TOPOLOC_ERR_STRUCT_SIZE,
        TOPOLOC_ERR_INVALID_UTF8,
        TOPOLOC_ERR_CONCURRENT_USE,
        TOPOLOC_ERR_IO,
        TOPOLOC_ERR_NOT_A_MAP,
        TOPOLOC_ERR_TRUNCATED,
        TOPOLOC_ERR_CORRUPT,
        TOPOLOC_ERR_UNSUPPORTED_VERSION,
        TOPOLOC_ERR_DESCRIPTOR_MISMATCH,
        TOPOLOC_ERR_EMPTY_MAP,
        TOPOLOC_ERR_INVALID_MAP,
        TOPOLOC_ERR_UNKNOWN_PLACE,
        TOPOLOC_ERR_UNKNOWN_VIEW,
        TOPOLOC_ERR_DIMENSION_MISMATCH,
        TOPOLOC_ERR_NON_FINITE,
        TOPOLOC_ERR_ZERO_DESCRIPTOR,
        TOPOLOC_ERR_TIMESTAMP,
        TOPOLOC_ERR_INVALID_OPTION,
        TOPOLOC_ERR_INVALID_IMAGE,
        TOPOLOC_ERR_UNINFORMATIVE_IMAGE,
        TOPOLOC_ERR_BACKEND_UNAVAILABLE,
        TOPOLOC_ERR_MODEL,
        TOPOLOC_ERR_NO_DESCRIBER,
        TOPOLOC_ERR_CANCELLED,
        TOPOLOC_ERR_PANIC,
    ];

    /// The status with this numeric value, if there is one.
    pub(crate) fn from_code(code: u32) -> Option<Self> {
        Self::ALL.iter().copied().find(|&s| s as u32 == code)
    }

    /// The status' C name (`"TOPOLOC_ERR_IO"`) and its short English description.
    pub(crate) fn entry(self) -> (&'static CStr, &'static CStr) {
        match self {
            TOPOLOC_OK => (c"TOPOLOC_OK", c"ok"),
            TOPOLOC_ERR_NULL_ARGUMENT => (
                c"TOPOLOC_ERR_NULL_ARGUMENT",
                c"a required pointer argument is NULL",
            ),
            TOPOLOC_ERR_INVALID_ARGUMENT => (c"TOPOLOC_ERR_INVALID_ARGUMENT", c"invalid argument"),
            TOPOLOC_ERR_BUFFER_TOO_SMALL => (c"TOPOLOC_ERR_BUFFER_TOO_SMALL", c"buffer too small"),
            TOPOLOC_ERR_STRUCT_SIZE => (c"TOPOLOC_ERR_STRUCT_SIZE", c"unknown struct_size"),
            TOPOLOC_ERR_INVALID_UTF8 => (c"TOPOLOC_ERR_INVALID_UTF8", c"string is not valid UTF-8"),
            TOPOLOC_ERR_CONCURRENT_USE => (
                c"TOPOLOC_ERR_CONCURRENT_USE",
                c"handle in use by another call",
            ),
            TOPOLOC_ERR_IO => (c"TOPOLOC_ERR_IO", c"I/O error"),
            TOPOLOC_ERR_NOT_A_MAP => (c"TOPOLOC_ERR_NOT_A_MAP", c"not a topoloc map"),
            TOPOLOC_ERR_TRUNCATED => (c"TOPOLOC_ERR_TRUNCATED", c"truncated map file"),
            TOPOLOC_ERR_CORRUPT => (c"TOPOLOC_ERR_CORRUPT", c"corrupt map file"),
            TOPOLOC_ERR_UNSUPPORTED_VERSION => (
                c"TOPOLOC_ERR_UNSUPPORTED_VERSION",
                c"unsupported map format version",
            ),
            TOPOLOC_ERR_DESCRIPTOR_MISMATCH => {
                (c"TOPOLOC_ERR_DESCRIPTOR_MISMATCH", c"descriptor mismatch")
            }
            TOPOLOC_ERR_EMPTY_MAP => (c"TOPOLOC_ERR_EMPTY_MAP", c"empty map"),
            TOPOLOC_ERR_INVALID_MAP => (c"TOPOLOC_ERR_INVALID_MAP", c"invalid map"),
            TOPOLOC_ERR_UNKNOWN_PLACE => (c"TOPOLOC_ERR_UNKNOWN_PLACE", c"unknown place"),
            TOPOLOC_ERR_UNKNOWN_VIEW => (c"TOPOLOC_ERR_UNKNOWN_VIEW", c"unknown view"),
            TOPOLOC_ERR_DIMENSION_MISMATCH => (
                c"TOPOLOC_ERR_DIMENSION_MISMATCH",
                c"descriptor dimension mismatch",
            ),
            TOPOLOC_ERR_NON_FINITE => (c"TOPOLOC_ERR_NON_FINITE", c"NaN or infinite value"),
            TOPOLOC_ERR_ZERO_DESCRIPTOR => (c"TOPOLOC_ERR_ZERO_DESCRIPTOR", c"all-zero descriptor"),
            TOPOLOC_ERR_TIMESTAMP => (c"TOPOLOC_ERR_TIMESTAMP", c"timestamp goes backwards"),
            TOPOLOC_ERR_INVALID_OPTION => {
                (c"TOPOLOC_ERR_INVALID_OPTION", c"invalid localizer option")
            }
            TOPOLOC_ERR_INVALID_IMAGE => (c"TOPOLOC_ERR_INVALID_IMAGE", c"invalid image"),
            TOPOLOC_ERR_UNINFORMATIVE_IMAGE => {
                (c"TOPOLOC_ERR_UNINFORMATIVE_IMAGE", c"uninformative image")
            }
            TOPOLOC_ERR_BACKEND_UNAVAILABLE => (
                c"TOPOLOC_ERR_BACKEND_UNAVAILABLE",
                c"descriptor backend unavailable",
            ),
            TOPOLOC_ERR_MODEL => (c"TOPOLOC_ERR_MODEL", c"model error"),
            TOPOLOC_ERR_NO_DESCRIBER => (c"TOPOLOC_ERR_NO_DESCRIBER", c"no describer for images"),
            TOPOLOC_ERR_CANCELLED => (c"TOPOLOC_ERR_CANCELLED", c"cancelled"),
            TOPOLOC_ERR_PANIC => (c"TOPOLOC_ERR_PANIC", c"internal error (panic caught)"),
        }
    }
}
