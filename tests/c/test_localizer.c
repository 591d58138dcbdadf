/*
 * Section "Localizer" of topoloc.h, with descriptor frames on the descriptor world: single-frame
 * mode, NULL arguments, bad frames (refused, the localizer and the result unchanged), options
 * out of range or of another descriptor, and metric mode. (Image frames are in test_images.c;
 * a localizer walking a loaded map is in test_map.c.)
 */
#include "harness.h"

static void single_frame_mode_answers_each_frame_as_a_fresh_localizer_would(void)
{
    topoloc_map *map;
    topoloc_localizer *single = NULL, *fresh = NULL;
    topoloc_localizer_options options;
    topoloc_frame frame;
    topoloc_result r1, r2;
    topoloc_candidate c1[5], c2[5];
    float desc[DIM];
    uint32_t places[] = {4, 0, 2, 5, 1}; /* jumps between non-neighbours */
    size_t i;

    SECTION();
    rng_seed(2);
    map = build_world_map();
    if (map == NULL) {
        return;
    }
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.mode = TOPOLOC_MODE_SINGLE_FRAME;
    CHECK_OK(topoloc_localizer_new(map, &options, &single));
    if (single == NULL) {
        topoloc_map_free(map);
        return;
    }
    CHECK_OK(topoloc_frame_default(&frame));
    result_with_candidates(&r1, c1, 5);
    result_with_candidates(&r2, c2, 5);
    for (i = 0; i < sizeof places / sizeof places[0]; i++) {
        uint32_t source = places[i] * VIEWS_PER_PLACE + (uint32_t)i % VIEWS_PER_PLACE;
        size_t j;
        noisy_copy(desc, source, 0.02f);
        frame.descriptor = desc;
        frame.descriptor_len = DIM;
        frame.timestamp = 10.0 - (double)i; /* decreasing: allowed in single-frame mode */
        CHECK_OK(topoloc_localizer_process(single, &frame, &r1));
        CHECK(r1.frame_index == i);
        CHECK(r1.place == places[i]);
        CHECK(r1.view == source);
        CHECK(candidates_consistent(&r1));
        /* No history: the same answer as a localizer that sees only this frame. */
        CHECK_OK(topoloc_localizer_new(map, &options, &fresh));
        if (fresh != NULL) {
            CHECK_OK(topoloc_localizer_process(fresh, &frame, &r2));
            CHECK(r2.frame_index == 0);
            CHECK(r2.place == r1.place && r2.view == r1.view);
            CHECK(r2.confidence == r1.confidence && r2.similarity == r1.similarity);
            CHECK(r2.off_map_probability == r1.off_map_probability);
            CHECK(r2.candidates_len == r1.candidates_len);
            for (j = 0; j < r1.candidates_len && j < r2.candidates_len; j++) {
                CHECK(c1[j].place == c2[j].place && c1[j].view == c2[j].view &&
                      c1[j].probability == c2[j].probability);
            }
        }
        topoloc_localizer_free(fresh);
        fresh = NULL;
    }
    topoloc_localizer_free(single);
    topoloc_map_free(map);
}

