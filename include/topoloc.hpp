/*
 * topoloc.hpp: header-only C++17 RAII layer over the C ABI in topoloc.h.
 *
 * Every owner class (`Map`, `MapBuilder`, `Localizer`, `Graph`, `LoopDetector`) is the one
 * move-only owner template `detail::Owner` over one C handle: its destructor calls the matching
 * C `_free` function, `capi()` / `get()` return the raw handle for code that talks to the C API
 * directly, and `release()` gives it up. Every failing C call is turned into a
 * `topoloc::Error` exception (or a subclass) carrying the C status and the thread-local message
 * of `topoloc_last_error_message`; `throw_error` maps each status to its exception class in one
 * switch. Nothing here adds behaviour the C API does not have; the C header documents the
 * semantics of each call.
 *
 * One name per operation. The per-frame call is `process` in C, C++ and Python; the Rust core
 * calls it `Localizer::localize(&Frame) -> Localization`.
 *
 *   operation                 C                                   C++                                Python
 *   load a map file           topoloc_map_load                    Map::load                          Map.load
 *   load a map from bytes     topoloc_map_load_from_memory        Map::from_memory                   Map.from_bytes
 *   save a map                topoloc_map_save                    Map::save                          Map.save
 *   build from descriptors    topoloc_map_builder_new/_add_*      MapBuilder, add_place/view/edge    MapBuilder
 *                             topoloc_map_builder_build           MapBuilder::build                  MapBuilder.build
 *   build from keyframes      topoloc_map_from_keyframes          map_from_keyframes                 map_from_keyframes
 *   build from images         topoloc_map_build_from_images       Map::build_from_images             Map.build_from_images
 *   build from image files    topoloc_map_build_from_image_files  Map::build_from_image_files        Map.build_from_image_files
 *   attach scene points       topoloc_map_with_keypoint_points    Map::with_keypoint_points          Map.with_keypoint_points
 *   graph from occupancy      topoloc_graph_from_occupancy        Graph::from_occupancy              skeleton_graph
 *   new localizer             topoloc_localizer_new               Localizer(map, options)            Localizer(map, ...)
 *   one frame (descriptor     topoloc_localizer_process           Localizer::process                 Localizer.process
 *     or image)                                                   (+ process_descriptor,
 *                                                                 process_image of a cv::Mat in
 *                                                                 topoloc_opencv.hpp)
 *   forget history            topoloc_localizer_reset             Localizer::reset                   Localizer.reset
 *   new loop detector         topoloc_loop_detector_new           LoopDetector::create               LoopDetector(kind, ...)
 *   loop detector from a map  topoloc_loop_detector_from_map      LoopDetector::from_map             LoopDetector.from_map
 *   add a keyframe (a hint)   topoloc_loop_detector_add           LoopDetector::add                  LoopDetector.add
 *   hints it confirmed        topoloc_loop_detector_confirmed     LoopDetector::confirmed            LoopDetector.confirmed
 *                             (+ _confirmed_count)
 *   relocalization            topoloc_loop_detector_query         LoopDetector::query                LoopDetector.query
 *   cull a keyframe           topoloc_loop_detector_erase         LoopDetector::erase                LoopDetector.erase
 *   save the session          topoloc_loop_detector_save          LoopDetector::save                 LoopDetector.save
 *   keyframes held            topoloc_loop_detector_len           LoopDetector::size                 len(LoopDetector)
 *   trajectory ATE/RPE        topoloc_trajectory_evaluate         evaluate_trajectory                evaluate_trajectory
 *                             topoloc_trajectory_evaluate_files   evaluate_trajectory_files          evaluate_trajectory_files
 *
 * Thread safety (the C rules, restated):
 *  - `Map`, `Graph`: immutable. A const one may be shared by many threads, its const methods
 *    called concurrently; many localizers on many threads may use one map.
 *  - `MapBuilder`, `Localizer`, `LoopDetector`: single-threaded state. Use each from one thread
 *    at a time (they may move between threads).
 *  - Error messages are per thread, so an `Error` always describes the failure of the call that
 *    threw it on that thread.
 *
 * Moved-from and default-constructed owners are empty (`!owner`, `capi() == nullptr`); calling a
 * method on an empty owner throws `Error` with `TOPOLOC_ERR_NULL_ARGUMENT`.
 *
 * Callbacks (the progress of map builds) are called from inside topoloc: they must not unwind,
 * longjmp or otherwise jump through it. This layer wraps a C++ callback so that an exception it
 * throws is caught before it reaches C, cancels the build, and is rethrown after the C call
 * returns; code that gives topoloc a C callback itself must do the same.
 *
 * Methods returning strings or id lists ask the library for the size first; such a sizing call
 * may leave a "buffer too small" text as the thread's `topoloc_last_error_message` even though
 * the method succeeds. Errors thrown by this layer always carry the right message.
 *
 * Images: `Image` is a borrowed view of pixels (the C `topoloc_image`; make one with
 * `image_view`). `Map::build_from_images` / `Map::build_from_image_files` build maps that store
 * their describer, with an optional progress callback; `Localizer::process` takes image frames
 * as well as descriptors. The image statuses throw subclasses of `Error` (`InvalidImageError`,
 * `UninformativeImageError`, `BackendUnavailableError`, `ModelError`, `NoDescriberError`,
 * `CancelledError`), so a stream can skip frames with
 * `catch (const topoloc::UninformativeImageError &)`.
 *
 * OpenCV: `cv::Mat` conveniences live in topoloc_opencv.hpp (which includes this header and
 * OpenCV). Nothing in this header depends on what was included before it.
 */

#ifndef TOPOLOC_HPP
#define TOPOLOC_HPP

#include "topoloc.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <exception>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

namespace topoloc {

// ---------------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------------

/// Static English description of a status code (`topoloc_status_str`); never null, never freed.
[[nodiscard]] inline const char *status_string(topoloc_status status) noexcept
{
    return topoloc_status_str(static_cast<uint32_t>(status));
}

namespace detail {

/// The exception class a status is thrown as (see `throw_error`).
enum class ErrorClass {
    None,               ///< `TOPOLOC_OK`: nothing is thrown.
    Error,              ///< `topoloc::Error` itself.
    InvalidImage,       ///< `InvalidImageError`.
    UninformativeImage, ///< `UninformativeImageError`.
    BackendUnavailable, ///< `BackendUnavailableError`.
    Model,              ///< `ModelError`.
    NoDescriber,        ///< `NoDescriberError`.
    Cancelled,          ///< `CancelledError`.
};

/// One row of the status table: the C name of a status and its exception class.
struct StatusInfo {
    const char *name; ///< "TOPOLOC_ERR_..." (null for a code this header does not know).
    ErrorClass error; ///< The exception class it is thrown as.
};

/// The status table: every `topoloc_status` of topoloc.h, its name and its exception class. The
/// switch names every enumerator and has no default, so a code added to topoloc.h and not here
/// is a -Wswitch warning (an error under -Werror); tests/cpp/run.sh also checks every
/// `TOPOLOC_ERR_*` of the header against it. A code newer than this header (from a newer
/// library) has no name and is thrown as `Error`.
constexpr StatusInfo status_info(topoloc_status status) noexcept
{
#define TOPOLOC_HPP_STATUS(code, error_class)                                                      \
    case code:                                                                                     \
        return StatusInfo{#code, ErrorClass::error_class};
    switch (status) {
        TOPOLOC_HPP_STATUS(TOPOLOC_OK, None)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_NULL_ARGUMENT, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_INVALID_ARGUMENT, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_BUFFER_TOO_SMALL, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_STRUCT_SIZE, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_INVALID_UTF8, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_CONCURRENT_USE, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_IO, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_NOT_A_MAP, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_TRUNCATED, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_CORRUPT, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_UNSUPPORTED_VERSION, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_DESCRIPTOR_MISMATCH, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_EMPTY_MAP, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_INVALID_MAP, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_UNKNOWN_PLACE, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_UNKNOWN_VIEW, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_DIMENSION_MISMATCH, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_NON_FINITE, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_ZERO_DESCRIPTOR, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_TIMESTAMP, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_INVALID_OPTION, Error)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_INVALID_IMAGE, InvalidImage)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_UNINFORMATIVE_IMAGE, UninformativeImage)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_BACKEND_UNAVAILABLE, BackendUnavailable)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_MODEL, Model)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_NO_DESCRIBER, NoDescriber)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_CANCELLED, Cancelled)
        TOPOLOC_HPP_STATUS(TOPOLOC_ERR_PANIC, Error)
    }
#undef TOPOLOC_HPP_STATUS
    return StatusInfo{nullptr, ErrorClass::Error};
}

} // namespace detail

/// The C name of a status ("TOPOLOC_ERR_IO"), or null for a code this header does not know.
[[nodiscard]] constexpr const char *status_name(topoloc_status status) noexcept
{
    return detail::status_info(status).name;
}

/// The message of the most recent failed C call on the calling thread ("" if none).
/// Reads the size first and then the text, so messages of any length are returned whole.
/// Does not change the stored message. Never throws except `std::bad_alloc`.
[[nodiscard]] inline std::string last_error_message()
{
    std::size_t needed = 0;
    // First ask for the size: with an empty buffer the call reports BUFFER_TOO_SMALL and `needed`.
    topoloc_last_error_message(nullptr, 0, &needed);
    // The stored message cannot change between these calls (it is per thread and only failing
    // C calls on this thread replace it), but loop anyway rather than trust that.
    for (int attempt = 0; attempt < 4 && needed > 0; ++attempt) {
        std::string text(needed, '\0');
        std::size_t again = 0;
        const topoloc_status status = topoloc_last_error_message(&text[0], text.size(), &again);
        if (status == TOPOLOC_OK) {
            text.resize(std::strlen(text.c_str()));
            return text;
        }
        if (status != TOPOLOC_ERR_BUFFER_TOO_SMALL) {
            break;
        }
        needed = again;
    }
    return std::string();
}

/// Exception thrown by every wrapper call whose C call fails. `status()` is the C status code;
/// `message()` the library's message for it (from `topoloc_last_error_message`, or written by
/// this layer for errors it detects itself); `what()` is "<status description>: <message>".
class Error : public std::runtime_error {
public:
    /// An error with an explicit status and message (used for errors this layer detects).
    Error(topoloc_status status, std::string message)
        : std::runtime_error(compose(status, message)), status_(status),
          message_(std::move(message))
    {
    }

    /// The error of the C call that just failed on this thread with `status`: reads the
    /// thread-local message. Call it before any other topoloc call on this thread.
    [[nodiscard]] static Error from_last(topoloc_status status)
    {
        return Error(status, last_error_message());
    }

    /// The C status code (never `TOPOLOC_OK`).
    [[nodiscard]] topoloc_status status() const noexcept { return status_; }

