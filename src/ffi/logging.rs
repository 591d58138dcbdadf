//! Host logging (ABI 1.13): the library's `log` records (and ONNX Runtime's, which the
//! library routes into `log`) go to one C callback the host sets at run time. Nothing is
//! written to stdout or stderr; without a callback records are dropped before they are
//! formatted.

use super::boundary::run;
use super::error::FfiError;
use super::status::topoloc_status;
use std::cell::{Cell, RefCell};
use std::ffi::{c_char, c_void};
use std::sync::{OnceLock, RwLock};

/// Severity of a log record, and the most verbose level a host asks for: a `TOPOLOC_LOG_*`
/// value.
pub type topoloc_log_level = u32;
/// No records (the callback is not called).
pub const TOPOLOC_LOG_OFF: topoloc_log_level = 0;
/// An operation failed in a way the returned status does not fully explain.
pub const TOPOLOC_LOG_ERROR: topoloc_log_level = 1;
/// Something the host should know: a degraded result, a file cleaned up, a backend's warning.
pub const TOPOLOC_LOG_WARN: topoloc_log_level = 2;
/// Rare, useful events: maps loaded and saved (sizes, times), backends loaded (paths).
pub const TOPOLOC_LOG_INFO: topoloc_log_level = 3;
/// Decisions per keyframe or per map build step (loop candidates, rejected hints).
pub const TOPOLOC_LOG_DEBUG: topoloc_log_level = 4;
/// Per-frame detail.
pub const TOPOLOC_LOG_TRACE: topoloc_log_level = 5;

/// Receives one log record: its `level` (`TOPOLOC_LOG_ERROR` ..= `TOPOLOC_LOG_TRACE`), its
/// `target` (the emitting module, e.g. `"topoloc::map::file"`, or `"onnxruntime"`), the
/// formatted `message` (both NUL-terminated UTF-8, valid only during the call), and the
/// `user_data` given to `topoloc_set_log_callback`. Called on whichever thread logs (a thread
/// of the host calling into topoloc, or a worker thread topoloc or ONNX Runtime runs), possibly
/// from several threads at once: it must be thread-safe, must return normally (no C++
/// exception, no `longjmp`), and must not call `topoloc_set_log_callback` (that call fails
/// with `TOPOLOC_ERR_CONCURRENT_USE`). Records that topoloc emits while the callback runs on
/// the same thread are dropped.
pub type topoloc_log_fn = Option<
    unsafe extern "C" fn(
        level: topoloc_log_level,
        target: *const c_char,
        message: *const c_char,
        user_data: *mut c_void,
    ),
>;

/// The host's callback and its user data.
#[derive(Clone, Copy)]
struct Sink {
    callback: unsafe extern "C" fn(topoloc_log_level, *const c_char, *const c_char, *mut c_void),
    user_data: *mut c_void,
}

// SAFETY: the callback contract makes the callback and its user data usable from any thread.
unsafe impl Send for Sink {}
unsafe impl Sync for Sink {}

/// The current sink; `topoloc_set_log_callback` replaces it under the write lock, so once it
/// returns no thread is still inside the previous callback.
static SINK: RwLock<Option<Sink>> = RwLock::new(None);

/// The logger registered with the `log` crate (once per process), forwarding to [`SINK`].
struct HostLogger;

static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();

thread_local! {
    /// Set while this thread runs the host's callback: nested records are dropped, and the
    /// callback may not replace itself.
    static IN_CALLBACK: Cell<bool> = const { Cell::new(false) };
    /// Reused formatting buffers (target, message).
    static BUFFERS: RefCell<(Vec<u8>, Vec<u8>)> = const { RefCell::new((Vec::new(), Vec::new())) };
}

/// `text` as a C string in `buffer` (NULs replaced by spaces), reusing its allocation.
fn c_string_in<'a>(buffer: &'a mut Vec<u8>, text: &str) -> &'a [u8] {
    buffer.clear();
    buffer.extend(text.bytes().map(|b| if b == 0 { b' ' } else { b }));
    buffer.push(0);
    buffer
}

fn level_code(level: log::Level) -> topoloc_log_level {
    match level {
        log::Level::Error => TOPOLOC_LOG_ERROR,
        log::Level::Warn => TOPOLOC_LOG_WARN,
        log::Level::Info => TOPOLOC_LOG_INFO,
        log::Level::Debug => TOPOLOC_LOG_DEBUG,
        log::Level::Trace => TOPOLOC_LOG_TRACE,
    }
}

fn level_filter(level: topoloc_log_level) -> Option<log::LevelFilter> {
    Some(match level {
        TOPOLOC_LOG_OFF => log::LevelFilter::Off,
        TOPOLOC_LOG_ERROR => log::LevelFilter::Error,
        TOPOLOC_LOG_WARN => log::LevelFilter::Warn,
        TOPOLOC_LOG_INFO => log::LevelFilter::Info,
        TOPOLOC_LOG_DEBUG => log::LevelFilter::Debug,
        TOPOLOC_LOG_TRACE => log::LevelFilter::Trace,
        _ => return None,
    })
}