static void
the_localizer_refuses_null_arguments_naming_them_and_counts_no_frame(const topoloc_map *map)
{
    topoloc_localizer *loc = NULL;
    topoloc_frame frame;
    topoloc_result result;
    float desc[DIM];
    uint32_t u = 0;

    SECTION();
    memcpy(desc, g_view_desc[0], sizeof desc);
    CHECK_NULL(topoloc_localizer_options_init(NULL, sizeof(topoloc_localizer_options)), "NULL");
    CHECK_NULL(topoloc_frame_init(NULL, sizeof(topoloc_frame)), "NULL");
    CHECK_NULL(topoloc_result_init(NULL, sizeof(topoloc_result)), "NULL");

    loc = (topoloc_localizer *)&u;
    CHECK_NULL(topoloc_localizer_new(NULL, NULL, &loc), "map");
    CHECK(loc == (topoloc_localizer *)&u);
    CHECK_NULL(topoloc_localizer_new(map, NULL, NULL), "out");
    loc = NULL;
    CHECK_OK(topoloc_localizer_new(map, NULL, &loc)); /* options may be NULL */
    CHECK_NULL(topoloc_localizer_reset(NULL), "localizer");
    CHECK_OK(topoloc_frame_default(&frame));
    frame.descriptor = desc;
    frame.descriptor_len = DIM;
    CHECK_OK(topoloc_result_default(&result));
    CHECK_NULL(topoloc_localizer_process(NULL, &frame, &result), "localizer");
    CHECK_NULL(topoloc_localizer_process(loc, NULL, &result), "frame");
    CHECK_NULL(topoloc_localizer_process(loc, &frame, NULL), "result");
    frame.descriptor = NULL;
    CHECK_NULL(topoloc_localizer_process(loc, &frame, &result), "frame.descriptor");
    frame.descriptor = desc;
    result.candidates_capacity = 4; /* capacity without a buffer */
    CHECK_NULL(topoloc_localizer_process(loc, &frame, &result), "result.candidates");
    result.candidates_capacity = 0;
    CHECK_OK(topoloc_localizer_process(loc, &frame, &result));
    CHECK(result.frame_index == 0); /* none of the failed calls counted as a frame */
    topoloc_localizer_free(loc);
}

/* One localizer sees one or two bad frames before each good one, its twin only the good ones:
 * every bad frame is refused with its status and a message, the result and its candidates are
 * untouched, and the twins agree exactly on every good frame, also after a reset. */
