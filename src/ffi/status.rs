//! Status codes of the C ABI: one enum (what cbindgen writes into the header, with its codes
//! and docs) and one table of descriptions beside it, whose completeness the compiler checks.
//! `topoloc_status_str` and `topoloc_status_name` read them; the C++ and Python layers build
//! their own tables from those two functions.

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

/// The description table: each status (in numeric order) with the short English description
/// that `topoloc_status_str` returns. Its C name comes from the variant itself, and a match
/// generated from the list fails to compile when the enum gains a variant the list lacks.
macro_rules! status_table {
    ($($status:ident => $text:literal,)*) => {
        impl topoloc_status {
            /// Every status, in numeric order, with its C name and its description.
            const TABLE: &'static [(topoloc_status, &'static CStr, &'static CStr)] = &[
                $((
                    topoloc_status::$status,
                    c_str(concat!(stringify!($status), "\0")),
                    c_str(concat!($text, "\0")),
                ),)*
            ];
        }

        /// Compiles only while the table names every status.
        #[allow(dead_code)]
        fn every_status_is_in_the_table(status: topoloc_status) {
            match status {
                $(topoloc_status::$status => {})*
            }
        }
    };
}

/// A C string from a literal ending in NUL (checked at compile time).
const fn c_str(text: &'static str) -> &'static CStr {
    match CStr::from_bytes_with_nul(text.as_bytes()) {
        Ok(c) => c,
        Err(_) => panic!("a status table string holds a NUL"),
    }
}

status_table! {
    TOPOLOC_OK => "ok",
    TOPOLOC_ERR_NULL_ARGUMENT => "a required pointer argument is NULL",
    TOPOLOC_ERR_INVALID_ARGUMENT => "invalid argument",
    TOPOLOC_ERR_BUFFER_TOO_SMALL => "buffer too small",
    TOPOLOC_ERR_STRUCT_SIZE => "unknown struct_size",
    TOPOLOC_ERR_INVALID_UTF8 => "string is not valid UTF-8",
    TOPOLOC_ERR_CONCURRENT_USE => "handle in use by another call",
    TOPOLOC_ERR_IO => "I/O error",
    TOPOLOC_ERR_NOT_A_MAP => "not a topoloc map",
    TOPOLOC_ERR_TRUNCATED => "truncated map file",
    TOPOLOC_ERR_CORRUPT => "corrupt map file",
    TOPOLOC_ERR_UNSUPPORTED_VERSION => "unsupported map format version",
    TOPOLOC_ERR_DESCRIPTOR_MISMATCH => "descriptor mismatch",
    TOPOLOC_ERR_EMPTY_MAP => "empty map",
    TOPOLOC_ERR_INVALID_MAP => "invalid map",
    TOPOLOC_ERR_UNKNOWN_PLACE => "unknown place",
    TOPOLOC_ERR_UNKNOWN_VIEW => "unknown view",
    TOPOLOC_ERR_DIMENSION_MISMATCH => "descriptor dimension mismatch",
    TOPOLOC_ERR_NON_FINITE => "NaN or infinite value",
    TOPOLOC_ERR_ZERO_DESCRIPTOR => "all-zero descriptor",
    TOPOLOC_ERR_TIMESTAMP => "timestamp goes backwards",
    TOPOLOC_ERR_INVALID_OPTION => "invalid localizer option",
    TOPOLOC_ERR_INVALID_IMAGE => "invalid image",
    TOPOLOC_ERR_UNINFORMATIVE_IMAGE => "uninformative image",
    TOPOLOC_ERR_BACKEND_UNAVAILABLE => "descriptor backend unavailable",
    TOPOLOC_ERR_MODEL => "model error",
    TOPOLOC_ERR_NO_DESCRIBER => "no describer for images",
    TOPOLOC_ERR_CANCELLED => "cancelled",
    TOPOLOC_ERR_PANIC => "internal error (panic caught)",
}

impl topoloc_status {
    /// Every status, in numeric order.
    pub(crate) fn all() -> impl Iterator<Item = topoloc_status> {
        Self::TABLE.iter().map(|&(status, _, _)| status)
    }

    /// The status with this numeric value, if there is one.
    pub(crate) fn from_code(code: u32) -> Option<Self> {
        Self::all().find(|&s| s as u32 == code)
    }

    /// The status' C name (`"TOPOLOC_ERR_IO"`) and its short English description.
    pub(crate) fn entry(self) -> (&'static CStr, &'static CStr) {
        let &(_, name, text) = Self::TABLE
            .iter()
            .find(|&&(status, _, _)| status == self)
            .expect("every status is in the table (checked at compile time)");
        (name, text)
    }
}
