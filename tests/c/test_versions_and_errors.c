/*
 * Section "Versions and errors" of topoloc.h, and the conventions every section follows: the
 * version strings and ABI version, status codes and their names, the thread's last error
 * message (its size, a buffer too small, a NULL buffer), _free(NULL), and versioned structs
 * (_init sizes; callers built against an older or a newer header, whose struct_size is smaller
 * or larger than this library's).
 */
#include "harness.h"

static void the_version_and_the_abi_version_match_the_header(void)
{
    char composed[64];
    SECTION();
    CHECK(topoloc_version() != NULL);
    CHECK(strcmp(topoloc_version(), TOPOLOC_VERSION_STRING) == 0);
    snprintf(composed, sizeof composed, "%d.%d.%d", TOPOLOC_VERSION_MAJOR, TOPOLOC_VERSION_MINOR,
             TOPOLOC_VERSION_PATCH);
    CHECK(strcmp(composed, TOPOLOC_VERSION_STRING) == 0);
    CHECK(topoloc_version() == topoloc_version()); /* static string */
    CHECK(topoloc_abi_version() == TOPOLOC_ABI_VERSION);
    CHECK(TOPOLOC_OK == 0);
}

static void every_status_has_its_own_name_and_unknown_codes_say_so(void)
{
    static const uint32_t known[] = {
        TOPOLOC_OK,
        TOPOLOC_ERR_NULL_ARGUMENT,
        TOPOLOC_ERR_INVALID_ARGUMENT,
        TOPOLOC_ERR_BUFFER_TOO_SMALL,
        TOPOLOC_ERR_STRUCT_SIZE,
        TOPOLOC_ERR_INVALID_UTF8,
        TOPOLOC_ERR_IO,
        TOPOLOC_ERR_NOT_A_MAP,
        TOPOLOC_ERR_TRUNCATED,
        TOPOLOC_ERR_CORRUPT,
        TOPOLOC_ERR_UNSUPPORTED_VERSION,
        TOPOLOC_ERR_DESCRIPTOR_MISMATCH,
        TOPOLOC_ERR_EMPTY_MAP,
        TOPOLOC_ERR_INVALID_MAP,
        TOPOLOC_ERR_UNKNOWN_PLACE,
        TOPOLOC_ERR_UNKNOWN_VIEW,
        TOPOLOC_ERR_DIMENSION_MISMATCH,
        TOPOLOC_ERR_NON_FINITE,
        TOPOLOC_ERR_ZERO_DESCRIPTOR,
        TOPOLOC_ERR_TIMESTAMP,
        TOPOLOC_ERR_INVALID_OPTION,
        TOPOLOC_ERR_INVALID_IMAGE,
        TOPOLOC_ERR_UNINFORMATIVE_IMAGE,
        TOPOLOC_ERR_BACKEND_UNAVAILABLE,
        TOPOLOC_ERR_MODEL,
        TOPOLOC_ERR_NO_DESCRIBER,
        TOPOLOC_ERR_CANCELLED,
        TOPOLOC_ERR_CONCURRENT_USE,
        TOPOLOC_ERR_PANIC,
    };
    static const uint32_t unknown[] = {7u,   99u,  110u, 199u,   205u,       299u,
                                       306u, 899u, 901u, 65536u, 0xFFFFFFFFu};
    const size_t n_known = sizeof known / sizeof known[0];
    size_t i, j;
    SECTION();
    /* Values are part of the ABI: they never change. */
    CHECK(TOPOLOC_ERR_NULL_ARGUMENT == 1 && TOPOLOC_ERR_IO == 100 && TOPOLOC_ERR_CORRUPT == 103 &&
          TOPOLOC_ERR_DIMENSION_MISMATCH == 200 && TOPOLOC_ERR_PANIC == 900);
    for (i = 0; i < n_known; i++) {
        const char *s = topoloc_status_str(known[i]);
        CHECK(s != NULL && s[0] != '\0');
        CHECK(s != NULL && strcmp(s, "unknown status code") != 0);
        for (j = 0; j < i; j++) {
            CHECK(s != NULL && strcmp(s, topoloc_status_str(known[j])) != 0);
        }
    }
    CHECK(strcmp(topoloc_status_str(TOPOLOC_OK), "ok") == 0);
    CHECK(strcmp(topoloc_status_str(TOPOLOC_ERR_CORRUPT), "corrupt map file") == 0);
    for (i = 0; i < sizeof unknown / sizeof unknown[0]; i++) {
        const char *s = topoloc_status_str(unknown[i]);
        CHECK(s != NULL && strcmp(s, "unknown status code") == 0);
    }
}

