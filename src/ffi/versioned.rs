//! Caller-owned structs with a leading `struct_size` (options, frames, results): the only way
//! the library reads or writes them, so that a caller compiled against an older, shorter layout
//! is never read or written past its end.

use super::boundary::{check_out, run};
use super::error::FfiError;
use super::status::topoloc_status::{self, *};

/// Structs passed across the ABI whose first field is `struct_size`, so that fields can be
/// appended in later versions. `Default` is what `_init` writes and what fields beyond a
/// caller's layout read as; implement both with [`versioned!`].
pub(crate) trait Versioned: Copy + Default {
    /// Sizes of the published layouts, oldest first; the last is `size_of::<Self>()`.
    const LAYOUTS: &'static [usize];
}

/// Implements [`Versioned`] and `Default` for a versioned struct:
/// `versioned!(T [f, g] { let ...; Self { fields } })` publishes the layouts that end before
/// fields `f` and `g` (oldest first; none when the struct never grew) and then the whole struct,
/// and makes `T::default()` the given fields with `struct_size` set to `size_of::<T>()`.
macro_rules! versioned {
    (
        $ty:ident $([$($ended_before:ident),+ $(,)?])? {
            $(let $binding:pat = $init:expr;)*
            Self { $($field:ident: $value:expr),+ $(,)? }
        }
    ) => {
        impl $crate::ffi::versioned::Versioned for $ty {
            const LAYOUTS: &'static [usize] = &[
                $($(std::mem::offset_of!(Self, $ended_before),)+)?
                std::mem::size_of::<Self>(),
            ];
        }

        impl Default for $ty {
            fn default() -> Self {
                $(let $binding = $init;)*
                Self {
                    struct_size: std::mem::size_of::<Self>(),
                    $($field: $value),+
                }
            }
        }
    };
}
pub(crate) use versioned;

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
/// size or larger ([`layout_bytes`]); fields beyond the caller's layout read as their defaults.
pub(crate) fn read_versioned<T: Versioned>(ptr: *const T, name: &str) -> Result<T, FfiError> {
    let copy = struct_size_of(ptr, name)?;
    let mut value = T::default();
    // SAFETY: the caller's struct is at least `copy` bytes long (its struct_size says so), `copy`
    // ends on a field boundary of T, and `value` is a T, so the first `copy` bytes of both are
    // valid to copy.
    unsafe {
        std::ptr::copy_nonoverlapping(ptr.cast::<u8>(), (&mut value as *mut T).cast::<u8>(), copy)
    };
    Ok(value)
}

/// Like [`read_versioned`] for the arguments that may be NULL (options): NULL reads as
/// `T::default()`.
pub(crate) fn read_optional<T: Versioned>(ptr: *const T, name: &str) -> Result<T, FfiError> {
    if ptr.is_null() {
        Ok(T::default())
    } else {
        read_versioned(ptr, name)
    }
}

/// Checks a caller's output struct (non-NULL, a published `struct_size`) before anything is
/// computed or changed; [`write_versioned`] fills it on success.
pub(crate) fn check_versioned<T: Versioned>(ptr: *mut T, name: &str) -> Result<(), FfiError> {
    struct_size_of(ptr.cast_const(), name).map(|_| ())
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
