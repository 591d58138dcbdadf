/*
 * Section "Loop closure" of topoloc.h (ABI 1.5 and later): keyframes in, gated hints with
 * relative poses out. Two keyframes see the same 60 keypoints (the same binary descriptors), so
 * the second's candidate verifies with all of them; bad keyframes are refused with the detector
 * unchanged; a detector saves as a map and a second session starts from it; a streak of
 * consistent revisits confirms the hints it had refused as inconsistent (ABI 1.10); a new
 * session finds the keyframes of the one just ended (ABI 1.15). The options
 * of every ABI minor since 1.5 are checked with older callers' struct sizes.
 */
#include "harness.h"

#include <math.h>

void loop_scene_points(float *first, float *second, uint8_t *descriptors, double tx, double tz,
                       double yaw_deg)
{
    uint32_t state = 12345u;
    const double c = cos(yaw_deg * 3.14159265358979323846 / 180.0);
    const double s = sin(yaw_deg * 3.14159265358979323846 / 180.0);
    int i = 0;
    while (i < LOOP_POINTS) {
        double x, y, z, qx, qz, u1, v1, u2, v2;
        state = state * 1664525u + 1013904223u;
        z = 3.0 + 5.0 * (double)(state >> 8) / 16777216.0;
        state = state * 1664525u + 1013904223u;
        x = ((double)(state >> 8) / 16777216.0 - 0.5) * z;
        state = state * 1664525u + 1013904223u;
        y = ((double)(state >> 8) / 16777216.0 - 0.5) * 0.7 * z;
        /* The second camera: p' = R^T (p - t), R a yaw about y. */
        qx = c * (x - tx) - s * (z - tz);
        qz = s * (x - tx) + c * (z - tz);
        u1 = 300.0 * x / z + 160.0;
        v1 = 300.0 * y / z + 120.0;
        u2 = 300.0 * qx / qz + 160.0;
        v2 = 300.0 * y / qz + 120.0;
        if (qz < 0.5 || u1 < 0 || u1 > 319 || v1 < 0 || v1 > 239 || u2 < 0 || u2 > 319 || v2 < 0 ||
            v2 > 239)
            continue;
        first[2 * i] = (float)u1;
        first[2 * i + 1] = (float)v1;
        second[2 * i] = (float)u2;
        second[2 * i + 1] = (float)v2;
        for (int b = 0; b < 32; b++) {
            state = state * 1664525u + 1013904223u;
            descriptors[32 * i + b] = (uint8_t)(state >> 24);
        }
        i++;
    }
}

/* LOOP_POINTS scene points seen from a camera 0.3 m to the right and 0.1 m ahead, turned 3
 * degrees. */
static void loop_keypoints(float *first, float *second, uint8_t *descriptors)
{
    loop_scene_points(first, second, descriptors, 0.3, 0.1, 3.0);
}

void loop_descriptor(float *d, int scene)
{
    for (int i = 0; i < LOOP_DIM; i++)
        d[i] = (i == scene % LOOP_DIM) ? 1.0f : 0.05f * (float)i;
}

void first_view_of_the_scene(struct loop_scene *scene, topoloc_loop_keyframe *kf,
                             topoloc_loop_hint *hint)
{
    loop_keypoints(scene->points, scene->seen_again, scene->descriptors);
    loop_descriptor(scene->d, 1);
    CHECK_STATUS(topoloc_loop_keyframe_default(kf), TOPOLOC_OK);
    CHECK_STATUS(topoloc_loop_hint_default(hint), TOPOLOC_OK);
    kf->descriptor = scene->d;
    kf->descriptor_len = LOOP_DIM;
    kf->keypoint_count = LOOP_POINTS;
    kf->keypoints = scene->points;
    kf->keypoint_descriptors = scene->descriptors;
}

topoloc_status new_detector(const topoloc_loop_options *options, topoloc_loop_detector **det)
{
    return topoloc_loop_detector_new("test", "loops", LOOP_DIM, options, det);
}

/* `old` holds a bad value in a field at or beyond `size`: a caller of that older layout gets
 * the default there (the detector is made), a caller of the whole struct is refused. */
static void check_loop_fields_beyond(topoloc_loop_options *old, size_t size)
{
    topoloc_loop_detector *det = NULL;
    old->struct_size = size;
    CHECK_STATUS(new_detector(old, &det), TOPOLOC_OK);
    topoloc_loop_detector_free(det);
    det = NULL;
    old->struct_size = sizeof *old;
    CHECK_STATUS(new_detector(old, &det), TOPOLOC_ERR_INVALID_OPTION);
    CHECK(det == NULL);
}

