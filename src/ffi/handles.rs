//! Typed handles: every opaque C handle type is tied, once, to the Rust value behind it and to
//! how that value is owned (a `Box` or an `Arc`), so that all pointer casts of the ABI happen
//! here and a cast to the wrong type or the wrong owner does not compile.
//!
//! A handle type is an empty struct (C sees `typedef struct topoloc_x topoloc_x;`) with a
//! [`Castable`] impl ([`castable!`]). `Box` handles are created by [`new_box`], borrowed by [`try_ref`] and
//! dropped by [`free_box`]; `Arc` handles by [`new_arc`], [`try_ref`],
//! [`clone_arc`] (a new strong reference, e.g. a localizer keeping its map) and [`free_arc`].
//! `Exclusive` handles (per-camera state that C must use from one thread at a time) are
//! created by [`new_exclusive`], entered by [`enter`] (which refuses a second, concurrent call
//! with `TOPOLOC_ERR_CONCURRENT_USE` instead of letting two threads share a `&mut`) and dropped
//! by [`free_exclusive`].

use super::boundary::{fill_out, run, run_void};
use super::error::FfiError;
use super::status::topoloc_status;
use std::cell::UnsafeCell;
use std::marker::PhantomData;
use std::ops::{Deref, DerefMut};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The handle owns its value through `Box::into_raw`: one owner, mutable through `T*`.
pub(crate) struct OwnedBox;

/// The handle is one strong reference of an `Arc` (`Arc::into_raw`): shared and immutable.
pub(crate) struct OwnedArc;

/// The handle owns an [`Exclusive`] through `Box::into_raw`: one owner, and every call on it
/// (reading or writing) enters it through [`enter`], one call at a time.
pub(crate) struct OwnedExclusive;

/// Ownerships whose handles point straight at the Rust value ([`try_ref`] may borrow them).
pub(crate) trait Direct {}
impl Direct for OwnedBox {}
impl Direct for OwnedArc {}

/// Ties an opaque C handle type to the Rust value it points to and to its ownership.
pub(crate) trait Castable {
    /// [`OwnedBox`] or [`OwnedArc`].
    type Ownership;
    /// The Rust value a handle of this type points to.
    type RustType;
}

/// Ties a handle type to its Rust value and ownership:
/// `castable!(topoloc_map: OwnedArc => Map);`.
macro_rules! castable {
    ($handle:ident: $ownership:ident => $rust:ty) => {
        impl $crate::ffi::handles::Castable for $handle {
            type Ownership = $crate::ffi::handles::$ownership;
            type RustType = $rust;
        }
    };
}
pub(crate) use castable;

/// The body of an opaque handle type (`pub struct topoloc_x(Opaque);`): no fields C could see, not constructible from Rust, and
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
pub(crate) fn try_ref<'a, C>(handle: *const C, name: &str) -> Result<&'a C::RustType, FfiError>
where
    C: Castable,
    C::Ownership: Direct,
{
    // SAFETY: a non-NULL handle came from `new_box` / `new_arc` for this type and is live for
    // the call (C contract); both point at a `C::RustType`.
    unsafe { handle.cast::<C::RustType>().as_ref() }.ok_or_else(|| FfiError::null(name))
}

/// Ownerships a call may read a value through: borrowed ([`try_ref`]) or entered ([`enter`]).
pub(crate) trait Readable: Sized {
    /// Runs `read` on the value behind `handle`, or fails as [`try_ref`] or [`enter`] does.
    fn read<C: Castable<Ownership = Self>, R>(
        handle: *const C,
        name: &str,
        read: impl FnOnce(&C::RustType) -> R,
    ) -> Result<R, FfiError>;
}

impl<O: Direct> Readable for O {
    fn read<C: Castable<Ownership = Self>, R>(
        handle: *const C,
        name: &str,
        read: impl FnOnce(&C::RustType) -> R,
    ) -> Result<R, FfiError> {
        Ok(read(try_ref(handle, name)?))
    }
}

impl Readable for OwnedExclusive {
    fn read<C: Castable<Ownership = Self>, R>(
        handle: *const C,
        name: &str,
        read: impl FnOnce(&C::RustType) -> R,
    ) -> Result<R, FfiError> {
        Ok(read(&*enter(handle, name)?))
    }
}

/// The body of an accessor that writes one value read from a handle (`name`) to the
/// out-parameter `out` (`out_name`): the handle is checked first, then `out`.
pub(crate) fn handle_value<C, T>(
    handle: *const C,
    name: &str,
    out: *mut T,
    out_name: &str,
    read: impl FnOnce(&C::RustType) -> T,
) -> topoloc_status
where
    C: Castable,
    C::Ownership: Readable,
{
    run_on(handle, name, |value| {
        fill_out(out, out_name, || Ok(read(value)))
    })
}

/// Runs an entry point's body ([`run`]) on the value behind `handle` (`name`), which is checked
/// first.
pub(crate) fn run_on<C>(
    handle: *const C,
    name: &str,
    body: impl FnOnce(&C::RustType) -> Result<(), FfiError>,
) -> topoloc_status
where
    C: Castable,
    C::Ownership: Readable,
{
    run(|| C::Ownership::read(handle, name, body)?)
}

