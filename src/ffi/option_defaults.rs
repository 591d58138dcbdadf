//! The defaults of the C ABI's options structs, as their `_init` functions write them (which
//! is what the Rust options' `Default` gives). `tools/gen-header` carries them into the docs of
//! `include/topoloc.h`, so that no default is written by hand in a C, C++ or Python doc.

use super::*;
use std::mem::{size_of, MaybeUninit};

/// One field's default.
#[derive(Clone, Debug, PartialEq)]
pub struct OptionDefault {
    /// The C struct, e.g. `topoloc_localizer_options`.
    pub struct_name: &'static str,
    /// The field, e.g. `temperature`.
    pub field: &'static str,
    /// The value `_init` writes, as Rust prints it (`0.2`, `-1`, `2000`).
    pub value: String,
}

/// The listed numeric fields of a versioned struct after its `_init`.
macro_rules! defaults_of {
    ($ty:ident, $init:ident, [$($field:ident),* $(,)?]) => {{
        let mut filled = MaybeUninit::<$ty>::zeroed();
        let status = $init(filled.as_mut_ptr(), size_of::<$ty>());
        assert_eq!(status, topoloc_status::TOPOLOC_OK, "{} fills a struct of its own size", stringify!($init));
        // SAFETY: zeroed, then filled by `_init` (which succeeded) for the struct's full size.
        let filled = unsafe { filled.assume_init() };
        vec![$(OptionDefault {
            struct_name: stringify!($ty),
            field: stringify!($field),
            value: filled.$field.to_string(),
        }),*]
    }};
}

/// Every documented default of the options structs, struct by struct in header order.
pub fn option_defaults() -> Vec<OptionDefault> {
    [
        defaults_of!(
            topoloc_localizer_options,
            topoloc_localizer_options_init,
            [
                temperature,
                stay_probability,
                jump_probability,
                off_map_probability,
                off_map_similarity,
                off_map_margin,
                top_k,
                verify_views_per_candidate,
                verify_inlier_weight,
                metric_particles,
                metric_temperature,
                metric_seed,
                pose_min_inliers,
                verify_off_map_inlier_scale,
            ]
        ),
        defaults_of!(
            topoloc_keyframe_options,
            topoloc_keyframe_options_init,
            [
                place_spacing_m,
                novelty_similarity,
                neighbour_radius_m,
                max_views_per_place
            ]
        ),
        defaults_of!(
            topoloc_image_map_options,
            topoloc_image_map_options_init,
            [
                dim,
                views_per_place,
                threads,
                grid_rows,
                vlad_clusters,
                place_spacing_m
            ]
        ),
        defaults_of!(
            topoloc_describer_options,
            topoloc_describer_options_init,
            [threads]
        ),
        defaults_of!(
            topoloc_skeleton_options,
            topoloc_skeleton_options_init,
            [
                z_min_m,
                z_max_m,
                min_clearance_m,
                merge_radius_m,
                max_edge_m,
                corner_angle_deg,
                corner_scale_m,
                min_spur_m,
            ]
        ),
        defaults_of!(
            topoloc_loop_options,
            topoloc_loop_options_init,
            [
                candidates,
                exclude_recent_ids,
                exclude_recent_s,
                min_inliers,
                consistent_keyframes,
                odometry_max_rotation_deg,
                odometry_max_translation_m,
                novelty_similarity,
                place_spacing_m,
                neighbour_radius_m,
                candidate_id_gap,
                odometry_max_translation_per_m,
                pose_reprojection_px,
                odometry_search_m,
                odometry_candidates,
            ]
        ),
        defaults_of!(
            topoloc_trajectory_options,
            topoloc_trajectory_options_init,
            [max_diff_s, offset_s, rpe_delta]
        ),
    ]
    .concat()
}
