/*
 * topoloc/options.hpp: the options of every operation (part of topoloc.hpp, which has the
 * overview): the C structs themselves, and a `default_*_options()` function for each that has
 * the library fill one (`detail::filled`). topoloc.h documents each field, its default and its
 * range. The concept headers include this one.
 */

#ifndef TOPOLOC_OPTIONS_HPP
#define TOPOLOC_OPTIONS_HPP

#include "../topoloc.h"
#include "detail.hpp"

#include <cstdint>
#include <type_traits>

namespace topoloc {

/// Local features (ABI 1.15; the C `TOPOLOC_LOCAL_FEATURES_*` values of `topoloc_local_features`):
/// which keypoints an image map stores for verification (`ImageMapOptions::local_features`) and
/// a `KeyframeDescriber` extracts (`KeyframeDescriberOptions::local_features`). The C option
/// fields take the C value: `to_c(LocalFeatures::XFeat)` or `TOPOLOC_LOCAL_FEATURES_XFEAT`. A
/// library newer than this header may report a value not listed here.
enum class LocalFeatures : uint32_t {
    Orb = TOPOLOC_LOCAL_FEATURES_ORB,     ///< ORB (OpenCV), 32-byte binary descriptors.
    XFeat = TOPOLOC_LOCAL_FEATURES_XFEAT, ///< XFeat (ONNX Runtime, the cache's export), 64-byte
                                          ///< learned descriptors.
    Cells = TOPOLOC_LOCAL_FEATURES_CELLS, ///< Dense cells of the describer's CNN, from the same
                                          ///< forward pass (ONNX maps only).
};
static_assert(std::is_same_v<std::underlying_type_t<LocalFeatures>, topoloc_local_features>,
              "LocalFeatures has the representation of topoloc_local_features");

/// The C value of `features`, for the `local_features` fields of the C option structs.
[[nodiscard]] constexpr topoloc_local_features to_c(LocalFeatures features) noexcept
{
    return static_cast<topoloc_local_features>(features);
}

/// Options of `Map::load` / `Map::from_memory` (the C struct). Start from
/// `default_load_options()`; a value-initialised struct has `struct_size == 0` and is refused
/// with `TOPOLOC_ERR_STRUCT_SIZE`. The string fields are borrowed for the duration of the call.
using LoadOptions = topoloc_map_load_options;

/// Parameters of `map_from_keyframes` (the C struct). Start from `default_keyframe_options()`;
/// see `topoloc_keyframe_options` in topoloc.h for each field.
using KeyframeOptions = topoloc_keyframe_options;

/// How `Map::build_from_images` / `build_from_image_files` build a map (the C struct). Start
/// from `default_image_map_options()`; see `topoloc_image_map_options` in topoloc.h for each
/// field (e.g. `backend`, `dim`; `pca_precision`, ABI 1.14; the keypoints stored per view for
/// verification and loop hints, `verification_keypoints`, and their kind, `local_features` =
/// `to_c(LocalFeatures::...)`, ABI 1.15). The string fields are borrowed for the duration of
/// the call.
using ImageMapOptions = topoloc_image_map_options;

/// Parameters of `Graph::from_occupancy` (the C struct). Start from
/// `default_skeleton_options()`; see `topoloc_skeleton_options` in topoloc.h for each field.
using SkeletonOptions = topoloc_skeleton_options;

/// Localizer parameters (the C struct). Start from `default_localizer_options()`; see
/// `topoloc_localizer_options` in topoloc.h for each field, its default and its range: e.g.
/// `top_k`, `verify_candidates` (geometric verification against the local features the map
/// stores), the camera intrinsics `camera_fx` .. `camera_cy` and `pose_min_inliers` of pose
/// fixes (ABI 1.6), `verify_off_map_inliers` (ABI 1.9). The string fields are borrowed only
/// during the `Localizer` constructor.
using LocalizerOptions = topoloc_localizer_options;

/// Where a `Describer` finds its runtime files (the C struct, ABI 1.12). Start from
/// `default_describer_options()`; see `topoloc_describer_options` in topoloc.h for each field.
/// The string fields are borrowed only during the constructor.
using DescriberOptions = topoloc_describer_options;

/// How a `KeyframeDescriber` is made (the C struct, ABI 1.15): its local features
/// (`local_features` = `to_c(LocalFeatures::...)`, XFeat by default), the backend it accepts and
/// where it finds its runtime files and models. Start from
/// `default_keyframe_describer_options()`; see `topoloc_keyframe_describer_options` in topoloc.h
/// for each field. The string fields are borrowed only during the constructor.
using KeyframeDescriberOptions = topoloc_keyframe_describer_options;

/// Loop detector parameters (the C struct). Start from `default_loop_options()`; see
/// `topoloc_loop_options` in topoloc.h for each field, its default and its range (set the
/// intrinsics `fx`, `fy`, `cx`, `cy` for hints with a relative pose). Read only by
/// `LoopDetector::create` / `LoopDetector::from_map`.
using LoopOptions = topoloc_loop_options;

/// How trajectories are associated and aligned (the C struct). Start from
/// `default_trajectory_options()`; see `topoloc_trajectory_options` in topoloc.h for each field
/// and its default.
using TrajectoryOptions = topoloc_trajectory_options;

// The defaults, as the header's `topoloc_*_options_default(p)` macros give them.

/// Load options that accept any map (`topoloc_map_load_options_default`).
[[nodiscard]] inline LoadOptions default_load_options()
{
    return detail::filled(&topoloc_map_load_options_init);
}

/// Default keyframe options (`topoloc_keyframe_options_default`).
[[nodiscard]] inline KeyframeOptions default_keyframe_options()
{
    return detail::filled(&topoloc_keyframe_options_init);
}

/// Default image map options (`topoloc_image_map_options_default`).
[[nodiscard]] inline ImageMapOptions default_image_map_options()
{
    return detail::filled(&topoloc_image_map_options_init);
}

/// Default skeleton options (`topoloc_skeleton_options_default`).
[[nodiscard]] inline SkeletonOptions default_skeleton_options()
{
    return detail::filled(&topoloc_skeleton_options_init);
}

/// Default localizer options (`topoloc_localizer_options_default`).
[[nodiscard]] inline LocalizerOptions default_localizer_options()
{
    return detail::filled(&topoloc_localizer_options_init);
}

/// Default describer options (`topoloc_describer_options_default`).
[[nodiscard]] inline DescriberOptions default_describer_options()
{
    return detail::filled(&topoloc_describer_options_init);
}

/// Default keyframe describer options (`topoloc_keyframe_describer_options_default`, ABI 1.15).
[[nodiscard]] inline KeyframeDescriberOptions default_keyframe_describer_options()
{
    return detail::filled(&topoloc_keyframe_describer_options_init);
}

/// Default loop detector options (`topoloc_loop_options_default`).
[[nodiscard]] inline LoopOptions default_loop_options()
{
    return detail::filled(&topoloc_loop_options_init);
}

/// Default trajectory options (`topoloc_trajectory_options_default`).
[[nodiscard]] inline TrajectoryOptions default_trajectory_options()
{
    return detail::filled(&topoloc_trajectory_options_init);
}

} // namespace topoloc

#endif // TOPOLOC_OPTIONS_HPP
