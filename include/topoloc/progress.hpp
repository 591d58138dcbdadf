/*
 * topoloc/progress.hpp: progress callbacks of map builds, and the trampoline that keeps a C++
 * callback's exceptions from crossing the C boundary (part of topoloc.hpp, which has the
 * overview).
 */

#ifndef TOPOLOC_PROGRESS_HPP
#define TOPOLOC_PROGRESS_HPP

#include "../topoloc.h"
#include "error.hpp"

#include <cstddef>
#include <cstdint>
#include <exception>
#include <functional>

namespace topoloc {

/// Stage of a map build reported to a `Progress` callback.
enum class Stage : uint32_t {
    Describing = TOPOLOC_STAGE_DESCRIBING, ///< Describing images: `done` of `total` images.
    Fitting = TOPOLOC_STAGE_FITTING,       ///< Fitting the describer and assembling.
};

/// Progress of a map build, called on the building thread as `topoloc_progress_fn` (topoloc.h)
/// says: return true to go on, false to cancel (`CancelledError`). It runs inside topoloc, so it
/// must not unwind, longjmp or otherwise jump through the C call; this layer guarantees that for
/// exceptions: one thrown by the callback is caught before it reaches C, cancels the build
/// (the callback is not called again), and is rethrown, unchanged, by the building function
/// once the C call has returned. A `longjmp` out of the callback is never safe.
using Progress = std::function<bool(Stage stage, std::size_t done, std::size_t total)>;

namespace detail {

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
} // namespace topoloc

#endif // TOPOLOC_PROGRESS_HPP