impl log::Log for HostLogger {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        metadata.level() <= log::max_level() && !IN_CALLBACK.with(Cell::get)
    }

    fn log(&self, record: &log::Record) {
        if !self.enabled(record.metadata()) {
            return;
        }
        let Ok(sink) = SINK.read() else { return };
        let Some(sink) = *sink else { return };
        BUFFERS.with(|buffers| {
            let Ok(mut buffers) = buffers.try_borrow_mut() else {
                return;
            };
            let (target, message) = &mut *buffers;
            let target = c_string_in(target, record.target())
                .as_ptr()
                .cast::<c_char>();
            let message = c_string_in(message, &record.args().to_string())
                .as_ptr()
                .cast::<c_char>();
            IN_CALLBACK.with(|c| c.set(true));
            // SAFETY: the host's callback with the strings it is promised (NUL-terminated,
            // live for the call) and its own user data.
            unsafe { (sink.callback)(level_code(record.level()), target, message, sink.user_data) };
            IN_CALLBACK.with(|c| c.set(false));
        });
    }

    fn flush(&self) {}
}

/// Registers [`HostLogger`] with the `log` crate, once; an error when another logger was
/// registered first (a Rust program linking topoloc and logging with its own logger).
fn register() -> Result<(), FfiError> {
    static LOGGER: HostLogger = HostLogger;
    REGISTERED
        .get_or_init(|| {
            log::set_logger(&LOGGER).map_err(|_| {
                "another `log` logger is registered in this process (a Rust host): topoloc's \
                 records already go to it"
                    .to_string()
            })
        })
        .clone()
        .map_err(FfiError::invalid)
}

/// Sends the library's log records of `max_level` and more severe to `callback` (with
/// `user_data`), replacing any previous callback; `NULL` (or `TOPOLOC_LOG_OFF`) turns logging
/// off, which is the default: topoloc writes nothing to stdout or stderr. Takes effect for all
/// threads; when it returns, no thread is still inside the previous callback, so its user data
/// may be freed. See `topoloc_log_fn` for what the callback must do. Thread-safe. Errors:
/// `_INVALID_ARGUMENT` (a level above `TOPOLOC_LOG_TRACE`; another `log` logger registered by a
/// Rust host), `_CONCURRENT_USE` (called from inside the callback). On error the previous
/// callback stays.
#[no_mangle]
pub extern "C" fn topoloc_set_log_callback(
    callback: topoloc_log_fn,
    max_level: topoloc_log_level,
    user_data: *mut c_void,
) -> topoloc_status {
    run(|| {
        let filter = level_filter(max_level).ok_or_else(|| {
            FfiError::invalid(format!(
                "max_level {max_level} is not a TOPOLOC_LOG_* level (0..=5)"
            ))
        })?;
        if IN_CALLBACK.with(Cell::get) {
            return Err(FfiError::concurrent_use("log callback"));
        }
        register()?;
        let sink = callback.map(|callback| Sink {
            callback,
            user_data,
        });
        let mut current = SINK
            .write()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        *current = sink;
        log::set_max_level(if sink.is_some() {
            filter
        } else {
            log::LevelFilter::Off
        });
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// Records received by [`collect`]: (level, target, message).
    static SEEN: Mutex<Vec<(u32, String, String)>> = Mutex::new(Vec::new());

    unsafe extern "C" fn collect(
        level: topoloc_log_level,
        target: *const c_char,
        message: *const c_char,
        user_data: *mut c_void,
    ) {
        assert_eq!(user_data as usize, 42);
        let text = |p: *const c_char| {
            // SAFETY: the callback contract.
            unsafe { std::ffi::CStr::from_ptr(p) }
                .to_string_lossy()
                .into_owned()
        };
        SEEN.lock()
            .unwrap()
            .push((level, text(target), text(message)));
        // A record emitted from inside the callback is dropped, and the callback cannot
        // replace itself.
        log::error!(target: "topoloc::nested", "dropped");
        let status = topoloc_set_log_callback(None, TOPOLOC_LOG_OFF, std::ptr::null_mut());
        assert_eq!(status, topoloc_status::TOPOLOC_ERR_CONCURRENT_USE);
    }

    #[test]
    fn records_reach_the_callback_up_to_its_level_and_stop_when_it_is_removed() {
        let data = 42usize as *mut c_void;
        let bad = topoloc_set_log_callback(Some(collect), 6, data);
        assert_eq!(bad, topoloc_status::TOPOLOC_ERR_INVALID_ARGUMENT);
        assert_eq!(
            topoloc_set_log_callback(Some(collect), TOPOLOC_LOG_INFO, data),
            topoloc_status::TOPOLOC_OK
        );
        log::info!(target: "topoloc::test", "seen {}", 1);
        log::debug!(target: "topoloc::test", "too verbose");
        log::warn!(target: "topoloc::test", "with a \0 NUL");
        assert_eq!(
            topoloc_set_log_callback(None, TOPOLOC_LOG_TRACE, data),
            topoloc_status::TOPOLOC_OK
        );
        log::error!(target: "topoloc::test", "after removal");
        let seen = std::mem::take(&mut *SEEN.lock().unwrap());
        let ours: Vec<_> = seen
            .into_iter()
            .filter(|(_, target, _)| target.starts_with("topoloc::test"))
            .collect();
        assert_eq!(
            ours,
            vec![
                (TOPOLOC_LOG_INFO, "topoloc::test".into(), "seen 1".into()),
                (
                    TOPOLOC_LOG_WARN,
                    "topoloc::test".into(),
                    "with a   NUL".into()
                ),
            ]
        );
    }
}