/* Fills `options` with the defaults. */
static void loop_options_have_defaults_and_older_callers_get_the_newer_fields_defaults(
    topoloc_loop_options *options)
{
    topoloc_loop_options old;
    topoloc_loop_detector *old_det = NULL;

    SECTION();
    CHECK(topoloc_abi_version_minor() >= 5);
    CHECK_STATUS(topoloc_loop_options_default(options), TOPOLOC_OK);
    CHECK(options->struct_size == sizeof *options && options->candidates == 5 &&
          options->min_inliers == 30 && options->consistent_keyframes == 3 && options->fx == 0.0);
    CHECK(options->candidate_id_gap == 10u); /* ABI 1.6 */
    CHECK(options->odometry_max_translation_m == 1.0 &&
          options->odometry_max_translation_per_m == 0.02 &&
          options->pose_reprojection_px == 5.0); /* ABI 1.7 */
    CHECK(topoloc_abi_version_minor() >= 8 && options->odometry_candidates == 1u &&
          options->odometry_search_m == 2.0); /* ABI 1.8 */
    CHECK(topoloc_abi_version_minor() >= 15 && options->max_match_pace == 3.0 &&
          options->match_pace_slack_s == 0.5); /* ABI 1.15 */

    /* A caller of ABI 1.5 gets the 1.6 fields' defaults. */
    CHECK_STATUS(topoloc_loop_options_default(&old), TOPOLOC_OK);
    old.struct_size = offsetof(topoloc_loop_options, candidate_id_gap);
    old.candidate_id_gap = 0u; /* beyond its size: the default (10) is used */
    CHECK_STATUS(new_detector(&old, &old_det), TOPOLOC_OK);
    topoloc_loop_detector_free(old_det);
    old.struct_size = offsetof(topoloc_loop_options, candidate_id_gap) - 1;
    CHECK_STATUS(new_detector(&old, &old_det), TOPOLOC_ERR_STRUCT_SIZE);
    /* A caller of ABI 1.6 gets the 1.7 fields' defaults; a bad 1.7 field is refused. */
    old.pose_reprojection_px = -1.0;
    check_loop_fields_beyond(&old, offsetof(topoloc_loop_options, odometry_max_translation_per_m));
    /* A caller of ABI 1.7 gets the 1.8 fields' defaults; a bad 1.8 field is refused. */
    CHECK_STATUS(topoloc_loop_options_default(&old), TOPOLOC_OK);
    old.odometry_candidates = 65u;
    check_loop_fields_beyond(&old, offsetof(topoloc_loop_options, odometry_search_m));
    /* A caller of ABI 1.14 gets the pace rule's defaults; a bad pace field is refused. */
    CHECK_STATUS(topoloc_loop_options_default(&old), TOPOLOC_OK);
    old.match_pace_slack_s = -1.0;
    check_loop_fields_beyond(&old, offsetof(topoloc_loop_options, max_match_pace));
}