    /// The message alone, without the status description ("" if the library gave none).
    [[nodiscard]] const std::string &message() const noexcept { return message_; }

private:
    // "<description> [<NAME> = <code>]: <message>", e.g.
    // "I/O error [TOPOLOC_ERR_IO = 100]: cannot open /x.topoloc: No such file or directory".
    static std::string compose(topoloc_status status, const std::string &message)
    {
        std::string text = status_string(status);
        text += " [";
        const char *name = status_name(status);
        text += name != nullptr ? name : "status";
        text += " = ";
        text += std::to_string(static_cast<uint32_t>(status));
        text += "]";
        if (!message.empty()) {
            text += ": ";
            text += message;
        }
        return text;
    }

    topoloc_status status_;
    std::string message_;
};

/// `TOPOLOC_ERR_INVALID_IMAGE`: an image buffer is unusable (size, stride, length, format), or
/// an image file cannot be read (the message names it).
class InvalidImageError : public Error {
public:
    using Error::Error;
};

/// `TOPOLOC_ERR_UNINFORMATIVE_IMAGE`: the image carries no place information (blank, constant,
/// featureless). The frame was not localized and the localizer is unchanged: skip the frame.
class UninformativeImageError : public Error {
public:
    using Error::Error;
};

/// `TOPOLOC_ERR_BACKEND_UNAVAILABLE`: ONNX Runtime or the model file is missing or cannot be
/// loaded; the message names every path tried.
class BackendUnavailableError : public Error {
public:
    using Error::Error;
};

/// `TOPOLOC_ERR_MODEL`: the model file loaded but does not work.
class ModelError : public Error {
public:
    using Error::Error;
};

/// `TOPOLOC_ERR_NO_DESCRIBER`: an image frame reached a localizer that cannot describe images
/// (a map built from descriptors, or `image_backend = TOPOLOC_BACKEND_NONE`).
class NoDescriberError : public Error {
public:
    using Error::Error;
};

/// `TOPOLOC_ERR_CANCELLED`: the progress callback returned false.
class CancelledError : public Error {
public:
    using Error::Error;
};

/// Throws the exception class of `status` (from the status table `detail::status_info`) with
/// `message`: a subclass of `Error` for the image statuses, `Error` itself for every other
/// status, including codes newer than this header. `status` must not be `TOPOLOC_OK` (it is
/// thrown as `Error` too, which is a caller's bug).
[[noreturn]] inline void throw_error(topoloc_status status, std::string message)
{
    switch (detail::status_info(status).error) {
    case detail::ErrorClass::InvalidImage:
        throw InvalidImageError(status, std::move(message));
    case detail::ErrorClass::UninformativeImage:
        throw UninformativeImageError(status, std::move(message));
    case detail::ErrorClass::BackendUnavailable:
        throw BackendUnavailableError(status, std::move(message));
    case detail::ErrorClass::Model:
        throw ModelError(status, std::move(message));
    case detail::ErrorClass::NoDescriber:
        throw NoDescriberError(status, std::move(message));
    case detail::ErrorClass::Cancelled:
        throw CancelledError(status, std::move(message));
    case detail::ErrorClass::None:
    case detail::ErrorClass::Error:
        break;
    }
    throw Error(status, std::move(message));
}

/// Throws (see `throw_error`) with the thread's last error message unless `status` is
/// `TOPOLOC_OK`. Use it right after a C call, before any other topoloc call on this thread.
inline void check(topoloc_status status)
{
    if (status != TOPOLOC_OK) {
        throw_error(status, last_error_message());
    }
}

// ---------------------------------------------------------------------------------------------
// Versions
// ---------------------------------------------------------------------------------------------

/// Version of the loaded library, "MAJOR.MINOR.PATCH" (static; never free it). The header's
/// version is `TOPOLOC_VERSION_STRING`.
[[nodiscard]] inline const char *version() noexcept { return topoloc_version(); }

/// ABI version of the loaded library.
[[nodiscard]] inline uint32_t abi_version() noexcept { return topoloc_abi_version(); }

/// ABI version of the header this program was compiled against.
constexpr uint32_t header_abi_version = TOPOLOC_ABI_VERSION;

/// True when the loaded library has the ABI of the header this program was compiled against.
/// Check it once at start-up; on false, do not use the library.
[[nodiscard]] inline bool abi_matches() noexcept
{
    return topoloc_abi_version() == TOPOLOC_ABI_VERSION;
}

// ---------------------------------------------------------------------------------------------
// Host logging (ABI 1.13)
// ---------------------------------------------------------------------------------------------

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
/// `LogLevel::Off` turns logging off (the default: topoloc writes nothing to stdout or stderr).
/// Thread-safe. Throws `Error` (`_INVALID_ARGUMENT`: another Rust `log` logger owns the process;
/// `_CONCURRENT_USE`: called from inside a handler); the previous handler then stays.
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

// ---------------------------------------------------------------------------------------------
// Options: the C structs themselves, filled by their _default() functions
// ---------------------------------------------------------------------------------------------
//
// The `topoloc_*_default(p)` macros of topoloc.h pass `sizeof *p`, so the library fills exactly
// the layout this program was compiled with. They fail only when the library refuses that size
// (a header older than the library's first published layout), which `check` turns into `Error`.

/// Options of `Map::load` / `Map::from_memory` (the C struct). Start from
/// `default_load_options()`; a value-initialised struct has `struct_size == 0` and is refused
/// with `TOPOLOC_ERR_STRUCT_SIZE`. The string fields are borrowed for the duration of the call.
using LoadOptions = topoloc_map_load_options;

/// Localizer parameters (the C struct). Start from `default_localizer_options()`; see topoloc.h
/// for each field's meaning and default (no camera intrinsics: set `camera_fx`, `camera_fy`,
/// `camera_cx`, `camera_cy` for results with a pose fix, which also need `verify_candidates` > 0
/// and a map from `Map::with_keypoint_points`; `pose_min_inliers`, default 30, is the fewest
/// PnP inliers of a fix; ABI 1.6; with verification on, `verify_off_map_inliers` and
/// `verify_off_map_inlier_scale` make the off-map flag read the inliers, negative = the map's
/// feature kind's threshold; ABI 1.9). The string fields are borrowed only during the
/// `Localizer` constructor.
using LocalizerOptions = topoloc_localizer_options;

/// Parameters of `map_from_keyframes` (the C struct). Start from `default_keyframe_options()`.
using KeyframeOptions = topoloc_keyframe_options;

/// How `Map::build_from_images` / `build_from_image_files` build a map (the C struct). Start
/// from `default_image_map_options()` (backend `TOPOLOC_BACKEND_AUTO` = ONNX; set `backend` to
/// `TOPOLOC_BACKEND_VLAD_ORB` or `_VLAD_SIFT` for VLAD, and `dim` to at most the number of
/// images minus one). The string fields are borrowed for the duration of the call.
using ImageMapOptions = topoloc_image_map_options;

/// Parameters of `Graph::from_occupancy` (the C struct). Start from
/// `default_skeleton_options()`; see topoloc.h for each field's meaning and default.
using SkeletonOptions = topoloc_skeleton_options;

/// Loop detector parameters (the C struct). Start from `default_loop_options()`; see topoloc.h
/// for each field's meaning and default (5 candidates, 30 inliers, 3 consistent keyframes, no
/// intrinsics: set `fx`, `fy`, `cx`, `cy` for hints with a relative pose). Read only by
/// `LoopDetector::create` / `LoopDetector::from_map`.
using LoopOptions = topoloc_loop_options;

/// Where a `Describer` finds its runtime files (the C struct, ABI 1.12). Start from
/// `default_describer_options()`; the string fields are borrowed only during the constructor.
using DescriberOptions = topoloc_describer_options;

/// Load options that accept any map (`topoloc_map_load_options_default`). Throws `Error`
/// (`TOPOLOC_ERR_STRUCT_SIZE`) only on a header/library layout mismatch.
[[nodiscard]] inline LoadOptions default_load_options()
{
    LoadOptions options;
    check(topoloc_map_load_options_default(&options));
    return options;
}

/// Default localizer options (`topoloc_localizer_options_default`). Throws `Error`
/// (`TOPOLOC_ERR_STRUCT_SIZE`) only on a header/library layout mismatch.
[[nodiscard]] inline LocalizerOptions default_localizer_options()
{
    LocalizerOptions options;
    check(topoloc_localizer_options_default(&options));
    return options;
}

/// Default keyframe options (`topoloc_keyframe_options_default`). Throws `Error`
/// (`TOPOLOC_ERR_STRUCT_SIZE`) only on a header/library layout mismatch.
[[nodiscard]] inline KeyframeOptions default_keyframe_options()
{
    KeyframeOptions options;
    check(topoloc_keyframe_options_default(&options));
    return options;
}

/// Default image map options (`topoloc_image_map_options_default`). Throws `Error`
/// (`TOPOLOC_ERR_STRUCT_SIZE`) only on a header/library layout mismatch.
[[nodiscard]] inline ImageMapOptions default_image_map_options()
{
    ImageMapOptions options;
    check(topoloc_image_map_options_default(&options));
    return options;
}

/// Default skeleton options (`topoloc_skeleton_options_default`). Throws `Error`
/// (`TOPOLOC_ERR_STRUCT_SIZE`) only on a header/library layout mismatch.
[[nodiscard]] inline SkeletonOptions default_skeleton_options()
{
    SkeletonOptions options;
    check(topoloc_skeleton_options_default(&options));
    return options;
}

/// Default loop detector options (`topoloc_loop_options_default`). Throws `Error`
/// (`TOPOLOC_ERR_STRUCT_SIZE`) only on a header/library layout mismatch.
[[nodiscard]] inline LoopOptions default_loop_options()
{
    LoopOptions options;
    check(topoloc_loop_options_default(&options));
    return options;
}

/// Default describer options (`topoloc_describer_options_default`: the map's backend, the
/// cache's model and runtime, one thread). Throws `Error` (`TOPOLOC_ERR_STRUCT_SIZE`) only on a
/// header/library layout mismatch.
[[nodiscard]] inline DescriberOptions default_describer_options()
{
    DescriberOptions options;
    check(topoloc_describer_options_default(&options));
    return options;
}

// ---------------------------------------------------------------------------------------------
// Plain values
// ---------------------------------------------------------------------------------------------

/// A position in metres (x, y, z).
using Position = std::array<double, 3>;

/// A rigid transform: 16 doubles, row-major 4x4 `[R t; 0 0 0 1]`, metres.
using Pose = std::array<double, 16>;

/// One ranked hypothesis of a frame (the C struct: place, view, probability, similarity).
using Candidate = topoloc_candidate;

/// One undirected edge of a map: places `a < b` and a positive weight.
struct Edge {
    uint32_t a = 0;     ///< Smaller place id.
    uint32_t b = 0;     ///< Larger place id.
    float weight = 0.f; ///< Edge weight (> 0).
};

/// Attributes of one map view, as returned by `Map::view_info`.
struct ViewInfo {
    uint32_t place = 0;                  ///< Place the view belongs to.
    std::optional<uint64_t> keyframe_id; ///< Host keyframe id, if the map stores one.
    std::optional<Pose> world_T_camera;  ///< Camera pose `world_T_camera`, if the map stores one.
};

