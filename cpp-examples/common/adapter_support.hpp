// What the SLAM adapters (vins/topoloc_vins.hpp, orbslam/topoloc_orbslam.hpp) share: how they
// report errors (a logger that hears of each, the last error of each calling thread, the count
// of failed calls) and the check that every keyframe image of a run has the first one's size.
//
// Part of the adapters: a host that copies an adapter copies this file with it, as
// ../common/adapter_support.hpp next to the adapter's directory. Header-only, C++17, OpenCV core.
#ifndef TOPOLOC_EXAMPLES_ADAPTER_SUPPORT_HPP
#define TOPOLOC_EXAMPLES_ADAPTER_SUPPORT_HPP

#include <opencv2/core.hpp>

#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <thread>
#include <unordered_map>
#include <utility>

namespace topoloc_adapter {

/// Receives an adapter's messages (e.g. ROS_WARN or spdlog). It should not throw: an exception
/// it throws is swallowed (`log`).
using Logger = std::function<void(const std::string &)>;

/// Passes `message` to `logger`, if one is set; an exception the logger throws is swallowed
/// (an adapter's callers do not expect exceptions from it).
inline void log(const Logger &logger, const std::string &message) noexcept
{
    if (!logger) {
        return;
    }
    try {
        logger(message);
    } catch (...) { // a logger must not throw; ignore it if it does
    }
}

/// The errors of an adapter's calls: the outcome of each calling thread's last call, how many
/// calls failed, and the logger that hears of each failure. Not thread-safe by itself: an
/// adapter called from several threads guards it with its own mutex, and calls the logger
/// `record` returns once that mutex is released.
class ErrorReport {
public:
    /// Records the outcome of the calling thread's call: "" for success, else its error, which
    /// is counted. Returns the logger to tell of a failure (a copy; empty on success, without a
    /// logger, or out of memory): pass it to `log` once any lock is released.
    Logger record(const std::string &error) noexcept
    {
        try {
            if (!error.empty()) {
                ++errors_;
            }
            last_[std::this_thread::get_id()] = error;
            return error.empty() ? Logger() : logger_;
        } catch (...) { // out of memory: nothing better to do
            return Logger();
        }
    }

    /// The error of the calling thread's last call ("" when it succeeded, or before any).
    [[nodiscard]] std::string last_error() const
    {
        const auto it = last_.find(std::this_thread::get_id());
        return it == last_.end() ? std::string() : it->second;
    }

    /// How many calls failed (all threads).
    [[nodiscard]] std::size_t error_count() const noexcept { return errors_; }

    /// The logger (empty = none), for messages that are not errors of a call.
    [[nodiscard]] const Logger &logger() const noexcept { return logger_; }

    /// Replaces the logger (empty = none).
    void set_logger(Logger logger) noexcept { logger_.swap(logger); }

private:
    std::unordered_map<std::thread::id, std::string> last_;
    std::size_t errors_ = 0;
    Logger logger_;
};

/// The size every image of a run must have: the first keyframe's (a describer's descriptors
/// are comparable only between images of one size).
class ImageSize {
public:
    /// Why an image of `size`, named `what` in the message, does not fit the run: "" when it
    /// does (also before the first keyframe), else "<what> is WxH, the first keyframe's was WxH".
    [[nodiscard]] std::string mismatch(const cv::Size &size, const std::string &what) const
    {
        if (!first_ || size == *first_) {
            return std::string();
        }
        return what + " is " + text(size) + ", the first keyframe's was " + text(*first_);
    }

    /// Takes `size` as the run's when it has none yet (call it once a keyframe is added).
    void remember(const cv::Size &size)
    {
        if (!first_) {
            first_ = size;
        }
    }

    /// Forgets the size: a new run starts.
    void reset() noexcept { first_.reset(); }

private:
    static std::string text(const cv::Size &size)
    {
        return std::to_string(size.width) + "x" + std::to_string(size.height);
    }

    std::optional<cv::Size> first_;
};

} // namespace topoloc_adapter

#endif // TOPOLOC_EXAMPLES_ADAPTER_SUPPORT_HPP