static void bad_frames_leave_the_localizer_and_the_result_unchanged(const topoloc_map *map)
{
    enum { FRAMES = 14, BAD_KINDS = 11 };
    static const uint32_t walk[FRAMES] = {0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 0, 0};
    static const uint32_t expected_status[BAD_KINDS] = {
        TOPOLOC_ERR_DIMENSION_MISMATCH, /* 0: too short */
        TOPOLOC_ERR_DIMENSION_MISMATCH, /* 1: too long */
        TOPOLOC_ERR_NON_FINITE,         /* 2: NaN in the descriptor */
        TOPOLOC_ERR_NON_FINITE,         /* 3: infinity in the descriptor */
        TOPOLOC_ERR_ZERO_DESCRIPTOR,    /* 4: all zeros */
        TOPOLOC_ERR_TIMESTAMP,          /* 5: timestamp going backwards */
        TOPOLOC_ERR_NON_FINITE,         /* 6: NaN timestamp */
        TOPOLOC_ERR_INVALID_ARGUMENT,   /* 7: odometry that is not a rigid transform */
        TOPOLOC_ERR_NON_FINITE,         /* 8: NaN in the odometry */
        TOPOLOC_ERR_STRUCT_SIZE,        /* 9: frame.struct_size 0 */
        TOPOLOC_ERR_STRUCT_SIZE,        /* 10: result.struct_size 0 */
    };
    topoloc_localizer *a = NULL, *b = NULL;
    topoloc_frame good, bad;
    topoloc_result ra, rb, snapshot;
    topoloc_candidate ca[5], cb[5], csnap[5];
    float desc[DIM], bad_desc[DIM + 4];
    double nan = 0.0, odometry[16], bad_odometry[16];
    size_t i, d;

    SECTION();
    rng_seed(3);
    nan = make_nan();
    if (!new_twin_localizers(map, &a, &b)) {
        return;
    }
    memset(ca, 0, sizeof ca);
    memset(cb, 0, sizeof cb);
    CHECK_OK(topoloc_frame_default(&good));
    result_with_candidates(&ra, ca, 5);
    result_with_candidates(&rb, cb, 5);
    memset(odometry, 0, sizeof odometry);
    odometry[0] = odometry[5] = odometry[10] = odometry[15] = 1.0;
    odometry[3] = 1.0;

    for (i = 0; i < FRAMES; i++) {
        uint32_t source = walk[i] * VIEWS_PER_PLACE + (uint32_t)(i % VIEWS_PER_PLACE);
        size_t kind;
        noisy_copy(desc, source, 0.05f);
        good.timestamp = 1.0 + (double)i;
        good.descriptor = desc;
        good.descriptor_len = DIM;
        good.odometry = (i % 3 == 1) ? odometry : NULL;

        /* Before every good frame, A sees one or two bad ones; B never does. */
        for (kind = i % BAD_KINDS; kind < BAD_KINDS; kind += 6) {
            topoloc_status st;
            topoloc_result *target = &ra;
            topoloc_result zero_size;
            bad = good;
            memcpy(bad_desc, desc, sizeof desc);
            bad_desc[DIM] = 1.0f;
            bad.descriptor = bad_desc;
            memcpy(bad_odometry, odometry, sizeof odometry);
            switch (kind) {
            case 0:
                bad.descriptor_len = DIM - 1;
                break;
            case 1:
                bad.descriptor_len = DIM + 1;
                break;
            case 2:
                bad_desc[DIM / 2] = (float)nan;
                break;
            case 3:
                bad_desc[0] = -make_inf();
                break;
            case 4:
                for (d = 0; d < DIM; d++) {
                    bad_desc[d] = 0.0f;
                }
                break;
            case 5:
                bad.timestamp = good.timestamp - 1.5;
                break; /* before the previous frame */
            case 6:
                bad.timestamp = nan;
                break;
            case 7:
                bad_odometry[0] = 1.1; /* scaled, not a rotation */
                bad.odometry = bad_odometry;
                break;
            case 8:
                bad_odometry[7] = nan;
                bad.odometry = bad_odometry;
                break;
            case 9:
                bad.struct_size = 0;
                break;
            case 10:
                zero_size = ra;
                zero_size.struct_size = 0;
                target = &zero_size;
                break;
            default:
                break;
            }
            if (kind == 5 && i == 0) {
                continue; /* the first frame has no predecessor */
            }
            snapshot = ra;
            memcpy(csnap, ca, sizeof csnap);
            st = topoloc_localizer_process(a, &bad, target);
            check_status_impl(st, expected_status[kind], "process(bad frame)", __FILE__, __LINE__);
            if (st != expected_status[kind]) {
                fprintf(stderr, "    (bad frame kind %zu before good frame %zu)\n", kind, i);
            }
            CHECK_HAS_MESSAGE();
            CHECK(identical_result(&snapshot, &ra));
            CHECK(memcmp(csnap, ca, sizeof csnap) == 0);
        }

        CHECK_OK(topoloc_localizer_process(a, &good, &ra));
        CHECK_OK(topoloc_localizer_process(b, &good, &rb));
        CHECK(ra.frame_index == i);
        CHECK(ra.place == walk[i]);
        CHECK(same_result(&ra, &rb));
    }

    /* The same holds across a reset. */
    CHECK_OK(topoloc_localizer_reset(a));
    CHECK_OK(topoloc_localizer_reset(b));
    good.timestamp = 0.5;
    CHECK_OK(topoloc_localizer_process(a, &good, &ra));
    CHECK_OK(topoloc_localizer_process(b, &good, &rb));
    CHECK(ra.frame_index == 0);
    CHECK(same_result(&ra, &rb));
    topoloc_localizer_free(a);
    topoloc_localizer_free(b);
}

