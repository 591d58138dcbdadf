/* Fuzz target: camera frames given as pixels (topoloc_image) to a localizer and a describer of
 * a seed map built from images (VLAD, so that each run is fast). The input declares the
 * image's size, stride, pixel format and claimed byte length, then the pixels. */
#include "common.h"

static topoloc_map *map = NULL;
static topoloc_localizer *loc = NULL;
static topoloc_describer *describer = NULL;
static size_t dim = 0;
static double timestamp = 0;

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    map = fuzz_load_seed("TOPOLOC_FUZZ_IMAGE_MAP");
    if (topoloc_localizer_new(map, NULL, &loc) != TOPOLOC_OK ||
        topoloc_describer_new(map, NULL, &describer) != TOPOLOC_OK ||
        topoloc_describer_dim(describer, &dim) != TOPOLOC_OK) {
        fprintf(stderr, "the image seed map must have a describer\n");
        exit(2);
    }
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fuzz_reader r = {data, size};
    uint32_t width = fuzz_u16(&r) % 600, height = fuzz_u16(&r) % 600;
    uint32_t pad = fuzz_u8(&r);
    uint32_t format = fuzz_u8(&r) % 7; /* 0..5 valid, 6 unknown */
    uint32_t channels = format == 1 ? 1 : (format == 2 || format == 3) ? 3 : 4;
    size_t stride = (size_t)width * channels + (pad & 0x7F) - ((pad & 0x80) ? 3 : 0);
    uint8_t shortfall = fuzz_u8(&r);
    /* The pixels: the rest of the input, repeated to fill the declared length, less a
     * shortfall that tests the length check. */
    size_t need = height ? stride * (height - 1) + (size_t)width * channels : 0;
    if (need > 4u << 20)
        need = 4u << 20;
    size_t claimed = need > shortfall ? need - (shortfall & 1 ? shortfall : 0) : need;
    uint8_t *pixels = malloc(claimed ? claimed : 1);
    for (size_t i = 0; i < claimed; i++)
        pixels[i] = r.n ? r.p[i % r.n] : (uint8_t)i;
    topoloc_image image = {.data = pixels,
                           .data_len = claimed,
                           .width = width,
                           .height = height,
                           .stride = stride,
                           .format = format};

    topoloc_frame frame;
    topoloc_frame_default(&frame);
    frame.timestamp = timestamp += 0.1;
    frame.image = image;
    topoloc_candidate cands[3];
    topoloc_result result;
    topoloc_result_default(&result);
    result.candidates = cands;
    result.candidates_capacity = 3;
    CHECK(topoloc_localizer_process(loc, &frame, &result));

    float *out = malloc(dim * sizeof(float));
    size_t n = 0;
    CHECK(topoloc_describer_describe(describer, &image, out, dim, &n));
    free(out);
    free(pixels);
    return 0;
}