/// [`run_on`] for the calls that change the value behind an `Exclusive` handle.
pub(crate) fn run_on_mut<C: Castable<Ownership = OwnedExclusive>>(
    handle: *mut C,
    name: &str,
    body: impl FnOnce(&mut C::RustType) -> Result<(), FfiError>,
) -> topoloc_status {
    run(|| body(&mut *enter(handle, name)?))
}

/// A value that one call at a time may use, checked: the busy flag is taken with one atomic
/// compare-exchange when a call enters and released when it leaves, so a second thread (or a
/// callback re-entering the handle) gets `TOPOLOC_ERR_CONCURRENT_USE` and the value is never
/// borrowed mutably twice.
pub(crate) struct Exclusive<T> {
    busy: AtomicBool,
    value: UnsafeCell<T>,
}

// SAFETY: the value is only reached through `InUse`, which the busy flag makes unique, so
// sharing an `Exclusive` between threads shares no `&T` or `&mut T` at once; moving the value
// between threads needs `T: Send`.
unsafe impl<T: Send> Sync for Exclusive<T> {}

impl<T> Exclusive<T> {
    fn new(value: T) -> Self {
        Self {
            busy: AtomicBool::new(false),
            value: UnsafeCell::new(value),
        }
    }

    /// The value for one call, or `TOPOLOC_ERR_CONCURRENT_USE` naming `name` when another call
    /// is using it.
    fn enter(&self, name: &str) -> Result<InUse<'_, T>, FfiError> {
        self.busy
            .compare_exchange(false, true, Ordering::Acquire, Ordering::Relaxed)
            .map_err(|_| FfiError::concurrent_use(name))?;
        Ok(InUse { owner: self })
    }
}

/// One call's unique access to an [`Exclusive`] value; leaving the call releases it.
pub(crate) struct InUse<'a, T> {
    owner: &'a Exclusive<T>,
}

impl<T> Deref for InUse<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        // SAFETY: the busy flag taken in `enter` makes this the only access until drop.
        unsafe { &*self.owner.value.get() }
    }
}

impl<T> DerefMut for InUse<'_, T> {
    fn deref_mut(&mut self) -> &mut T {
        // SAFETY: as for `deref`.
        unsafe { &mut *self.owner.value.get() }
    }
}

impl<T> Drop for InUse<'_, T> {
    fn drop(&mut self) {
        self.owner.busy.store(false, Ordering::Release);
    }
}

/// Moves `value` to the heap behind a busy flag and returns the handle C will own (release
/// with [`free_exclusive`]).
pub(crate) fn new_exclusive<C: Castable<Ownership = OwnedExclusive>>(value: C::RustType) -> *mut C {
    Box::into_raw(Box::new(Exclusive::new(value))).cast::<C>()
}

/// Enters the value behind an `Exclusive` handle for one call: fails naming the NULL argument,
/// or with `TOPOLOC_ERR_CONCURRENT_USE` while another call uses the handle.
pub(crate) fn enter<'a, C: Castable<Ownership = OwnedExclusive>>(
    handle: *const C,
    name: &str,
) -> Result<InUse<'a, C::RustType>, FfiError> {
    // SAFETY: a non-NULL handle came from `new_exclusive` for this type and is live for the
    // call (C contract); only shared references to the `Exclusive` are formed.
    let exclusive = unsafe { handle.cast::<Exclusive<C::RustType>>().as_ref() }
        .ok_or_else(|| FfiError::null(name))?;
    exclusive.enter(name)
}

/// Drops a handle made by [`new_exclusive`]; NULL is a no-op. A handle that another call is
/// still using is not freed under it: it is leaked, and the calling thread's last error says so
/// (freeing a handle in use is the caller's bug; leaking is the only safe answer).
pub(crate) fn free_exclusive<C: Castable<Ownership = OwnedExclusive>>(handle: *mut C) {
    run_void(|| {
        if handle.is_null() {
            return;
        }
        let raw = handle.cast::<Exclusive<C::RustType>>();
        // SAFETY: as for `enter`.
        let in_use = unsafe { &*raw }.busy.load(Ordering::Acquire);
        if in_use {
            super::boundary::record_error(&FfiError::concurrent_use("handle being freed"));
            return;
        }
        // SAFETY: the C contract: `handle` came from `new_exclusive` for this type and is
        // freed once; no call is using it (checked above).
        drop(unsafe { Box::from_raw(raw) });
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ffi::status::topoloc_status::TOPOLOC_ERR_CONCURRENT_USE;

    #[test]
    fn a_second_entry_is_refused_until_the_first_leaves() {
        let value = Exclusive::new(7_u32);
        let mut first = value.enter("value").unwrap();
        *first += 1;
        let second = value.enter("value").err().expect("refused while in use");
        assert_eq!(second.status, TOPOLOC_ERR_CONCURRENT_USE);
        assert!(second.message.contains("'value'"), "{}", second.message);
        drop(first);
        assert_eq!(*value.enter("value").unwrap(), 8);
    }
}
