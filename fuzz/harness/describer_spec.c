/* Fuzz target: the describer spec stored in a map (backend, taps, grid, input size, PCA and
 * codebook shapes). The input is the spec's JSON text; it is spliced into a seed map built from
 * images (resealed), loaded, and when it loads a describer is made from it and describes a small
 * image. Seeds: the specs of the seed maps (fuzz/run.sh). */
#include "common.h"

static uint8_t *base = NULL;
static size_t base_len = 0;
static uint8_t pixels[96 * 72];

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    base = fuzz_read_file("TOPOLOC_FUZZ_BASE_MAP", &base_len);
    for (size_t i = 0; i < sizeof pixels; i++)
        pixels[i] = (uint8_t)((i * 2654435761u) >> 24);
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    size_t len = 0;
    uint8_t *bytes = topoloc_fuzz_splice_describer(base, base_len, data, size, &len);
    if (!bytes)
        return 0; /* not JSON: nothing of topoloc's runs */
    topoloc_map *map = NULL;
    topoloc_status s = CHECK(topoloc_map_load_from_memory(bytes, len, NULL, &map));
    EXPECT_NULL_ON_ERROR(s, map);
    topoloc_fuzz_free(bytes, len);
    if (s != TOPOLOC_OK)
        return 0;
    topoloc_describer *describer = NULL;
    s = CHECK(topoloc_describer_new(map, NULL, &describer));
    EXPECT_NULL_ON_ERROR(s, describer);
    if (s == TOPOLOC_OK) {
        size_t dim = 0;
        CHECK(topoloc_describer_dim(describer, &dim));
        float *out = calloc(dim ? dim : 1, sizeof(float));
        size_t n = 0;
        topoloc_image image = {.data = pixels,
                               .data_len = sizeof pixels,
                               .width = 96,
                               .height = 72,
                               .stride = 96,
                               .format = TOPOLOC_PIXEL_GRAY8};
        CHECK(topoloc_describer_describe(describer, &image, out, dim, &n));
        free(out);
        topoloc_describer_free(describer);
    }
    topoloc_map_free(map);
    return 0;
}
