/*
 * topoloc/loops.hpp: loop closure (ABI 1.5; part of topoloc.hpp, which has the overview):
 * `LoopDetector` turns the keyframes of a SLAM run (with the host's keypoints, or as images
 * described by a `KeyframeDescriber` of keyframes.hpp, ABI 1.15) into gated loop hints with
 * relative poses, ranks the candidates it verified, and answers relocalization queries.
 */

#ifndef TOPOLOC_LOOPS_HPP
#define TOPOLOC_LOOPS_HPP

#include "../topoloc.h"
#include "detail.hpp"
#include "error.hpp"
#include "options.hpp"
#include "geometry.hpp"
#include "image.hpp"
#include "keyframes.hpp"
#include "map.hpp"

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

namespace topoloc {

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
    SelfMatch = 6,     ///< `TOPOLOC_GATE_SELF_MATCH` (ABI 1.17): the candidate is the keyframe's
                       ///< own image (a map built from this run's images; see `from_map`).
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
static_assert(static_cast<topoloc_gate>(Gate::SelfMatch) == TOPOLOC_GATE_SELF_MATCH, "SelfMatch");

/// What a hint's translation holds (`LoopHint::translation`; the C `TOPOLOC_TRANSLATION_*`
/// values, ABI 1.17).
enum class Translation : uint32_t {
    None = 0,      ///< `TOPOLOC_TRANSLATION_NONE`: no pose, or a rotation only (exactly zero).
    Direction = 1, ///< `TOPOLOC_TRANSLATION_DIRECTION`: unit length; the host finds the scale.
    Metric = 2,    ///< `TOPOLOC_TRANSLATION_METRIC`: metres (the matched keyframe's points).
};
static_assert(std::is_same_v<std::underlying_type_t<Translation>, topoloc_translation>,
              "Translation has the representation of topoloc_translation");
static_assert(static_cast<topoloc_translation>(Translation::None) == TOPOLOC_TRANSLATION_NONE,
              "None");
static_assert(static_cast<topoloc_translation>(Translation::Direction) ==
                  TOPOLOC_TRANSLATION_DIRECTION,
              "Direction");
static_assert(static_cast<topoloc_translation>(Translation::Metric) == TOPOLOC_TRANSLATION_METRIC,
              "Metric");

/// One relocalization candidate of `LoopDetector::query` (the C struct: keyframe id, place,
/// cosine similarity).
using LoopCandidate = topoloc_loop_candidate;

/// One loop candidate that `LoopDetector::add` / `add_image` verified, of
/// `LoopDetector::candidates` (the C struct, ABI 1.15): `keyframe_id`, `place`, the cosine
/// `similarity` of the global descriptors, fundamental-matrix `inliers` of the pair check, and
/// `confidence`, its share of the inliers of every verified candidate of the keyframe (0..=1).
using LoopCandidateCheck = topoloc_loop_candidate_check;

/// One keyframe for `LoopDetector::add`, as the host's SLAM gives it (for `add_image`, ABI 1.15:
/// only its id, timestamp and poses; the arrays stay empty). Owns its data. The arrays are per
/// keypoint: keypoint `i` is at (`keypoints[2i]`, `keypoints[2i+1]`), has descriptor bytes
/// `keypoint_descriptors[32i .. 32i+32)` and scene point `camera_points[3i .. 3i+3)`.
struct LoopKeyframe {
    /// Host keyframe id: its keyframe counter (not a frame index or a time; the exclusion
    /// window and the candidate id gap count keyframes in it). Must increase from one to the
    /// next, past erased keyframes' ids too.
    uint64_t id = 0;
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
    float confidence = 0.f;   ///< The matched keyframe's share of the inliers of all verified ones.
    bool has_pose = false;    ///< `matched_T_query` and `covariance` are set (intrinsics given).
    bool scale_known = false; ///< The translation is metric (`translation == Metric`).
    /// What the translation holds (ABI 1.17): metres, a unit direction, or none (no pose, or a
    /// rotation only: exactly zero).
    Translation translation = Translation::None;
    /// The query camera in the matched camera's optical frame (z forward, x right, y down),
    /// row-major 4x4; identity unless `has_pose`.
    Pose matched_T_query{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    /// Covariance of `matched_T_query` for a right perturbation, 6x6 row-major, GTSAM Pose3
    /// tangent order: rotation (rad) x y z, then translation (m) x y z; zero unless `has_pose`.
    std::array<double, 36> covariance{};
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
        topoloc_loop_keyframe raw = detail::filled(&topoloc_loop_keyframe_init);
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
        topoloc_loop_hint raw = detail::filled(&topoloc_loop_hint_init);
        check(topoloc_loop_detector_add(get(), &keyframe, &raw));
        return from_raw(raw);
    }

