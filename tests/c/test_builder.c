/*
 * Section "Building maps" of topoloc.h, from places and views and from keyframes (maps from
 * images are in test_images.c): keyframes with poses become places at their spots, keyframes
 * without poses a place per change of appearance; bad keyframes, names, views, places and edges
 * are refused and leave the builder as it was; a builder stays usable after build; NULL
 * arguments.
 */
#include "harness.h"

/* Keyframes with poses: 5 spots 3 m apart, visited out and back; the way back sees new
 * appearances (random descriptors). */
enum { SPOTS = 5, KEYFRAMES = 2 * SPOTS };
static float g_kf_desc[KEYFRAMES][DIM];
static double g_kf_poses[KEYFRAMES][16];

static void init_keyframe_world(void)
{
    size_t i;
    uint32_t d;
    rng_seed(5);
    for (i = 0; i < KEYFRAMES; i++) {
        size_t spot = i < SPOTS ? i : KEYFRAMES - 1 - i;
        double *m = g_kf_poses[i];
        for (d = 0; d < DIM; d++) {
            g_kf_desc[i][d] = rng_normalish();
        }
        memset(m, 0, sizeof g_kf_poses[i]);
        m[0] = m[5] = m[10] = m[15] = 1.0;
        m[3] = 3.0 * (double)spot + (i < SPOTS ? 0.0 : 0.1);
    }
}

/* Six keyframes without poses, in pairs of identical descriptors (the first three of
 * g_kf_desc). */
static void pairs_of_keyframes_without_poses(topoloc_keyframe plain[6])
{
    size_t i;
    for (i = 0; i < 6; i++) {
        plain[i].id = i;
        plain[i].descriptor = g_kf_desc[i / 2];
        plain[i].descriptor_len = DIM;
        plain[i].world_T_camera = NULL;
    }
}

static void keyframes_with_poses_become_places_at_their_spots_and_localize_there(void)
{
    topoloc_keyframe keyframes[KEYFRAMES];
    topoloc_keyframe_options options;
    topoloc_map *map = NULL;
    size_t count = 0, i;
    uint32_t v;
    char kind[32];

    SECTION();
    for (i = 0; i < KEYFRAMES; i++) {
        keyframes[i].id = 500u + i;
        keyframes[i].descriptor = g_kf_desc[i];
        keyframes[i].descriptor_len = DIM;
        keyframes[i].world_T_camera = g_kf_poses[i];
    }
    CHECK_OK(topoloc_keyframe_options_default(&options));
    CHECK(options.struct_size == sizeof options);
    CHECK(options.place_spacing_m == 2.0);
    CHECK(options.max_views_per_place == 4);
    options.neighbour_radius_m = 2.5; /* below the 3 m spot spacing: only consecutive edges */
    CHECK_OK(
        topoloc_map_from_keyframes("kf-desc", NULL, DIM, keyframes, KEYFRAMES, &options, &map));
    if (map == NULL) {
        return;
    }
    CHECK_COUNTS(map, SPOTS, KEYFRAMES, SPOTS - 1);
    CHECK_OK(topoloc_map_descriptor_kind(map, kind, sizeof kind, NULL));
    CHECK(strcmp(kind, "kf-desc") == 0);
    CHECK_OK(topoloc_map_descriptor_model(map, kind, sizeof kind, &count));
    CHECK(strcmp(kind, "") == 0 && count == 1);
    for (v = 0; v < KEYFRAMES; v++) {
        topoloc_view_info info;
        double xyz[3];
        bool has_position = false;
        CHECK_OK(topoloc_view_info_default(&info));
        CHECK_OK(topoloc_map_view_info(map, v, &info));
        CHECK(info.has_keyframe_id && info.keyframe_id >= 500u && info.keyframe_id < 510u);
        CHECK(info.has_pose);
        /* The view's keyframe and its place sit at the same spot. */
        CHECK_OK(topoloc_map_place_position(map, info.place, xyz, &has_position));
        CHECK(has_position);
        CHECK_NEAR(xyz[0], g_kf_poses[info.keyframe_id - 500u][3], 0.1 + 1e-9);
    }
    /* A keyframe's own descriptor localizes to its place. */
    {
        topoloc_localizer *loc = NULL;
        topoloc_frame frame;
        topoloc_result result;
        topoloc_view_info info;
        CHECK_OK(topoloc_localizer_new(map, NULL, &loc));
        CHECK_OK(topoloc_frame_default(&frame));
        CHECK_OK(topoloc_result_default(&result));
        frame.descriptor = g_kf_desc[7];
        frame.descriptor_len = DIM;
        if (loc != NULL) {
            CHECK_OK(topoloc_localizer_process(loc, &frame, &result));
            CHECK_OK(topoloc_view_info_default(&info));
            CHECK_OK(topoloc_map_view_info(map, result.view, &info));
            CHECK(info.keyframe_id == 507u);
            CHECK(result.candidates_len == 0); /* no buffer given */
        }
        topoloc_localizer_free(loc);
    }
    topoloc_map_free(map);
}