static void a_loop_detector_needs_an_out_pointer_a_kind_a_bounded_dim_and_candidates(
    topoloc_loop_options *options)
{
    topoloc_loop_detector *det = NULL;
    const uint32_t too_large[] = {65537u, 1u << 30, UINT32_MAX};

    SECTION();
    CHECK_NULL(new_detector(options, NULL), "out");
    CHECK_STATUS(topoloc_loop_detector_new("", "loops", LOOP_DIM, options, &det),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(det == NULL);
    /* Refused before anything is allocated for them (2^30 once aborted the host). */
    for (size_t i = 0; i < sizeof too_large / sizeof too_large[0]; i++) {
        CHECK_STATUS(topoloc_loop_detector_new("test", "loops", too_large[i], options, &det),
                     TOPOLOC_ERR_INVALID_ARGUMENT);
        CHECK(det == NULL);
    }
    CHECK_STATUS(topoloc_loop_detector_new("test", "loops", 65536u, options, &det), TOPOLOC_OK);
    topoloc_loop_detector_free(det);
    det = NULL;
    options->candidates = 0;
    CHECK_STATUS(new_detector(options, &det), TOPOLOC_ERR_INVALID_OPTION);
    options->candidates = 5;
}

/* Keyframe 0 first: nothing to match. Then bad keyframes: the detector keeps its one keyframe
 * and the hint is untouched. */
static void bad_keyframes_after_the_first_are_refused_and_change_nothing(topoloc_loop_detector *det,
                                                                         topoloc_loop_keyframe *kf,
                                                                         topoloc_loop_hint *hint)
{
    const uint8_t *descriptors = kf->keypoint_descriptors;
    size_t len = 0;

    SECTION();
    kf->id = 0;
    kf->timestamp = 0.0;
    CHECK_STATUS(topoloc_loop_detector_add(det, kf, hint), TOPOLOC_OK);
    CHECK(hint->query_id == 0 && !hint->has_match && !hint->accepted &&
          hint->gate == TOPOLOC_GATE_NO_CANDIDATE);

    kf->id = 10;
    kf->timestamp = 10.0;
    kf->descriptor_len = LOOP_DIM - 1;
    CHECK_STATUS(topoloc_loop_detector_add(det, kf, hint), TOPOLOC_ERR_DIMENSION_MISMATCH);
    kf->descriptor_len = LOOP_DIM;
    kf->keypoint_descriptors = NULL;
    CHECK_NULL(topoloc_loop_detector_add(det, kf, hint), "keyframe.keypoint_descriptors");
    kf->keypoint_descriptors = descriptors;
    kf->id = 0;
    CHECK_ERROR(topoloc_loop_detector_add(det, kf, hint), TOPOLOC_ERR_INVALID_ARGUMENT);
    kf->id = 10;
    kf->timestamp = make_nan();
    CHECK_STATUS(topoloc_loop_detector_add(det, kf, hint), TOPOLOC_ERR_NON_FINITE);
    kf->timestamp = 10.0;
    kf->struct_size = 3;
    CHECK_STATUS(topoloc_loop_detector_add(det, kf, hint), TOPOLOC_ERR_STRUCT_SIZE);
    kf->struct_size = sizeof *kf;
    CHECK_STATUS(topoloc_loop_detector_len(det, &len), TOPOLOC_OK);
    CHECK(len == 1 && hint->query_id == 0);
}

/* Keyframe 10 sees the scene from another pose: every keypoint matches, the hint names keyframe
 * 0; a query by descriptor lists both keyframes. */
static void a_revisit_from_another_pose_is_accepted_with_every_keypoint_an_inlier(
    topoloc_loop_detector *det, topoloc_loop_keyframe *kf, topoloc_loop_hint *hint,
    const struct loop_scene *scene)
{
    topoloc_loop_candidate found[4];
    size_t count = 0;

    SECTION();
    kf->keypoints = scene->seen_again;
    CHECK_STATUS(topoloc_loop_detector_add(det, kf, hint), TOPOLOC_OK);
    CHECK(hint->query_id == 10 && hint->has_match && hint->accepted);
    CHECK(hint->gate == TOPOLOC_GATE_ACCEPTED && hint->matched_id == 0);
    CHECK(hint->inliers >= 30 && hint->confidence > 0.99f && !hint->has_pose);

    CHECK_STATUS(topoloc_loop_detector_query(det, scene->d, LOOP_DIM, found, 4, &count),
                 TOPOLOC_OK);
    CHECK(count == 2 && found[0].similarity > 0.99f);
    CHECK_NULL(topoloc_loop_detector_query(det, scene->d, LOOP_DIM, found, 4, NULL), "count");
}

/* Saved to `path`; erasing an unknown keyframe is refused, a known one leaves one keyframe. */
static void a_detector_saves_as_a_map_and_erases_keyframes_by_id(topoloc_loop_detector *det,
                                                                 const char *path)
{
    size_t len = 0;

    SECTION();
    CHECK_STATUS(topoloc_loop_detector_save(det, path), TOPOLOC_OK);
    CHECK_STATUS(topoloc_loop_detector_erase(det, 77), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_STATUS(topoloc_loop_detector_erase(det, 10), TOPOLOC_OK);
    CHECK_STATUS(topoloc_loop_detector_len(det, &len), TOPOLOC_OK);
    CHECK(len == 1);
}

/* A second session from the map saved at `path` has both keyframes with their keypoints: a
 * revisit (a new image: its keypoints a quarter pixel off the saved ones) verifies against them
 * as the first session did (the first keyframe of a streak). */
static void a_second_session_from_the_saved_map_verifies_against_its_keypoints(
    const char *path, topoloc_loop_keyframe *kf, topoloc_loop_hint *hint)
{
    topoloc_map *saved = NULL;
    topoloc_loop_detector *again = NULL;
    size_t len = 0, keypoints = 0;
    float new_image[2 * LOOP_POINTS];

    SECTION();
    for (size_t i = 0; i < 2 * LOOP_POINTS; i++)
        new_image[i] = kf->keypoints[i] + 0.25f;
    kf->keypoints = new_image;
    CHECK_STATUS(topoloc_map_load(path, NULL, &saved), TOPOLOC_OK);
    CHECK_STATUS(topoloc_map_keypoint_total(saved, &keypoints), TOPOLOC_OK);
    CHECK(keypoints == 2 * LOOP_POINTS);
    CHECK_STATUS(topoloc_loop_detector_from_map(saved, NULL, &again), TOPOLOC_OK);
    CHECK_STATUS(topoloc_loop_detector_len(again, &len), TOPOLOC_OK);
    CHECK(len == 2);
    kf->id = 20;
    kf->timestamp = 20.0;
    CHECK_STATUS(topoloc_loop_detector_add(again, kf, hint), TOPOLOC_OK);
    CHECK(hint->query_id == 20 && hint->has_match && hint->inliers >= 30);
    CHECK(hint->matched_id == 0 || hint->matched_id == 10);
    CHECK(hint->gate == TOPOLOC_GATE_INCONSISTENT);
    kf->keypoints = NULL;
    topoloc_loop_detector_free(again);
    topoloc_map_free(saved);
}

static void loop_closure(void)
{
    topoloc_loop_options options;
    topoloc_loop_detector *det = NULL;
    topoloc_loop_keyframe kf;
    topoloc_loop_hint hint;
    struct loop_scene scene;
    char path[4200];

    loop_options_have_defaults_and_older_callers_get_the_newer_fields_defaults(&options);
    options.exclude_recent_ids = 5;
    options.exclude_recent_s = 0.0;
    options.consistent_keyframes = 1;
    a_loop_detector_needs_an_out_pointer_a_kind_a_bounded_dim_and_candidates(&options);
    CHECK_STATUS(new_detector(&options, &det), TOPOLOC_OK);
    if (det == NULL)
        return;
    first_view_of_the_scene(&scene, &kf, &hint);
    bad_keyframes_after_the_first_are_refused_and_change_nothing(det, &kf, &hint);
    a_revisit_from_another_pose_is_accepted_with_every_keypoint_an_inlier(det, &kf, &hint, &scene);
    tmp_path(path, sizeof path, "loops.topoloc");
    a_detector_saves_as_a_map_and_erases_keyframes_by_id(det, path);
    topoloc_loop_detector_free(det);
    topoloc_loop_detector_free(NULL);
    a_second_session_from_the_saved_map_verifies_against_its_keypoints(path, &kf, &hint);
    CHECK(remove(path) == 0);
}

/* Confirmed hints (ABI 1.10): with a streak of 3, keyframes 10 and 11 revisit keyframe 0 but
 * are refused as inconsistent; keyframe 12 completes the streak and confirms both. */
static void a_streak_of_three_confirms_the_revisits_it_first_refused_as_inconsistent(void)
{
    topoloc_loop_options options;
    topoloc_loop_detector *det = NULL;
    topoloc_loop_keyframe kf;
    topoloc_loop_hint hint, confirmed;
    struct loop_scene scene;
    size_t count = 99;
    const uint64_t ids[] = {0, 10, 11, 12, 13};

    SECTION();
    CHECK(topoloc_abi_version_minor() >= 10);
    CHECK_STATUS(topoloc_loop_options_default(&options), TOPOLOC_OK);
    options.exclude_recent_ids = 5;
    options.exclude_recent_s = 0.0;
    CHECK_STATUS(new_detector(&options, &det), TOPOLOC_OK);
    if (det == NULL)
        return;
    CHECK_STATUS(topoloc_loop_detector_confirmed_count(det, &count), TOPOLOC_OK);
    CHECK(count == 0);
    first_view_of_the_scene(&scene, &kf, &hint);
    CHECK_STATUS(topoloc_loop_hint_default(&confirmed), TOPOLOC_OK);
    for (size_t k = 0; k < sizeof ids / sizeof ids[0]; k++) {
        kf.id = ids[k];
        kf.timestamp = (double)ids[k];
        kf.keypoints = k == 0 ? scene.points : scene.seen_again;
        CHECK_STATUS(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_OK);
        CHECK_STATUS(topoloc_loop_detector_confirmed_count(det, &count), TOPOLOC_OK);
        if (k == 1 || k == 2)
            CHECK(hint.gate == TOPOLOC_GATE_INCONSISTENT && count == 0);
        if (k == 3) {
            CHECK(hint.accepted && hint.query_id == 12 && count == 2);
            CHECK_STATUS(topoloc_loop_detector_confirmed(det, 0, &confirmed), TOPOLOC_OK);
            CHECK(confirmed.query_id == 10 && confirmed.matched_id == 0 && confirmed.accepted &&
                  confirmed.gate == TOPOLOC_GATE_ACCEPTED && confirmed.inliers >= 30);
            CHECK_STATUS(topoloc_loop_detector_confirmed(det, 1, &confirmed), TOPOLOC_OK);
            CHECK(confirmed.query_id == 11 && confirmed.accepted);
            /* Out of range: refused, *hint unchanged. */
            CHECK_ERROR(topoloc_loop_detector_confirmed(det, 2, &confirmed),
                        TOPOLOC_ERR_INVALID_ARGUMENT);
            CHECK(confirmed.query_id == 11);
            CHECK_NULL(topoloc_loop_detector_confirmed(det, 0, NULL), "hint");
            CHECK_NULL(topoloc_loop_detector_confirmed_count(det, NULL), "count");
            confirmed.struct_size = 3;
            CHECK_STATUS(topoloc_loop_detector_confirmed(det, 0, &confirmed),
                         TOPOLOC_ERR_STRUCT_SIZE);
            confirmed.struct_size = sizeof confirmed;
        }
        if (k == 4)
            CHECK(hint.accepted && count == 0); /* the streak goes on: nothing pending */
    }
    CHECK_NULL(topoloc_loop_detector_confirmed_count(NULL, &count), "detector");
    topoloc_loop_detector_free(det);
}

/* Sessions (ABI 1.15): at the default exclusion (30 ids, 10 s) keyframe 3 cannot match
 * keyframe 0; after `topoloc_loop_detector_begin_session` (a host's new map, its clock
 * restarted) keyframe 4, earlier in time, finds the keyframes of the session just ended. */
static void a_new_session_finds_the_keyframes_just_lost_and_may_restart_its_clock(void)
{
    topoloc_loop_options options;
    topoloc_loop_detector *det = NULL;
    topoloc_loop_keyframe kf;
    topoloc_loop_hint hint;
    struct loop_scene scene;

    SECTION();
    CHECK_STATUS(topoloc_loop_options_default(&options), TOPOLOC_OK);
    options.consistent_keyframes = 1;
    CHECK_STATUS(new_detector(&options, &det), TOPOLOC_OK);
    if (det == NULL)
        return;
    first_view_of_the_scene(&scene, &kf, &hint);
    kf.timestamp = 100.0;
    CHECK_STATUS(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_OK);
    kf.id = 3;
    kf.timestamp = 100.5;
    kf.keypoints = scene.seen_again;
    CHECK_STATUS(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_OK);
    CHECK(!hint.has_match && hint.gate == TOPOLOC_GATE_NO_CANDIDATE);

    CHECK_STATUS(topoloc_loop_detector_begin_session(det), TOPOLOC_OK);
    /* A new image of the same spot (a quarter pixel off keyframe 3's keypoints). */
    for (size_t i = 0; i < 2 * LOOP_POINTS; i++)
        scene.seen_again[i] += 0.25f;
    kf.id = 4;
    kf.timestamp = 0.0;
    CHECK_STATUS(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_OK);
    CHECK(hint.query_id == 4 && hint.accepted && hint.inliers >= 30);
    CHECK(hint.matched_id == 0 || hint.matched_id == 3);
    /* Within the new session time must not go back. */
    kf.id = 5;
    kf.timestamp = -1.0;
    CHECK_ERROR(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_NULL(topoloc_loop_detector_begin_session(NULL), "detector");
    topoloc_loop_detector_free(det);
}

void run_loop_tests(void)
{
    loop_closure();
    a_streak_of_three_confirms_the_revisits_it_first_refused_as_inconsistent();
    a_new_session_finds_the_keyframes_just_lost_and_may_restart_its_clock();
}