    /// Adds a keyframe given as an image (ABI 1.15): `describer` (a `KeyframeDescriber` of the
    /// map whose descriptors this detector holds) gives its global descriptor and local features
    /// in one pass, then it is verified and gated as `add` does; returns its hint as `add` does.
    /// `keyframe` gives the id, timestamp and poses only: its `descriptor`, `keypoints`,
    /// `keypoint_descriptors` and `camera_points` must be empty (the image gives them). `depth`
    /// (optional; registered to `image`, same size) needs intrinsics in the detector's options
    /// and gives each keypoint its scene point, so later hints matched to this keyframe are
    /// metric. The pixels and depth values are read only during the call. On any error the
    /// detector and the describer are unchanged. Throws the errors of `add` (but the array checks
    /// of this layer), and `InvalidImageError` (a bad image buffer, no image),
    /// `UninformativeImageError` (no content), `ModelError`, `Error`
    /// (`TOPOLOC_ERR_INVALID_ARGUMENT`: a descriptor or keypoints given, a depth image of
    /// another size than the image, local features of another kind than earlier keyframes';
    /// `_INVALID_OPTION`: depth without intrinsics; `_DIMENSION_MISMATCH`: a describer of
    /// another map than the detector's descriptors; `_CONCURRENT_USE`; `_NULL_ARGUMENT` for an
    /// empty detector or describer). `[[nodiscard]]` as `add`.
    [[nodiscard]] LoopHint add_image(KeyframeDescriber &describer, const LoopKeyframe &keyframe,
                                     const Image &image,
                                     const std::optional<DepthImage> &depth = std::nullopt)
    {
        topoloc_loop_keyframe raw = detail::filled(&topoloc_loop_keyframe_init);
        raw.id = keyframe.id;
        raw.timestamp = keyframe.timestamp;
        raw.world_T_body = keyframe.world_T_body ? keyframe.world_T_body->data() : nullptr;
        raw.body_T_camera = keyframe.body_T_camera ? keyframe.body_T_camera->data() : nullptr;
        // Arrays a host filled anyway are passed on, so that the library refuses them with its
        // message (an empty vector may still own storage: it passes as NULL).
        raw.descriptor = keyframe.descriptor.empty() ? nullptr : keyframe.descriptor.data();
        raw.descriptor_len = keyframe.descriptor.size();
        raw.keypoint_count = keyframe.keypoints.size() / 2;
        raw.keypoints = keyframe.keypoints.empty() ? nullptr : keyframe.keypoints.data();
        raw.keypoint_descriptors =
            keyframe.keypoint_descriptors.empty() ? nullptr : keyframe.keypoint_descriptors.data();
        raw.camera_points =
            keyframe.camera_points.empty() ? nullptr : keyframe.camera_points.data();
        return add_image(describer, raw, image, depth);
    }