/// Optional attributes of a view given to `MapBuilder::add_view`. Owns its data.
struct ViewAttributes {
    std::optional<uint64_t> keyframe_id; ///< Host keyframe id.
    std::optional<Pose> world_T_camera;  ///< Camera pose `world_T_camera` (must be rigid).
    std::string image;                   ///< Image reference (path or URI), UTF-8; "" = none.
};

/// One keyframe for `map_from_keyframes`. Owns its data.
struct Keyframe {
    uint64_t id = 0;                    ///< Host keyframe id, stored with the view it becomes.
    std::vector<float> descriptor;      ///< Global descriptor (D floats).
    std::optional<Pose> world_T_camera; ///< Camera pose; all keyframes have one or none has.
};

/// A metric pose of the camera of one frame, found against one map view whose keypoints carry
/// scene points (`Result::pose_fix`; the pose-fix fields of `topoloc_result`, ABI 1.6).
struct PoseFix {
    uint32_t view = 0;    ///< The view the camera was placed against.
    uint32_t inliers = 0; ///< PnP inliers of the fix (at least the options' `pose_min_inliers`).
    /// The camera in the map frame, row-major 4x4, camera axes optical (z forward, x right,
    /// y down). A pose graph adds it as a prior or loop constraint on the frame's pose.
    Pose world_T_camera{};
};

/// The answer for one frame (the fields of `topoloc_result`), with its candidates.
struct Result {
    uint64_t frame_index = 0;        ///< 0-based frame count since creation or reset.
    uint32_t place = 0;              ///< Most probable place.
    uint32_t view = 0;               ///< Best-matching view of that place.
    float confidence = 0.f;          ///< P(at `place`) = place belief x on-map probability.
    float similarity = 0.f;          ///< Cosine similarity of the frame to `view`.
    float off_map_probability = 0.f; ///< Posterior probability of the off-map state.
    bool off_map = false;            ///< True when more likely off the map than on it.
    std::vector<Candidate>
        candidates;        ///< Top candidates, best first; `candidates[0].place == place`.
    bool verified = false; ///< `place` verified geometrically this frame (`verify_candidates` > 0).
    uint32_t inliers = 0;  ///< RANSAC inliers between the frame and `view` (0 unless verified).
    /// The camera's pose against the best-verified view (ABI 1.6), when the options have camera
    /// intrinsics, the map's keypoints carry scene points and enough keypoints agree; else none.
    std::optional<PoseFix> pose_fix;
};

// ---------------------------------------------------------------------------------------------
// Images
// ---------------------------------------------------------------------------------------------

/// A borrowed image (the C struct): `height` rows of `stride` bytes at `data`, each starting
/// with `width` pixels of `format` (a `TOPOLOC_PIXEL_*` value); `data_len` bytes are readable.
/// The pixels are read only during the call the image is passed to. Make one with
/// `image_view`; a value-initialised `Image{}` means "no image" (`TOPOLOC_PIXEL_NONE`).
using Image = topoloc_image;

/// Bytes per pixel of a `TOPOLOC_PIXEL_*` format; 0 for `TOPOLOC_PIXEL_NONE` and unknown values.
[[nodiscard]] constexpr std::size_t pixel_bytes(uint32_t format) noexcept
{
    return format == TOPOLOC_PIXEL_GRAY8                                    ? 1
           : format == TOPOLOC_PIXEL_RGB8 || format == TOPOLOC_PIXEL_BGR8   ? 3
           : format == TOPOLOC_PIXEL_RGBA8 || format == TOPOLOC_PIXEL_BGRA8 ? 4
                                                                            : 0;
}

/// A view of `data_len` bytes holding `width` x `height` pixels of `format` in rows `stride`
/// bytes apart (all checked by the library when the image is used).
[[nodiscard]] inline Image image_view(const void *data, std::size_t data_len, uint32_t width,
                                      uint32_t height, uint32_t format, std::size_t stride) noexcept
{
    Image image{};
    image.data = static_cast<const uint8_t *>(data);
    image.data_len = data_len;
    image.width = width;
    image.height = height;
    image.stride = stride;
    image.format = format;
    return image;
}

/// A view of `width` x `height` pixels of `format` at `data`, rows `stride` bytes apart
/// (0 = packed rows of `width * pixel_bytes(format)`). The caller promises that
/// `stride * (height - 1) + width * pixel_bytes(format)` bytes are readable at `data`, which
/// becomes `data_len`. Throws `InvalidImageError` for an unknown format or a size whose byte
/// count overflows; everything else (zero sizes, a stride shorter than a row, sizes above the
/// library's limit) is judged by the library when the image is used.
[[nodiscard]] inline Image image_view(const void *data, uint32_t width, uint32_t height,
                                      uint32_t format, std::size_t stride = 0)
{
    const std::size_t bytes = pixel_bytes(format);
    if (bytes == 0) {
        throw InvalidImageError(TOPOLOC_ERR_INVALID_IMAGE,
                                "image format " + std::to_string(format) +
                                    " is not a TOPOLOC_PIXEL_* format with pixels");
    }
    const std::size_t row = static_cast<std::size_t>(width) * bytes;
    if (stride == 0) {
        stride = row;
    }
    std::size_t len = 0;
    if (width != 0 && height != 0) {
        const std::size_t max = std::numeric_limits<std::size_t>::max();
        if (height - 1 > 0 && stride > (max - row) / (height - 1)) {
            throw InvalidImageError(TOPOLOC_ERR_INVALID_IMAGE,
                                    "image of " + std::to_string(height) + " rows of stride " +
                                        std::to_string(stride) + " bytes is larger than memory");
        }
        len = stride * (height - 1) + row;
    }
    return image_view(data, len, width, height, format, stride);
}

/// One camera frame for `Localizer::process(const Frame &)`: a descriptor (used when given) or
/// an image (described with the map's backend when `descriptor_len` is 0). Borrows everything.
struct Frame {
    double timestamp = 0.0;            ///< Seconds; must not decrease in filter mode.
    const float *descriptor = nullptr; ///< Global descriptor (`descriptor_len` floats) or null.
    std::size_t descriptor_len = 0;    ///< The map's D, or 0 to describe `image`.
    const double *odometry = nullptr;  ///< `previous_T_current`, 16 doubles row-major, or null.
    Image image{};                     ///< The camera image (`TOPOLOC_PIXEL_NONE` = none).
};

/// Stage of a map build reported to a `Progress` callback.
enum class Stage : uint32_t {
    Describing = TOPOLOC_STAGE_DESCRIBING, ///< Describing images: `done` of `total` images.
    Fitting = TOPOLOC_STAGE_FITTING,       ///< Fitting the describer and assembling: 0 or 1 of 1.
};

/// Progress of a map build, called on the building thread about ten times a second: return
/// true to go on, false to cancel (`CancelledError`). It runs inside topoloc, so it must not
/// unwind, longjmp or otherwise jump through the C call; this layer guarantees that for
/// exceptions: one thrown by the callback is caught before it reaches C, cancels the build
/// (the callback is not called again), and is rethrown, unchanged, by the building function
/// once the C call has returned. A `longjmp` out of the callback is never safe.
using Progress = std::function<bool(Stage stage, std::size_t done, std::size_t total)>;

namespace detail {

/// The one move-only owner of a C handle, shared by every owner class of this header (`Map`,
/// `MapBuilder`, `Localizer`, `Graph`, `LoopDetector` derive from it): it holds a `Handle *`,
/// calls `Free` (the handle's C `_free` function, a no-op for null) when destroyed or assigned
/// over, hands the handle out for interop (`capi()`, `get()`) or gives it up (`release()`), and
/// cannot be copied. Moved-from owners are empty. Not thread-safe by itself; the derived classes
/// state their own rules.
template <typename Handle, void (*Free)(Handle *)> class Owner {
public:
    /// The C handle type.
    using handle_type = Handle;

    /// The raw handle, still owned by this object (null when empty).
    [[nodiscard]] const Handle *capi() const noexcept { return handle_; }
    /// The raw handle, still owned by this object (null when empty).
    [[nodiscard]] Handle *capi() noexcept { return handle_; }
    /// Same as `capi()`.
    [[nodiscard]] const Handle *get() const noexcept { return handle_; }
    /// Same as `capi()`.
    [[nodiscard]] Handle *get() noexcept { return handle_; }

    /// Gives up ownership: returns the handle (free it with the C `_free` function) and leaves
    /// this object empty.
    [[nodiscard]] Handle *release() noexcept
    {
        Handle *raw = handle_;
        handle_ = nullptr;
        return raw;
    }

    /// True when this object owns a handle.
    explicit operator bool() const noexcept { return handle_ != nullptr; }

protected:
    Owner() noexcept = default;
    /// Takes ownership of `raw` (null gives an empty owner).
    explicit Owner(Handle *raw) noexcept : handle_(raw) {}
    Owner(const Owner &) = delete;
    Owner &operator=(const Owner &) = delete;
    Owner(Owner &&other) noexcept : handle_(other.release()) {}
    Owner &operator=(Owner &&other) noexcept
    {
        if (this != &other) {
            adopt(other.release());
        }
        return *this;
    }
    ~Owner() { Free(handle_); }

    /// Frees the current handle (if any) and owns `raw` instead.
    void adopt(Handle *raw) noexcept
    {
        Handle *old = handle_;
        handle_ = raw;
        Free(old);
    }

private:
    Handle *handle_ = nullptr;
};

/// Optional string argument: "" becomes NULL (the C API treats both as "not given").
inline const char *optional_c_str(const std::string &s) noexcept
{
    return s.empty() ? nullptr : s.c_str();
}

/// Reads a string through a C function of the (buf, len, &needed) contract.
template <typename Call> std::string read_string(Call call)
{
    std::string text(64, '\0');
    for (int attempt = 0; attempt < 4; ++attempt) {
        std::size_t needed = 0;
        const topoloc_status status = call(&text[0], text.size(), &needed);
        if (status == TOPOLOC_OK) {
            text.resize(std::strlen(text.c_str())); // C strings hold no interior NUL
            return text;
        }
        if (status != TOPOLOC_ERR_BUFFER_TOO_SMALL) {
            check(status);
        }
        text.assign(needed, '\0');
    }
    throw Error(TOPOLOC_ERR_BUFFER_TOO_SMALL, "string kept growing while being read");
}

/// Reads an array through a C function of the (buf, len, &count) contract whose `count` items
/// are `per_item` values of `T` each (`len` counts values): returns the `count * per_item`
/// values.
template <typename T, typename Call> std::vector<T> read_array(Call call, std::size_t per_item = 1)
{
    std::vector<T> values;
    std::size_t count = 0;
    topoloc_status status = call(nullptr, 0, &count);
    if (status == TOPOLOC_OK) {
        return values; // empty
    }
    if (status != TOPOLOC_ERR_BUFFER_TOO_SMALL) {
        check(status);
    }
    values.resize(count * per_item);
    check(call(values.data(), values.size(), &count));
    values.resize(count * per_item);
    return values;
}

/// Reads an id array through a C function of the (buf, len, &count) contract.
template <typename Call> std::vector<uint32_t> read_ids(Call call)
{
    return read_array<uint32_t>(call);
}

/// What the progress trampoline carries through the C `user_data`.
struct ProgressContext {
    const Progress *progress = nullptr;
    std::exception_ptr error; // thrown by the callback; rethrown after the C call
};

/// The C progress callback: calls the `Progress` in `user_data`. Exceptions never cross the C
/// boundary: the first one is stored, the build is cancelled, and the callback is not called
/// again.
inline bool progress_trampoline(void *user_data, uint32_t stage, std::size_t done,
                                std::size_t total) noexcept
{
    auto *context = static_cast<ProgressContext *>(user_data);
    if (context->error) {
        return false;
    }
    try {
        return (*context->progress)(static_cast<Stage>(stage), done, total);
    } catch (...) {
        context->error = std::current_exception();
        return false;
    }
}

/// Runs a C building call `call(progress_fn, user_data, &raw)` with `progress` (may be empty),
/// and returns the map; rethrows an exception of the callback, else throws for the status.
template <typename Call> topoloc_map *build_with_progress(const Progress &progress, Call call)
{
    ProgressContext context;
    context.progress = &progress;
    topoloc_map *raw = nullptr;
    const topoloc_status status =
        progress ? call(&progress_trampoline, &context, &raw) : call(nullptr, nullptr, &raw);
    if (context.error) {
        topoloc_map_free(raw); // null unless the library ignored the cancellation
        std::rethrow_exception(context.error);
    }
    check(status);
    return raw;
}

} // namespace detail