static void keyframes_without_poses_start_a_place_when_the_appearance_changes(void)
{
    topoloc_keyframe plain[6];
    topoloc_map *map = NULL;
    double xyz[3];
    bool has_position = true;

    SECTION();
    pairs_of_keyframes_without_poses(plain);
    CHECK_OK(topoloc_map_from_keyframes("kf-desc", "m", DIM, plain, 6, NULL, &map));
    if (map != NULL) {
        CHECK_COUNTS(map, 3, 3, 2); /* duplicates are dropped */
        CHECK_OK(topoloc_map_place_position(map, 0, xyz, &has_position));
        CHECK(!has_position);
        CHECK(xyz[0] == 0.0 && xyz[1] == 0.0 && xyz[2] == 0.0);
    }
    topoloc_map_free(map);
}

static void no_keyframes_mixed_poses_bad_lengths_and_bad_options_are_refused(void)
{
    topoloc_keyframe plain[6];
    topoloc_keyframe_options options;
    topoloc_map *map = NULL;

    SECTION();
    pairs_of_keyframes_without_poses(plain);
    CHECK_ERROR(topoloc_map_from_keyframes("k", NULL, DIM, NULL, 0, NULL, &map),
                TOPOLOC_ERR_EMPTY_MAP);
    plain[3].world_T_camera = g_kf_poses[0]; /* a mix of keyframes with and without poses */
    CHECK_ERROR(topoloc_map_from_keyframes("k", NULL, DIM, plain, 6, NULL, &map),
                TOPOLOC_ERR_INVALID_ARGUMENT);
    plain[3].world_T_camera = NULL;
    plain[2].descriptor_len = DIM - 1;
    CHECK_STATUS(topoloc_map_from_keyframes("k", NULL, DIM, plain, 6, NULL, &map),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("keyframe 2");
    plain[2].descriptor_len = DIM;
    CHECK_OK(topoloc_keyframe_options_default(&options));
    options.max_views_per_place = 0;
    CHECK_STATUS(topoloc_map_from_keyframes("k", NULL, DIM, plain, 6, &options, &map),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("max_views_per_place");
    options.struct_size = 0;
    CHECK_ERROR(topoloc_map_from_keyframes("k", NULL, DIM, plain, 6, &options, &map),
                TOPOLOC_ERR_STRUCT_SIZE);
    CHECK(map == NULL); /* never written on error */
}

static void a_builder_needs_a_kind_a_dimension_and_utf8_names(void)
{
    topoloc_map_builder *b = NULL;

    SECTION();
    CHECK_ERROR(topoloc_map_builder_new("", NULL, DIM, &b), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_ERROR(topoloc_map_builder_new(KIND, NULL, 0, &b), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_ERROR(topoloc_map_builder_new("\xff\xfe", NULL, DIM, &b), TOPOLOC_ERR_INVALID_UTF8);
    CHECK_STATUS(topoloc_map_builder_new(KIND, "\xc3", DIM, &b), TOPOLOC_ERR_INVALID_UTF8);
    CHECK(b == NULL);
}

/* On a new builder: a map needs places and views; views with a wrong length, non-finite or zero
 * descriptors, poses that are not rigid or not finite, or bad attributes are refused, after which
 * the next view is still view 0. */
static void
empty_maps_and_bad_views_are_refused_and_leave_the_builder_unchanged(topoloc_map_builder *b)
{
    topoloc_map *map = NULL;
    topoloc_view_attributes attributes;
    uint32_t place = 77, view = 77;
    float desc[DIM];
    double bad_pose[16] = {2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}; /* a scale */
    double nan = make_nan();
    uint32_t d;

    SECTION();
    memcpy(desc, g_view_desc[0], sizeof desc);
    CHECK_ERROR(topoloc_map_builder_build(b, &map), TOPOLOC_ERR_EMPTY_MAP);
    CHECK_OK(topoloc_map_builder_add_place(b, NULL, &place));
    CHECK(place == 0);
    CHECK_ERROR(topoloc_map_builder_build(b, &map), TOPOLOC_ERR_INVALID_MAP); /* no views */
    CHECK(map == NULL);

    CHECK_ERROR(topoloc_map_builder_add_view(b, 1, desc, DIM, NULL, &view),
                TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_ERROR(topoloc_map_builder_add_view(b, 0, desc, DIM - 1, NULL, &view),
                TOPOLOC_ERR_DIMENSION_MISMATCH);
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM + 1, NULL, &view),
                 TOPOLOC_ERR_DIMENSION_MISMATCH);
    desc[5] = (float)nan;
    CHECK_ERROR(topoloc_map_builder_add_view(b, 0, desc, DIM, NULL, &view), TOPOLOC_ERR_NON_FINITE);
    desc[5] = make_inf();
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM, NULL, &view),
                 TOPOLOC_ERR_NON_FINITE);
    for (d = 0; d < DIM; d++) {
        desc[d] = 0.0f;
    }
    CHECK_ERROR(topoloc_map_builder_add_view(b, 0, desc, DIM, NULL, &view),
                TOPOLOC_ERR_ZERO_DESCRIPTOR);
    memcpy(desc, g_view_desc[0], sizeof desc);
    CHECK_OK(topoloc_view_attributes_default(&attributes));
    attributes.world_T_camera = bad_pose;
    CHECK_ERROR(topoloc_map_builder_add_view(b, 0, desc, DIM, &attributes, &view),
                TOPOLOC_ERR_INVALID_ARGUMENT);
    bad_pose[0] = 1.0;
    bad_pose[15] = 2.0; /* last row not 0 0 0 1 */
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM, &attributes, &view),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    bad_pose[15] = 1.0;
    bad_pose[3] = nan;
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM, &attributes, &view),
                 TOPOLOC_ERR_NON_FINITE);
    attributes.world_T_camera = NULL;
    attributes.image = "\xff";
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM, &attributes, &view),
                 TOPOLOC_ERR_INVALID_UTF8);
    attributes.image = NULL;
    attributes.struct_size = 0;
    CHECK_ERROR(topoloc_map_builder_add_view(b, 0, desc, DIM, &attributes, &view),
                TOPOLOC_ERR_STRUCT_SIZE);
    CHECK(view == 77); /* never written on error */

    /* After all those errors the builder is unchanged: the next view is view 0. */
    CHECK_OK(topoloc_view_attributes_default(&attributes));
    CHECK_OK(topoloc_map_builder_add_view(b, 0, desc, DIM, &attributes, &view));
    CHECK(view == 0);
}

