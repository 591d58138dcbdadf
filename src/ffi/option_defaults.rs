//! The defaults and ranges of the C ABI's options fields: the defaults as their `_init`
//! functions write them (which is what the Rust options' `Default` gives), the ranges as the
//! Rust options' bounds constants (which their `validate` checks). `tools/gen-header` carries
//! both into the docs of `include/topoloc.h`, so that neither is written by hand in a C, C++
//! or Python doc.

use super::*;
use crate::bounds::Bounds;
use crate::build::{ImageMapOptions, KeyframeOptions};
use crate::describe::describer::FitOptions;
use crate::describe::limits::POOL_GRID_RANGE;
use crate::describe::onnx::OnnxOptions;
use crate::describe::vlad::VladOptions;
use crate::eval::TrajectoryOptions;
use crate::localize::{LocalizerOptions, MetricOptions};
use crate::loops::{DatabaseOptions, HintOptions, OdometryGate};
use crate::skeleton::SkeletonOptions;
use crate::verify::{
    LocateOptions, PairOptions, VerificationOptions, PAIR_MIN_INLIERS_RANGE,
    RANSAC_ITERATIONS_RANGE, RANSAC_THRESHOLD_PX_RANGE,
};
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
                place_spacing_m,
                verification_keypoints
            ]
        ),
        defaults_of!(
            topoloc_describer_options,
            topoloc_describer_options_init,
            [threads]
        ),
        defaults_of!(
            topoloc_keyframe_describer_options,
            topoloc_keyframe_describer_options_init,
            [xfeat_max_pixels, threads]
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
                max_match_pace,
                match_pace_slack_s,
                refine_keyframes,
                pose_min_inliers,
                pair_iterations,
                pair_min_cosine,
                cells_pair_iterations,
                cells_pair_min_cosine,
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

/// One field's accepted values.
#[derive(Clone, Debug, PartialEq)]
pub struct OptionRange {
    /// The C struct, e.g. `topoloc_loop_options`.
    pub struct_name: &'static str,
    /// The field, e.g. `candidates`.
    pub field: &'static str,
    /// The Rust bounds the field is checked against.
    pub bounds: Bounds,
}

/// `OptionRange`s of one struct's fields, each with the Rust constant that bounds it.
macro_rules! ranges_of {
    ($ty:ident, [$($field:ident: $bounds:expr),* $(,)?]) => {
        vec![$(OptionRange { struct_name: stringify!($ty), field: stringify!($field), bounds: $bounds }),*]
    };
}

/// Every documented range of the options structs' numeric fields, struct by struct in header
/// order. Fields whose sentinel values (0 = none, negative = default) lie outside the Rust
/// bounds state their rule in their own doc.
pub fn option_ranges() -> Vec<OptionRange> {
    [
        ranges_of!(
            topoloc_localizer_options,
            [
                temperature: LocalizerOptions::TEMPERATURE_RANGE,
                stay_probability: LocalizerOptions::PROBABILITY_RANGE,
                jump_probability: LocalizerOptions::PROBABILITY_RANGE,
                off_map_probability: LocalizerOptions::PROBABILITY_RANGE,
                off_map_similarity: LocalizerOptions::OFF_MAP_SIMILARITY_RANGE,
                off_map_margin: LocalizerOptions::OFF_MAP_MARGIN_RANGE,
                top_k: LocalizerOptions::TOP_K_RANGE,
                verify_candidates: VerificationOptions::CANDIDATES_RANGE,
                verify_views_per_candidate: VerificationOptions::VIEWS_PER_CANDIDATE_RANGE,
                verify_inlier_weight: VerificationOptions::INLIER_WEIGHT_RANGE,
                metric_particles: MetricOptions::PARTICLES_RANGE,
                metric_temperature: MetricOptions::TEMPERATURE_RANGE,
                pose_min_inliers: LocateOptions::MIN_INLIERS_RANGE,
                verify_off_map_inlier_scale: VerificationOptions::OFF_MAP_INLIER_SCALE_RANGE,
            ]
        ),
        ranges_of!(
            topoloc_keyframe_options,
            [
                place_spacing_m: KeyframeOptions::PLACE_SPACING_M_RANGE,
                novelty_similarity: KeyframeOptions::NOVELTY_SIMILARITY_RANGE,
                neighbour_radius_m: KeyframeOptions::NEIGHBOUR_RADIUS_M_RANGE,
                max_views_per_place: KeyframeOptions::MAX_VIEWS_PER_PLACE_RANGE,
            ]
        ),
        ranges_of!(
            topoloc_image_map_options,
            [
                dim: FitOptions::DIM_RANGE,
                views_per_place: ImageMapOptions::VIEWS_PER_PLACE_RANGE,
                threads: ImageMapOptions::THREADS_RANGE,
                grid_rows: POOL_GRID_RANGE,
                grid_cols: POOL_GRID_RANGE,
                vlad_clusters: VladOptions::CLUSTERS_RANGE,
                place_spacing_m: KeyframeOptions::PLACE_SPACING_M_RANGE,
                verification_keypoints: ImageMapOptions::KEYPOINTS_RANGE,
            ]
        ),
        ranges_of!(topoloc_describer_options, [threads: OnnxOptions::THREADS_RANGE]),
        ranges_of!(
            topoloc_keyframe_describer_options,
            [threads: OnnxOptions::THREADS_RANGE]
        ),
        ranges_of!(
            topoloc_skeleton_options,
            [
                z_min_m: SkeletonOptions::Z_RANGE,
                z_max_m: SkeletonOptions::Z_RANGE,
                min_clearance_m: SkeletonOptions::DISTANCE_RANGE,
                merge_radius_m: SkeletonOptions::DISTANCE_RANGE,
                max_edge_m: SkeletonOptions::LENGTH_RANGE,
                corner_angle_deg: SkeletonOptions::CORNER_ANGLE_DEG_RANGE,
                corner_scale_m: SkeletonOptions::LENGTH_RANGE,
                min_spur_m: SkeletonOptions::DISTANCE_RANGE,
            ]
        ),
        ranges_of!(
            topoloc_loop_options,
            [
                candidates: HintOptions::CANDIDATES_RANGE,
                exclude_recent_s: HintOptions::EXCLUDE_RECENT_S_RANGE,
                min_inliers: HintOptions::MIN_INLIERS_RANGE,
                consistent_keyframes: HintOptions::CONSISTENT_KEYFRAMES_RANGE,
                odometry_max_rotation_deg: OdometryGate::BOUND_RANGE,
                odometry_max_translation_m: OdometryGate::BOUND_RANGE,
                novelty_similarity: DatabaseOptions::NOVELTY_SIMILARITY_RANGE,
                place_spacing_m: DatabaseOptions::DISTANCE_RANGE,
                neighbour_radius_m: DatabaseOptions::DISTANCE_RANGE,
                odometry_max_translation_per_m: OdometryGate::PER_M_RANGE,
                pose_reprojection_px: RANSAC_THRESHOLD_PX_RANGE,
                odometry_search_m: HintOptions::ODOMETRY_SEARCH_M_RANGE,
                odometry_candidates: HintOptions::ODOMETRY_CANDIDATES_RANGE,
                max_match_pace: HintOptions::MAX_MATCH_PACE_RANGE,
                match_pace_slack_s: HintOptions::MATCH_PACE_SLACK_S_RANGE,
                exclude_recent_ids: HintOptions::ID_COUNT_RANGE,
                candidate_id_gap: HintOptions::ID_COUNT_RANGE,
                refine_keyframes: HintOptions::REFINE_KEYFRAMES_RANGE,
                pose_min_inliers: PAIR_MIN_INLIERS_RANGE,
                pair_iterations: RANSAC_ITERATIONS_RANGE,
                pair_min_cosine: PairOptions::MIN_COSINE_RANGE,
                cells_pair_iterations: RANSAC_ITERATIONS_RANGE,
                cells_pair_min_cosine: PairOptions::MIN_COSINE_RANGE,
            ]
        ),
        ranges_of!(
            topoloc_trajectory_options,
            [
                max_diff_s: TrajectoryOptions::MAX_DIFF_S_RANGE,
                offset_s: TrajectoryOptions::OFFSET_S_RANGE,
                rpe_delta: TrajectoryOptions::RPE_DELTA_RANGE,
            ]
        ),
    ]
    .concat()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `(struct, field, doc)` of every documented field of the header's structs, the doc's lines
    /// without their ` * ` prefixes.
    fn field_docs(header: &str) -> Vec<(String, String, String)> {
        let mut docs = Vec::new();
        for block in header.split("typedef struct ").skip(1) {
            let Some((name, body)) = block.split_once(" {") else {
                continue;
            };
            let body = body.split("\n} ").next().unwrap_or("");
            for doc_and_decl in body.split("/**").skip(1) {
                let Some((doc, decl)) = doc_and_decl.split_once("*/") else {
                    continue;
                };
                let decl = decl.split(';').next().unwrap_or("");
                let field = decl.split_whitespace().last().unwrap_or("");
                let doc = doc
                    .lines()
                    .map(|l| l.trim().trim_start_matches('*').trim())
                    .filter(|l| !l.is_empty())
                    .collect::<Vec<_>>()
                    .join("\n");
                docs.push((name.into(), field.trim_start_matches('*').into(), doc));
            }
        }
        docs
    }

    /// What a range written by hand looks like: "1..=64", "(>= 0)", "> 0", "in [0, 1]".
    fn states_a_range(text: &str) -> bool {
        ["..=", ">= ", "> 0", "(0, ", "[0, ", "[-1, "]
            .iter()
            .any(|token| text.contains(token))
    }

    #[test]
    fn every_range_in_the_header_is_generated_from_the_rust_bounds() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/include/topoloc.h");
        let docs = field_docs(&std::fs::read_to_string(path).unwrap());
        let ranges = option_ranges();
        let mut wrong = Vec::new();
        for (name, field, doc) in &docs {
            let range = ranges
                .iter()
                .find(|r| r.struct_name == name && r.field == field);
            let generated = range.map(|r| format!("Range: {}.", r.bounds));
            let prose: Vec<&str> = doc
                .lines()
                .filter(|l| Some(*l) != generated.as_deref())
                .collect();
            if range.is_some() && prose.iter().any(|l| states_a_range(l)) {
                wrong.push(format!("{name}.{field}: a range written by hand: {doc:?}"));
            }
            if let Some(generated) = &generated {
                if doc.lines().filter(|l| l == generated).count() != 1 {
                    wrong.push(format!("{name}.{field}: no generated {generated:?}"));
                }
            }
        }
        assert!(wrong.is_empty(), "{wrong:#?}");
        let documented = ranges
            .iter()
            .filter(|r| {
                docs.iter()
                    .any(|(n, f, _)| n == r.struct_name && f == r.field)
            })
            .count();
        assert_eq!(
            documented,
            ranges.len(),
            "a ranged field is not in the header"
        );
    }

    /// `(struct, field, generated, value)` of every numeric default stated in the docs of the
    /// header's struct fields: "Default: 0.2." as gen-header writes it (generated), or
    /// "Default 0.2." by hand.
    fn defaults_stated_in(
        docs: &[(String, String, String)],
    ) -> Vec<(String, String, bool, String)> {
        let mut stated = Vec::new();
        for (name, field, doc) in docs {
            for sentence in doc.split("Default").skip(1) {
                let generated = sentence.starts_with(": ");
                let rest = sentence.strip_prefix(": ").unwrap_or(sentence).trim_start();
                let value = rest.split_whitespace().next().unwrap_or("");
                let value = value.trim_end_matches(['.', ',', ';']);
                if value.starts_with(|c: char| c.is_ascii_digit() || c == '-') {
                    stated.push((name.clone(), field.clone(), generated, value.into()));
                }
            }
        }
        stated
    }

    #[test]
    fn every_default_in_the_header_is_generated_from_what_init_writes() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/include/topoloc.h");
        let stated = defaults_stated_in(&field_docs(&std::fs::read_to_string(path).unwrap()));
        let generated = option_defaults();
        assert!(generated.len() >= 40, "too few defaults: {generated:?}");
        let mut wrong = Vec::new();
        for (name, field, was_generated, value) in &stated {
            let found = generated
                .iter()
                .any(|d| d.struct_name == name && d.field == field && d.value == *value);
            if !was_generated || !found {
                wrong.push(format!(
                    "{name}.{field}: {value} (generated: {was_generated})"
                ));
            }
        }
        assert!(
            wrong.is_empty(),
            "defaults written by hand or stale: {wrong:#?}"
        );
        assert_eq!(
            stated.len(),
            generated.len(),
            "a generated default is missing"
        );
    }

    #[test]
    fn a_hand_written_default_is_told_from_a_generated_one() {
        let header = "typedef struct topoloc_x {\n  /**\n   * Scale. Default 0.5.\n   */\n  \
                      float scale;\n  /**\n   * Count.\n   * Default: 3.\n   */\n  uint32_t *count;\n} \
                      topoloc_x;\n";
        let stated = defaults_stated_in(&field_docs(header));
        assert_eq!(
            stated,
            [
                ("topoloc_x".into(), "scale".into(), false, "0.5".into()),
                ("topoloc_x".into(), "count".into(), true, "3".into()),
            ]
        );
    }

    #[test]
    fn a_hand_written_range_is_told_from_a_generated_one() {
        assert!(states_a_range(
            "Loop candidates verified per keyframe, 1..=64."
        ));
        assert!(states_a_range("Largest rotation difference (> 0)."));
        assert!(states_a_range("Free voxels closer than this (>= 0)."));
        assert!(!states_a_range("Descriptor dimension D; 0 = none."));
        let header =
            "typedef struct topoloc_x {\n  /**\n   * Scale.\n   * Range: finite, > 0.\n   \
                      */\n  float scale;\n} topoloc_x;\n";
        assert_eq!(
            field_docs(header),
            [(
                "topoloc_x".to_string(),
                "scale".to_string(),
                "Scale.\nRange: finite, > 0.".to_string()
            )]
        );
    }

    #[test]
    fn every_documented_default_lies_in_its_documented_range() {
        let defaults = option_defaults();
        let ranges = option_ranges();
        assert!(ranges.len() >= 45, "too few ranges: {}", ranges.len());
        let mut checked = 0;
        for range in &ranges {
            let default = defaults
                .iter()
                .find(|d| d.struct_name == range.struct_name && d.field == range.field);
            if let Some(default) = default {
                let value: f64 = default.value.parse().unwrap();
                assert!(
                    range.bounds.contains(value),
                    "{}.{} defaults to {value}, outside {}",
                    range.struct_name,
                    range.field,
                    range.bounds
                );
                checked += 1;
            }
        }
        assert!(checked >= 35, "only {checked} defaults checked");
    }
}