// ---------------------------------------------------------------------------------------------
// Map
// ---------------------------------------------------------------------------------------------

/// Owner of an immutable map (`topoloc_map*`). Move-only; the destructor calls
/// `topoloc_map_free`. Localizers keep their own reference to the map, so a `Map` may be
/// destroyed while localizers made from it are still in use.
///
/// Thread safety: all const methods may be called concurrently from many threads.
/// Errors: every method that calls the library throws `Error` on failure.
class Map : public detail::Owner<topoloc_map, &topoloc_map_free> {
public:
    /// An empty owner (`!map`).
    Map() noexcept = default;

    /// Takes ownership of `raw` (from a C call such as `topoloc_map_load`); null gives an empty
    /// owner.
    explicit Map(topoloc_map *raw) noexcept : Owner(raw) {}

    // Moves (noexcept; the source is left empty) and the destructor (calls `topoloc_map_free`) come
    // from `detail::Owner`; copies are deleted.

    /// Loads and validates a map file (memory-mapped: do not modify the file while the map
    /// lives). Throws `Error` (`TOPOLOC_ERR_IO`, `_NOT_A_MAP`, `_TRUNCATED`, `_CORRUPT`,
    /// `_UNSUPPORTED_VERSION`, `_DESCRIPTOR_MISMATCH`, ...).
    [[nodiscard]] static Map load(const std::string &path,
                                  const LoadOptions &options = default_load_options())
    {
        topoloc_map *raw = nullptr;
        check(topoloc_map_load(path.c_str(), &options, &raw));
        return Map(raw);
    }

    /// Loads and validates a map from `len` bytes in the map file format (copied: the buffer may
    /// be released afterwards). Same errors as `load`.
    [[nodiscard]] static Map from_memory(const void *data, std::size_t len,
                                         const LoadOptions &options = default_load_options())
    {
        topoloc_map *raw = nullptr;
        check(
            topoloc_map_load_from_memory(static_cast<const uint8_t *>(data), len, &options, &raw));
        return Map(raw);
    }

    /// `from_memory` over a byte vector.
    [[nodiscard]] static Map from_memory(const std::vector<uint8_t> &bytes,
                                         const LoadOptions &options = default_load_options())
    {
        return from_memory(bytes.data(), bytes.size(), options);
    }

    /// Builds a map from `count` images in memory (`topoloc_map_build_from_images`): every image
    /// is described (in parallel), the describer is fitted on all of them and stored in the map,
    /// so localizers on it accept image frames (`Localizer::process` of an `Image`). Without poses the map is
    /// a sequence: `options.views_per_place` consecutive images per place, places chained in
    /// order; view `i` has keyframe id `i`. `progress` (may be empty) is called on this thread;
    /// returning false throws `CancelledError`, and an exception it throws cancels the build and
    /// is rethrown here. The pixels are read only during the call.
    /// Throws `InvalidImageError` (a bad buffer; the message names `images[i]`),
    /// `BackendUnavailableError`, `ModelError`, `CancelledError`, `Error` (`_INVALID_ARGUMENT`:
    /// fewer than 2 images or bad options; `_IO`: poses file; `_STRUCT_SIZE`).
    [[nodiscard]] static Map
    build_from_images(const Image *images, std::size_t count,
                      const ImageMapOptions &options = default_image_map_options(),
                      const Progress &progress = Progress())
    {
        return Map(detail::build_with_progress(
            progress, [&](topoloc_progress_fn fn, void *user_data, topoloc_map **out) {
                return topoloc_map_build_from_images(images, count, &options, fn, user_data, out);
            }));
    }

    /// `build_from_images` over a vector of image views.
    [[nodiscard]] static Map
    build_from_images(const std::vector<Image> &images,
                      const ImageMapOptions &options = default_image_map_options(),
                      const Progress &progress = Progress())
    {
        return build_from_images(images.data(), images.size(), options, progress);
    }

    /// Builds a map from image files (any format OpenCV reads), like `build_from_images`; views
    /// also record their file's path (`view_image`). Throws `InvalidImageError` for a missing or
    /// unreadable file (the message names it), and the errors of `build_from_images`.
    [[nodiscard]] static Map
    build_from_image_files(const std::vector<std::string> &paths,
                           const ImageMapOptions &options = default_image_map_options(),
                           const Progress &progress = Progress())
    {
        std::vector<const char *> c_paths;
        c_paths.reserve(paths.size());
        for (const std::string &path : paths) {
            c_paths.push_back(path.c_str());
        }
        return Map(detail::build_with_progress(
            progress, [&](topoloc_progress_fn fn, void *user_data, topoloc_map **out) {
                return topoloc_map_build_from_image_files(c_paths.data(), c_paths.size(), &options,
                                                          fn, user_data, out);
            }));
    }

    /// Saves the map to `path` atomically (temporary file, fsync, rename). Throws `Error`
    /// (`TOPOLOC_ERR_IO`, ...).
    void save(const std::string &path) const { check(topoloc_map_save(get(), path.c_str())); }

    /// Number of places.
    [[nodiscard]] std::size_t place_count() const
    {
        std::size_t n = 0;
        check(topoloc_map_place_count(get(), &n));
        return n;
    }

    /// Number of views.
    [[nodiscard]] std::size_t view_count() const
    {
        std::size_t n = 0;
        check(topoloc_map_view_count(get(), &n));
        return n;
    }

    /// Number of undirected edges.
    [[nodiscard]] std::size_t edge_count() const
    {
        std::size_t n = 0;
        check(topoloc_map_edge_count(get(), &n));
        return n;
    }

    /// Descriptor dimension D: every descriptor given to a localizer of this map has D floats.
    [[nodiscard]] uint32_t dim() const
    {
        uint32_t d = 0;
        check(topoloc_map_descriptor_dim(get(), &d));
        return d;
    }

    /// Descriptor kind the map was built with (e.g. the backend family).
    [[nodiscard]] std::string descriptor_kind() const
    {
        return detail::read_string([this](char *buf, std::size_t len, std::size_t *needed) {
            return topoloc_map_descriptor_kind(get(), buf, len, needed);
        });
    }

    /// Descriptor model identity the map was built with ("" when none).
    [[nodiscard]] std::string descriptor_model() const
    {
        return detail::read_string([this](char *buf, std::size_t len, std::size_t *needed) {
            return topoloc_map_descriptor_model(get(), buf, len, needed);
        });
    }

    /// Places joined to `place` by an edge. Throws `Error` (`TOPOLOC_ERR_UNKNOWN_PLACE`).
    [[nodiscard]] std::vector<uint32_t> neighbours(uint32_t place) const
    {
        return detail::read_ids([this, place](uint32_t *buf, std::size_t len, std::size_t *count) {
            return topoloc_map_neighbours(get(), place, buf, len, count);
        });
    }

    /// View ids of `place`. Throws `Error` (`TOPOLOC_ERR_UNKNOWN_PLACE`).
    [[nodiscard]] std::vector<uint32_t> place_views(uint32_t place) const
    {
        return detail::read_ids([this, place](uint32_t *buf, std::size_t len, std::size_t *count) {
            return topoloc_map_place_views(get(), place, buf, len, count);
        });
    }

    /// Position of `place` in metres, or nullopt when the map has none. Throws `Error`
    /// (`TOPOLOC_ERR_UNKNOWN_PLACE`).
    [[nodiscard]] std::optional<Position> place_position(uint32_t place) const
    {
        Position xyz{};
        bool has = false;
        check(topoloc_map_place_position(get(), place, xyz.data(), &has));
        if (!has) {
            return std::nullopt;
        }
        return xyz;
    }

    /// Edge number `index` (0..edge_count(), sorted by (a, b)). Throws `Error`
    /// (`TOPOLOC_ERR_INVALID_ARGUMENT` when out of range).
    [[nodiscard]] Edge edge(std::size_t index) const
    {
        Edge e;
        check(topoloc_map_edge(get(), index, &e.a, &e.b, &e.weight));
        return e;
    }

    /// All edges, sorted by (a, b).
    [[nodiscard]] std::vector<Edge> edges() const
    {
        std::vector<Edge> all(edge_count());
        for (std::size_t i = 0; i < all.size(); ++i) {
            all[i] = edge(i);
        }
        return all;
    }

    /// Attributes of `view`. Throws `Error` (`TOPOLOC_ERR_UNKNOWN_VIEW`).
    [[nodiscard]] ViewInfo view_info(uint32_t view) const
    {
        topoloc_view_info raw;
        check(topoloc_view_info_default(&raw));
        check(topoloc_map_view_info(get(), view, &raw));
        ViewInfo info;
        info.place = raw.place;
        if (raw.has_keyframe_id) {
            info.keyframe_id = raw.keyframe_id;
        }
        if (raw.has_pose) {
            Pose pose;
            std::memcpy(pose.data(), raw.world_T_camera, sizeof raw.world_T_camera);
            info.world_T_camera = pose;
        }
        return info;
    }

    /// The unit-norm descriptor of `view` (D floats). Throws `Error` (`TOPOLOC_ERR_UNKNOWN_VIEW`).
    [[nodiscard]] std::vector<float> view_descriptor(uint32_t view) const
    {
        std::vector<float> descriptor(dim());
        check(topoloc_map_view_descriptor(get(), view, descriptor.data(), descriptor.size()));
        return descriptor;
    }

    /// Image reference of `view` ("" when none). Throws `Error` (`TOPOLOC_ERR_UNKNOWN_VIEW`).
    [[nodiscard]] std::string view_image(uint32_t view) const
    {
        return detail::read_string([this, view](char *buf, std::size_t len, std::size_t *needed) {
            return topoloc_map_view_image(get(), view, buf, len, needed);
        });
    }

    // Keypoints (ABI 1.6): read each view's keypoints, attach their scene points for pose fixes.