/* On a builder with place 0 and view 0: a NaN position, self edges, edges to unknown places,
 * weights that are not positive and finite and a second edge between two places are refused. */
static void bad_places_and_edges_are_refused(topoloc_map_builder *b)
{
    double nan_position[3];
    uint32_t place = 77, view = 77;

    SECTION();
    nan_position[0] = 0.0;
    nan_position[1] = make_nan();
    nan_position[2] = 0.0;
    /* A NaN position is refused as a non-finite value, like NaN poses and descriptors. */
    CHECK_ERROR(topoloc_map_builder_add_place(b, nan_position, &place), TOPOLOC_ERR_NON_FINITE);
    CHECK_OK(topoloc_map_builder_add_place(b, NULL, &place));
    CHECK(place == 1);
    CHECK_OK(topoloc_map_builder_add_view(b, 1, g_view_desc[5], DIM, NULL, &view));
    CHECK(view == 1);

    CHECK_ERROR(topoloc_map_builder_add_edge(b, 0, 0, 1.0f), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_ERROR(topoloc_map_builder_add_edge(b, 0, 2, 1.0f), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_STATUS(topoloc_map_builder_add_edge(b, 9, 0, 1.0f), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_STATUS(topoloc_map_builder_add_edge(b, 0, 1, 0.0f), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_STATUS(topoloc_map_builder_add_edge(b, 0, 1, -1.0f), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_STATUS(topoloc_map_builder_add_edge(b, 0, 1, (float)nan_position[1]),
                 TOPOLOC_ERR_NON_FINITE);
    CHECK_OK(topoloc_map_builder_add_edge(b, 1, 0, 0.5f));
    CHECK_STATUS(topoloc_map_builder_add_edge(b, 0, 1, 0.5f), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("exists");
}

/* Two maps from one builder (two places and an edge, then a third place): the first map is not
 * affected by what is added after it was built. */
static void a_builder_stays_usable_after_build(topoloc_map_builder *b)
{
    topoloc_map *map = NULL, *second = NULL;
    uint32_t place = 77, view = 77;
    size_t count = 0;

    SECTION();
    CHECK_OK(topoloc_map_builder_build(b, &map));
    if (map == NULL) {
        return;
    }
    CHECK_OK(topoloc_map_place_count(map, &count));
    CHECK(count == 2);
    CHECK_OK(topoloc_map_edge_count(map, &count));
    CHECK(count == 1);
    CHECK_OK(topoloc_map_builder_add_place(b, NULL, &place));
    CHECK_OK(topoloc_map_builder_add_view(b, 2, g_view_desc[9], DIM, NULL, &view));
    CHECK_OK(topoloc_map_builder_build(b, &second));
    if (second != NULL) {
        CHECK_OK(topoloc_map_place_count(second, &count));
        CHECK(count == 3);
    }
    CHECK_OK(topoloc_map_place_count(map, &count));
    CHECK(count == 2); /* the first map is unaffected */
    topoloc_map_free(second);
    topoloc_map_free(map);
}

static void the_builder_and_keyframes_refuse_null_arguments_naming_them(void)
{
    topoloc_map_builder *b = NULL;
    topoloc_map *m = NULL;
    topoloc_keyframe keyframe;
    float desc[DIM];
    uint32_t u = 0;
    topoloc_map_builder *const sentinel_builder = (topoloc_map_builder *)&u;

    SECTION();
    memcpy(desc, g_view_desc[0], sizeof desc);
    CHECK_NULL(topoloc_view_attributes_init(NULL, sizeof(topoloc_view_attributes)), "NULL");
    CHECK_NULL(topoloc_keyframe_options_init(NULL, sizeof(topoloc_keyframe_options)), "NULL");

    /* Builder. */
    b = sentinel_builder;
    CHECK_NULL(topoloc_map_builder_new(NULL, NULL, DIM, &b), "kind");
    CHECK(b == sentinel_builder); /* out-parameter untouched */
    CHECK_NULL(topoloc_map_builder_new(KIND, NULL, DIM, NULL), "out");
    b = NULL;
    CHECK_OK(topoloc_map_builder_new(KIND, NULL, DIM, &b)); /* model may be NULL */
    CHECK_NULL(topoloc_map_builder_add_place(NULL, NULL, &u), "builder");
    CHECK_NULL(topoloc_map_builder_add_place(b, NULL, NULL), "place_out");
    CHECK_OK(topoloc_map_builder_add_place(b, NULL, &u)); /* position may be NULL */
    CHECK_NULL(topoloc_map_builder_add_view(NULL, 0, desc, DIM, NULL, &u), "builder");
    CHECK_NULL(topoloc_map_builder_add_view(b, 0, NULL, DIM, NULL, &u), "descriptor");
    CHECK_NULL(topoloc_map_builder_add_view(b, 0, desc, DIM, NULL, NULL), "view_out");
    CHECK_OK(topoloc_map_builder_add_view(b, 0, desc, DIM, NULL, &u)); /* attributes may be NULL */
    CHECK_NULL(topoloc_map_builder_add_edge(NULL, 0, 1, 1.0f), "builder");
    m = (topoloc_map *)&u;
    CHECK_NULL(topoloc_map_builder_build(NULL, &m), "builder");
    CHECK(m == (topoloc_map *)&u);
    CHECK_NULL(topoloc_map_builder_build(b, NULL), "out");
    topoloc_map_builder_free(b);

    /* Keyframes. */
    keyframe.id = 1;
    keyframe.descriptor = desc;
    keyframe.descriptor_len = DIM;
    keyframe.world_T_camera = NULL;
    m = NULL;
    CHECK_NULL(topoloc_map_from_keyframes(NULL, NULL, DIM, &keyframe, 1, NULL, &m), "kind");
    CHECK_NULL(topoloc_map_from_keyframes(KIND, NULL, DIM, NULL, 1, NULL, &m), "keyframes");
    CHECK_NULL(topoloc_map_from_keyframes(KIND, NULL, DIM, &keyframe, 1, NULL, NULL), "out");
    keyframe.descriptor = NULL;
    CHECK_NULL(topoloc_map_from_keyframes(KIND, NULL, DIM, &keyframe, 1, NULL, &m),
               "keyframes[0].descriptor");
    CHECK(m == NULL);
}

void run_builder_tests(void)
{
    topoloc_map_builder *b = NULL;

    init_keyframe_world();
    keyframes_with_poses_become_places_at_their_spots_and_localize_there();
    keyframes_without_poses_start_a_place_when_the_appearance_changes();
    no_keyframes_mixed_poses_bad_lengths_and_bad_options_are_refused();

    a_builder_needs_a_kind_a_dimension_and_utf8_names();
    CHECK_OK(topoloc_map_builder_new(KIND, NULL, DIM, &b));
    if (b != NULL) {
        empty_maps_and_bad_views_are_refused_and_leave_the_builder_unchanged(b);
        bad_places_and_edges_are_refused(b);
        a_builder_stays_usable_after_build(b);
    }
    topoloc_map_builder_free(b);
    the_builder_and_keyframes_refuse_null_arguments_naming_them();
}
