/*
 * Contracts of the loop-closure section of topoloc.h that a new host trips over (issue 46):
 * a session saved with odometry poses and reloaded closes loops in a new world frame; the
 * option that once hung the first verified add (`candidate_id_gap = UINT64_MAX`) returns; a
 * detector whose map could not be loaded is refused at `_new`, not at `_load`; what a hint's
 * translation holds is told by `translation` (a rotation only gives `_NONE`); the ranked
 * candidates always hold the matched keyframe, whose confidence the hint carries; bounds of a
 * gate that is off, a huge descriptor length, and ids after an erase are refused as the header
 * says; a keyframe whose own image is in the map is refused as `TOPOLOC_GATE_SELF_MATCH`.
 */
#include "harness.h"

#include <math.h>
#include <stdlib.h>

/* Options with intrinsics of the scene's camera, no streak, a short exclusion window. */
static void contract_options(topoloc_loop_options *options)
{
    CHECK_OK(topoloc_loop_options_default(options));
    options->exclude_recent_ids = 5;
    options->exclude_recent_s = 0.0;
    options->consistent_keyframes = 1;
    options->fx = 300.0;
    options->fy = 300.0;
    options->cx = 160.0;
    options->cy = 120.0;
}

/* A row-major 4x4 pose: a yaw of `yaw_deg` about z and a translation. */
static void pose_of(double out[16], double x, double y, double z, double yaw_deg)
{
    const double c = cos(yaw_deg * 3.14159265358979323846 / 180.0);
    const double s = sin(yaw_deg * 3.14159265358979323846 / 180.0);
    const double pose[16] = {c, -s, 0, x, s, c, 0, y, 0, 0, 1, z, 0, 0, 0, 1};
    memcpy(out, pose, sizeof pose);
}

/* `first` saved as a map, freed, and the map loaded and reloaded with `_from_map` and
 * `options`: the next session (NULL on a failure, which a check reports). */
static topoloc_loop_detector *reload_as_next_session(topoloc_loop_detector *first,
                                                     const topoloc_loop_options *options)
{
    topoloc_loop_detector *next = NULL;
    topoloc_map *saved = NULL;
    char path[4200];

    tmp_path(path, sizeof path, "saved-session.topoloc");
    CHECK_OK(topoloc_loop_detector_save(first, path));
    topoloc_loop_detector_free(first);
    CHECK_OK(topoloc_map_load(path, NULL, &saved));
    CHECK_OK(topoloc_loop_detector_from_map(saved, options, &next));
    topoloc_map_free(saved);
    CHECK(remove(path) == 0);
    return next;
}

/* A first session with odometry poses is saved, loaded and reloaded with `_from_map`; the
 * revisit's odometry is in a new world frame (500 m and 90 degrees away from the map's), so
 * comparing it with the map's poses would refuse every hint (TOPOLOC_GATE_ODOMETRY, the
 * defect). The map's keyframes are an earlier session's: the hint is accepted, with a pose. */
static void a_session_saved_with_poses_closes_loops_after_a_reload(void)
{
    topoloc_loop_options options;
    topoloc_loop_detector *first = NULL, *second = NULL;
    topoloc_loop_keyframe kf;
    topoloc_loop_hint hint;
    struct loop_scene scene;
    double odometry[16];
    uint64_t next = 99;

    SECTION();
    contract_options(&options);
    CHECK_OK(new_detector(&options, &first));
    CHECK_OK(topoloc_loop_detector_next_id(first, &next));
    CHECK(next == 0);
    if (first == NULL)
        return;
    first_view_of_the_scene(&scene, &kf, &hint);
    pose_of(odometry, 0.0, 0.0, 0.0, 0.0);
    kf.world_T_body = odometry;
    CHECK_OK(topoloc_loop_detector_add(first, &kf, &hint));
    second = reload_as_next_session(first, &options);
    if (second == NULL)
        return;
    CHECK_OK(topoloc_loop_detector_next_id(second, &next));
    CHECK(next == 1); /* the new run's ids go on past the map's */
    /* The second session's world frame: far from the first's. */
    pose_of(odometry, 500.0, -200.0, 3.0, 90.0);
    kf.id = 1;
    kf.timestamp = 0.0;
    kf.keypoints = scene.seen_again;
    CHECK_OK(topoloc_loop_detector_add(second, &kf, &hint));
    CHECK(hint.has_match && hint.matched_id == 0 && hint.inliers >= 30);
    CHECK(hint.gate == TOPOLOC_GATE_ACCEPTED && hint.accepted && hint.has_pose);
    /* No scene points: the pose has a unit translation, and says so. */
    CHECK(hint.translation == TOPOLOC_TRANSLATION_DIRECTION && !hint.scale_known);
    topoloc_loop_detector_free(second);
}

