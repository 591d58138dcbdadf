/*
 * Images: maps built from images (the image part of section "Building maps" of topoloc.h) and
 * image frames given to the localizer. Maps are built with the VLAD backend from the grey places
 * of harness.h (no model needed), in memory and from PGM files, with a small codebook and one
 * describing thread so that the section stays fast under valgrind: progress and cancellation,
 * revisits localized in every pixel format, backends asked for or refused, an ABI 1.0-sized
 * frame, geometric verification, pose fixes from the host's scene points, bad and uninformative
 * images, and bad files. The ONNX checks that need the model run only when
 * scripts/setup-models.sh has installed it, and not under valgrind.
 */
#include "harness.h"

#include <pthread.h>
#include <stdlib.h>
#include <unistd.h>

#define IMG_CLUSTERS 16u
#define IMG_FILES 4u

/* A grey image repacked as `channels` channels (alpha 255) in rows of `stride` bytes (padding
 * filled with 0xAB); malloc'd into *buffer. */
static topoloc_image repack(const uint8_t *px, uint32_t format, uint32_t channels, size_t stride,
                            uint8_t **buffer)
{
    topoloc_image image = gray_image(px);
    size_t len = stride * (IMG_H - 1) + (size_t)IMG_W * channels;
    uint32_t x, y, c;
    *buffer = malloc(len);
    if (*buffer == NULL) {
        image.data = NULL;
        return image;
    }
    memset(*buffer, 0xAB, len);
    for (y = 0; y < IMG_H; y++) {
        for (x = 0; x < IMG_W; x++) {
            for (c = 0; c < channels; c++) {
                (*buffer)[y * stride + x * channels + c] = c == 3 ? 255 : px[y * IMG_W + x];
            }
        }
    }
    image.data = *buffer;
    image.data_len = len;
    image.stride = stride;
    image.format = format;
    return image;
}

/* Image map options for `images` images: VLAD-ORB with ORB keypoints (no learned weights, so
 * no ONNX Runtime under valgrind), dim images - 1, one thread, a small codebook (one check). */
static void vlad_options(topoloc_image_map_options *options, uint32_t images)
{
    CHECK_OK(topoloc_image_map_options_default(options));
    options->backend = TOPOLOC_BACKEND_VLAD_ORB;
    options->dim = images - 1;
    options->threads = 1;
    options->vlad_clusters = IMG_CLUSTERS;
    options->local_features = TOPOLOC_LOCAL_FEATURES_ORB;
}

/* What a progress callback saw. */
struct progress_log {
    pthread_t caller;
    int cancel_stage; /* stage at which to return false; -1 = never */
    size_t expected_total;
    unsigned calls;
    unsigned calls_after_cancel;
    bool cancelled;
    bool first_is_describing;
    bool saw_describing_all; /* DESCRIBING with done == total == expected_total */
    bool saw_fitting;
    bool saw_fitting_done; /* FITTING 1 of 1 */
    bool last_is_fitting_done;
    bool bad_values; /* unknown stage, done > total, wrong total, or going back */
    bool other_thread;
    uint32_t last_stage;
    size_t last_done;
};

static void progress_log_init(struct progress_log *log, int cancel_stage, size_t expected_total)
{
    memset(log, 0, sizeof *log);
    log->caller = pthread_self();
    log->cancel_stage = cancel_stage;
    log->expected_total = expected_total;
}

static bool record_progress(void *user_data, uint32_t stage, size_t done, size_t total)
{
    struct progress_log *log = user_data;
    if (log->calls == 0) {
        log->first_is_describing = stage == TOPOLOC_STAGE_DESCRIBING;
    } else if (stage < log->last_stage || (stage == log->last_stage && done < log->last_done)) {
        log->bad_values = true; /* progress goes forward only */
    }
    log->calls++;
    if (!pthread_equal(pthread_self(), log->caller)) {
        log->other_thread = true;
    }
    if (done > total || (stage == TOPOLOC_STAGE_DESCRIBING && total != log->expected_total) ||
        (stage == TOPOLOC_STAGE_FITTING && total != 1) || stage > TOPOLOC_STAGE_FITTING) {
        log->bad_values = true;
    }
    if (stage == TOPOLOC_STAGE_DESCRIBING && done == total && total == log->expected_total) {
        log->saw_describing_all = true;
    }
    if (stage == TOPOLOC_STAGE_FITTING) {
        log->saw_fitting = true;
        log->saw_fitting_done = log->saw_fitting_done || (done == 1 && total == 1);
    }
    log->last_is_fitting_done = stage == TOPOLOC_STAGE_FITTING && done == 1 && total == 1;
    log->last_stage = stage;
    log->last_done = done;
    if (log->cancelled) {
        log->calls_after_cancel++;
        return false;
    }
    if ((int)stage == log->cancel_stage) {
        log->cancelled = true;
        return false;
    }
    return true;
}

/* A value no library writes: shows that an out-parameter was left alone. */
static topoloc_map *untouched_map(void)
{
    static char marker;
    return (topoloc_map *)(void *)&marker;
}

/* Localizes `image` with `loc` at time `t`; returns the status. */
static topoloc_status localize_image(topoloc_localizer *loc, const topoloc_image *image, double t,
                                     topoloc_result *result)
{
    topoloc_frame frame;
    topoloc_frame_default(&frame);
    frame.timestamp = t;
    frame.image = *image;
    return topoloc_localizer_process(loc, &frame, result);
}

/* A localizer made with `options` localizes one image of `place` there (one check per step). */
static void check_new_localizer_finds(const topoloc_map *map,
                                      const topoloc_localizer_options *options, const uint8_t *px,
                                      uint32_t place)
{
    topoloc_localizer *loc = NULL;
    topoloc_image image = gray_image(px);
    topoloc_result r;
    topoloc_result_default(&r);
    CHECK_OK(topoloc_localizer_new(map, options, &loc));
    if (loc != NULL) {
        CHECK_OK(localize_image(loc, &image, 0.0, &r));
        CHECK(r.place == place);
    }
    topoloc_localizer_free(loc);
}

/* A single-frame localizer on `map` (one check for the options, one for the localizer). */
static topoloc_status new_single_frame_localizer(const topoloc_map *map, topoloc_localizer **loc)
{
    topoloc_localizer_options options;
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.mode = TOPOLOC_MODE_SINGLE_FRAME;
    return topoloc_localizer_new(map, &options, loc);
}

/* ------------------------------------------------------------------------------------------ */
/* Constants, defaults and old layouts                                                         */
/* ------------------------------------------------------------------------------------------ */