static void options_shorter_than_the_first_abi_or_out_of_range_are_refused(const topoloc_map *map)
{
    topoloc_localizer_options options, bad[4];
    topoloc_localizer *loc = NULL;
    size_t i;

    SECTION();
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.struct_size = 0;
    CHECK_ERROR(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_STRUCT_SIZE);
    /* One byte short of the first published (ABI 1.0) layout, which ends before image_backend. */
    options.struct_size = offsetof(topoloc_localizer_options, image_backend) - 1;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK(loc == NULL);

    /* The defaults with one option out of range in each. */
    for (i = 0; i < 4; i++) {
        CHECK_OK(topoloc_localizer_options_default(&bad[i]));
    }
    bad[0].mode = 7;
    bad[1].top_k = 0;
    bad[2].temperature = 0.0f;
    bad[3].stay_probability = 1.5f;
    for (i = 0; i < 4; i++) {
        CHECK_STATUS(topoloc_localizer_new(map, &bad[i], &loc), TOPOLOC_ERR_INVALID_OPTION);
    }
    CHECK_HAS_MESSAGE();
}

static void a_localizer_expecting_another_descriptor_is_refused(const topoloc_map *map)
{
    topoloc_localizer_options options;
    topoloc_localizer *loc = NULL;

    SECTION();
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.expected_descriptor_kind = "another-desc";
    CHECK_ERROR(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    options.expected_descriptor_kind = KIND;
    options.expected_descriptor_model = "another-model";
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    options.expected_descriptor_model = "\xff";
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_INVALID_UTF8);
    CHECK(loc == NULL);
    options.expected_descriptor_model = MODEL;
    CHECK_OK(topoloc_localizer_new(map, &options, &loc));
    topoloc_localizer_free(loc);
}

/* ABI 1.9: off-map evidence from verification; negative = the map's kind's default. */
static void
off_map_evidence_options_are_checked_and_older_callers_get_their_defaults(const topoloc_map *map)
{
    topoloc_localizer_options options;
    topoloc_localizer *loc = NULL;

    SECTION();
    CHECK(topoloc_abi_version_minor() >= 9);
    CHECK_OK(topoloc_localizer_options_default(&options));
    CHECK(options.verify_off_map_inliers == -1.0 && options.verify_off_map_inlier_scale == 4.0);
    options.verify_off_map_inliers = make_nan();
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("off_map_inliers");
    options.verify_off_map_inliers = 30.0;
    options.verify_off_map_inlier_scale = 0.0;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("off_map_inlier_scale");
    CHECK(loc == NULL);
    /* A caller of ABI 1.6 gets the 1.9 defaults: the bad scale beyond its size is ignored. */
    options.struct_size = offsetof(topoloc_localizer_options, verify_off_map_inliers);
    CHECK_OK(topoloc_localizer_new(map, &options, &loc));
    topoloc_localizer_free(loc);
}

/* Particles moved by odometry place a walk along the row of places; a map with a view without a
 * pose (the world's last) is refused, and so are zero particles. */