/* `candidate_id_gap = UINT64_MAX` once made the first verified add walk 2^64 ids. Now the
 * refinement walks the keyframes held: the add returns with the hint. So does the largest
 * exclusion window (no candidate then). */
static void the_largest_id_counts_cost_no_more_than_small_ones(void)
{
    topoloc_loop_options options;
    topoloc_loop_detector *det = NULL;
    topoloc_loop_keyframe kf;
    topoloc_loop_hint hint;
    struct loop_scene scene;

    SECTION();
    contract_options(&options);
    options.candidate_id_gap = UINT64_MAX;
    CHECK_OK(new_detector(&options, &det));
    if (det == NULL)
        return;
    first_view_of_the_scene(&scene, &kf, &hint);
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    kf.id = 10;
    kf.timestamp = 10.0;
    kf.keypoints = scene.seen_again;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    CHECK(hint.accepted && hint.matched_id == 0);
    topoloc_loop_detector_free(det);

    options.exclude_recent_ids = UINT64_MAX;
    det = NULL;
    CHECK_OK(new_detector(&options, &det));
    if (det == NULL)
        return;
    kf.id = 0;
    kf.keypoints = scene.points;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    kf.id = 5;
    kf.keypoints = scene.seen_again;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    CHECK(!hint.has_match && hint.gate == TOPOLOC_GATE_NO_CANDIDATE);
    topoloc_loop_detector_free(det);
}

/* A descriptor kind of 1.1 MB (or a model of 200 kB of control characters, which the map's
 * header escapes twice) once passed `_new`, `_add` and `_save`, and then `topoloc_map_load`
 * refused the file: the session was lost. Now `_new` refuses it, and a kind and model at the
 * limits save a map that loads. */
