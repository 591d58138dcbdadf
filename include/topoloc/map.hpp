/*
 * topoloc/map.hpp: maps (part of topoloc.hpp, which has the overview): `Map`, the immutable
 * place graph with its views, loaded, saved, inspected and built from images, image files or
 * keyframes; `MapBuilder`, which assembles one from descriptors (their options are in
 * options.hpp).
 */

#ifndef TOPOLOC_MAP_HPP
#define TOPOLOC_MAP_HPP

#include "../topoloc.h"
#include "detail.hpp"
#include "error.hpp"
#include "options.hpp"
#include "geometry.hpp"
#include "image.hpp"
#include "progress.hpp"

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

namespace topoloc {

// ---------------------------------------------------------------------------------------------
// Plain values
// ---------------------------------------------------------------------------------------------

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
    /// so localizers on it accept image frames (`Localizer::process` of an `Image`). Without
    /// poses the map is a sequence: `options.views_per_place` consecutive images per place,
    /// places chained in order; view `i` has keyframe id `i`. `progress` (may be empty) is
    /// called on this thread; returning false throws `CancelledError`, and an exception it
    /// throws cancels the build and is rethrown here. The pixels are read only during the call.
    /// Throws `InvalidImageError` (a bad buffer; the message names `images[i]`),
    /// `BackendUnavailableError`, `ModelError`, `CancelledError`, and `Error` for the other
    /// statuses of `topoloc_map_build_from_image_files` in topoloc.h (`_INVALID_ARGUMENT`: too
    /// few images or bad options; `_IO`: poses file; `_STRUCT_SIZE`).
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
    [[nodiscard]] std::size_t place_count() const { return read_value(&topoloc_map_place_count); }

    /// Number of views.
    [[nodiscard]] std::size_t view_count() const { return read_value(&topoloc_map_view_count); }

    /// Number of undirected edges.
    [[nodiscard]] std::size_t edge_count() const { return read_value(&topoloc_map_edge_count); }

    /// Descriptor dimension D: every descriptor given to a localizer of this map has D floats.
    [[nodiscard]] uint32_t dim() const { return read_value(&topoloc_map_descriptor_dim); }

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
        return read_edge(&topoloc_map_edge, index, &Edge::weight);
    }

    /// All edges, sorted by (a, b).
    [[nodiscard]] std::vector<Edge> edges() const
    {
        return detail::read_all<Edge>(edge_count(), [this](std::size_t i) { return edge(i); });
    }

    /// Attributes of `view`. Throws `Error` (`TOPOLOC_ERR_UNKNOWN_VIEW`).
    [[nodiscard]] ViewInfo view_info(uint32_t view) const
    {
        topoloc_view_info raw = detail::filled(&topoloc_view_info_init);
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
        return read_value(&topoloc_map_keypoint_total);
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

    // Moves (noexcept; the source is left empty) and the destructor (calls
    // `topoloc_map_builder_free`) come from `detail::Owner`; copies are deleted.

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
        topoloc_view_attributes raw = detail::filled(&topoloc_view_attributes_init);
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

} // namespace topoloc

#endif // TOPOLOC_MAP_HPP