static void
the_last_error_message_says_how_long_it_is_and_is_written_only_whole(const topoloc_map *map)
{
    char buf[256];
    size_t needed = 0, count = 0, len;
    uint32_t ids[1] = {4242};

    SECTION();
    CHECK_STATUS(topoloc_map_neighbours(map, 999, ids, 1, &count), TOPOLOC_ERR_UNKNOWN_PLACE);
    needed = 0;
    CHECK_STATUS(topoloc_last_error_message(NULL, 0, &needed), TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(needed > 1);
    len = needed;
    memset(buf, 'z', sizeof buf);
    needed = 0;
    CHECK_STATUS(topoloc_last_error_message(buf, len - 1, &needed), TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(needed == len);
    CHECK(buf[0] == 'z' && buf[len - 2] == 'z'); /* nothing written */
    CHECK_STATUS(topoloc_last_error_message(buf, 1, NULL), TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(len <= sizeof buf);
    CHECK_OK(topoloc_last_error_message(buf, len, &needed)); /* exact fit */
    CHECK(needed == len && strlen(buf) == len - 1);
    CHECK(strstr(buf, "999") != NULL);
    CHECK(strcmp(buf, last_error()) == 0); /* reading it does not change it */
}

static void a_null_message_buffer_with_room_claimed_is_refused_and_the_message_kept(void)
{
    char before[512];
    SECTION();
    snprintf(before, sizeof before, "%s", last_error());
    CHECK(topoloc_last_error_message(NULL, 100, NULL) == TOPOLOC_ERR_NULL_ARGUMENT);
    CHECK(strcmp(before, last_error()) == 0);
}

static void freeing_a_null_handle_does_nothing(void)
{
    SECTION();
    topoloc_map_builder_free(NULL);
    topoloc_map_free(NULL);
    topoloc_localizer_free(NULL);
    CHECK(true);
}

/* One of each versioned struct of the maps, the builder and the localizer. */
struct versioned_structs {
    topoloc_frame frame;
    topoloc_result result;
    topoloc_localizer_options options;
    topoloc_keyframe_options kf_options;
    topoloc_map_load_options load_options;
    topoloc_view_attributes attributes;
    topoloc_view_info info;
};

static void defaults_fill_each_versioned_struct_and_its_size(void)
{
    struct versioned_structs v;

    SECTION();
    CHECK_OK(topoloc_frame_default(&v.frame));
    CHECK(v.frame.struct_size == sizeof v.frame && v.frame.timestamp == 0.0);
    CHECK_OK(topoloc_result_default(&v.result));
    CHECK(v.result.struct_size == sizeof v.result && v.result.candidates_len == 0);
    CHECK_OK(topoloc_localizer_options_default(&v.options));
    CHECK(v.options.struct_size == sizeof v.options);
    CHECK(v.options.temperature > 0.0f && v.options.stay_probability > 0.0f);
    CHECK_OK(topoloc_keyframe_options_default(&v.kf_options));
    CHECK(v.kf_options.struct_size == sizeof v.kf_options &&
          v.kf_options.neighbour_radius_m == 3.0);
    CHECK_OK(topoloc_map_load_options_default(&v.load_options));
    CHECK(v.load_options.struct_size == sizeof v.load_options);
    CHECK_OK(topoloc_view_attributes_default(&v.attributes));
    CHECK(v.attributes.struct_size == sizeof v.attributes);
    CHECK_OK(topoloc_view_info_default(&v.info));
    CHECK(v.info.struct_size == sizeof v.info && !v.info.has_pose && !v.info.has_keyframe_id);
}

static void sizes_below_the_first_published_layout_are_refused_and_nothing_written(void)
{
    struct versioned_structs v;

    SECTION();
    memset(&v.frame, 0x5A, sizeof v.frame);
    CHECK_ERROR(topoloc_frame_init(&v.frame, 0), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK(all_bytes((const unsigned char *)&v.frame, sizeof v.frame, 0x5A));
    /* The first published (ABI 1.0) frame ends before `image`. */
    CHECK_STATUS(topoloc_frame_init(&v.frame, offsetof(topoloc_frame, image) - 1),
                 TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_localizer_options_init(
                     &v.options, offsetof(topoloc_localizer_options, image_backend) - 1),
                 TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_result_init(&v.result, sizeof(size_t)), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_localizer_options_init(&v.options, 1), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_keyframe_options_init(&v.kf_options, 0), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_map_load_options_init(&v.load_options, 0), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_view_attributes_init(&v.attributes, 0), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_view_info_init(&v.info, 0), TOPOLOC_ERR_STRUCT_SIZE);
}

/* A newer caller's larger struct: the library fills what it knows, says so in struct_size, and
 * never writes past it; on input the caller's appended (zeroed) fields are ignored, on output the
 * caller's size is kept. */
static void larger_structs_of_a_newer_caller_are_filled_only_as_far_as_this_library_knows(
    const topoloc_map *map)
{
    /* What a caller compiled against a newer header (with appended fields) looks like. */
    struct newer_frame {
        topoloc_frame f;
        unsigned char tail[64];
    } nf;
    struct newer_result {
        topoloc_result r;
        unsigned char tail[64];
    } nr;
    struct newer_info {
        topoloc_view_info i;
        unsigned char tail[64];
    } ni;
    struct newer_options {
        topoloc_localizer_options o;
        unsigned char tail[64];
    } no;
    topoloc_localizer *loc = NULL;
    float desc[DIM];

    SECTION();
    memset(&nf, 0xEE, sizeof nf);
    CHECK_OK(topoloc_frame_init(&nf.f, sizeof nf));
    CHECK(nf.f.struct_size == sizeof(topoloc_frame));
    CHECK(nf.f.descriptor == NULL && nf.f.odometry == NULL && nf.f.descriptor_len == 0);
    CHECK(all_bytes(nf.tail, sizeof nf.tail, 0xEE));
    memset(&no, 0xEE, sizeof no);
    CHECK_OK(topoloc_localizer_options_init(&no.o, sizeof no));
    CHECK(no.o.struct_size == sizeof(topoloc_localizer_options));
    CHECK(all_bytes(no.tail, sizeof no.tail, 0xEE));

    /* Larger struct_size on input (options, frame) and output (result, view info). */
    no.o.struct_size = sizeof no;
    memset(no.tail, 0, sizeof no.tail); /* a newer caller's appended fields, zeroed */
    CHECK_OK(topoloc_localizer_new(map, &no.o, &loc));
    if (loc != NULL) {
        memcpy(desc, g_view_desc[6], sizeof desc);
        nf.f.struct_size = sizeof nf;
        nf.f.descriptor = desc;
        nf.f.descriptor_len = DIM;
        memset(&nr, 0xEE, sizeof nr);
        nr.r.struct_size = sizeof nr;
        nr.r.candidates = NULL;
        nr.r.candidates_capacity = 0;
        CHECK_OK(topoloc_localizer_process(loc, &nf.f, &nr.r));
        CHECK(nr.r.struct_size == sizeof nr); /* the caller's size is kept */
        CHECK(nr.r.place == 1 && nr.r.view == 6 && nr.r.frame_index == 0);
        CHECK(nr.r.candidates_len == 0);
        CHECK(all_bytes(nr.tail, sizeof nr.tail, 0xEE));

        /* A result whose struct_size is too small is refused, untouched. */
        nr.r.struct_size = sizeof(topoloc_result) - 2; /* cuts the last field */
        nr.r.place = 4242;
        CHECK_STATUS(topoloc_localizer_process(loc, &nf.f, &nr.r), TOPOLOC_ERR_STRUCT_SIZE);
        CHECK(nr.r.place == 4242);
        /* So is a frame. */
        nf.f.struct_size = 4;
        nr.r.struct_size = sizeof nr;
        CHECK_STATUS(topoloc_localizer_process(loc, &nf.f, &nr.r), TOPOLOC_ERR_STRUCT_SIZE);
        CHECK(nr.r.place == 4242);
        /* Neither counted as a frame. */
        nf.f.struct_size = sizeof(topoloc_frame);
        nr.r.struct_size = sizeof(topoloc_result);
        CHECK_OK(topoloc_localizer_process(loc, &nf.f, &nr.r));
        CHECK(nr.r.frame_index == 1);
    }
    topoloc_localizer_free(loc);

    memset(&ni, 0xEE, sizeof ni);
    ni.i.struct_size = sizeof ni;
    CHECK_OK(topoloc_map_view_info(map, 5, &ni.i));
    CHECK(ni.i.struct_size == sizeof ni);
    CHECK(ni.i.place == 1 && ni.i.has_keyframe_id && ni.i.keyframe_id == 1005u);
    CHECK(all_bytes(ni.tail, sizeof ni.tail, 0xEE));
}

void run_versions_and_errors_tests(const topoloc_map *world)
{
    the_version_and_the_abi_version_match_the_header();
    every_status_has_its_own_name_and_unknown_codes_say_so();
    the_last_error_message_says_how_long_it_is_and_is_written_only_whole(world);
    a_null_message_buffer_with_room_claimed_is_refused_and_the_message_kept();
    freeing_a_null_handle_does_nothing();
    defaults_fill_each_versioned_struct_and_its_size();
    sizes_below_the_first_published_layout_are_refused_and_nothing_written();
    larger_structs_of_a_newer_caller_are_filled_only_as_far_as_this_library_knows(world);
}
