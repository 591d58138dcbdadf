/*
 * Image keyframes of the loop-closure section of topoloc.h (ABI 1.15): a keyframe describer on
 * the map test_images.c builds (VLAD-ORB) describes grey places and their ORB keypoints in one
 * pass, so a second pass over the places (shifted, brighter) closes a loop at each with ranked
 * candidates; bad keyframes, images and depth change nothing. With the cache's models (required
 * in CI), the learned path: an ONNX map built with XFeat keypoints, reloaded as a first session,
 * and XFeat image keyframes whose hints carry a pose from the intrinsics.
 */
#include "harness.h"

#include <math.h>

/* Loop options for the small grey places: every place may close a loop at once. */
static void image_loop_options(topoloc_loop_options *options, uint32_t min_inliers)
{
    CHECK_OK(topoloc_loop_options_default(options));
    options->exclude_recent_ids = 1;
    options->exclude_recent_s = 0.0;
    options->candidate_id_gap = 0;
    options->consistent_keyframes = 1;
    options->min_inliers = min_inliers;
    options->odometry_gate = false;
}

/* Whether two hints hold the same values, field by field (their padding bytes are not
 * values: memcmp would read them uninitialised). */
static bool same_hint(const topoloc_loop_hint *a, const topoloc_loop_hint *b)
{
    return a->struct_size == b->struct_size && a->query_id == b->query_id &&
           a->query_place == b->query_place && a->has_match == b->has_match &&
           a->accepted == b->accepted && a->gate == b->gate && a->matched_id == b->matched_id &&
           a->place == b->place && a->inliers == b->inliers && a->confidence == b->confidence &&
           a->has_pose == b->has_pose && a->scale_known == b->scale_known &&
           a->translation == b->translation &&
           memcmp(a->matched_T_query, b->matched_T_query, sizeof a->matched_T_query) == 0 &&
           memcmp(a->covariance, b->covariance, sizeof a->covariance) == 0;
}

/* A keyframe with only an id and a timestamp (the image gives the rest). */
static topoloc_loop_keyframe image_keyframe(uint64_t id)
{
    topoloc_loop_keyframe k;
    CHECK_OK(topoloc_loop_keyframe_default(&k));
    k.id = id;
    k.timestamp = (double)id;
    return k;
}

/* A detector for `map`'s descriptors (kind, model and dimension read from the map). */
static topoloc_loop_detector *detector_for(const topoloc_map *map,
                                           const topoloc_loop_options *options)
{
    topoloc_loop_detector *det = NULL;
    char kind[64], model[256];
    uint32_t dim = 0;
    CHECK_OK(topoloc_map_descriptor_kind(map, kind, sizeof kind, NULL));
    CHECK_OK(topoloc_map_descriptor_model(map, model, sizeof model, NULL));
    CHECK_OK(topoloc_map_descriptor_dim(map, &dim));
    CHECK_OK(topoloc_loop_detector_new(kind, model, dim, options, &det));
    return det;
}

/* Adds place p's image (first pass) or its revisit (second pass) as keyframe `id`. */
static topoloc_status add_place(topoloc_loop_detector *det, topoloc_keyframe_describer *kd,
                                uint32_t p, bool revisit, uint64_t id, topoloc_loop_hint *hint)
{
    static uint8_t px[IMG_PIXELS];
    topoloc_loop_keyframe k = image_keyframe(id);
    topoloc_image image;
    if (revisit) {
        make_revisit(g_place_px[p], 300u + p, px);
    } else {
        memcpy(px, g_place_px[p], sizeof px);
    }
    image = gray_image(px);
    return topoloc_loop_detector_add_image(det, kd, &k, &image, NULL, hint);
}