    /// `add_image` of a C keyframe record (start from `topoloc_loop_keyframe_default`; its
    /// descriptor and keypoint fields stay NULL and 0). Same result and errors as `add_image`,
    /// plus `_STRUCT_SIZE`.
    [[nodiscard]] LoopHint add_image(KeyframeDescriber &describer,
                                     const topoloc_loop_keyframe &keyframe, const Image &image,
                                     const std::optional<DepthImage> &depth = std::nullopt)
    {
        topoloc_loop_hint raw = detail::filled(&topoloc_loop_hint_init);
        check(topoloc_loop_detector_add_image(get(), describer.get(), &keyframe, &image,
                                              depth ? &*depth : nullptr, &raw));
        return from_raw(raw);
    }

    /// The loop candidates the last successful `add` or `add_image` verified (ABI 1.15), most
    /// inliers first, accepted or not (keyframes erased since are left out): at most `max`. For
    /// hosts that run their own check on several candidates (ORB-SLAM3 takes 3 loop and 3 merge
    /// candidates). Replaced by the next `add` / `add_image`, kept by a failed one; empty before
    /// the first. Throws `Error` (`TOPOLOC_ERR_NULL_ARGUMENT` when empty).
    [[nodiscard]] std::vector<LoopCandidateCheck> candidates(std::size_t max = 8) const
    {
        const std::size_t held = size();
        std::vector<LoopCandidateCheck> found(max < held ? max : held);
        std::size_t count = 0;
        check(topoloc_loop_detector_candidates(get(), found.data(), found.size(), &count));
        found.resize(count);
        return found;
    }

    /// The hints of earlier keyframes that the last `add` confirmed (ABI 1.10), oldest first:
    /// when an added keyframe's hint is accepted because it completes a consistency streak, the
    /// streak's earlier keyframes, refused as `Gate::Inconsistent` while it was short, are
    /// accepted too (each with its own `query_id`; at most one accepted hint per keyframe in
    /// all). Empty after an `add` whose hint was not accepted; replaced by the next `add`, kept
    /// by a failed one and by `erase`. Throws `Error` (`TOPOLOC_ERR_NULL_ARGUMENT` when empty).
    [[nodiscard]] std::vector<LoopHint> confirmed() const
    {
        const std::size_t count = read_value(&topoloc_loop_detector_confirmed_count);
        std::vector<LoopHint> hints;
        hints.reserve(count);
        for (std::size_t i = 0; i < count; ++i) {
            topoloc_loop_hint raw = detail::filled(&topoloc_loop_hint_init);
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
        hint.translation = static_cast<Translation>(raw.translation);
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

    /// Starts a new session whose odometry is in a new world frame (ABI 1.15): ORB-SLAM3's new
    /// map after tracking is lost, VINS-Fusion's new sequence. The keyframes held become an
    /// earlier session's: never inside the exclusion window, not compared by time or by the
    /// odometry gate; the next keyframe's timestamp may be earlier than the last one's (ids
    /// must still increase). The consistency streak ends. Throws `Error` only for a detector
    /// used by two threads at once.
    void begin_session() { check(topoloc_loop_detector_begin_session(get())); }

    /// Saves the keyframes and their place graph as a map file (a view per keyframe, keyframe
    /// ids kept) atomically, for a later session: `Map::load`, then `from_map`. Throws `Error`
    /// (`TOPOLOC_ERR_IO`, `_EMPTY_MAP`, `_INVALID_UTF8`).
    void save(const std::string &path) const
    {
        check(topoloc_loop_detector_save(get(), path.c_str()));
    }

    /// Number of keyframes held.
    [[nodiscard]] std::size_t size() const { return read_value(&topoloc_loop_detector_len); }

    /// The smallest id the next keyframe may have (ABI 1.17): one above the largest id ever
    /// added or reloaded, 0 for an empty new detector. A host whose keyframe ids restart at 0
    /// in a new run adds it to them after `from_map`. Throws `Error`
    /// (`TOPOLOC_ERR_INVALID_ARGUMENT` once id `UINT64_MAX` was added).
    [[nodiscard]] std::uint64_t next_id() const
    {
        return read_value(&topoloc_loop_detector_next_id);
    }
};

} // namespace topoloc

#endif // TOPOLOC_LOOPS_HPP
