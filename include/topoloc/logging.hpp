/*
 * topoloc/logging.hpp: topoloc's log records sent to a host's handler (ABI 1.13; part of
 * topoloc.hpp, which has the overview).
 */

#ifndef TOPOLOC_LOGGING_HPP
#define TOPOLOC_LOGGING_HPP

#include "../topoloc.h"
#include "error.hpp"

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string_view>
#include <utility>

namespace topoloc {

/// Severity of a log record (the C `TOPOLOC_LOG_*` values).
enum class LogLevel : uint32_t {
    Off = TOPOLOC_LOG_OFF,     ///< No records.
    Error = TOPOLOC_LOG_ERROR, ///< Failures the returned status does not fully explain.
    Warn = TOPOLOC_LOG_WARN,   ///< Degraded results, files cleaned up, a backend's warnings.
    Info = TOPOLOC_LOG_INFO,   ///< Maps loaded and saved, backends loaded.
    Debug = TOPOLOC_LOG_DEBUG, ///< Decisions per keyframe.
    Trace = TOPOLOC_LOG_TRACE, ///< Per-frame detail.
};

/// Receives one record: level, target (the emitting module, "topoloc::map::file", or
/// "onnxruntime") and message; the views are valid only during the call. Called on whichever
/// thread logs, possibly on several at once: it must be thread-safe. An exception it throws is
/// caught and dropped (it never reaches topoloc). It must not call `set_log_handler`.
using LogHandler = std::function<void(LogLevel, std::string_view target, std::string_view message)>;

namespace detail {

/// The installed handler (owned here; the C library holds a pointer to it as user data).
struct LogState {
    std::mutex mutex;
    std::unique_ptr<LogHandler> handler;
};

inline LogState &log_state()
{
    static LogState state;
    return state;
}

inline void log_trampoline(topoloc_log_level level, const char *target, const char *message,
                           void *user_data)
{
    try {
        (*static_cast<LogHandler *>(user_data))(static_cast<LogLevel>(level), target, message);
    } catch (...) {
        // A handler's exception must not unwind into topoloc; the record is dropped.
    }
}

} // namespace detail

/// Sends topoloc's log records of `max_level` and more severe to `handler`, replacing the
/// previous handler (which is destroyed once no thread is inside it); an empty `handler` or
/// `LogLevel::Off` turns logging off, as it is before any handler is set (see
/// `topoloc_set_log_callback` in topoloc.h). Thread-safe. Throws `Error` (`_INVALID_ARGUMENT`:
/// another Rust `log` logger owns the process; `_CONCURRENT_USE`: called from inside a
/// handler); the previous handler then stays.
inline void set_log_handler(LogHandler handler, LogLevel max_level = LogLevel::Info)
{
    auto &state = detail::log_state();
    std::lock_guard<std::mutex> lock(state.mutex);
    std::unique_ptr<LogHandler> next;
    if (handler && max_level != LogLevel::Off) {
        next = std::make_unique<LogHandler>(std::move(handler));
        check(topoloc_set_log_callback(detail::log_trampoline,
                                       static_cast<topoloc_log_level>(max_level), next.get()));
    } else {
        check(topoloc_set_log_callback(nullptr, TOPOLOC_LOG_OFF, nullptr));
    }
    // The library no longer calls the previous handler: it may go.
    state.handler = std::move(next);
}

} // namespace topoloc

#endif // TOPOLOC_LOGGING_HPP
