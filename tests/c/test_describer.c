/*
 * Section "Describers" of topoloc.h (ABI 1.12), on the map test_images.c builds from the grey
 * places: a describer from that map describes each map image as its view was described, refuses
 * options it cannot honour and maps without a describer, and leaves the caller's buffer and
 * itself untouched on errors.
 */
#include "harness.h"

#include <math.h>

/* Leaves `options` at their defaults. */
static void describer_options_have_defaults_and_a_map_without_a_describer_gives_none(
    const topoloc_map *map, const topoloc_map *world, topoloc_describer_options *options)
{
    topoloc_describer *describer = NULL, *untouched = (topoloc_describer *)0x1;

    SECTION();
    memset(options, 0x5A, sizeof *options);
    CHECK_OK(topoloc_describer_options_default(options));
    CHECK(options->struct_size == sizeof *options && options->backend == TOPOLOC_BACKEND_AUTO &&
          options->onnx_model_path == NULL && options->onnx_runtime_path == NULL &&
          options->threads == 1);
    CHECK_STATUS(topoloc_describer_options_init(options, 3), TOPOLOC_ERR_STRUCT_SIZE);

    /* A map built from descriptors stores no describer. */
    CHECK_ERROR(topoloc_describer_new(world, NULL, &untouched), TOPOLOC_ERR_NO_DESCRIBER);
    CHECK(untouched == (topoloc_describer *)0x1);
    /* Options it cannot honour. */
    options->backend = TOPOLOC_BACKEND_NONE;
    CHECK_STATUS(topoloc_describer_new(map, options, &untouched), TOPOLOC_ERR_INVALID_OPTION);
    options->backend = TOPOLOC_BACKEND_ONNX; /* the map is VLAD-ORB */
    CHECK_STATUS(topoloc_describer_new(map, options, &untouched), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    options->backend = TOPOLOC_BACKEND_AUTO;
    options->threads = 0;
    CHECK_STATUS(topoloc_describer_new(map, options, &untouched), TOPOLOC_ERR_INVALID_OPTION);
    options->threads = 1;
    CHECK(untouched == (topoloc_describer *)0x1);
    CHECK_NULL(topoloc_describer_new(NULL, options, &describer), "map");
    CHECK_NULL(topoloc_describer_new(map, options, NULL), "out");
}

static void a_describer_describes_each_map_image_as_its_view_and_errors_change_nothing(
    const topoloc_map *map, const topoloc_describer_options *options)
{
    topoloc_describer *describer = NULL;
    topoloc_image image, none;
    float got[IMG_PLACES], view[IMG_PLACES], small[2] = {7.0f, 7.0f};
    size_t dim = 0, len = 0;
    uint32_t i, map_dim = 0;

    SECTION();
    CHECK_OK(topoloc_describer_new(map, options, &describer));
    if (describer == NULL) {
        return;
    }
    CHECK_OK(topoloc_describer_dim(describer, &dim));
    CHECK_OK(topoloc_map_descriptor_dim(map, &map_dim));
    CHECK(dim == map_dim && dim == IMG_PLACES - 1);
    for (i = 0; i < IMG_PLACES; i++) {
        double dot = 0.0;
        uint32_t k;
        image = gray_image(g_place_px[i]);
        CHECK_OK(topoloc_describer_describe(describer, &image, got, IMG_PLACES, &len));
        CHECK(len == dim);
        CHECK_OK(topoloc_map_view_descriptor(map, i, view, IMG_PLACES));
        for (k = 0; k < dim; k++) {
            dot += (double)got[k] * view[k];
        }
        CHECK(dot > 0.9999); /* the same image, described again */
    }

    /* Errors: the caller's buffer and the describer are left as they were. */
    len = 0;
    CHECK_STATUS(topoloc_describer_describe(describer, &image, small, 2, &len),
                 TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(len == dim && small[0] == 7.0f && small[1] == 7.0f);
    memset(&none, 0, sizeof none);
    CHECK_STATUS(topoloc_describer_describe(describer, &none, got, IMG_PLACES, NULL),
                 TOPOLOC_ERR_INVALID_IMAGE);
    none = image;
    none.stride = 1; /* shorter than a row */
    CHECK_STATUS(topoloc_describer_describe(describer, &none, got, IMG_PLACES, NULL),
                 TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_NULL(topoloc_describer_describe(describer, NULL, got, IMG_PLACES, NULL), "image");
    CHECK_NULL(topoloc_describer_describe(NULL, &image, got, IMG_PLACES, NULL), "describer");
    CHECK_NULL(topoloc_describer_dim(describer, NULL), "out");
    image = gray_image(g_place_px[0]);
    CHECK_OK(topoloc_describer_describe(describer, &image, got, IMG_PLACES, NULL));
    CHECK_OK(topoloc_map_view_descriptor(map, 0, view, IMG_PLACES));
    CHECK(fabsf(got[0] - view[0]) < 1e-4f); /* still describing as before */
    topoloc_describer_free(describer);
    topoloc_describer_free(NULL);
}

void run_describer_tests(const topoloc_map *image_map, const topoloc_map *world)
{
    topoloc_describer_options options;
    describer_options_have_defaults_and_a_map_without_a_describer_gives_none(image_map, world,
                                                                             &options);
    a_describer_describes_each_map_image_as_its_view_and_errors_change_nothing(image_map, &options);
}