    /// Number of keypoints of all views together (0 when the map stores none; maps built from
    /// images store them): `with_keypoint_points` takes 3 floats per keypoint.
    [[nodiscard]] std::size_t keypoint_total() const
    {
        std::size_t n = 0;
        check(topoloc_map_keypoint_total(get(), &n));
        return n;
    }

    /// Pixel positions of `view`'s keypoints: x, y (x right, y down; the centre of the top-left
    /// pixel is (0, 0)), 2 floats per keypoint, in the order `with_keypoint_points` expects
    /// their scene points (empty when the view has none). Throws `Error`
    /// (`TOPOLOC_ERR_UNKNOWN_VIEW`, `_INVALID_ARGUMENT` when the map stores no keypoints).
    [[nodiscard]] std::vector<float> view_keypoints(uint32_t view) const
    {
        return detail::read_array<float>(
            [this, view](float *buf, std::size_t len, std::size_t *count) {
                return topoloc_map_view_keypoints(get(), view, buf, len, count);
            },
            2);
    }

    /// A new map, a copy of this one whose keypoints carry their scene points: `xyz` holds `len`
    /// = 3 * `keypoint_total()` floats, the map-frame position (metres; the frame of the place
    /// positions and view poses) of each keypoint, view after view in the order of
    /// `view_keypoints`; all three NaN where unknown. Read during the call only. With the copy
    /// and camera intrinsics in its options, a `Localizer` reports pose fixes
    /// (`Result::pose_fix`). This map is unchanged (and stays usable, also when the call
    /// throws); the copy is an independent owner that holds its descriptors in memory. Throws
    /// `Error` (`TOPOLOC_ERR_INVALID_ARGUMENT`: no keypoints, the wrong length, a point neither
    /// finite nor all NaN).
    [[nodiscard]] Map with_keypoint_points(const float *xyz, std::size_t len) const
    {
        topoloc_map *raw = nullptr;
        check(topoloc_map_with_keypoint_points(get(), xyz, len, &raw));
        return Map(raw);
    }

    /// `with_keypoint_points` over a vector (3 floats per keypoint).
    [[nodiscard]] Map with_keypoint_points(const std::vector<float> &xyz) const
    {
        return with_keypoint_points(xyz.data(), xyz.size());
    }
};

// ---------------------------------------------------------------------------------------------
// MapBuilder
// ---------------------------------------------------------------------------------------------

/// Owner of a map builder (`topoloc_map_builder*`): collects places, views and edges, then
/// `build()`s a `Map`. Move-only; the destructor calls `topoloc_map_builder_free`.
///
/// Thread safety: not thread-safe; use from one thread at a time.
/// Errors: every method that calls the library throws `Error` on failure; a failed call leaves
/// the builder unchanged.
class MapBuilder : public detail::Owner<topoloc_map_builder, &topoloc_map_builder_free> {
public:
    /// An empty owner (`!builder`).
    MapBuilder() noexcept = default;

    /// Starts a map of descriptors of `kind` / `model` ("" = none) with dimension `dim`.
    /// Throws `Error` (`TOPOLOC_ERR_INVALID_ARGUMENT` for an empty kind or dim 0, ...).
    MapBuilder(const std::string &kind, const std::string &model, uint32_t dim)
    {
        topoloc_map_builder *raw = nullptr;
        check(topoloc_map_builder_new(kind.c_str(), detail::optional_c_str(model), dim, &raw));
        adopt(raw);
    }

    /// Takes ownership of `raw`; null gives an empty owner.
    explicit MapBuilder(topoloc_map_builder *raw) noexcept : Owner(raw) {}

    // Moves (noexcept; the source is left empty) and the destructor (calls `topoloc_map_builder_free`) come
    // from `detail::Owner`; copies are deleted.

    /// Adds a place, optionally at `position` (metres); returns its id.
    uint32_t add_place(const std::optional<Position> &position = std::nullopt)
    {
        uint32_t id = 0;
        check(topoloc_map_builder_add_place(get(), position ? position->data() : nullptr, &id));
        return id;
    }

    /// Adds a view with `descriptor` (`len` floats; normalised by the library) to `place`;
    /// returns its id. Throws `Error` (`TOPOLOC_ERR_UNKNOWN_PLACE`, `_DIMENSION_MISMATCH`,
    /// `_NON_FINITE`, `_ZERO_DESCRIPTOR`, `_INVALID_ARGUMENT` for a non-rigid pose).
    uint32_t add_view(uint32_t place, const float *descriptor, std::size_t len,
                      const ViewAttributes &attributes = ViewAttributes())
    {
        topoloc_view_attributes raw;
        check(topoloc_view_attributes_default(&raw));
        raw.has_keyframe_id = attributes.keyframe_id.has_value();
        raw.keyframe_id = attributes.keyframe_id.value_or(0);
        raw.world_T_camera =
            attributes.world_T_camera ? attributes.world_T_camera->data() : nullptr;
        raw.image = detail::optional_c_str(attributes.image);
        uint32_t id = 0;
        check(topoloc_map_builder_add_view(get(), place, descriptor, len, &raw, &id));
        return id;
    }

    /// `add_view` with a vector descriptor.
    uint32_t add_view(uint32_t place, const std::vector<float> &descriptor,
                      const ViewAttributes &attributes = ViewAttributes())
    {
        return add_view(place, descriptor.data(), descriptor.size(), attributes);
    }

    /// Joins places `a` and `b` (different, existing, not yet joined) with `weight` > 0.
    void add_edge(uint32_t a, uint32_t b, float weight = 1.0f)
    {
        check(topoloc_map_builder_add_edge(get(), a, b, weight));
    }

    /// Validates and returns a map of what was added; the builder stays usable. Throws `Error`
    /// (`TOPOLOC_ERR_EMPTY_MAP`, `_INVALID_MAP` e.g. for a place without views).
    [[nodiscard]] Map build() const
    {
        topoloc_map *raw = nullptr;
        check(topoloc_map_builder_build(get(), &raw));
        return Map(raw);
    }
};

/// Builds a map from keyframes in order (`topoloc_map_from_keyframes`): places by spacing and
/// appearance novelty, edges between consecutive and nearby places. Either every keyframe has
/// a pose or none has. Throws `Error` (`TOPOLOC_ERR_EMPTY_MAP`, `_INVALID_ARGUMENT` naming the
/// bad keyframe or option).
[[nodiscard]] inline Map
map_from_keyframes(const std::string &kind, const std::string &model, uint32_t dim,
                   const std::vector<Keyframe> &keyframes,
                   const KeyframeOptions &options = default_keyframe_options())
{
    std::vector<topoloc_keyframe> raw(keyframes.size());
    for (std::size_t i = 0; i < keyframes.size(); ++i) {
        raw[i].id = keyframes[i].id;
        raw[i].descriptor = keyframes[i].descriptor.data();
        raw[i].descriptor_len = keyframes[i].descriptor.size();
        raw[i].world_T_camera =
            keyframes[i].world_T_camera ? keyframes[i].world_T_camera->data() : nullptr;
    }
    topoloc_map *out = nullptr;
    check(topoloc_map_from_keyframes(kind.c_str(), detail::optional_c_str(model), dim, raw.data(),
                                     raw.size(), &options, &out));
    return Map(out);
}

/// `map_from_keyframes` over C keyframe records (borrowed for the duration of the call).
[[nodiscard]] inline Map
map_from_keyframes(const std::string &kind, const std::string &model, uint32_t dim,
                   const topoloc_keyframe *keyframes, std::size_t count,
                   const KeyframeOptions &options = default_keyframe_options())
{
    topoloc_map *out = nullptr;
    check(topoloc_map_from_keyframes(kind.c_str(), detail::optional_c_str(model), dim, keyframes,
                                     count, &options, &out));
    return Map(out);
}

// ---------------------------------------------------------------------------------------------
// Localizer
// ---------------------------------------------------------------------------------------------

/// Owner of a localizer (`topoloc_localizer*`) that follows one camera through a map, plus the
/// buffers it reuses for results: after construction, `process` allocates nothing. Move-only;
/// the destructor calls `topoloc_localizer_free`. It keeps its own reference to the map, so the
/// `Map` it was made from may be destroyed first.
///
/// Thread safety: single-threaded state; use from one thread at a time (it may move between
/// threads). Many localizers may share one map on many threads.
/// Errors: every method that calls the library throws `Error` (or the subclass of its status,
/// see `throw_error`) on failure; a failed `process` leaves the localizer and its last result
/// unchanged. `process` is `[[nodiscard]]`: to feed a frame without reading its result, write
/// `(void)localizer.process(...)`.
class Localizer : public detail::Owner<topoloc_localizer, &topoloc_localizer_free> {
public:
    /// An empty owner (`!localizer`).
    Localizer() noexcept = default;

    /// Creates a localizer on `map`. The candidate buffer holds min(options.top_k, places)
    /// entries. With `options.image_backend` `TOPOLOC_BACKEND_AUTO` (the default) and a map built
    /// from images, the map's describer is loaded now, so that `process` accepts images (for
    /// ONNX: the runtime and model, from `options.onnx_runtime_path` / `onnx_model_path` or the
    /// defaults); `TOPOLOC_BACKEND_NONE` never loads one (descriptor frames only).
    /// Camera intrinsics in `options` (ABI 1.6) need verification on and a map whose keypoints
    /// carry scene points (`Map::with_keypoint_points`).
    /// Throws `Error` (`TOPOLOC_ERR_INVALID_OPTION`, also for bad intrinsics or intrinsics on a
    /// map without scene points; `_DESCRIPTOR_MISMATCH` also for another backend or model than
    /// the map's, `_STRUCT_SIZE`, `_NULL_ARGUMENT` for an empty map),
    /// `BackendUnavailableError` (paths tried in the message), `ModelError`, `NoDescriberError`
    /// (a backend was required but the map stores none).
    explicit Localizer(const Map &map,
                       const LocalizerOptions &options = default_localizer_options())
    {
        topoloc_localizer *raw = nullptr;
        check(topoloc_localizer_new(map.capi(), &options, &raw));
        adopt(raw);
        check(topoloc_frame_default(&frame_template_));
        check(topoloc_result_default(&result_template_));
        const std::size_t places = map.place_count();
        const std::size_t capacity =
            static_cast<std::size_t>(options.top_k) < places ? options.top_k : places;
        buffer_.resize(capacity);
        last_.candidates.reserve(capacity);
    }

    // Copies are deleted and the destructor (calls `topoloc_localizer_free`) comes from
    // `detail::Owner`; the moves below also move the result buffers.

    /// Moves ownership and buffers; `other` is left empty (no handle, no buffers).
    Localizer(Localizer &&other) noexcept
        : Owner(std::move(other)), frame_template_(other.frame_template_),
          result_template_(other.result_template_), buffer_(std::move(other.buffer_)),
          last_(std::move(other.last_))
    {
        other.clear_buffers();
    }

