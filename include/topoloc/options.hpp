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

namespace topoloc {

/// Options of `Map::load` / `Map::from_memory` (the C struct). Start from
/// `default_load_options()`; a value-initialised struct has `struct_size == 0` and is refused
/// with `TOPOLOC_ERR_STRUCT_SIZE`. The string fields are borrowed for the duration of the call.
using LoadOptions = topoloc_map_load_options;

/// Parameters of `map_from_keyframes` (the C struct). Start from `default_keyframe_options()`;
/// see `topoloc_keyframe_options` in topoloc.h for each field.
using KeyframeOptions = topoloc_keyframe_options;

/// How `Map::build_from_images` / `build_from_image_files` build a map (the C struct). Start
/// from `default_image_map_options()`; see `topoloc_image_map_options` in topoloc.h for each
/// field (e.g. `backend`, `dim`). The string fields are borrowed for the duration of the call.
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