static void metric_mode_follows_odometry_and_needs_a_pose_for_every_view(const topoloc_map *world)
{
    topoloc_localizer_options options;
    topoloc_localizer *loc = NULL;
    topoloc_map *posed = NULL;
    topoloc_frame frame;
    topoloc_result r;
    float desc[DIM];
    double forward[16] = {1, 0, 0, 2, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    uint32_t p, placed = 0;

    SECTION();
    rng_seed(4);
    CHECK_OK(topoloc_localizer_options_default(&options));
    CHECK(options.metric_particles == 2000 && options.metric_temperature == 1.0f);
    CHECK(options.metric_seed == 0);
    options.mode = TOPOLOC_MODE_METRIC;
    /* The world's last view has no pose. */
    CHECK_STATUS(topoloc_localizer_new(world, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("pose");
    CHECK(loc == NULL);

    posed = build_world(false);
    if (posed == NULL) {
        return;
    }
    options.metric_particles = 0;
    CHECK_STATUS(topoloc_localizer_new(posed, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("metric.particles");
    options.metric_particles = 1000;
    options.metric_seed = 7;
    CHECK_OK(topoloc_localizer_new(posed, &options, &loc));
    if (loc != NULL) {
        /* Along the row of places facing +x (view 0 of each), 2 m of odometry per frame. */
        CHECK_OK(topoloc_frame_default(&frame));
        CHECK_OK(topoloc_result_default(&r));
        for (p = 0; p < PLACES; p++) {
            noisy_copy(desc, p * VIEWS_PER_PLACE, 0.3f);
            frame.timestamp = (double)p;
            frame.descriptor = desc;
            frame.descriptor_len = DIM;
            frame.odometry = p > 0 ? forward : NULL;
            CHECK_OK(topoloc_localizer_process(loc, &frame, &r));
            placed += r.place == p;
        }
        printf("   metric walk: %u of %u places right\n", (unsigned)placed, (unsigned)PLACES);
        CHECK(placed >= PLACES - 1);
        topoloc_localizer_free(loc);
        loc = NULL;
    }
    /* A caller of ABI 1.2 gets the metric defaults. */
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.mode = TOPOLOC_MODE_METRIC;
    options.struct_size = offsetof(topoloc_localizer_options, metric_particles);
    options.metric_particles = 0; /* beyond its size: ignored */
    CHECK_OK(topoloc_localizer_new(posed, &options, &loc));
    topoloc_localizer_free(loc);
    topoloc_map_free(posed);
}

/* The learned mode's options are checked before ONNX Runtime is loaded: a map without edges
 * and a model file that does not exist are refused naming the problem; a caller of ABI 1.15
 * (no grnn_model_path) gets the built-in model. */
static void grnn_mode_refuses_a_map_without_graph_and_a_missing_model(const topoloc_map *world)
{
    topoloc_localizer_options options;
    topoloc_localizer *loc = NULL;
    topoloc_map_builder *b = NULL;
    topoloc_map *bare = NULL;
    uint32_t id = 0;
    CHECK(topoloc_abi_version_minor() >= 16);
    CHECK_OK(topoloc_localizer_options_default(&options));
    CHECK(options.grnn_model_path == NULL);
    options.mode = TOPOLOC_MODE_GRNN;
    options.grnn_model_path = "/nonexistent/grnn.onnx";
    CHECK_STATUS(topoloc_localizer_new(world, &options, &loc), TOPOLOC_ERR_BACKEND_UNAVAILABLE);
    CHECK_MESSAGE_HAS("/nonexistent/grnn.onnx");
    CHECK(loc == NULL);

    CHECK_OK(topoloc_map_builder_new(KIND, MODEL, DIM, &b));
    if (b == NULL) {
        return;
    }
    CHECK_OK(topoloc_map_builder_add_place(b, NULL, &id));
    CHECK_OK(topoloc_map_builder_add_view(b, 0, g_view_desc[0], DIM, NULL, &id));
    CHECK_OK(topoloc_map_builder_build(b, &bare));
    topoloc_map_builder_free(b);
    options.grnn_model_path = NULL;
    CHECK_STATUS(topoloc_localizer_new(bare, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("no graph");
    CHECK(loc == NULL);
    /* A caller of ABI 1.15: the path lies beyond its struct and is not read. */
    options.struct_size = offsetof(topoloc_localizer_options, grnn_model_path);
    options.grnn_model_path = "/nonexistent/grnn.onnx";
    CHECK_STATUS(topoloc_localizer_new(bare, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("no graph");
    topoloc_map_free(bare);
}

void run_localizer_tests(const topoloc_map *world)
{
    single_frame_mode_answers_each_frame_as_a_fresh_localizer_would();
    the_localizer_refuses_null_arguments_naming_them_and_counts_no_frame(world);
    bad_frames_leave_the_localizer_and_the_result_unchanged(world);
    options_shorter_than_the_first_abi_or_out_of_range_are_refused(world);
    a_localizer_expecting_another_descriptor_is_refused(world);
    off_map_evidence_options_are_checked_and_older_callers_get_their_defaults(world);
    metric_mode_follows_odometry_and_needs_a_pose_for_every_view(world);
    grnn_mode_refuses_a_map_without_graph_and_a_missing_model(world);
}