    /// Frees the current localizer (if any) and takes `other`'s; `other` is left empty.
    Localizer &operator=(Localizer &&other) noexcept
    {
        if (this != &other) {
            Owner::operator=(std::move(other));
            frame_template_ = other.frame_template_;
            result_template_ = other.result_template_;
            buffer_ = std::move(other.buffer_);
            last_ = std::move(other.last_);
            other.clear_buffers();
        }
        return *this;
    }

    /// Localizes one frame: `descriptor` holds `len` floats (the map's D; normalised by the
    /// library), `timestamp` is in seconds and must not decrease in filter mode, `odometry` is
    /// the motion since the previous frame `previous_T_current` (16 doubles, row-major 4x4) or
    /// null. Returns the result, which stays valid (and is overwritten) until the next
    /// `process`/`reset` or the destruction of this localizer: copy it to keep it.
    /// Throws `Error` (`TOPOLOC_ERR_DIMENSION_MISMATCH`, `_NON_FINITE`, `_ZERO_DESCRIPTOR`,
    /// `_TIMESTAMP`, `_INVALID_ARGUMENT` for non-rigid odometry, `_NULL_ARGUMENT` when empty).
    /// Cost: one pass over the map's descriptors plus O(places + edges); no allocation.
    [[nodiscard]] const Result &process(const float *descriptor, std::size_t len, double timestamp,
                                        const double *odometry = nullptr)
    {
        Frame frame;
        frame.timestamp = timestamp;
        frame.descriptor = descriptor;
        frame.descriptor_len = len;
        frame.odometry = odometry;
        return process(frame);
    }

    /// Localizes one frame, of a descriptor or of an image (see `Frame`): the general form of
    /// the other `process` overloads, with the same result lifetime and errors as theirs.
    [[nodiscard]] const Result &process(const Frame &input)
    {
        topoloc_frame frame = frame_template_;
        frame.timestamp = input.timestamp;
        frame.descriptor = input.descriptor;
        frame.descriptor_len = input.descriptor_len;
        frame.odometry = input.odometry;
        frame.image = input.image;
        topoloc_result raw = result_template_;
        raw.candidates = buffer_.empty() ? nullptr : buffer_.data();
        raw.candidates_capacity = buffer_.size();
        check(topoloc_localizer_process(get(), &frame, &raw));
        last_.frame_index = raw.frame_index;
        last_.place = raw.place;
        last_.view = raw.view;
        last_.confidence = raw.confidence;
        last_.similarity = raw.similarity;
        last_.off_map_probability = raw.off_map_probability;
        last_.off_map = raw.off_map;
        last_.verified = raw.verified;
        last_.inliers = raw.inliers;
        if (raw.has_pose_fix) {
            PoseFix fix;
            fix.view = raw.pose_fix_view;
            fix.inliers = raw.pose_fix_inliers;
            std::memcpy(fix.world_T_camera.data(), raw.world_T_camera, sizeof raw.world_T_camera);
            last_.pose_fix = fix;
        } else {
            last_.pose_fix.reset();
        }
        // Within the reserved capacity: no allocation.
        last_.candidates.assign(buffer_.begin(),
                                buffer_.begin() + static_cast<std::ptrdiff_t>(raw.candidates_len));
        return last_;
    }

    /// `process` with a vector descriptor.
    [[nodiscard]] const Result &process(const std::vector<float> &descriptor, double timestamp,
                                        const double *odometry = nullptr)
    {
        return process(descriptor.data(), descriptor.size(), timestamp, odometry);
    }

    /// `process` with odometry as a `Pose` (`previous_T_current`).
    [[nodiscard]] const Result &process(const std::vector<float> &descriptor, double timestamp,
                                        const Pose &odometry)
    {
        return process(descriptor.data(), descriptor.size(), timestamp, odometry.data());
    }

    /// Localizes one camera image (see `image_view`), described with the map's own backend; the
    /// localizer needs a describer (see the constructor). Same result lifetime as the descriptor
    /// `process`. Throws `UninformativeImageError` for a blank, constant or featureless image
    /// (the frame is skipped: state, frame count and last result unchanged, so just go on with
    /// the next frame), `InvalidImageError` for an unusable buffer, `NoDescriberError`,
    /// `ModelError`, and the `Error`s of the descriptor `process` (`_TIMESTAMP`,
    /// `_INVALID_ARGUMENT` for non-rigid odometry, ...).
    /// Cost: describing the image, then as `process`.
    [[nodiscard]] const Result &process(const Image &image, double timestamp,
                                        const double *odometry = nullptr)
    {
        Frame frame;
        frame.timestamp = timestamp;
        frame.odometry = odometry;
        frame.image = image;
        return process(frame);
    }

    /// `process` of an image with odometry as a `Pose` (`previous_T_current`).
    [[nodiscard]] const Result &process(const Image &image, double timestamp, const Pose &odometry)
    {
        return process(image, timestamp, odometry.data());
    }

    /// Forgets all history: the next frame is treated as the first (any timestamp accepted).
    void reset()
    {
        check(topoloc_localizer_reset(get()));
        clear_result();
    }

    /// The result of the last successful `process` since creation or `reset` (all zero and
    /// without candidates before the first).
    [[nodiscard]] const Result &last_result() const noexcept { return last_; }

    /// Most candidates a result can hold: min(options.top_k, places). 0 when empty.
    [[nodiscard]] std::size_t candidate_capacity() const noexcept { return buffer_.size(); }

    /// Gives up ownership: returns the handle (free it with `topoloc_localizer_free`) and leaves
    /// this object empty, its buffers released.
    [[nodiscard]] topoloc_localizer *release() noexcept
    {
        clear_buffers();
        return Owner::release();
    }

private:
    // Keeps the reserved capacity of the candidates: reset() must not cost an allocation later.
    void clear_result() noexcept
    {
        last_.frame_index = 0;
        last_.place = 0;
        last_.view = 0;
        last_.confidence = 0.f;
        last_.similarity = 0.f;
        last_.off_map_probability = 0.f;
        last_.off_map = false;
        last_.verified = false;
        last_.inliers = 0;
        last_.pose_fix.reset();
        last_.candidates.clear();
    }

    // Leaves the buffers of a moved-from or released localizer empty (no memory held).
    void clear_buffers() noexcept
    {
        std::vector<Candidate>().swap(buffer_);
        last_ = Result();
    }

    topoloc_frame frame_template_{};   // filled once by topoloc_frame_default
    topoloc_result result_template_{}; // filled once by topoloc_result_default
    std::vector<Candidate> buffer_;    // handed to the C call as the candidate array
    Result last_;                      // returned by reference from process()
};

// ---------------------------------------------------------------------------------------------
// Graph (skeleton map building)
// ---------------------------------------------------------------------------------------------

/// One place of a skeleton graph: its position in metres and its `TOPOLOC_NODE_*` kind.
struct GraphPlace {
    Position position{}; ///< Centre of the place's skeleton voxel, world metres.
    uint32_t kind = 0;   ///< `TOPOLOC_NODE_END`, `_CORNER`, `_BRANCH` or `_INTERMEDIATE`.
};

/// One undirected edge of a skeleton graph: places `a < b` and their straight distance.
struct GraphEdge {
    uint32_t a = 0;        ///< Smaller place index.
    uint32_t b = 0;        ///< Larger place index.
    double length_m = 0.0; ///< Straight-line distance between the places, metres.
};

/// Owner of a topological graph built from an occupancy voxel grid (`topoloc_graph*`, made by
/// `topoloc_graph_from_occupancy`). Move-only; the destructor calls `topoloc_graph_free`.
///
/// Thread safety: immutable; const methods may be called from many threads at once.
/// Errors: every method that calls the library throws `Error` on failure.
class Graph : public detail::Owner<topoloc_graph, &topoloc_graph_free> {
public:
    /// An empty owner (`!graph`).
    Graph() noexcept = default;

    /// Takes ownership of `raw` (from `topoloc_graph_from_occupancy`); null gives an empty owner.
    explicit Graph(topoloc_graph *raw) noexcept : Owner(raw) {}

    // Moves (noexcept; the source is left empty) and the destructor (calls `topoloc_graph_free`) come
    // from `detail::Owner`; copies are deleted.

    /// Builds the graph of the free space of an occupancy grid of `dims` voxels (x, y, z) of
    /// `voxel_size` metres whose voxel (0, 0, 0) starts at `origin`; `cells` holds one byte per
    /// voxel, x fastest (`cells[x + nx * (y + ny * z)]`), non-zero = occupied. Read during the
    /// call only. Throws `Error` (`TOPOLOC_ERR_INVALID_ARGUMENT` naming the field: `dims`,
    /// `voxel_size`, `origin`, `cells_len`, `cells` when every voxel is occupied, `z_band`,
    /// `min_clearance_m` or another option; `_STRUCT_SIZE`).
    [[nodiscard]] static Graph
    from_occupancy(const std::array<std::size_t, 3> &dims, double voxel_size,
                   const Position &origin, const uint8_t *cells, std::size_t cells_len,
                   const SkeletonOptions &options = default_skeleton_options())
    {
        topoloc_graph *raw = nullptr;
        check(topoloc_graph_from_occupancy(dims.data(), voxel_size, origin.data(), cells, cells_len,
                                           &options, &raw));
        return Graph(raw);
    }

    /// `from_occupancy` over a byte vector.
    [[nodiscard]] static Graph
    from_occupancy(const std::array<std::size_t, 3> &dims, double voxel_size,
                   const Position &origin, const std::vector<uint8_t> &cells,
                   const SkeletonOptions &options = default_skeleton_options())
    {
        return from_occupancy(dims, voxel_size, origin, cells.data(), cells.size(), options);
    }

    /// Number of places.
    [[nodiscard]] std::size_t place_count() const
    {
        std::size_t n = 0;
        check(topoloc_graph_place_count(get(), &n));
        return n;
    }

    /// Number of undirected edges.
    [[nodiscard]] std::size_t edge_count() const
    {
        std::size_t n = 0;
        check(topoloc_graph_edge_count(get(), &n));
        return n;
    }

    /// Place `index` (branches first, then ends, corners, intermediate places). Throws `Error`
    /// (`TOPOLOC_ERR_UNKNOWN_PLACE`).
    [[nodiscard]] GraphPlace place(uint32_t index) const
    {
        GraphPlace p;
        check(topoloc_graph_place(get(), index, p.position.data(), &p.kind));
        return p;
    }

    /// All places.
    [[nodiscard]] std::vector<GraphPlace> places() const
    {
        std::vector<GraphPlace> all(place_count());
        for (std::size_t i = 0; i < all.size(); ++i) {
            all[i] = place(static_cast<uint32_t>(i));
        }
        return all;
    }

    /// Edge number `index` (0..edge_count(), sorted by (a, b)). Throws `Error`
    /// (`TOPOLOC_ERR_INVALID_ARGUMENT` when out of range).
    [[nodiscard]] GraphEdge edge(std::size_t index) const
    {
        GraphEdge e;
        check(topoloc_graph_edge(get(), index, &e.a, &e.b, &e.length_m));
        return e;
    }

    /// All edges, sorted by (a, b).
    [[nodiscard]] std::vector<GraphEdge> edges() const
    {
        std::vector<GraphEdge> all(edge_count());
        for (std::size_t i = 0; i < all.size(); ++i) {
            all[i] = edge(i);
        }
        return all;
    }