static void image_constants_and_the_defaults_of_the_image_structs_are_part_of_the_abi(void)
{
    topoloc_image_map_options options;
    topoloc_localizer_options lo;
    topoloc_frame frame;

    SECTION();
    CHECK(TOPOLOC_PIXEL_NONE == 0 && TOPOLOC_PIXEL_GRAY8 == 1 && TOPOLOC_PIXEL_RGB8 == 2 &&
          TOPOLOC_PIXEL_BGR8 == 3 && TOPOLOC_PIXEL_RGBA8 == 4 && TOPOLOC_PIXEL_BGRA8 == 5);
    CHECK(TOPOLOC_BACKEND_AUTO == 0 && TOPOLOC_BACKEND_NONE == 1 && TOPOLOC_BACKEND_ONNX == 2 &&
          TOPOLOC_BACKEND_VLAD_ORB == 3 && TOPOLOC_BACKEND_VLAD_SIFT == 4);
    CHECK(TOPOLOC_STAGE_DESCRIBING == 0 && TOPOLOC_STAGE_FITTING == 1);
    CHECK(TOPOLOC_ERR_INVALID_IMAGE == 300 && TOPOLOC_ERR_UNINFORMATIVE_IMAGE == 301 &&
          TOPOLOC_ERR_BACKEND_UNAVAILABLE == 302 && TOPOLOC_ERR_MODEL == 303 &&
          TOPOLOC_ERR_NO_DESCRIBER == 304 && TOPOLOC_ERR_CANCELLED == 305);
    /* The frame's image is appended after the ABI 1.0 fields. */
    CHECK(offsetof(topoloc_frame, image) > offsetof(topoloc_frame, odometry));
    CHECK(offsetof(topoloc_localizer_options, image_backend) >
          offsetof(topoloc_localizer_options, expected_descriptor_model));

    memset(&frame, 0x5A, sizeof frame);
    CHECK_OK(topoloc_frame_default(&frame));
    CHECK(frame.image.data == NULL && frame.image.data_len == 0 && frame.image.width == 0 &&
          frame.image.height == 0 && frame.image.stride == 0 &&
          frame.image.format == TOPOLOC_PIXEL_NONE);

    memset(&lo, 0x5A, sizeof lo);
    CHECK_OK(topoloc_localizer_options_default(&lo));
    CHECK(lo.image_backend == TOPOLOC_BACKEND_AUTO);
    CHECK(lo.onnx_model_path == NULL && lo.onnx_runtime_path == NULL);

    memset(&options, 0x5A, sizeof options);
    CHECK_OK(topoloc_image_map_options_default(&options));
    CHECK(options.struct_size == sizeof options);
    CHECK(options.backend == TOPOLOC_BACKEND_AUTO);
    CHECK(options.dim == 512 && options.views_per_place == 1 && options.threads == 0);
    CHECK(options.grid_rows == 4 && options.grid_cols == 4 && options.vlad_clusters == 64);
    CHECK(options.onnx_model_path == NULL && options.onnx_runtime_path == NULL &&
          options.onnx_taps == NULL && options.poses_tum_path == NULL);
    CHECK(options.place_spacing_m == 2.0);
    /* ABI 1.14: the PCA rows' storage, i8 by default; a caller of the 1.13 layout gets it. */
    CHECK(TOPOLOC_PCA_I8 == 0 && TOPOLOC_PCA_F32 == 1);
    CHECK(options.pca_precision == TOPOLOC_PCA_I8);
    CHECK(offsetof(topoloc_image_map_options, pca_precision) >
          offsetof(topoloc_image_map_options, place_spacing_m));
    options.pca_precision = 77;
    CHECK_OK(topoloc_image_map_options_init(&options,
                                            offsetof(topoloc_image_map_options, pca_precision)));
    CHECK(options.pca_precision == 77); /* beyond the older layout: not written */
    CHECK_ERROR(topoloc_image_map_options_init(&options, 0), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_image_map_options_init(&options, sizeof options - 1),
                 TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_NULL(topoloc_image_map_options_init(NULL, sizeof options), "options");
}

/* The ABI 1.0 layout of topoloc_frame, followed by bytes that would be an invalid image if they
 * were read: it localizes descriptors, and its struct_size is checked against that layout. */
static void a_frame_of_the_first_abi_without_an_image_field_still_localizes_descriptors(
    const topoloc_map *world)
{
    struct frame_1_0 {
        size_t struct_size;
        double timestamp;
        const float *descriptor;
        size_t descriptor_len;
        const double *odometry;
    };
    union {
        struct frame_1_0 f;
        unsigned char bytes[sizeof(topoloc_frame) + 16];
    } old;
    topoloc_localizer *loc = NULL;
    topoloc_result r;
    float desc[DIM];

    SECTION();
    rng_seed(6);
    CHECK(sizeof(struct frame_1_0) == offsetof(topoloc_frame, image));
    memset(&old, 0xEE, sizeof old);
    CHECK_OK(topoloc_frame_init((topoloc_frame *)(void *)&old.f, sizeof old.f));
    CHECK(old.f.struct_size == sizeof old.f);
    CHECK(all_bytes(old.bytes + sizeof old.f, sizeof old.bytes - sizeof old.f, 0xEE));
    CHECK_STATUS(topoloc_frame_init((topoloc_frame *)(void *)&old.f, sizeof old.f - 1),
                 TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_OK(topoloc_localizer_new(world, NULL, &loc));
    if (loc == NULL) {
        return;
    }
    CHECK_OK(topoloc_result_default(&r));
    noisy_copy(desc, 9, 0.05f);
    old.f.timestamp = 1.0;
    old.f.descriptor = desc;
    old.f.descriptor_len = DIM;
    old.f.odometry = NULL;
    CHECK_OK(topoloc_localizer_process(loc, (const topoloc_frame *)(const void *)&old.f, &r));
    CHECK(r.place == 2 && r.frame_index == 0);
    old.f.struct_size = sizeof old.f - 1;
    CHECK_STATUS(topoloc_localizer_process(loc, (const topoloc_frame *)(const void *)&old.f, &r),
                 TOPOLOC_ERR_STRUCT_SIZE);
    old.f.struct_size = sizeof old.f;
    old.f.timestamp = 2.0;
    CHECK_OK(topoloc_localizer_process(loc, (const topoloc_frame *)(const void *)&old.f, &r));
    CHECK(r.frame_index == 1);
    topoloc_localizer_free(loc);
}

/* ------------------------------------------------------------------------------------------ */
/* A map from images in memory                                                                 */
/* ------------------------------------------------------------------------------------------ */

/* Cancelled while describing, or when fitting starts (every image described): no map. */
static void building_from_images_can_be_cancelled_while_describing_or_when_fitting(
    const topoloc_image *images, const topoloc_image_map_options *options)
{
    struct progress_log log;
    topoloc_map *out;

    SECTION();
    progress_log_init(&log, TOPOLOC_STAGE_DESCRIBING, IMG_PLACES);
    out = untouched_map();
    CHECK_ERROR(
        topoloc_map_build_from_images(images, IMG_PLACES, options, record_progress, &log, &out),
        TOPOLOC_ERR_CANCELLED);
    CHECK(out == untouched_map());
    CHECK(log.cancelled && log.calls >= 1 && !log.other_thread);
    CHECK(!log.saw_fitting); /* nothing after the describing stage */

    progress_log_init(&log, TOPOLOC_STAGE_FITTING, IMG_PLACES);
    CHECK_STATUS(
        topoloc_map_build_from_images(images, IMG_PLACES, options, record_progress, &log, &out),
        TOPOLOC_ERR_CANCELLED);
    CHECK(out == untouched_map());
    CHECK(log.cancelled && log.saw_describing_all && log.saw_fitting && !log.saw_fitting_done);
}

/* A sequence map: one place per image, chained, views know their image's index; progress is
 * reported on the caller's thread, forward only, describing then fitting. Returns the map, and
 * its descriptor kind and model in `kind` (64 bytes) and `model` (512 bytes). */
static topoloc_map *a_map_from_images_has_a_place_per_image_and_reports_its_progress(
    const topoloc_image *images, const topoloc_image_map_options *options, char *kind, char *model)
{
    struct progress_log log;
    topoloc_map *built = NULL;
    uint32_t i, dim = 0;

    SECTION();
    progress_log_init(&log, -1, IMG_PLACES);
    CHECK_OK(
        topoloc_map_build_from_images(images, IMG_PLACES, options, record_progress, &log, &built));
    if (built == NULL) {
        return NULL;
    }
    CHECK(log.calls >= 3);
    CHECK(log.first_is_describing);
    CHECK(log.saw_describing_all);
    CHECK(log.saw_fitting && log.saw_fitting_done && log.last_is_fitting_done);
    CHECK(!log.bad_values);
    CHECK(!log.other_thread); /* called on the caller's thread */
    CHECK(log.calls_after_cancel == 0);

    CHECK_COUNTS(built, IMG_PLACES, IMG_PLACES, IMG_PLACES - 1);
    CHECK_OK(topoloc_map_descriptor_dim(built, &dim));
    CHECK(dim == IMG_PLACES - 1);
    CHECK_OK(topoloc_map_descriptor_kind(built, kind, 64, NULL));
    CHECK(strcmp(kind, "vlad-orb") == 0);
    CHECK_OK(topoloc_map_descriptor_model(built, model, 512, NULL));
    CHECK(strstr(model, "/i8 fit=") != NULL); /* i8 PCA rows by default */
    for (i = 0; i < IMG_PLACES; i++) {
        topoloc_view_info info;
        char image[16];
        CHECK_OK(topoloc_view_info_default(&info));
        CHECK_OK(topoloc_map_view_info(built, i, &info));
        CHECK(info.place == i && info.has_keyframe_id && info.keyframe_id == i && !info.has_pose);
        CHECK_OK(topoloc_map_view_image(built, i, image, sizeof image, NULL));
        CHECK(image[0] == '\0'); /* pixels have no path */
    }
    return built;
}

static void
two_threads_and_no_progress_callback_build_the_same_map(const topoloc_image *images,
                                                        const topoloc_image_map_options *vlad,
                                                        const topoloc_map *built, const char *model)
{
    topoloc_image_map_options options = *vlad;
    topoloc_map *again = NULL;
    char model2[512];
    float a[IMG_PLACES], b[IMG_PLACES];

    SECTION();
    options.threads = 2;
    CHECK_OK(topoloc_map_build_from_images(images, IMG_PLACES, &options, NULL, NULL, &again));
    if (again == NULL) {
        return;
    }
    CHECK_OK(topoloc_map_view_descriptor(built, 3, a, IMG_PLACES));
    CHECK_OK(topoloc_map_view_descriptor(again, 3, b, IMG_PLACES));
    CHECK(memcmp(a, b, sizeof(float) * (IMG_PLACES - 1)) == 0); /* deterministic */
    CHECK_OK(topoloc_map_descriptor_model(again, model2, sizeof model2, NULL));
    CHECK(strcmp(model, model2) == 0);
    topoloc_map_free(again);
}

/* f32 PCA rows on request make another describer (another model identity); an unknown
 * precision is refused. */
static void pca_rows_in_f32_are_another_describer_and_unknown_precisions_are_refused(
    const topoloc_image *images, const topoloc_image_map_options *vlad, const char *model)
{
    topoloc_image_map_options options = *vlad;
    topoloc_map *map = NULL, *out;
    char model2[512];

    SECTION();
    options.pca_precision = TOPOLOC_PCA_F32;
    CHECK_OK(topoloc_map_build_from_images(images, IMG_PLACES, &options, NULL, NULL, &map));
    if (map != NULL) {
        CHECK_OK(topoloc_map_descriptor_model(map, model2, sizeof model2, NULL));
        CHECK(strstr(model2, "/i8") == NULL && strcmp(model, model2) != 0);
        topoloc_map_free(map);
    }
    options.pca_precision = 2;
    out = untouched_map();
    CHECK_STATUS(topoloc_map_build_from_images(images, IMG_PLACES, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("pca_precision");
    CHECK(out == untouched_map());
}

/* Saved and loaded, the map keeps its describer; it is memory-mapped, so unlinking the file keeps
 * it readable (POSIX). Frees `built`; returns the loaded map, or NULL. */
static topoloc_map *
the_describer_survives_the_file_and_the_file_may_go_once_loaded(topoloc_map *built,
                                                                const char *kind, const char *model)
{
    topoloc_map *loaded = NULL;
    char path[4200], kind2[64], model2[512];
    size_t n = 0;

    SECTION();
    tmp_path(path, sizeof path, "images.topoloc");
    CHECK_OK(topoloc_map_save(built, path));
    CHECK_OK(topoloc_map_load(path, NULL, &loaded));
    if (loaded != NULL) {
        CHECK_OK(topoloc_map_descriptor_kind(loaded, kind2, sizeof kind2, NULL));
        CHECK_OK(topoloc_map_descriptor_model(loaded, model2, sizeof model2, NULL));
        CHECK(strcmp(kind, kind2) == 0 && strcmp(model, model2) == 0);
        CHECK_OK(topoloc_map_place_count(loaded, &n));
        CHECK(n == IMG_PLACES);
    }
    CHECK(unlink(path) == 0);
    topoloc_map_free(built);
    return loaded;
}

/* Builds the map of the IMG_PLACES grey places (checking it on the way): the map the rest of
 * this section and the describers use, or NULL. */
static topoloc_map *image_map(void)
{
    topoloc_image images[IMG_PLACES];
    topoloc_image_map_options options;
    topoloc_map *built;
    char kind[64], model[512];
    uint32_t i;

    for (i = 0; i < IMG_PLACES; i++) {
        images[i] = gray_image(g_place_px[i]);
    }
    vlad_options(&options, IMG_PLACES);
    building_from_images_can_be_cancelled_while_describing_or_when_fitting(images, &options);
    built = a_map_from_images_has_a_place_per_image_and_reports_its_progress(images, &options, kind,
                                                                             model);
    if (built == NULL) {
        return NULL;
    }
    two_threads_and_no_progress_callback_build_the_same_map(images, &options, built, model);
    pca_rows_in_f32_are_another_describer_and_unknown_precisions_are_refused(images, &options,
                                                                             model);
    return the_describer_survives_the_file_and_the_file_may_go_once_loaded(built, kind, model);
}

/* ------------------------------------------------------------------------------------------ */
/* Image frames                                                                                */
/* ------------------------------------------------------------------------------------------ */

/* Revisits of the image places, shared by the image frame checks. */
static uint8_t g_revisit[IMG_PLACES][IMG_PIXELS];

/* AUTO (NULL options too) loads the map's describer. */
static void revisits_find_their_place_in_single_frame_and_filter_mode(topoloc_localizer *single,
                                                                      topoloc_localizer *filter,
                                                                      topoloc_result *r)
{
    unsigned correct_single = 0, correct_filter = 0;
    topoloc_image image;
    uint32_t p;

    SECTION();
    for (p = 0; p < IMG_PLACES; p++) {
        image = gray_image(g_revisit[p]);
        CHECK_OK(localize_image(single, &image, (double)p, r));
        correct_single += r->place == p;
        CHECK(r->frame_index == p && r->candidates_len == 3 && r->candidates[0].place == r->place);
        CHECK(r->similarity > 0.0f && r->similarity <= 1.0001f);
        CHECK_OK(localize_image(filter, &image, (double)p, r));
        correct_filter += r->place == p;
    }
    printf("   revisits localized: %u/%u single-frame, %u/%u filter\n", correct_single, IMG_PLACES,
           correct_filter, IMG_PLACES);
    CHECK(correct_single >= IMG_PLACES - 1);
    CHECK(correct_filter >= IMG_PLACES - 1);
}

/* `image` localizes with `loc` at the place of `reference`, with a similarity within
 * `tolerance` of its (three checks). */
static void check_localizes_like(topoloc_localizer *loc, const topoloc_image *image,
                                 const topoloc_result *reference, float tolerance,
                                 topoloc_result *r)
{
    CHECK_OK(localize_image(loc, image, 0.0, r));
    CHECK(r->place == reference->place);
    CHECK_NEAR(r->similarity, reference->similarity, tolerance);
}

/* Every pixel format, with padded rows (stride > width, like a cv::Mat ROI), describes like the
 * grey original; the exact minimum length is accepted, one byte less refused. */
static void
every_pixel_format_with_padded_rows_describes_like_the_grey_image(topoloc_localizer *single,
                                                                  topoloc_result *r)
{
    static const uint32_t formats[4] = {TOPOLOC_PIXEL_RGB8, TOPOLOC_PIXEL_BGR8, TOPOLOC_PIXEL_RGBA8,
                                        TOPOLOC_PIXEL_BGRA8};
    static const uint32_t channels[4] = {3, 3, 4, 4};
    topoloc_result reference;
    topoloc_image image, roi;
    uint8_t *padded = NULL;
    size_t k;

    SECTION();
    CHECK_OK(topoloc_localizer_reset(single));
    image = gray_image(g_revisit[4]);
    CHECK_OK(topoloc_result_default(&reference));
    CHECK_OK(localize_image(single, &image, 0.0, &reference));
    roi = repack(g_revisit[4], TOPOLOC_PIXEL_GRAY8, 1, IMG_W + 40, &padded);
    CHECK(roi.data != NULL);
    if (roi.data != NULL) {
        check_localizes_like(single, &roi, &reference, 1e-4f, r);
    }
    free(padded);
    for (k = 0; k < 4; k++) {
        uint8_t *buffer = NULL;
        topoloc_image colour =
            repack(g_revisit[4], formats[k], channels[k], IMG_W * channels[k] + 13, &buffer);
        CHECK(colour.data != NULL);
        if (colour.data != NULL) {
            check_localizes_like(single, &colour, &reference, 1e-3f, r);
            colour.data_len = colour.stride * (IMG_H - 1) + (size_t)IMG_W * channels[k];
            CHECK_OK(localize_image(single, &colour, 0.0, r));
            colour.data_len -= 1;
            CHECK_STATUS(localize_image(single, &colour, 0.0, r), TOPOLOC_ERR_INVALID_IMAGE);
        }
        free(buffer);
    }
}

/* `frame` gets view 5's descriptor and the image of another place: the descriptor is used. */
static void a_frame_with_a_descriptor_and_an_image_is_localized_by_the_descriptor(
    const topoloc_map *map, topoloc_localizer *single, topoloc_frame *frame, float *view5,
    topoloc_result *r)
{
    SECTION();
    CHECK_OK(topoloc_map_view_descriptor(map, 5, view5, IMG_PLACES - 1));
    CHECK_OK(topoloc_frame_default(frame));
    frame->timestamp = 0.0;
    frame->descriptor = view5;
    frame->descriptor_len = IMG_PLACES - 1;
    frame->image = gray_image(g_revisit[2]);
    CHECK_OK(topoloc_localizer_process(single, frame, r));
    CHECK(r->place == 5 && r->view == 5);
}

/* The map's own backend is accepted, another is a mismatch naming it, an unknown one an invalid
 * option; a localizer with ABI 1.0 options (no image fields) gets AUTO. */
static void the_backend_of_the_map_is_accepted_and_another_refused(const topoloc_map *map)
{
    topoloc_localizer_options options;
    topoloc_localizer *loc = NULL;

    SECTION();
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.image_backend = TOPOLOC_BACKEND_VLAD_ORB;
    check_new_localizer_finds(map, &options, g_revisit[6], 6);
    options.image_backend = TOPOLOC_BACKEND_ONNX;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    CHECK_MESSAGE_HAS("onnx");
    CHECK(loc == NULL);
    options.image_backend = TOPOLOC_BACKEND_VLAD_SIFT;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    CHECK_MESSAGE_HAS("sift");
    options.image_backend = 42;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("42");
    CHECK(loc == NULL);

    CHECK_OK(topoloc_localizer_options_default(&options));
    options.struct_size = offsetof(topoloc_localizer_options, image_backend);
    options.image_backend = TOPOLOC_BACKEND_NONE; /* beyond struct_size: not read */
    check_new_localizer_finds(map, &options, g_revisit[1], 1);
}

/* BACKEND_NONE: descriptor frames only (`frame` holds view 5's descriptor and an image); an
 * image frame is refused and changes nothing. */
static void backend_none_refuses_image_frames_and_leaves_the_localizer_unchanged(
    const topoloc_map *map, topoloc_frame *frame, topoloc_result *r)
{
    topoloc_localizer_options options;
    topoloc_localizer *loc = NULL;
    topoloc_result snapshot;
    topoloc_image image;

    SECTION();
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.image_backend = TOPOLOC_BACKEND_NONE;
    CHECK_OK(topoloc_localizer_new(map, &options, &loc));
    if (loc != NULL) {
        frame->image = gray_image(g_place_px[0]); /* with the descriptor of view 5: fine */
        CHECK_OK(topoloc_localizer_process(loc, frame, r));
        CHECK(r->place == 5 && r->frame_index == 0);
        snapshot = *r;
        image = gray_image(g_revisit[3]);
        CHECK_ERROR(localize_image(loc, &image, 1.0, r), TOPOLOC_ERR_NO_DESCRIBER);
        CHECK(identical_result(&snapshot, r));
        frame->timestamp = 1.0;
        CHECK_OK(topoloc_localizer_process(loc, frame, r));
        CHECK(r->frame_index == 1);
    }
    topoloc_localizer_free(loc);
}

static void a_map_built_from_descriptors_has_no_describer_for_image_frames(const topoloc_map *world,
                                                                           topoloc_result *r)
{
    topoloc_localizer_options options;
    topoloc_localizer *loc = NULL;
    topoloc_image image;

    SECTION();
    CHECK_OK(topoloc_localizer_new(world, NULL, &loc)); /* AUTO: fine, descriptors only */
    if (loc != NULL) {
        image = gray_image(g_revisit[0]);
        CHECK_ERROR(localize_image(loc, &image, 0.0, r), TOPOLOC_ERR_NO_DESCRIBER);
    }
    topoloc_localizer_free(loc);
    loc = NULL;
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.image_backend = TOPOLOC_BACKEND_VLAD_ORB;
    CHECK_ERROR(topoloc_localizer_new(world, &options, &loc), TOPOLOC_ERR_NO_DESCRIBER);
    CHECK(loc == NULL);
}

static void image_frames(const topoloc_map *map, const topoloc_map *world)
{
    topoloc_localizer *single = NULL, *filter = NULL;
    topoloc_result r;
    topoloc_candidate candidates[3];
    topoloc_frame frame;
    float view5[IMG_PLACES];
    uint32_t p;

    for (p = 0; p < IMG_PLACES; p++) {
        make_revisit(g_place_px[p], 100u + p, g_revisit[p]);
    }
    result_with_candidates(&r, candidates, 3);
    CHECK_OK(new_single_frame_localizer(map, &single));
    CHECK_OK(topoloc_localizer_new(map, NULL, &filter)); /* NULL options: AUTO, filter mode */
    if (single == NULL || filter == NULL) {
        topoloc_localizer_free(single);
        topoloc_localizer_free(filter);
        return;
    }
    revisits_find_their_place_in_single_frame_and_filter_mode(single, filter, &r);
    every_pixel_format_with_padded_rows_describes_like_the_grey_image(single, &r);
    a_frame_with_a_descriptor_and_an_image_is_localized_by_the_descriptor(map, single, &frame,
                                                                          view5, &r);
    topoloc_localizer_free(single);
    topoloc_localizer_free(filter);
    the_backend_of_the_map_is_accepted_and_another_refused(map);
    backend_none_refuses_image_frames_and_leaves_the_localizer_unchanged(map, &frame, &r);
    a_map_built_from_descriptors_has_no_describer_for_image_frames(world, &r);
}

/* ------------------------------------------------------------------------------------------ */
/* Verification and pose fixes                                                                 */
/* ------------------------------------------------------------------------------------------ */

/* Geometric verification (ABI 1.2): maps built from images store keypoints; the top place of a
 * revisit is verified with many inliers; a map without keypoints refuses the option; a frame
 * without its image is refused with the state unchanged; an ABI 1.1 result is still filled. */
static void a_revisit_is_verified_with_many_inliers_and_verification_needs_keypoints_and_images(
    const topoloc_map *map, const topoloc_map *world)
{
    static uint8_t revisit[IMG_PIXELS];
    static float descriptor[1024];
    topoloc_localizer_options options;
    topoloc_localizer *loc = NULL;
    topoloc_result r;
    topoloc_frame frame;
    topoloc_image image;
    uint32_t dim = 0;

    SECTION();
    make_revisit(g_place_px[4], 204u, revisit);
    CHECK_OK(topoloc_localizer_options_default(&options));
    CHECK(options.verify_candidates == 0 && options.verify_views_per_candidate == 2);
    CHECK(options.verify_inlier_weight > 0.0f);
    options.verify_candidates = 3;
    CHECK_STATUS(topoloc_localizer_new(world, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("keypoints");
    CHECK(loc == NULL);
    options.verify_views_per_candidate = 0;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("views_per_candidate");
    options.verify_views_per_candidate = 2;

    CHECK_OK(topoloc_localizer_new(map, &options, &loc));
    if (loc == NULL) {
        return;
    }
    CHECK_OK(topoloc_result_default(&r));
    image = gray_image(revisit);
    CHECK_OK(localize_image(loc, &image, 0.0, &r));
    CHECK(r.place == 4 && r.verified);
    CHECK(r.inliers >= 20);
    printf("   revisit of place 4: place %u, %u inliers\n", (unsigned)r.place, (unsigned)r.inliers);
    CHECK(r.frame_index == 0);

    /* A descriptor-only frame cannot be verified: refused, nothing changes. */
    topoloc_frame_default(&frame);
    frame.timestamp = 1.0;
    CHECK_OK(topoloc_map_descriptor_dim(map, &dim));
    CHECK(dim >= 1 && dim <= 1024);
    descriptor[0] = 1.0f;
    frame.descriptor = descriptor;
    frame.descriptor_len = dim;
    CHECK_STATUS(topoloc_localizer_process(loc, &frame, &r), TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_MESSAGE_HAS("verification");
    CHECK(r.frame_index == 0 && r.place == 4 && r.verified);

    /* A caller of ABI 1.1 gets its result without the verification fields. */
    CHECK_OK(topoloc_result_default(&r));
    r.struct_size = offsetof(topoloc_result, verified);
    r.inliers = 12345u;
    CHECK_OK(localize_image(loc, &image, 2.0, &r));
    CHECK(r.place == 4 && r.frame_index == 1 && r.inliers == 12345u);
    topoloc_localizer_free(loc);
}

/* Pose fixes (ABI 1.6): the host reads each view's keypoints, attaches their scene points (here:
 * the view's optical frame is the map frame, points 1 m away left of the centre and 4 m right of
 * it, pinhole focal 400 px) and gets the camera of a revisit placed metrically; the revisit moved
 * the content 2 px left, so the fixed pose reprojects the view's scene points 2 px left of their
 * keypoints. Bad lengths, bad intrinsics and a camera without scene points are refused. */
#define PF_FOCAL 400.0
static double pf_depth(float u) { return (double)u < (IMG_W - 1) / 2.0 ? 1.0 : 4.0; }

static int compare_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static void scene_points_from_the_host_give_a_revisit_a_metric_camera_pose(const topoloc_map *map)
{
    static uint8_t revisit[IMG_PIXELS];
    static float xy[2 * 4096], xyz[3 * 65536];
    static double error[4096];
    const double cx = (IMG_W - 1) / 2.0, cy = (IMG_H - 1) / 2.0;
    topoloc_localizer_options options;
    topoloc_localizer *loc = NULL;
    topoloc_map *posed = NULL;
    topoloc_image image;
    topoloc_result r;
    size_t total = 0, filled = 0, count = 0, i, n = 0, views = 0;
    uint32_t v;

    SECTION();
    CHECK_OK(topoloc_map_keypoint_total(map, &total));
    CHECK_OK(topoloc_map_view_count(map, &views));
    CHECK(total > 0 && total <= 65536);
    if (total == 0 || total > 65536) {
        return;
    }
    for (v = 0; v < views; v++) {
        CHECK_OK(topoloc_map_view_keypoints(map, v, xy, sizeof xy / sizeof xy[0], &count));
        for (i = 0; i < count; i++) {
            double d = pf_depth(xy[2 * i]);
            xyz[3 * (filled + i)] = (float)((xy[2 * i] - cx) / PF_FOCAL * d);
            xyz[3 * (filled + i) + 1] = (float)((xy[2 * i + 1] - cy) / PF_FOCAL * d);
            xyz[3 * (filled + i) + 2] = (float)d;
        }
        filled += count;
    }
    CHECK(filled == total);
    CHECK_STATUS(topoloc_map_view_keypoints(map, 0, xy, 1, &count), TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(count > 0);
    CHECK_STATUS(topoloc_map_view_keypoints(map, (uint32_t)views, xy, 2, &count),
                 TOPOLOC_ERR_UNKNOWN_VIEW);
    CHECK_STATUS(topoloc_map_with_keypoint_points(map, xyz, 3 * total - 3, &posed),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("keypoints need");
    CHECK(posed == NULL);
    xyz[1] = (float)make_nan(); /* neither finite nor all NaN */
    CHECK_STATUS(topoloc_map_with_keypoint_points(map, xyz, 3 * total, &posed),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    xyz[0] = xyz[1] = xyz[2] = (float)make_nan(); /* unknown: allowed */
    CHECK_OK(topoloc_map_with_keypoint_points(map, xyz, 3 * total, &posed));
    if (posed == NULL) {
        return;
    }

    /* A camera on the map without scene points, or a bad focal length: refused. */
    CHECK_OK(topoloc_localizer_options_default(&options));
    CHECK(options.camera_fx == 0.0 && options.pose_min_inliers == 30u);
    options.verify_candidates = 3;
    options.camera_fx = options.camera_fy = PF_FOCAL;
    options.camera_cx = cx;
    options.camera_cy = cy;
    options.pose_min_inliers = 12;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("scene points");
    options.camera_fy = -1.0;
    CHECK_STATUS(topoloc_localizer_new(posed, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_MESSAGE_HAS("fy");
    CHECK(loc == NULL);
    options.camera_fy = PF_FOCAL;

    CHECK_OK(topoloc_localizer_new(posed, &options, &loc));
    if (loc != NULL) {
        double *T = r.world_T_camera;
        make_revisit(g_place_px[4], 204u, revisit);
        image = gray_image(revisit);
        CHECK_OK(topoloc_result_default(&r));
        CHECK(!r.has_pose_fix && T[0] == 1.0 && T[5] == 1.0 && T[3] == 0.0);
        CHECK_OK(localize_image(loc, &image, 0.0, &r));
        printf(
            "   revisit of place 4: pose fix %d against view %u, %u inliers, t = %.3f %.3f %.3f\n",
            (int)r.has_pose_fix, (unsigned)r.pose_fix_view, (unsigned)r.pose_fix_inliers, T[3],
            T[7], T[11]);
        CHECK(r.place == 4 && r.has_pose_fix && r.pose_fix_inliers >= 12u);
        CHECK_OK(topoloc_map_view_keypoints(posed, r.pose_fix_view, xy, sizeof xy / sizeof xy[0],
                                            &count));
        /* camera_T_world = inverse of world_T_camera: R^T (X - t). */
        for (i = 1; i < count && r.has_pose_fix; i++) {
            double d = pf_depth(xy[2 * i]), X[3], c[3];
            int k;
            X[0] = (xy[2 * i] - cx) / PF_FOCAL * d - T[3];
            X[1] = (xy[2 * i + 1] - cy) / PF_FOCAL * d - T[7];
            X[2] = d - T[11];
            for (k = 0; k < 3; k++) {
                c[k] = T[k] * X[0] + T[4 + k] * X[1] + T[8 + k] * X[2];
            }
            if (c[2] > 0.1) {
                double du = cx + PF_FOCAL * c[0] / c[2] - (xy[2 * i] - 2.0);
                double dv = cy + PF_FOCAL * c[1] / c[2] - xy[2 * i + 1];
                error[n++] = du * du + dv * dv; /* squared: no libm */
            }
        }
        CHECK(n > 0);
        if (n > 0) {
            qsort(error, n, sizeof error[0], compare_double);
            printf("   median squared reprojection against the 2 px shift: %.2f px^2 over %zu "
                   "points\n",
                   error[n / 2], n);
            CHECK(error[n / 2] < 1.5 * 1.5);
        }

        /* A caller of ABI 1.5 gets its result without the pose-fix fields. */
        CHECK_OK(topoloc_result_default(&r));
        r.struct_size = offsetof(topoloc_result, has_pose_fix);
        r.pose_fix_inliers = 777u;
        CHECK_OK(localize_image(loc, &image, 1.0, &r));
        CHECK(r.place == 4 && r.pose_fix_inliers == 777u);
        topoloc_localizer_free(loc);
    }
    topoloc_map_free(posed);
}

/* ------------------------------------------------------------------------------------------ */
/* Bad images                                                                                  */
/* ------------------------------------------------------------------------------------------ */

/* One localizer sees bad images between two good ones, its twin only the good ones: each bad
 * image is refused with its status (naming frame.image when invalid) and changes nothing, so the
 * twins agree exactly afterwards. */
static void bad_and_uninformative_images_leave_the_localizer_unchanged(const topoloc_map *map)
{
    enum { BAD = 13 };
    static uint8_t constant[IMG_PIXELS];
    static uint8_t black_rgb[IMG_PIXELS * 3];
    static const uint8_t one_pixel[1] = {128};
    static const uint32_t expected[BAD] = {
        TOPOLOC_ERR_INVALID_IMAGE,       /* 0: width 0 */
        TOPOLOC_ERR_INVALID_IMAGE,       /* 1: height 0 */
        TOPOLOC_ERR_INVALID_IMAGE,       /* 2: 10000 x 10000 */
        TOPOLOC_ERR_INVALID_IMAGE,       /* 3: stride smaller than a row */
        TOPOLOC_ERR_INVALID_IMAGE,       /* 4: data_len one byte short */
        TOPOLOC_ERR_INVALID_IMAGE,       /* 5: format 99 */
        TOPOLOC_ERR_INVALID_IMAGE,       /* 6: data_len 0 */
        TOPOLOC_ERR_NULL_ARGUMENT,       /* 7: data NULL */
        TOPOLOC_ERR_UNINFORMATIVE_IMAGE, /* 8: constant grey */
        TOPOLOC_ERR_UNINFORMATIVE_IMAGE, /* 9: 1 x 1 */
        TOPOLOC_ERR_UNINFORMATIVE_IMAGE, /* 10: all-black RGB */
        TOPOLOC_ERR_INVALID_IMAGE,       /* 11: RGB8 format over a grey buffer (too short) */
        TOPOLOC_ERR_INVALID_IMAGE,       /* 12: stride * (height - 1) overflows size_t */
    };
    topoloc_localizer *a = NULL, *b = NULL;
    topoloc_result ra, rb, snapshot;
    topoloc_image image, good;
    size_t k;

    SECTION();
    memset(constant, 90, sizeof constant);
    memset(black_rgb, 0, sizeof black_rgb);
    if (!new_twin_localizers(map, &a, &b)) {
        return;
    }
    CHECK_OK(topoloc_result_default(&ra));
    CHECK_OK(topoloc_result_default(&rb));
    good = gray_image(g_place_px[0]);
    CHECK_OK(localize_image(a, &good, 1.0, &ra));
    CHECK_OK(localize_image(b, &good, 1.0, &rb));
    CHECK(ra.frame_index == 0 && same_result(&ra, &rb));

    for (k = 0; k < BAD; k++) {
        topoloc_status st;
        image = gray_image(g_place_px[1]);
        switch (k) {
        case 0:
            image.width = 0;
            break;
        case 1:
            image.height = 0;
            break;
        case 2:
            image.width = 10000;
            image.height = 10000;
            image.stride = 10000;
            break;
        case 3:
            image.stride = IMG_W - 1;
            break;
        case 4:
            image.data_len = IMG_PIXELS - 1;
            break;
        case 5:
            image.format = 99;
            break;
        case 6:
            image.data_len = 0;
            break;
        case 7:
            image.data = NULL;
            break;
        case 8:
            image = gray_image(constant);
            break;
        case 9:
            image.data = one_pixel;
            image.data_len = 1;
            image.width = image.height = 1;
            image.stride = 1;
            break;
        case 10:
            image.data = black_rgb;
            image.data_len = sizeof black_rgb;
            image.stride = IMG_W * 3;
            image.format = TOPOLOC_PIXEL_RGB8;
            break;
        case 11:
            image.format = TOPOLOC_PIXEL_RGB8;
            break;
        case 12:
            /* 2^63 * 2 wraps to 0: the needed length must be computed with overflow checks, or
             * rows 2^63 bytes apart would be read (SIGSEGV). */
            image.height = 3;
            image.stride = (SIZE_MAX >> 1) + 1;
            image.data_len = IMG_W;
            break;
        default:
            break;
        }
        snapshot = ra;
        /* A later timestamp than the good frame that follows: it must not be remembered. */
        st = localize_image(a, &image, 100.0 + (double)k, &ra);
        check_status_impl(st, expected[k], "process(bad image)", __FILE__, __LINE__);
        if (st != expected[k]) {
            fprintf(stderr, "    (bad image kind %zu)\n", k);
        }
        CHECK_HAS_MESSAGE();
        if (expected[k] == TOPOLOC_ERR_INVALID_IMAGE || expected[k] == TOPOLOC_ERR_NULL_ARGUMENT) {
            CHECK_MESSAGE_HAS("frame.image");
        }
        CHECK(identical_result(&snapshot, &ra));
    }
    /* As if the bad frames never happened: an earlier timestamp than theirs is accepted, the
     * frame index continues, and the twin that never saw them agrees exactly. */
    good = gray_image(g_place_px[2]);
    CHECK_OK(localize_image(a, &good, 2.0, &ra));
    CHECK_OK(localize_image(b, &good, 2.0, &rb));
    CHECK(ra.frame_index == 1);
    CHECK(same_result(&ra, &rb));
    CHECK(ra.place == 2);
    topoloc_localizer_free(a);
    topoloc_localizer_free(b);
}

/* Three grey places built with `options` (default: vlad_options); the status. */
static topoloc_status build_three(const topoloc_image *images,
                                  const topoloc_image_map_options *options, topoloc_map **out)
{
    return topoloc_map_build_from_images(images, 3, options, NULL, NULL, out);
}

/* Refused before any describing (the callback is never called), naming the bad image or option;
 * the out-parameter is left alone. */
static void bad_images_and_options_are_refused_before_a_build_describes_anything(void)
{
    topoloc_image_map_options options;
    topoloc_image images[3];
    topoloc_map *out;
    struct progress_log log;

    SECTION();
    vlad_options(&options, 3);
    images[0] = gray_image(g_place_px[0]);
    images[1] = gray_image(g_place_px[1]);
    images[2] = gray_image(g_place_px[2]);
    images[1].stride = 3;
    progress_log_init(&log, -1, 3);
    out = untouched_map();
    CHECK_STATUS(topoloc_map_build_from_images(images, 3, &options, record_progress, &log, &out),
                 TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_MESSAGE_HAS("images[1]");
    CHECK(log.calls == 0 && out == untouched_map());
    images[1] = gray_image(g_place_px[1]);
    images[2].format = TOPOLOC_PIXEL_NONE;
    CHECK_STATUS(topoloc_map_build_from_images(images, 3, &options, record_progress, &log, &out),
                 TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_MESSAGE_HAS("images[2]");
    images[2] = gray_image(g_place_px[2]);
    CHECK_ERROR(topoloc_map_build_from_images(images, 1, &options, NULL, NULL, &out),
                TOPOLOC_ERR_INVALID_ARGUMENT); /* fewer than 2 images */
    options.backend = 77;
    CHECK_STATUS(build_three(images, &options, &out), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("77");
    options.backend = TOPOLOC_BACKEND_NONE; /* a localizer-only choice */
    CHECK_STATUS(build_three(images, &options, &out), TOPOLOC_ERR_INVALID_ARGUMENT);
    vlad_options(&options, 3);
    options.views_per_place = 0;
    CHECK_STATUS(build_three(images, &options, &out), TOPOLOC_ERR_INVALID_ARGUMENT);
    vlad_options(&options, 3);
    options.threads = 100000; /* more than 256: refused, not a hang */
    CHECK_STATUS(build_three(images, &options, &out), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("threads");
    vlad_options(&options, 3);
    options.vlad_clusters = 1;
    CHECK_STATUS(build_three(images, &options, &out), TOPOLOC_ERR_INVALID_ARGUMENT);
    vlad_options(&options, 3);
    options.struct_size = 0;
    CHECK_STATUS(build_three(images, &options, &out), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK(out == untouched_map());
    vlad_options(&options, 3);
    CHECK_NULL(topoloc_map_build_from_images(NULL, 3, &options, NULL, NULL, &out), "images");
    CHECK_NULL(build_three(images, &options, NULL), "out");
    CHECK(out == untouched_map());
}

/* ------------------------------------------------------------------------------------------ */
/* Image files                                                                                 */
/* ------------------------------------------------------------------------------------------ */

/* Writes a binary PGM (P5) file. */
static bool write_pgm(const char *path, const uint8_t *px, uint32_t width, uint32_t height)
{
    FILE *f = fopen(path, "wb");
    bool ok;
    if (f == NULL) {
        return false;
    }
    ok = fprintf(f, "P5\n%u %u\n255\n", (unsigned)width, (unsigned)height) > 0 &&
         fwrite(px, 1, (size_t)width * height, f) == (size_t)width * height;
    return fclose(f) == 0 && ok;
}

/* Views record their file; files read by OpenCV (as colour) and grey pixels in memory describe
 * alike. */
static void a_map_from_image_files_records_their_paths_and_describes_like_pixels(
    const char *const *list, const topoloc_image_map_options *options)
{
    static uint8_t revisit[IMG_PIXELS];
    struct progress_log log;
    topoloc_map *map = NULL;
    topoloc_localizer *loc = NULL;
    topoloc_result r;
    topoloc_image image;
    size_t n = 0;
    uint32_t i;

    SECTION();
    progress_log_init(&log, -1, IMG_FILES);
    CHECK_OK(
        topoloc_map_build_from_image_files(list, IMG_FILES, options, record_progress, &log, &map));
    CHECK(log.saw_describing_all && log.saw_fitting_done && !log.bad_values);
    if (map == NULL) {
        return;
    }
    CHECK_OK(topoloc_map_place_count(map, &n));
    CHECK(n == IMG_FILES);
    for (i = 0; i < IMG_FILES; i++) {
        char image_ref[4200];
        topoloc_view_info info;
        CHECK_OK(topoloc_map_view_image(map, i, image_ref, sizeof image_ref, NULL));
        CHECK(strcmp(image_ref, list[i]) == 0);
        CHECK_OK(topoloc_view_info_default(&info));
        CHECK_OK(topoloc_map_view_info(map, i, &info));
        CHECK(info.has_keyframe_id && info.keyframe_id == i);
    }
    CHECK_OK(new_single_frame_localizer(map, &loc));
    CHECK_OK(topoloc_result_default(&r));
    if (loc != NULL) {
        make_revisit(g_place_px[2], 7, revisit);
        image = gray_image(revisit);
        CHECK_OK(localize_image(loc, &image, 0.0, &r));
        CHECK(r.place == 2);
    }
    topoloc_localizer_free(loc);
    topoloc_map_free(map);
}

/* With one pose per image (TUM), places come from the poses and carry positions; fewer poses
 * than images, or a missing poses file, are refused. */
static void poses_from_a_tum_file_place_the_images_and_must_cover_them_all(
    const char *const *list, const topoloc_image_map_options *vlad, const char *tum,
    const char *short_tum)
{
    topoloc_image_map_options options = *vlad;
    topoloc_map *map = NULL, *out = untouched_map();
    char missing[4200];
    size_t n = 0;
    uint32_t i;
    FILE *f;

    SECTION();
    f = fopen(tum, "w");
    CHECK(f != NULL);
    if (f != NULL) {
        fprintf(f, "# timestamp tx ty tz qx qy qz qw\n");
        for (i = 0; i < IMG_FILES; i++) {
            fprintf(f, "%u.0 %u.0 0 0 0 0 0 1\n", (unsigned)i, (unsigned)(5 * i));
        }
        CHECK(fclose(f) == 0);
    }
    options.poses_tum_path = tum;
    CHECK_OK(topoloc_map_build_from_image_files(list, IMG_FILES, &options, NULL, NULL, &map));
    if (map != NULL) {
        double xyz[3] = {0, 0, 0};
        bool has = false;
        CHECK_OK(topoloc_map_place_count(map, &n));
        CHECK(n == IMG_FILES);
        CHECK_OK(topoloc_map_place_position(map, 2, xyz, &has));
        CHECK(has && xyz[0] == 10.0);
        topoloc_map_free(map);
    }
    CHECK(write_file(short_tum, (const unsigned char *)"0 0 0 0 0 0 0 1\n", 16));
    options.poses_tum_path = short_tum;
    CHECK_ERROR(topoloc_map_build_from_image_files(list, IMG_FILES, &options, NULL, NULL, &out),
                TOPOLOC_ERR_INVALID_ARGUMENT);
    tmp_path(missing, sizeof missing, "no-such-poses.tum");
    options.poses_tum_path = missing;
    CHECK_STATUS(topoloc_map_build_from_image_files(list, IMG_FILES, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_IO);
    CHECK_MESSAGE_HAS(missing);
}

/* A missing file and a file that is no image: INVALID_IMAGE naming the path; a NULL or non-UTF-8
 * path is refused; the out-parameter is left alone. */
static void missing_unreadable_and_null_image_paths_are_refused_naming_them(
    const char **list, const topoloc_image_map_options *options, const char *text)
{
    topoloc_map *out = untouched_map();
    char missing[4200];

    SECTION();
    tmp_path(missing, sizeof missing, "no-such-image.pgm");
    list[2] = missing;
    CHECK_STATUS(topoloc_map_build_from_image_files(list, IMG_FILES, options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_MESSAGE_HAS(missing);
    CHECK(write_file(text, (const unsigned char *)"hello\n", 6));
    list[2] = text;
    CHECK_STATUS(topoloc_map_build_from_image_files(list, IMG_FILES, options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_MESSAGE_HAS(text);
    list[2] = NULL;
    CHECK_NULL(topoloc_map_build_from_image_files(list, IMG_FILES, options, NULL, NULL, &out),
               "paths[2]");
    list[2] = "\xff\xfe.pgm";
    CHECK_STATUS(topoloc_map_build_from_image_files(list, IMG_FILES, options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_UTF8);
    CHECK_NULL(topoloc_map_build_from_image_files(NULL, IMG_FILES, options, NULL, NULL, &out),
               "paths");
    CHECK(out == untouched_map());
}

/* The image file checks, on IMG_FILES places written as PGM files (removed at the end). */
static void image_files(void)
{
    char paths[IMG_FILES][4200], text[4200], tum[4200], short_tum[4200];
    const char *list[IMG_FILES];
    topoloc_image_map_options options;
    uint32_t i;
    bool written = true;

    for (i = 0; i < IMG_FILES; i++) {
        char name[32];
        snprintf(name, sizeof name, "place_%u.pgm", (unsigned)i);
        tmp_path(paths[i], sizeof paths[i], name);
        written = write_pgm(paths[i], g_place_px[i], IMG_W, IMG_H) && written;
        list[i] = paths[i];
    }
    CHECK(written);
    tmp_path(tum, sizeof tum, "poses.tum");
    tmp_path(short_tum, sizeof short_tum, "short.tum");
    tmp_path(text, sizeof text, "not-an-image.pgm");
    vlad_options(&options, IMG_FILES);
    a_map_from_image_files_records_their_paths_and_describes_like_pixels(list, &options);
    poses_from_a_tum_file_place_the_images_and_must_cover_them_all(list, &options, tum, short_tum);
    missing_unreadable_and_null_image_paths_are_refused_naming_them(list, &options, text);
    CHECK(unlink(text) == 0 && unlink(tum) == 0 && unlink(short_tum) == 0);
    for (i = 0; i < IMG_FILES; i++) {
        CHECK(unlink(paths[i]) == 0);
    }
}

/* ------------------------------------------------------------------------------------------ */
/* ONNX                                                                                        */
/* ------------------------------------------------------------------------------------------ */

/* A missing model is BACKEND_UNAVAILABLE naming it (for ONNX and AUTO) always; with the model
 * installed, an ONNX map localizes revisits, refuses uninformative images, accepts its own model
 * named explicitly and refuses another backend, a missing or a broken model file. */
static void the_onnx_backend_needs_its_model_and_with_it_localizes_revisits(void)
{
    enum { ONNX_IMAGES = 6 };
    topoloc_image images[ONNX_IMAGES];
    topoloc_image_map_options options;
    topoloc_localizer_options lo;
    topoloc_localizer *loc = NULL;
    topoloc_map *map = NULL, *out = untouched_map();
    topoloc_result r;
    topoloc_image image;
    char missing[4200], model_path[4200], garbage[4200], kind[64];
    static uint8_t revisit[IMG_PIXELS];
    unsigned correct = 0;
    uint32_t i;

    SECTION();
    for (i = 0; i < ONNX_IMAGES; i++) {
        images[i] = gray_image(g_place_px[i]);
    }
    tmp_path(missing, sizeof missing, "no-such-model.onnx");
    CHECK_OK(topoloc_image_map_options_default(&options));
    options.dim = ONNX_IMAGES - 1;
    options.threads = 1;
    options.onnx_model_path = missing;
    options.backend = TOPOLOC_BACKEND_ONNX;
    CHECK_STATUS(topoloc_map_build_from_images(images, ONNX_IMAGES, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_BACKEND_UNAVAILABLE);
    CHECK_MESSAGE_HAS(missing);
    options.backend = TOPOLOC_BACKEND_AUTO;
    CHECK_STATUS(topoloc_map_build_from_images(images, ONNX_IMAGES, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_BACKEND_UNAVAILABLE);
    CHECK_MESSAGE_HAS(missing);
    CHECK(out == untouched_map());

    if (!models_ready(ONNX_MODEL_FILE, model_path, sizeof model_path, "ONNX map")) {
        return;
    }
    options.onnx_model_path = NULL; /* the cache's model */
    CHECK_OK(topoloc_map_build_from_images(images, ONNX_IMAGES, &options, NULL, NULL, &map));
    if (map == NULL) {
        return;
    }
    CHECK_OK(topoloc_map_descriptor_kind(map, kind, sizeof kind, NULL));
    CHECK(strcmp(kind, "onnx-mlf") == 0);

    /* AUTO loads the runtime and the map's model. */
    CHECK_OK(topoloc_localizer_options_default(&lo));
    lo.mode = TOPOLOC_MODE_SINGLE_FRAME;
    CHECK_OK(topoloc_localizer_new(map, &lo, &loc));
    CHECK_OK(topoloc_result_default(&r));
    if (loc != NULL) {
        for (i = 0; i < ONNX_IMAGES; i++) {
            make_revisit(g_place_px[i], 200u + i, revisit);
            image = gray_image(revisit);
            CHECK_OK(localize_image(loc, &image, (double)i, &r));
            correct += r.place == i;
        }
        printf("   ONNX revisits localized: %u/%u\n", correct, (unsigned)ONNX_IMAGES);
        CHECK(correct >= ONNX_IMAGES - 1);
        /* Uninformative images are refused for ONNX too. */
        memset(revisit, 77, sizeof revisit);
        image = gray_image(revisit);
        CHECK_STATUS(localize_image(loc, &image, 10.0, &r), TOPOLOC_ERR_UNINFORMATIVE_IMAGE);
    }
    topoloc_localizer_free(loc);
    loc = NULL;

    /* The same model named explicitly works; another backend, a missing or a broken model
     * file do not. */
    lo.image_backend = TOPOLOC_BACKEND_ONNX;
    lo.onnx_model_path = model_path;
    CHECK_OK(topoloc_localizer_new(map, &lo, &loc));
    topoloc_localizer_free(loc);
    loc = NULL;
    lo.onnx_model_path = missing;
    CHECK_STATUS(topoloc_localizer_new(map, &lo, &loc), TOPOLOC_ERR_BACKEND_UNAVAILABLE);
    CHECK_MESSAGE_HAS(missing);
    tmp_path(garbage, sizeof garbage, "garbage.onnx");
    CHECK(write_file(garbage, (const unsigned char *)"this is not an ONNX model", 25));
    lo.onnx_model_path = garbage;
    {
        /* Not the map's model: refused either by its hash or as a broken model. */
        topoloc_status st = topoloc_localizer_new(map, &lo, &loc);
        CHECK(st == TOPOLOC_ERR_DESCRIPTOR_MISMATCH || st == TOPOLOC_ERR_MODEL);
        CHECK(loc == NULL);
    }
    CHECK(unlink(garbage) == 0);
    lo.onnx_model_path = NULL;
    lo.image_backend = TOPOLOC_BACKEND_VLAD_ORB;
    CHECK_STATUS(topoloc_localizer_new(map, &lo, &loc), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    /* NONE needs no runtime: descriptor frames only. */
    lo.image_backend = TOPOLOC_BACKEND_NONE;
    CHECK_OK(topoloc_localizer_new(map, &lo, &loc));
    if (loc != NULL) {
        image = gray_image(g_place_px[0]);
        CHECK_STATUS(localize_image(loc, &image, 0.0, &r), TOPOLOC_ERR_NO_DESCRIBER);
    }
    topoloc_localizer_free(loc);
    topoloc_map_free(map);
}

topoloc_map *run_image_tests(const topoloc_map *world)
{
    topoloc_map *map;
    image_constants_and_the_defaults_of_the_image_structs_are_part_of_the_abi();
    a_frame_of_the_first_abi_without_an_image_field_still_localizes_descriptors(world);
    map = image_map();
    CHECK(map != NULL);
    if (map != NULL) {
        image_frames(map, world);
        a_revisit_is_verified_with_many_inliers_and_verification_needs_keypoints_and_images(map,
                                                                                            world);
        scene_points_from_the_host_give_a_revisit_a_metric_camera_pose(map);
        bad_and_uninformative_images_leave_the_localizer_unchanged(map);
    }
    bad_images_and_options_are_refused_before_a_build_describes_anything();
    image_files();
    the_onnx_backend_needs_its_model_and_with_it_localizes_revisits();
    return map;
}