static void keyframe_describer_options_have_defaults_and_refuse_what_they_cannot_honour(
    const topoloc_map *map, const topoloc_map *world)
{
    topoloc_keyframe_describer_options options;
    topoloc_keyframe_describer *kd = NULL, *untouched = (topoloc_keyframe_describer *)0x1;
    topoloc_local_features kind = 0;
    char missing[4200];

    SECTION();
    memset(&options, 0x5A, sizeof options);
    CHECK_OK(topoloc_keyframe_describer_options_default(&options));
    CHECK(options.struct_size == sizeof options &&
          options.local_features == TOPOLOC_LOCAL_FEATURES_XFEAT &&
          options.backend == TOPOLOC_BACKEND_AUTO && options.onnx_model_path == NULL &&
          options.onnx_runtime_path == NULL && options.xfeat_model_path == NULL &&
          options.xfeat_max_pixels == 160000 && options.threads == 1);
    CHECK_STATUS(topoloc_keyframe_describer_options_init(&options, 3), TOPOLOC_ERR_STRUCT_SIZE);

    CHECK_ERROR(topoloc_keyframe_describer_new(world, NULL, &untouched), TOPOLOC_ERR_NO_DESCRIBER);
    options.local_features = 99;
    CHECK_ERROR(topoloc_keyframe_describer_new(map, &options, &untouched),
                TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("TOPOLOC_LOCAL_FEATURES_");
    /* Dense cells come from a CNN's feature map: the map is VLAD. */
    options.local_features = TOPOLOC_LOCAL_FEATURES_CELLS;
    CHECK_ERROR(topoloc_keyframe_describer_new(map, &options, &untouched),
                TOPOLOC_ERR_INVALID_OPTION);
    /* A missing XFeat model names the path tried. */
    tmp_path(missing, sizeof missing, "no-such-xfeat.onnx");
    options.local_features = TOPOLOC_LOCAL_FEATURES_XFEAT;
    options.xfeat_model_path = missing;
    CHECK_ERROR(topoloc_keyframe_describer_new(map, &options, &untouched),
                TOPOLOC_ERR_BACKEND_UNAVAILABLE);
    CHECK_MESSAGE_HAS(missing);
    options.xfeat_model_path = NULL;
    options.local_features = TOPOLOC_LOCAL_FEATURES_ORB;
    options.threads = 0;
    CHECK_STATUS(topoloc_keyframe_describer_new(map, &options, &untouched),
                 TOPOLOC_ERR_INVALID_OPTION);
    CHECK(untouched == (topoloc_keyframe_describer *)0x1);
    options.threads = 1;
    CHECK_NULL(topoloc_keyframe_describer_new(NULL, &options, &kd), "map");
    CHECK_NULL(topoloc_keyframe_describer_new(map, &options, NULL), "out");

    CHECK_OK(topoloc_keyframe_describer_new(map, &options, &kd));
    CHECK_OK(topoloc_keyframe_describer_local_features(kd, &kind));
    CHECK(kind == TOPOLOC_LOCAL_FEATURES_ORB);
    CHECK_NULL(topoloc_keyframe_describer_local_features(kd, NULL), "out");
    topoloc_keyframe_describer_free(kd);
    topoloc_keyframe_describer_free(NULL);
}

static void
image_keyframes_close_loops_with_ranked_candidates_and_errors_change_nothing(const topoloc_map *map)
{
    topoloc_keyframe_describer_options options;
    topoloc_keyframe_describer *kd = NULL;
    topoloc_loop_options lo;
    topoloc_loop_detector *det = NULL, *with_camera = NULL;
    topoloc_loop_hint hint, kept;
    topoloc_loop_candidate_check checks[8];
    topoloc_loop_keyframe k;
    topoloc_depth_image depth;
    topoloc_image image, none;
    static uint16_t depth_px[IMG_PIXELS];
    float descriptor[4] = {1.0f, 0.0f, 0.0f, 0.0f};
    size_t count = 0, len = 0, i;
    unsigned closed = 0;
    uint32_t p;

    SECTION();
    CHECK_OK(topoloc_keyframe_describer_options_default(&options));
    options.local_features = TOPOLOC_LOCAL_FEATURES_ORB;
    CHECK_OK(topoloc_keyframe_describer_new(map, &options, &kd));
    image_loop_options(&lo, 12);
    det = detector_for(map, &lo);
    CHECK_OK(topoloc_loop_hint_default(&hint));
    if (kd == NULL || det == NULL) {
        topoloc_keyframe_describer_free(kd);
        topoloc_loop_detector_free(det);
        return;
    }
    for (p = 0; p < IMG_PLACES; p++) {
        CHECK_OK(add_place(det, kd, p, false, p, &hint));
    }
    for (p = 0; p < IMG_PLACES; p++) {
        CHECK_OK(add_place(det, kd, p, true, 100u + p, &hint));
        closed += hint.accepted && hint.matched_id == p;
        CHECK(!hint.accepted || hint.matched_id == p);
        CHECK_OK(topoloc_loop_detector_candidates(det, checks, 8, &count));
        CHECK(count >= 1 && count <= 8);
        for (i = 1; i < count; i++) {
            CHECK(checks[i].inliers <= checks[i - 1].inliers);
        }
        if (count > 0 && hint.has_match) {
            /* The hint's candidate is among them (refinement may pick a neighbour of it). */
            CHECK(checks[0].inliers >= 12 && checks[0].confidence > 0.0f &&
                  checks[0].confidence <= 1.0f && checks[0].similarity > -1.0f);
        }
    }
    printf("   image keyframes closed %u/%u loops (ORB)\n", closed, (unsigned)IMG_PLACES);
    CHECK(closed >= IMG_PLACES - 1);
    CHECK_OK(topoloc_loop_detector_candidates(det, checks, 1, &count));
    CHECK(count == 1);
    CHECK_NULL(topoloc_loop_detector_candidates(det, checks, 8, NULL), "count");

    /* Bad keyframes: the detector and the caller's hint are unchanged. */
    CHECK_OK(topoloc_loop_detector_len(det, &len));
    CHECK(len == 2u * IMG_PLACES);
    kept = hint;
    image = gray_image(g_place_px[0]);
    k = image_keyframe(500);
    k.descriptor = descriptor;
    k.descriptor_len = 4;
    CHECK_ERROR(topoloc_loop_detector_add_image(det, kd, &k, &image, NULL, &hint),
                TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("come from the image");
    k = image_keyframe(50); /* below the last id */
    CHECK_STATUS(topoloc_loop_detector_add_image(det, kd, &k, &image, NULL, &hint),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    k = image_keyframe(500);
    memset(&none, 0, sizeof none);
    CHECK_STATUS(topoloc_loop_detector_add_image(det, kd, &k, &none, NULL, &hint),
                 TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_NULL(topoloc_loop_detector_add_image(det, kd, &k, NULL, NULL, &hint), "image");
    CHECK_NULL(topoloc_loop_detector_add_image(det, NULL, &k, &image, NULL, &hint), "describer");
    /* Depth needs intrinsics. */
    depth.values = depth_px;
    depth.values_len = IMG_PIXELS;
    depth.units_per_metre = 1000.0;
    for (i = 0; i < IMG_PIXELS; i++) {
        depth_px[i] = 2000;
    }
    CHECK_ERROR(topoloc_loop_detector_add_image(det, kd, &k, &image, &depth, &hint),
                TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("intrinsics");
    CHECK(same_hint(&hint, &kept));
    CHECK_OK(topoloc_loop_detector_len(det, &len));
    CHECK(len == 2u * IMG_PLACES);

    /* With intrinsics, a depth image of another size is refused; the right size is taken. */
    lo.fx = 150.0;
    lo.fy = 150.0;
    lo.cx = 79.5;
    lo.cy = 59.5;
    with_camera = detector_for(map, &lo);
    if (with_camera != NULL) {
        depth.values_len = IMG_PIXELS - 1;
        CHECK_ERROR(topoloc_loop_detector_add_image(with_camera, kd, &k, &image, &depth, &hint),
                    TOPOLOC_ERR_INVALID_ARGUMENT);
        CHECK_MESSAGE_HAS("depth.values_len");
        CHECK_OK(topoloc_loop_detector_len(with_camera, &len));
        CHECK(len == 0);
        depth.values_len = IMG_PIXELS;
        CHECK_OK(topoloc_loop_detector_add_image(with_camera, kd, &k, &image, &depth, &hint));
        CHECK_OK(topoloc_loop_detector_len(with_camera, &len));
        CHECK(len == 1);
    }
    topoloc_loop_detector_free(with_camera);
    topoloc_loop_detector_free(det);
    topoloc_keyframe_describer_free(kd);
}

/* The learned path: an ONNX map with XFeat keypoints (ABI 1.15 map options) is the first
 * session; XFeat image keyframes of the revisits close loops against it with a pose. */
static void the_learned_path_closes_loops_with_poses_against_an_xfeat_map(void)
{
    enum { XPLACES = 6 };
    topoloc_image images[XPLACES];
    topoloc_image_map_options options;
    topoloc_keyframe_describer *kd = NULL;
    topoloc_loop_options lo;
    topoloc_loop_detector *det = NULL;
    topoloc_loop_hint hint;
    topoloc_map *map = NULL;
    char onnx[4200], xfeat[4200];
    unsigned closed = 0, posed = 0, rotation_only = 0;
    uint32_t p;

    SECTION();
    if (!models_ready(ONNX_MODEL_FILE, onnx, sizeof onnx, "learned loop") ||
        !models_ready(XFEAT_MODEL_FILE, xfeat, sizeof xfeat, "learned loop")) {
        return;
    }
    for (p = 0; p < XPLACES; p++) {
        images[p] = gray_image(g_place_px[p]);
    }
    CHECK_OK(topoloc_image_map_options_default(&options));
    CHECK(options.verification_keypoints == 500 &&
          options.local_features == TOPOLOC_LOCAL_FEATURES_XFEAT &&
          options.xfeat_model_path == NULL);
    options.backend = TOPOLOC_BACKEND_ONNX;
    options.dim = XPLACES - 1;
    options.threads = 1;
    options.local_features = 77;
    CHECK_STATUS(topoloc_map_build_from_images(images, XPLACES, &options, NULL, NULL, &map),
                 TOPOLOC_ERR_INVALID_OPTION);
    options.local_features = TOPOLOC_LOCAL_FEATURES_XFEAT;
    options.verification_keypoints = 256;
    options.xfeat_model_path = "/nonexistent/xfeat.onnx";
    CHECK_STATUS(topoloc_map_build_from_images(images, XPLACES, &options, NULL, NULL, &map),
                 TOPOLOC_ERR_BACKEND_UNAVAILABLE);
    CHECK(map == NULL);
    CHECK_MESSAGE_HAS("/nonexistent/xfeat.onnx");
    options.xfeat_model_path = xfeat;
    CHECK_OK(topoloc_map_build_from_images(images, XPLACES, &options, NULL, NULL, &map));
    if (map == NULL) {
        return;
    }
    CHECK_OK(topoloc_keyframe_describer_new(map, NULL, &kd));
    image_loop_options(&lo, 30);
    lo.fx = 150.0;
    lo.fy = 150.0;
    lo.cx = 79.5;
    lo.cy = 59.5;
    CHECK_OK(topoloc_loop_detector_from_map(map, &lo, &det));
    CHECK_OK(topoloc_loop_hint_default(&hint));
    if (kd != NULL && det != NULL) {
        for (p = 0; p < XPLACES; p++) {
            CHECK_OK(add_place(det, kd, p, true, 100u + p, &hint));
            closed += hint.accepted && hint.matched_id == p;
            posed += hint.accepted && hint.has_pose;
            CHECK(!hint.accepted || hint.matched_id == p);
            if (hint.accepted && hint.has_pose) {
                /* A 2-pixel shift is a turn of atan(2 / 150) = 0.76 degrees: unscaled, with
                 * a zero translation (rotation only) or a unit direction. */
                const double *T = hint.matched_T_query;
                double t = sqrt(T[3] * T[3] + T[7] * T[7] + T[11] * T[11]);
                double turn =
                    acos(fmin(1.0, (T[0] + T[5] + T[10] - 1.0) / 2.0)) * 57.29577951308232;
                CHECK(!hint.scale_known && (t == 0.0 || fabs(t - 1.0) < 1e-6));
                CHECK(turn < 2.0);
                rotation_only += t == 0.0;
            }
        }
        printf("   XFeat image keyframes closed %u/%u loops, %u with a pose (%u rotation only)\n",
               closed, (unsigned)XPLACES, posed, rotation_only);
        CHECK(closed >= XPLACES - 1 && posed == closed);
    }
    topoloc_loop_detector_free(det);
    topoloc_keyframe_describer_free(kd);
    topoloc_map_free(map);
}

void run_loop_image_tests(const topoloc_map *image_map, const topoloc_map *world)
{
    keyframe_describer_options_have_defaults_and_refuse_what_they_cannot_honour(image_map, world);
    image_keyframes_close_loops_with_ranked_candidates_and_errors_change_nothing(image_map);
    the_learned_path_closes_loops_with_poses_against_an_xfeat_map();
}