    /// The skeleton the graph was built on: voxel indices x0, y0, z0, x1, y1, z1, ... in grid order.
    [[nodiscard]] std::vector<uint32_t> skeleton() const
    {
        return detail::read_ids([this](uint32_t *buf, std::size_t len, std::size_t *count) {
            return topoloc_graph_skeleton(get(), buf, len, count);
        });
    }
};

// ---------------------------------------------------------------------------------------------
// Loop closure (ABI 1.5): keyframes in, gated hints with relative poses out
// ---------------------------------------------------------------------------------------------

/// The gate that decided a loop hint (`LoopHint::gate`; the C `TOPOLOC_GATE_*` values). A
/// library newer than this header may report a value not listed here; treat it as a refusal.
enum class Gate : uint32_t {
    Accepted = 0,      ///< `TOPOLOC_GATE_ACCEPTED`: every gate passed, the hint is a loop closure.
    NoCandidate = 1,   ///< `TOPOLOC_GATE_NO_CANDIDATE`: no keyframe outside the exclusion window
                       ///< had features to verify.
    TooFewInliers = 2, ///< `TOPOLOC_GATE_TOO_FEW_INLIERS`: fewer inliers than `min_inliers`.
    Inconsistent = 3,  ///< `TOPOLOC_GATE_INCONSISTENT`: too few consecutive keyframes agreed on
                       ///< the place (`consistent_keyframes`).
    NoPose = 4,        ///< `TOPOLOC_GATE_NO_POSE`: intrinsics given but no relative pose fitted.
    Odometry = 5,      ///< `TOPOLOC_GATE_ODOMETRY`: the pose disagrees with the host's odometry.
};
static_assert(std::is_same_v<std::underlying_type_t<Gate>, topoloc_gate>,
              "Gate has the representation of topoloc_gate");
static_assert(static_cast<topoloc_gate>(Gate::Accepted) == TOPOLOC_GATE_ACCEPTED, "Accepted");
static_assert(static_cast<topoloc_gate>(Gate::NoCandidate) == TOPOLOC_GATE_NO_CANDIDATE,
              "NoCandidate");
static_assert(static_cast<topoloc_gate>(Gate::TooFewInliers) == TOPOLOC_GATE_TOO_FEW_INLIERS,
              "TooFewInliers");
static_assert(static_cast<topoloc_gate>(Gate::Inconsistent) == TOPOLOC_GATE_INCONSISTENT,
              "Inconsistent");
static_assert(static_cast<topoloc_gate>(Gate::NoPose) == TOPOLOC_GATE_NO_POSE, "NoPose");
static_assert(static_cast<topoloc_gate>(Gate::Odometry) == TOPOLOC_GATE_ODOMETRY, "Odometry");

/// One relocalization candidate of `LoopDetector::query` (the C struct: keyframe id, place,
/// cosine similarity).
using LoopCandidate = topoloc_loop_candidate;

/// One keyframe for `LoopDetector::add`, as the host's SLAM gives it. Owns its data. The arrays
/// are per keypoint: keypoint `i` is at (`keypoints[2i]`, `keypoints[2i+1]`), has descriptor
/// bytes `keypoint_descriptors[32i .. 32i+32)` and scene point `camera_points[3i .. 3i+3)`.
struct LoopKeyframe {
    uint64_t id = 0;                   ///< Host keyframe id; must increase from one to the next.
    double timestamp = 0.0;            ///< Seconds; must not decrease.
    std::vector<float> descriptor;     ///< Global descriptor (the detector's D floats).
    std::optional<Pose> world_T_body;  ///< Odometry pose of the body; all keyframes or none.
    std::optional<Pose> body_T_camera; ///< Camera in the body frame; none = identity.
    std::vector<float> keypoints;      ///< Pixel positions x, y (x right, y down): 2 per keypoint.
    std::vector<uint8_t> keypoint_descriptors; ///< 32-byte binary descriptors (ORB, BRIEF).
    /// Scene points in this keyframe's camera frame, metres (NaN x3 when unknown): 3 per
    /// keypoint, or empty for none. With intrinsics, a later hint matched to this keyframe is
    /// metric.
    std::vector<float> camera_points;
};

/// The hint of one added keyframe (the fields of `topoloc_loop_hint`): its best verified loop
/// candidate, if any, and the gate that decided.
struct LoopHint {
    uint64_t query_id = 0;    ///< The query keyframe's id (the added one, or a confirmed one's).
    uint32_t query_place = 0; ///< The place the query keyframe joined.
    bool has_match = false;   ///< A candidate was verified (the fields below describe it).
    bool accepted = false;    ///< Every gate passed: a loop closure for the pose graph.
    Gate gate = Gate::NoCandidate; ///< The gate that decided: why a candidate was refused.
    uint64_t matched_id = 0;       ///< The matched keyframe's id.
    uint32_t place = 0;            ///< The matched keyframe's place.
    uint32_t inliers = 0;          ///< Fundamental-matrix inliers between the two keyframes.
    float confidence = 0.f;        ///< The candidate's share of the inliers of all verified ones.
    bool has_pose = false;    ///< `matched_T_query` and `covariance` are set (intrinsics given).
    bool scale_known = false; ///< The translation is metric; else it has unit length.
    /// The query camera in the matched camera's optical frame (z forward, x right, y down),
    /// row-major 4x4; identity unless `has_pose`.
    Pose matched_T_query{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    /// Covariance of `matched_T_query` for a right perturbation, 6x6 row-major, GTSAM Pose3
    /// tangent order: rotation (rad) x y z, then translation (m) x y z; zero unless `has_pose`.
    std::array<double, 36> covariance{};
};

/// Owner of a describer (`topoloc_describer*`, ABI 1.12): a map's describer on its own, which
/// turns images into global descriptors exactly as the map's views were described, e.g. for
/// `LoopKeyframe::descriptor` or `Frame::descriptor`. Move-only; the destructor calls
/// `topoloc_describer_free`; it does not keep the map.
///
/// Thread safety: single-threaded state; use from one thread at a time (it may move between
/// threads); one describer per thread for parallel work.
/// Errors: every method that calls the library throws `Error` (or its status subclass); a
/// failed `describe` leaves the output untouched.
class Describer : public detail::Owner<topoloc_describer, &topoloc_describer_free> {
public:
    /// An empty owner (`!describer`).
    Describer() noexcept = default;

    /// Loads `map`'s describer (for ONNX: the runtime and the model, checked by hash). Throws
    /// `NoDescriberError` (a map built from descriptors), `BackendUnavailableError` (paths tried
    /// in the message), `ModelError`, `Error` (`TOPOLOC_ERR_DESCRIPTOR_MISMATCH` for another
    /// backend or model than the map's, `_INVALID_OPTION`, `_STRUCT_SIZE`, `_NULL_ARGUMENT` for
    /// an empty map).
    explicit Describer(const Map &map,
                       const DescriberOptions &options = default_describer_options())
    {
        topoloc_describer *raw = nullptr;
        check(topoloc_describer_new(map.capi(), &options, &raw));
        adopt(raw);
        check(topoloc_describer_dim(get(), &dim_));
    }

    /// The descriptor dimension D (the map's).
    [[nodiscard]] std::size_t dim() const noexcept { return dim_; }

    /// Describes `image` into `out` (resized to D; its storage is reused from call to call).
    /// Throws `InvalidImageError` (also for no image), `UninformativeImageError` (no content),
    /// `ModelError`, `Error` (`TOPOLOC_ERR_NULL_ARGUMENT` when empty).
    void describe(const Image &image, std::vector<float> &out)
    {
        std::vector<float> next(dim_);
        check(topoloc_describer_describe(get(), &image, next.data(), next.size(), nullptr));
        out.swap(next);
    }

    /// Describes `image`: D floats of unit norm. Same errors as the other overload.
    [[nodiscard]] std::vector<float> describe(const Image &image)
    {
        std::vector<float> out;
        describe(image, out);
        return out;
    }

private:
    std::size_t dim_ = 0;
};

/// Owner of a loop detector (`topoloc_loop_detector*`): a keyframe database with each
/// keyframe's local features that turns every added keyframe into at most one gated hint, for
/// one SLAM run and, from a map, against an earlier one. Move-only; the destructor calls
/// `topoloc_loop_detector_free`. A detector made `from_map` does not keep the map.
///
/// Thread safety: single-threaded state; use from one thread at a time (it may move between
/// threads).
/// Errors: every method that calls the library throws `Error` on failure; a failed call leaves
/// the detector unchanged.
class LoopDetector : public detail::Owner<topoloc_loop_detector, &topoloc_loop_detector_free> {
public:
    /// An empty owner (`!detector`).
    LoopDetector() noexcept = default;

    /// Takes ownership of `raw` (from `topoloc_loop_detector_new` / `_from_map`); null gives an
    /// empty owner.
    explicit LoopDetector(topoloc_loop_detector *raw) noexcept : Owner(raw) {}

    // Moves (noexcept; the source is left empty) and the destructor (calls
    // `topoloc_loop_detector_free`) come from `detail::Owner`; copies are deleted.

    /// An empty detector for descriptors of `kind` / `model` (both non-empty) with dimension
    /// `dim`: the place graph grows from nothing. Throws `Error` (`TOPOLOC_ERR_INVALID_OPTION`,
    /// `_INVALID_ARGUMENT` for an empty kind or model or dim 0, `_STRUCT_SIZE`, `_INVALID_UTF8`).
    [[nodiscard]] static LoopDetector create(const std::string &kind, const std::string &model,
                                             uint32_t dim,
                                             const LoopOptions &options = default_loop_options())
    {
        topoloc_loop_detector *raw = nullptr;
        check(topoloc_loop_detector_new(kind.c_str(), model.c_str(), dim, &options, &raw));
        return LoopDetector(raw);
    }

    /// An empty detector for the descriptors of `map`'s describer (its kind, model and D), for a
    /// host that describes its keyframe images with a `Describer` of the same map (ABI 1.12).
    /// The map is not kept. Same errors as `create`.
    [[nodiscard]] static LoopDetector
    for_descriptors_of(const Map &map, const LoopOptions &options = default_loop_options())
    {
        return create(map.descriptor_kind(), map.descriptor_model(), map.dim(), options);
    }

    /// A detector whose first session is `map`'s views (with their stored keypoints and, where
    /// known, scene points): new keyframes (ids above the map's) close loops against it. The map
    /// is not kept. Throws `Error` (`TOPOLOC_ERR_INVALID_OPTION`, also for a view without
    /// keyframe id; `_INVALID_ARGUMENT` for ids not increasing; `_STRUCT_SIZE`; `_NULL_ARGUMENT`
    /// for an empty map).
    [[nodiscard]] static LoopDetector from_map(const Map &map,
                                               const LoopOptions &options = default_loop_options())
    {
        topoloc_loop_detector *raw = nullptr;
        check(topoloc_loop_detector_from_map(map.capi(), &options, &raw));
        return LoopDetector(raw);
    }

