/*
 * topoloc/localizer.hpp: `Localizer`, which follows one camera through a map frame by frame
 * (part of topoloc.hpp, which has the overview), with its frames and results (its options are
 * in options.hpp).
 */

#ifndef TOPOLOC_LOCALIZER_HPP
#define TOPOLOC_LOCALIZER_HPP

#include "../topoloc.h"
#include "detail.hpp"
#include "error.hpp"
#include "options.hpp"
#include "geometry.hpp"
#include "image.hpp"
#include "map.hpp"

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <optional>
#include <utility>
#include <vector>

namespace topoloc {

/// One ranked hypothesis of a frame (the C struct: place, view, probability, similarity).
using Candidate = topoloc_candidate;

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
    bool verified = false; ///< `place` verified geometrically this frame (see topoloc_result).
    uint32_t inliers = 0;  ///< Verification inliers with `view` (see `topoloc_result::inliers`).
    /// The camera's pose against the best-verified view (ABI 1.6), when the options have camera
    /// intrinsics, the map's keypoints carry scene points and enough keypoints agree; else none.
    std::optional<PoseFix> pose_fix;
};

/// One camera frame for `Localizer::process(const Frame &)`: a descriptor (used when given) or
/// an image (described with the map's backend when `descriptor_len` is 0). Borrows everything.
struct Frame {
    double timestamp = 0.0;            ///< Seconds; must not decrease in filter mode.
    const float *descriptor = nullptr; ///< Global descriptor (`descriptor_len` floats) or null.
    std::size_t descriptor_len = 0;    ///< The map's D, or 0 to describe `image`.
    const double *odometry = nullptr;  ///< `previous_T_current`, 16 doubles row-major, or null.
    Image image{};                     ///< The camera image (`TOPOLOC_PIXEL_NONE` = none).
};

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
    /// entries. Whether the map's describer is loaded now, so that `process` accepts images, and
    /// from where, is `options.image_backend`'s choice (see `topoloc_localizer_options` in
    /// topoloc.h); `TOPOLOC_BACKEND_NONE` never loads one (descriptor frames only).
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
        frame_template_ = detail::filled(&topoloc_frame_init);
        result_template_ = detail::filled(&topoloc_result_init);
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
    /// Cost: `topoloc_localizer_process`'s (topoloc.h); this layer allocates nothing.
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
    /// Cost: describing the image, then as the descriptor `process`.
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

    topoloc_frame frame_template_{};   // filled once by the library (topoloc_frame_init)
    topoloc_result result_template_{}; // filled once by the library (topoloc_result_init)
    std::vector<Candidate> buffer_;    // handed to the C call as the candidate array
    Result last_;                      // returned by reference from process()
};

} // namespace topoloc

#endif // TOPOLOC_LOCALIZER_HPP
