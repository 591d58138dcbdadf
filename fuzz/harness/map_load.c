/* Fuzz target: a map file from memory (topoloc_map_load_from_memory), then every accessor and a
 * localizer on what loaded. Seeds: maps of every format version and backend (fuzz/run.sh);
 * mutation: structure-aware and resealed (topoloc_fuzz_mutate_map). */
#include "common.h"

#define MAX_ITEMS 64

static void exercise(const topoloc_map *map)
{
    size_t places = 0, views = 0, edges = 0, needed = 0, keypoints = 0;
    uint32_t dim = 0;
    char text[256];
    CHECK(topoloc_map_place_count(map, &places));
    CHECK(topoloc_map_view_count(map, &views));
    CHECK(topoloc_map_edge_count(map, &edges));
    CHECK(topoloc_map_descriptor_dim(map, &dim));
    CHECK(topoloc_map_descriptor_kind(map, text, sizeof text, &needed));
    CHECK(topoloc_map_descriptor_model(map, text, sizeof text, &needed));
    CHECK(topoloc_map_keypoint_total(map, &keypoints));
    uint32_t ids[MAX_ITEMS];
    size_t count = 0;
    for (uint32_t p = 0; p < places && p < MAX_ITEMS; p++) {
        double xyz[3];
        bool has = false;
        CHECK(topoloc_map_neighbours(map, p, ids, MAX_ITEMS, &count));
        CHECK(topoloc_map_place_views(map, p, ids, MAX_ITEMS, &count));
        CHECK(topoloc_map_place_position(map, p, xyz, &has));
    }
    for (size_t e = 0; e < edges && e < MAX_ITEMS; e++) {
        uint32_t a, b;
        float w;
        CHECK(topoloc_map_edge(map, e, &a, &b, &w));
    }
    float *descriptor = calloc(dim, sizeof(float));
    float xy[2 * 64];
    for (uint32_t v = 0; v < views && v < MAX_ITEMS; v++) {
        topoloc_view_info info;
        topoloc_view_info_default(&info);
        CHECK(topoloc_map_view_info(map, v, &info));
        CHECK(topoloc_map_view_image(map, v, text, sizeof text, &needed));
        CHECK(topoloc_map_view_descriptor(map, v, descriptor, dim));
        CHECK(topoloc_map_view_keypoints(map, v, xy, 64, &count));
    }
    /* Out-of-range ids are typed errors. */
    CHECK(topoloc_map_view_info(map, (uint32_t)views,
                                &(topoloc_view_info){.struct_size = sizeof(topoloc_view_info)}));
    CHECK(topoloc_map_neighbours(map, (uint32_t)places, ids, MAX_ITEMS, &count));

    /* A localizer follows view 0's descriptor for a few frames, then a loop detector is made
     * from the map (needs keyframe ids; a typed error otherwise). */
    if (views > 0 && topoloc_map_view_descriptor(map, 0, descriptor, dim) == TOPOLOC_OK) {
        topoloc_localizer *loc = NULL;
        topoloc_status s = CHECK(topoloc_localizer_new(map, NULL, &loc));
        EXPECT_NULL_ON_ERROR(s, loc);
        if (s == TOPOLOC_OK) {
            topoloc_candidate cands[5];
            for (int i = 0; i < 3; i++) {
                topoloc_frame frame;
                topoloc_frame_default(&frame);
                frame.timestamp = i;
                frame.descriptor = descriptor;
                frame.descriptor_len = dim;
                topoloc_result result;
                topoloc_result_default(&result);
                result.candidates = cands;
                result.candidates_capacity = 5;
                CHECK(topoloc_localizer_process(loc, &frame, &result));
            }
            topoloc_localizer_free(loc);
        }
    }
    topoloc_loop_detector *det = NULL;
    topoloc_status s = CHECK(topoloc_loop_detector_from_map(map, NULL, &det));
    EXPECT_NULL_ON_ERROR(s, det);
    topoloc_loop_detector_free(det);
    free(descriptor);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    topoloc_map *map = NULL;
    topoloc_status s = CHECK(topoloc_map_load_from_memory(data, size, NULL, &map));
    EXPECT_NULL_ON_ERROR(s, map);
    if (s == TOPOLOC_OK) {
        exercise(map);
        topoloc_map_free(map);
    }
    return 0;
}

size_t LLVMFuzzerCustomMutator(uint8_t *data, size_t size, size_t max_size, unsigned int seed)
{
    return topoloc_fuzz_mutate_map(data, size, max_size, seed);
}