    /// Adds a keyframe: its loop candidates (outside the exclusion window) are verified against
    /// its keypoints and gated, then it joins the place graph. Returns its hint (`has_match`
    /// false when no candidate was verified). The whole keyframe is validated first.
    /// Throws `Error`: `TOPOLOC_ERR_INVALID_ARGUMENT` from this layer when the arrays disagree
    /// (an odd number of keypoint coordinates, not 32 descriptor bytes or, when given, 3 scene
    /// coordinates per keypoint); from the library `_DIMENSION_MISMATCH`, `_NON_FINITE`,
    /// `_ZERO_DESCRIPTOR`, `_INVALID_ARGUMENT` (duplicate or decreasing id, earlier timestamp,
    /// poses on some keyframes only, bad keypoints, non-rigid poses), `_NULL_ARGUMENT` when
    /// empty. `[[nodiscard]]`: to add a keyframe without reading its hint, write
    /// `(void)detector.add(...)`.
    [[nodiscard]] LoopHint add(const LoopKeyframe &keyframe)
    {
        const std::size_t count = keyframe.keypoints.size() / 2;
        if (keyframe.keypoints.size() % 2 != 0) {
            throw Error(TOPOLOC_ERR_INVALID_ARGUMENT,
                        "keyframe.keypoints holds " + std::to_string(keyframe.keypoints.size()) +
                            " floats, not 2 per keypoint");
        }
        if (keyframe.keypoint_descriptors.size() / 32 != count ||
            keyframe.keypoint_descriptors.size() % 32 != 0) {
            throw Error(TOPOLOC_ERR_INVALID_ARGUMENT,
                        "keyframe.keypoint_descriptors holds " +
                            std::to_string(keyframe.keypoint_descriptors.size()) + " bytes, " +
                            std::to_string(count) + " keypoints need 32 each");
        }
        if (!keyframe.camera_points.empty() && (keyframe.camera_points.size() / 3 != count ||
                                                keyframe.camera_points.size() % 3 != 0)) {
            throw Error(TOPOLOC_ERR_INVALID_ARGUMENT,
                        "keyframe.camera_points holds " +
                            std::to_string(keyframe.camera_points.size()) + " floats, " +
                            std::to_string(count) + " keypoints need 3 each (or none)");
        }
        topoloc_loop_keyframe raw;
        check(topoloc_loop_keyframe_default(&raw));
        raw.id = keyframe.id;
        raw.timestamp = keyframe.timestamp;
        raw.descriptor = keyframe.descriptor.data();
        raw.descriptor_len = keyframe.descriptor.size();
        raw.world_T_body = keyframe.world_T_body ? keyframe.world_T_body->data() : nullptr;
        raw.body_T_camera = keyframe.body_T_camera ? keyframe.body_T_camera->data() : nullptr;
        raw.keypoint_count = count;
        raw.keypoints = keyframe.keypoints.data();
        raw.keypoint_descriptors = keyframe.keypoint_descriptors.data();
        raw.camera_points =
            keyframe.camera_points.empty() ? nullptr : keyframe.camera_points.data();
        return add(raw);
    }

    /// `add` of a C keyframe record (start from `topoloc_loop_keyframe_default`; its arrays are
    /// borrowed for the call and must hold what its counts say): no copy of the host's
    /// buffers. Same result and errors as `add`, plus `_STRUCT_SIZE`.
    [[nodiscard]] LoopHint add(const topoloc_loop_keyframe &keyframe)
    {
        topoloc_loop_hint raw;
        check(topoloc_loop_hint_default(&raw));
        check(topoloc_loop_detector_add(get(), &keyframe, &raw));
        return from_raw(raw);
    }

    /// The hints of earlier keyframes that the last `add` confirmed (ABI 1.10), oldest first:
    /// when an added keyframe's hint is accepted because it completes a consistency streak, the
    /// streak's earlier keyframes, refused as `Gate::Inconsistent` while it was short, are
    /// accepted too (each with its own `query_id`; at most one accepted hint per keyframe in
    /// all). Empty after an `add` whose hint was not accepted; replaced by the next `add`, kept
    /// by a failed one and by `erase`. Throws `Error` (`TOPOLOC_ERR_NULL_ARGUMENT` when empty).
    [[nodiscard]] std::vector<LoopHint> confirmed() const
    {
        std::size_t count = 0;
        check(topoloc_loop_detector_confirmed_count(get(), &count));
        std::vector<LoopHint> hints;
        hints.reserve(count);
        for (std::size_t i = 0; i < count; ++i) {
            topoloc_loop_hint raw;
            check(topoloc_loop_hint_default(&raw));
            check(topoloc_loop_detector_confirmed(get(), i, &raw));
            hints.push_back(from_raw(raw));
        }
        return hints;
    }

private:
    /// The C++ form of a C hint.
    static LoopHint from_raw(const topoloc_loop_hint &raw)
    {
        LoopHint hint;
        hint.query_id = raw.query_id;
        hint.query_place = raw.query_place;
        hint.has_match = raw.has_match;
        hint.accepted = raw.accepted;
        hint.gate = static_cast<Gate>(raw.gate);
        hint.matched_id = raw.matched_id;
        hint.place = raw.place;
        hint.inliers = raw.inliers;
        hint.confidence = raw.confidence;
        hint.has_pose = raw.has_pose;
        hint.scale_known = raw.scale_known;
        std::memcpy(hint.matched_T_query.data(), raw.matched_T_query, sizeof raw.matched_T_query);
        std::memcpy(hint.covariance.data(), raw.covariance, sizeof raw.covariance);
        return hint;
    }

public:
    /// Relocalization candidates for `descriptor` (`len` floats, the detector's D), which is not
    /// added: at most `max` keyframes (every keyframe may match), most similar first. Throws
    /// `Error` (`TOPOLOC_ERR_DIMENSION_MISMATCH`, `_NON_FINITE`, `_ZERO_DESCRIPTOR`,
    /// `_NULL_ARGUMENT` when empty).
    [[nodiscard]] std::vector<LoopCandidate> query(const float *descriptor, std::size_t len,
                                                   std::size_t max) const
    {
        const std::size_t held = size();
        std::vector<LoopCandidate> found(max < held ? max : held);
        std::size_t count = 0;
        check(topoloc_loop_detector_query(get(), descriptor, len, found.data(), found.size(),
                                          &count));
        found.resize(count);
        return found;
    }

    /// `query` with a vector descriptor.
    [[nodiscard]] std::vector<LoopCandidate> query(const std::vector<float> &descriptor,
                                                   std::size_t max) const
    {
        return query(descriptor.data(), descriptor.size(), max);
    }

    /// Removes keyframe `id` and its features (as ORB-SLAM culls keyframes). Throws `Error`
    /// (`TOPOLOC_ERR_INVALID_ARGUMENT` when no keyframe has that id).
    void erase(uint64_t id) { check(topoloc_loop_detector_erase(get(), id)); }

    /// Saves the keyframes and their place graph as a map file (a view per keyframe, keyframe
    /// ids kept) atomically, for a later session: `Map::load`, then `from_map`. Throws `Error`
    /// (`TOPOLOC_ERR_IO`, `_EMPTY_MAP`, `_INVALID_UTF8`).
    void save(const std::string &path) const
    {
        check(topoloc_loop_detector_save(get(), path.c_str()));
    }

    /// Number of keyframes held.
    [[nodiscard]] std::size_t size() const
    {
        std::size_t n = 0;
        check(topoloc_loop_detector_len(get(), &n));
        return n;
    }
};

// ---------------------------------------------------------------------------------------------
// Trajectory metrics (ABI 1.11): ATE, ARE, RPE and R_traj against ground truth
// ---------------------------------------------------------------------------------------------

/// How trajectories are associated and aligned (the C struct; see topoloc.h): Sim3 alignment,
/// 0.01 s association tolerance, no offset, RPE over 1 pose by default.
using TrajectoryOptions = topoloc_trajectory_options;

/// What `evaluate_trajectory` measured (the C struct: `pairs`, `scale`, `alignment`, `ate_m`,
/// `are_deg`, `rpe_m`, `rpe_deg` with rmse/mean/median/std/min/max, path lengths and
/// `length_ratio`, R_traj).
using TrajectoryReport = topoloc_trajectory_report;

/// The default trajectory options (`topoloc_trajectory_options_default`).
[[nodiscard]] inline TrajectoryOptions default_trajectory_options()
{
    TrajectoryOptions options;
    check(topoloc_trajectory_options_default(&options));
    return options;
}

/// One pose of a trajectory in TUM's layout: seconds, then `world_T_body` as
/// `tx ty tz qx qy qz qw` (unit quaternion, w last).
struct TimedPose {
    double timestamp = 0.0;
    std::array<double, 7> pose{0, 0, 0, 0, 0, 0, 1};
};

/// Judges `estimate` against `reference` as `evo_ape` / `evo_rpe` do
/// (`topoloc_trajectory_evaluate`). Thread-safe. Throws `Error` (`TOPOLOC_ERR_INVALID_ARGUMENT`
/// for decreasing timestamps, a quaternion not of norm 1, no associated pair, too few pairs or
/// degenerate positions; `_NON_FINITE`; `_INVALID_OPTION`).
[[nodiscard]] inline TrajectoryReport
evaluate_trajectory(const std::vector<TimedPose> &reference, const std::vector<TimedPose> &estimate,
                    const TrajectoryOptions &options = default_trajectory_options())
{
    auto split = [](const std::vector<TimedPose> &t, std::vector<double> &stamps,
                    std::vector<double> &poses) {
        for (const TimedPose &p : t) {
            stamps.push_back(p.timestamp);
            poses.insert(poses.end(), p.pose.begin(), p.pose.end());
        }
    };
    std::vector<double> ref_t, ref_p, est_t, est_p;
    split(reference, ref_t, ref_p);
    split(estimate, est_t, est_p);
    TrajectoryReport report;
    check(topoloc_trajectory_report_default(&report));
    check(topoloc_trajectory_evaluate(ref_t.data(), ref_p.data(), reference.size(), est_t.data(),
                                      est_p.data(), estimate.size(), &options, &report));
    return report;
}

/// `evaluate_trajectory` of two files (`topoloc_trajectory_evaluate_files`) in `format`
/// (`TOPOLOC_TRAJECTORY_DETECT` tells each file's format: TUM, KITTI or EuRoC). Throws `Error`
/// (`TOPOLOC_ERR_IO`, `_INVALID_ARGUMENT` for a malformed line, and those of
/// `evaluate_trajectory`).
[[nodiscard]] inline TrajectoryReport
evaluate_trajectory_files(const std::string &reference_path, const std::string &estimate_path,
                          topoloc_trajectory_format format = TOPOLOC_TRAJECTORY_DETECT,
                          const TrajectoryOptions &options = default_trajectory_options())
{
    TrajectoryReport report;
    check(topoloc_trajectory_report_default(&report));
    check(topoloc_trajectory_evaluate_files(reference_path.c_str(), estimate_path.c_str(), format,
                                            &options, &report));
    return report;
}

} // namespace topoloc

#endif // TOPOLOC_HPP