static void a_detector_that_could_not_be_reloaded_is_refused_at_new(void)
{
    enum { HUGE_KIND = 1100 * 1000, CONTROL_MODEL = 200 * 1000 };
    topoloc_loop_detector *det = NULL;
    topoloc_loop_keyframe kf;
    topoloc_loop_hint hint;
    struct loop_scene scene;
    topoloc_map *saved = NULL;
    char path[4200];
    char *text = malloc(HUGE_KIND + 1);

    SECTION();
    CHECK(text != NULL);
    if (text == NULL)
        return;
    memset(text, 'k', HUGE_KIND);
    text[HUGE_KIND] = '\0';
    CHECK_ERROR(topoloc_loop_detector_new(text, "loops", LOOP_DIM, NULL, &det),
                TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("kind");
    CHECK(det == NULL);
    memset(text, '\x01', CONTROL_MODEL);
    text[CONTROL_MODEL] = '\0';
    CHECK_ERROR(topoloc_loop_detector_new("test", text, LOOP_DIM, NULL, &det),
                TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("model");
    CHECK(det == NULL);

    /* At the limits (256 bytes of kind, 4,096 of control characters as model): saves, loads. */
    memset(text, 'k', 256);
    text[256] = '\0';
    memset(text + 300, '\x01', 4096);
    text[300 + 4096] = '\0';
    CHECK_OK(topoloc_loop_detector_new(text, text + 300, LOOP_DIM, NULL, &det));
    if (det != NULL) {
        first_view_of_the_scene(&scene, &kf, &hint);
        CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
        tmp_path(path, sizeof path, "long-identity.topoloc");
        CHECK_OK(topoloc_loop_detector_save(det, path));
        CHECK_OK(topoloc_map_load(path, NULL, &saved));
        topoloc_map_free(saved);
        CHECK(remove(path) == 0);
    }
    topoloc_loop_detector_free(det);
    free(text);
}

/* A revisit from the same spot, turned 3 degrees: the views differ by a rotation only. The
 * hint has a pose whose translation is exactly zero, and `translation` says so
 * (TOPOLOC_TRANSLATION_NONE); a revisit from another spot has a unit direction. */
static void a_rotation_only_hint_says_its_translation_is_none(void)
{
    topoloc_loop_options options;
    topoloc_loop_detector *det = NULL;
    topoloc_loop_keyframe kf;
    topoloc_loop_hint hint;
    struct loop_scene scene;
    float turned[2 * LOOP_POINTS], turned_first[2 * LOOP_POINTS];
    uint8_t turned_descriptors[32 * LOOP_POINTS];
    double length;

    SECTION();
    CHECK(topoloc_abi_version_minor() >= 17);
    CHECK_OK(topoloc_loop_hint_default(&hint));
    CHECK(hint.translation == TOPOLOC_TRANSLATION_NONE);
    contract_options(&options);
    CHECK_OK(new_detector(&options, &det));
    if (det == NULL)
        return;
    first_view_of_the_scene(&scene, &kf, &hint);
    loop_scene_points(turned_first, turned, turned_descriptors, 0.0, 0.0, 3.0);
    kf.keypoints = turned_first;
    kf.keypoint_descriptors = turned_descriptors;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    kf.id = 10;
    kf.timestamp = 10.0;
    kf.keypoints = turned;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    CHECK(hint.accepted && hint.has_pose && !hint.scale_known);
    CHECK(hint.translation == TOPOLOC_TRANSLATION_NONE);
    CHECK(hint.matched_T_query[3] == 0.0 && hint.matched_T_query[7] == 0.0 &&
          hint.matched_T_query[11] == 0.0);
    /* The rotation holds: 3 degrees about the camera's y axis. */
    CHECK_NEAR(hint.matched_T_query[0], cos(3.0 * 3.14159265358979323846 / 180.0), 2e-3);
    topoloc_loop_detector_free(det);

    /* From 0.3 m to the right and 0.1 m ahead: a direction. */
    det = NULL;
    CHECK_OK(new_detector(&options, &det));
    if (det == NULL)
        return;
    kf.id = 0;
    kf.timestamp = 0.0;
    kf.keypoints = scene.points;
    kf.keypoint_descriptors = scene.descriptors;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    kf.id = 10;
    kf.timestamp = 10.0;
    kf.keypoints = scene.seen_again;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    CHECK(hint.accepted && hint.matched_id == 0);
    CHECK(hint.translation == TOPOLOC_TRANSLATION_DIRECTION);
    length = sqrt(hint.matched_T_query[3] * hint.matched_T_query[3] +
                  hint.matched_T_query[7] * hint.matched_T_query[7] +
                  hint.matched_T_query[11] * hint.matched_T_query[11]);
    CHECK_NEAR(length, 1.0, 1e-9);
    topoloc_loop_detector_free(det);
}

/* Keyframe 0 sees 40 of the scene's points, keyframe 1 (the same stretch, less similar) all 60:
 * the revisit's candidate is keyframe 0 (the more similar; the id gap leaves keyframe 1 out),
 * and refinement swaps it for keyframe 1, which has more inliers. The ranked candidates list
 * keyframe 1 (once missing), with the confidence the hint carries. */
static void the_ranked_candidates_hold_the_keyframe_refinement_chose(void)
{
    topoloc_loop_options options;
    topoloc_loop_detector *det = NULL;
    topoloc_loop_keyframe kf;
    topoloc_loop_hint hint;
    struct loop_scene scene;
    topoloc_loop_candidate_check found[8];
    size_t count = 0, listed = 0;
    float d_other[LOOP_DIM];

    SECTION();
    contract_options(&options);
    options.fx = 0.0; /* no pose needed */
    CHECK_OK(new_detector(&options, &det));
    if (det == NULL)
        return;
    first_view_of_the_scene(&scene, &kf, &hint);
    kf.keypoint_count = 40;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    loop_descriptor(d_other, 1);
    d_other[2] += 0.2f;
    kf.id = 1;
    kf.timestamp = 1.0;
    kf.keypoint_count = LOOP_POINTS;
    kf.descriptor = d_other;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    kf.id = 10;
    kf.timestamp = 10.0;
    kf.descriptor = scene.d;
    kf.keypoints = scene.seen_again;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    CHECK(hint.accepted && hint.matched_id == 1 && hint.inliers >= 50);
    CHECK_OK(topoloc_loop_detector_candidates(det, found, 8, &count));
    for (size_t i = 0; i < count; i++) {
        if (found[i].keyframe_id == hint.matched_id) {
            listed++;
            CHECK(found[i].inliers == hint.inliers);
            CHECK(found[i].confidence == hint.confidence);
            CHECK(found[i].similarity < 0.999f); /* keyframe 1's own similarity */
        }
        CHECK(found[i].keyframe_id != 0); /* the swapped candidate is not listed twice */
    }
    CHECK(listed == 1 && count >= 1 && found[0].keyframe_id == 1);
    topoloc_loop_detector_free(det);
}

/* The header's rules, each once broken: a gate's bounds are checked with the gate off; a
 * descriptor length other than D is _DIMENSION_MISMATCH however large; ids must increase past
 * erased keyframes' ids. */
static void bounds_lengths_and_ids_are_refused_as_the_header_says(void)
{
    topoloc_loop_options options;
    topoloc_loop_detector *det = NULL;
    topoloc_loop_keyframe kf;
    topoloc_loop_hint hint;
    struct loop_scene scene;
    topoloc_loop_candidate found[2];
    size_t count = 0, len = 0;
    uint64_t next = 0;

    SECTION();
    contract_options(&options);
    options.odometry_gate = false;
    options.odometry_max_rotation_deg = make_nan();
    CHECK_ERROR(new_detector(&options, &det), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("max_rotation_deg");
    options.odometry_max_rotation_deg = 30.0;
    options.odometry_max_translation_m = -1.0;
    CHECK_ERROR(new_detector(&options, &det), TOPOLOC_ERR_INVALID_OPTION);
    options.odometry_max_translation_m = 1.0;
    options.odometry_max_translation_per_m = make_nan();
    CHECK_ERROR(new_detector(&options, &det), TOPOLOC_ERR_INVALID_OPTION);
    options.odometry_max_translation_per_m = 0.02;
    options.pair_estimator = 7u;
    CHECK_ERROR(new_detector(&options, &det), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("pair_estimator");
    options.pair_estimator = TOPOLOC_PAIR_ESTIMATOR_MAGSAC;
    options.pair_iterations = 0u;
    CHECK_ERROR(new_detector(&options, &det), TOPOLOC_ERR_INVALID_OPTION);
    options.pair_iterations = 100u;
    CHECK(det == NULL);
    CHECK_OK(new_detector(&options, &det));
    if (det == NULL)
        return;

    first_view_of_the_scene(&scene, &kf, &hint);
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    kf.id = 10;
    kf.timestamp = 10.0;
    kf.descriptor_len = SIZE_MAX / 2;
    CHECK_ERROR(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_ERR_DIMENSION_MISMATCH);
    CHECK_ERROR(topoloc_loop_detector_query(det, scene.d, SIZE_MAX / 2, found, 2, &count),
                TOPOLOC_ERR_DIMENSION_MISMATCH);
    kf.descriptor_len = LOOP_DIM;
    kf.keypoints = scene.seen_again;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    CHECK_OK(topoloc_loop_detector_erase(det, 10));
    /* Id 10 again, and an id below it: refused, the detector unchanged. */
    CHECK_ERROR(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_ERR_INVALID_ARGUMENT);
    kf.id = 5;
    CHECK_ERROR(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("must increase");
    CHECK_OK(topoloc_loop_detector_len(det, &len));
    CHECK(len == 1);
    /* The next id a host may give: past the erased keyframe's. */
    CHECK_OK(topoloc_loop_detector_next_id(det, &next));
    CHECK(next == 11);
    CHECK_ERROR(topoloc_loop_detector_next_id(det, NULL), TOPOLOC_ERR_NULL_ARGUMENT);
    kf.id = 11;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    /* After the largest id no id can follow: said, not wrapped to 0. */
    kf.id = UINT64_MAX;
    kf.timestamp = 20.0;
    kf.keypoints = scene.points;
    CHECK_OK(topoloc_loop_detector_add(det, &kf, &hint));
    next = 7;
    CHECK_ERROR(topoloc_loop_detector_next_id(det, &next), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("no id can follow");
    CHECK(next == 7);
    topoloc_loop_detector_free(det);
    CHECK_ERROR(topoloc_loop_detector_next_id(NULL, &next), TOPOLOC_ERR_NULL_ARGUMENT);
}

/* A map built from this run's own images: every keyframe is also a view of the map, with the
 * very same keypoints. The README's first run did this and got a "hint" per keyframe, each to
 * itself. Now such a keyframe is refused as TOPOLOC_GATE_SELF_MATCH (and a warning logged). */
static void a_keyframe_whose_own_image_is_in_the_map_is_a_self_match(void)
{
    topoloc_loop_options options;
    topoloc_loop_detector *first = NULL, *live = NULL;
    topoloc_loop_keyframe kf;
    topoloc_loop_hint hint;
    struct loop_scene scene;

    SECTION();
    contract_options(&options);
    CHECK_OK(new_detector(&options, &first));
    if (first == NULL)
        return;
    first_view_of_the_scene(&scene, &kf, &hint);
    CHECK_OK(topoloc_loop_detector_add(first, &kf, &hint));
    kf.id = 1;
    kf.timestamp = 1.0;
    kf.keypoints = scene.seen_again;
    CHECK_OK(topoloc_loop_detector_add(first, &kf, &hint));
    live = reload_as_next_session(first, &options);
    if (live == NULL)
        return;
    /* The run again, on its own map: keyframe 0's image is the map's view 0. */
    kf.id = 2;
    kf.timestamp = 0.0;
    kf.keypoints = scene.points;
    CHECK_OK(topoloc_loop_detector_add(live, &kf, &hint));
    CHECK(hint.has_match && !hint.accepted && hint.gate == TOPOLOC_GATE_SELF_MATCH);
    CHECK(hint.matched_id == 0);
    topoloc_loop_detector_free(live);
}

void run_loop_contract_tests(void)
{
    a_session_saved_with_poses_closes_loops_after_a_reload();
    the_largest_id_counts_cost_no_more_than_small_ones();
    a_detector_that_could_not_be_reloaded_is_refused_at_new();
    a_rotation_only_hint_says_its_translation_is_none();
    the_ranked_candidates_hold_the_keyframe_refinement_chose();
    bounds_lengths_and_ids_are_refused_as_the_header_says();
    a_keyframe_whose_own_image_is_in_the_map_is_a_self_match();
}
