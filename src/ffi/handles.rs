//! Typed handles: every opaque C handle type is tied, once, to the Rust value behind it and to
//! how that value is owned (a `Box` or an `Arc`), so that all pointer casts of the ABI happen
//! here and a cast to the wrong type or the wrong owner does not compile.
//!
//! A handle type is an empty struct (C sees `typedef struct topoloc_x topoloc_x;`) with a
//! [`Castable`] impl. `Box` handles are created by [`new_box`], borrowed by [`try_ref`] /
//! [`try_mut`] and dropped by [`free_box`]; `Arc` handles by [`new_arc`], [`try_ref`],
//! [`clone_arc`] (a new strong reference, e.g. a localizer keeping its map) and [`free_arc`].

use super::boundary::run_void;
use super::error::FfiError;
use std::marker::PhantomData;
use std::sync::Arc;

/// The handle owns its value through `Box::into_raw`: one owner, mutable through `T*`.
pub(crate) struct OwnedBox;

/// The handle is one strong reference of an `Arc` (`Arc::into_raw`): shared and immutable.
pub(crate) struct OwnedArc;

/// Ties an opaque C handle type to the Rust value it points to and to its ownership.
pub(crate) trait Castable {
    /// [`OwnedBox`] or [`OwnedArc`].
    type Ownership;
    /// The Rust value a handle of this type points to.
    type RustType;
}

/// The body of an opaque handle type: no fields C could see, not constructible from Rust, and
/// neither `Send` nor `Sync` by accident (the pointee decides that).
pub(crate) type Opaque = PhantomData<*mut ()>;

/// Moves `value` to the heap and returns the handle C will own (release with [`free_box`]).
pub(crate) fn new_box<C: Castable<Ownership = OwnedBox>>(value: C::RustType) -> *mut C {
    Box::into_raw(Box::new(value)).cast::<C>()
}

/// Drops a handle made by [`new_box`]; NULL is a no-op; a panic in the drop is contained.
pub(crate) fn free_box<C: Castable<Ownership = OwnedBox>>(handle: *mut C) {
    run_void(|| {
        if !handle.is_null() {
            // SAFETY: the C contract: `handle` came from `new_box` for this handle type (the
            // trait bound makes the pointee type `C::RustType`) and is freed once.
            drop(unsafe { Box::from_raw(handle.cast::<C::RustType>()) });
        }
    })
}

/// Gives C one strong reference of `value` (release with [`free_arc`]).
pub(crate) fn new_arc<C: Castable<Ownership = OwnedArc>>(value: Arc<C::RustType>) -> *mut C {
    Arc::into_raw(value).cast::<C>().cast_mut()
}

/// Releases the strong reference a handle made by [`new_arc`] holds; NULL is a no-op.
pub(crate) fn free_arc<C: Castable<Ownership = OwnedArc>>(handle: *const C) {
    run_void(|| {
        if !handle.is_null() {
            // SAFETY: `handle` came from `new_arc` for this handle type and is released once.
            drop(unsafe { Arc::from_raw(handle.cast::<C::RustType>()) });
        }
    })
}

/// A new strong reference to the value behind an `Arc` handle, or an error naming the NULL
/// argument.
pub(crate) fn clone_arc<C: Castable<Ownership = OwnedArc>>(
    handle: *const C,
    name: &str,
) -> Result<Arc<C::RustType>, FfiError> {
    if handle.is_null() {
        return Err(FfiError::null(name));
    }
    let raw = handle.cast::<C::RustType>();
    // SAFETY: `handle` came from `new_arc` and is live (C contract), so its strong count is at
    // least one; incrementing it first makes the `Arc` built here an additional owner.
    unsafe {
        Arc::increment_strong_count(raw);
        Ok(Arc::from_raw(raw))
    }
}

/// Borrows the value behind a handle of either ownership, or fails naming the NULL argument.
pub(crate) fn try_ref<'a, C: Castable>(
    handle: *const C,
    name: &str,
) -> Result<&'a C::RustType, FfiError> {
    // SAFETY: a non-NULL handle came from `new_box` / `new_arc` for this type and is live for
    // the call (C contract); both point at a `C::RustType`.
    unsafe { handle.cast::<C::RustType>().as_ref() }.ok_or_else(|| FfiError::null(name))
}

/// Mutably borrows the value behind a `Box` handle (an `Arc` handle is shared, so this does not
/// compile for one), or fails naming the NULL argument.
pub(crate) fn try_mut<'a, C: Castable<Ownership = OwnedBox>>(
    handle: *mut C,
    name: &str,
) -> Result<&'a mut C::RustType, FfiError> {
    // SAFETY: as for `try_ref`, and the C caller does not use the handle from another thread
    // during the call (documented per type).
    unsafe { handle.cast::<C::RustType>().as_mut() }.ok_or_else(|| FfiError::null(name))
}
