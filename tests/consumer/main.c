/*
 * A program that uses an *installed* topoloc through find_package(Topoloc): builds a small map,
 * saves it, loads it back, localizes a few frames and checks the answers. Built twice by
 * tests/consumer/CMakeLists.txt: against Topoloc::topoloc (shared) and Topoloc::topoloc_static.
 * Exits non-zero on any failure.
 */
#define _POSIX_C_SOURCE 200809L

#include <topoloc.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#ifndef CONSUMER_VARIANT
#define CONSUMER_VARIANT "shared"
#endif

#define DIM 8u
#define PLACES 3u
#define VIEWS_PER_PLACE 2u

static int failures;

#define EXPECT(cond)                                                                               \
    do {                                                                                           \
        if (!(cond)) {                                                                             \
            failures++;                                                                            \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond);               \
        }                                                                                          \
    } while (0)

/* Runs a topoloc call; on failure reports it with the library's message and returns from main. */
#define TRY(call)                                                                                  \
    do {                                                                                           \
        topoloc_status try_status_ = (call);                                                       \
        if (try_status_ != TOPOLOC_OK) {                                                           \
            char try_message_[512] = "";                                                           \
            topoloc_last_error_message(try_message_, sizeof try_message_, NULL);                   \
            fprintf(stderr, "%s:%d: %s failed: %s (%s)\n", __FILE__, __LINE__, #call,              \
                    topoloc_status_str((uint32_t)try_status_), try_message_);                      \
            return 1;                                                                              \
        }                                                                                          \
    } while (0)

/* Descriptor of view `j` of place `p`: mostly the place's own axis pair. */
static void view_descriptor(uint32_t p, uint32_t j, float out[DIM])
{
    uint32_t d;
    for (d = 0; d < DIM; d++) {
        out[d] = 0.05f;
    }
    out[2 * p] = 1.0f;
    out[2 * p + 1] = j == 0 ? 0.3f : -0.3f;
}

int main(void)
{
    topoloc_map_builder *builder = NULL;
    topoloc_map *built = NULL, *map = NULL;
    topoloc_localizer *localizer = NULL;
    topoloc_frame frame;
    topoloc_result result;
    topoloc_candidate candidates[PLACES];
    char path[512], kind[32];
    const char *tmp = getenv("TMPDIR");
    size_t count = 0;
    uint32_t p, j, id, k;
    float desc[DIM];

    printf("consumer (%s): header %s, library %s\n", CONSUMER_VARIANT, TOPOLOC_VERSION_STRING,
           topoloc_version());
    EXPECT(strcmp(topoloc_version(), TOPOLOC_VERSION_STRING) == 0);
    EXPECT(topoloc_abi_version() == TOPOLOC_ABI_VERSION);

    TRY(topoloc_map_builder_new("consumer-desc", "v1", DIM, &builder));
    for (p = 0; p < PLACES; p++) {
        double position[3];
        position[0] = 3.0 * p;
        position[1] = 0.0;
        position[2] = 0.0;
        TRY(topoloc_map_builder_add_place(builder, position, &id));
        EXPECT(id == p);
        for (j = 0; j < VIEWS_PER_PLACE; j++) {
            view_descriptor(p, j, desc);
            TRY(topoloc_map_builder_add_view(builder, p, desc, DIM, NULL, &id));
        }
        if (p > 0) {
            TRY(topoloc_map_builder_add_edge(builder, p - 1, p, 1.0f));
        }
    }
    TRY(topoloc_map_builder_build(builder, &built));
    topoloc_map_builder_free(builder);

    snprintf(path, sizeof path, "%s/topoloc-consumer-%s-%ld.map", tmp && *tmp ? tmp : "/tmp",
             CONSUMER_VARIANT, (long)getpid());
    TRY(topoloc_map_save(built, path));
    topoloc_map_free(built);
    TRY(topoloc_map_load(path, NULL, &map));
    remove(path);

    TRY(topoloc_map_place_count(map, &count));
    EXPECT(count == PLACES);
    TRY(topoloc_map_view_count(map, &count));
    EXPECT(count == PLACES * VIEWS_PER_PLACE);
    TRY(topoloc_map_edge_count(map, &count));
    EXPECT(count == PLACES - 1);
    TRY(topoloc_map_descriptor_kind(map, kind, sizeof kind, NULL));
    EXPECT(strcmp(kind, "consumer-desc") == 0);

    TRY(topoloc_localizer_new(map, NULL, &localizer));
    topoloc_map_free(map); /* the localizer keeps its own reference */
    TRY(topoloc_frame_default(&frame));
    TRY(topoloc_result_default(&result));
    result.candidates = candidates;
    result.candidates_capacity = PLACES;
    for (k = 0; k < 2 * PLACES; k++) {
        uint32_t place = k / 2;
        view_descriptor(place, k % 2, desc);
        desc[DIM - 1] += 0.02f; /* not an exact copy of the view */
        frame.timestamp = 0.5 * k;
        frame.descriptor = desc;
        frame.descriptor_len = DIM;
        TRY(topoloc_localizer_process(localizer, &frame, &result));
        EXPECT(result.frame_index == k);
        EXPECT(result.place == place);
        EXPECT(result.view == place * VIEWS_PER_PLACE + k % 2);
        EXPECT(!result.off_map);
        EXPECT(result.candidates_len == PLACES);
        EXPECT(result.candidates[0].place == place);
        EXPECT(result.candidates[0].probability >= result.candidates[1].probability);
    }
    /* A frame of the wrong length is refused and changes nothing. */
    frame.descriptor_len = DIM - 1;
    EXPECT(topoloc_localizer_process(localizer, &frame, &result) == TOPOLOC_ERR_DIMENSION_MISMATCH);
    frame.descriptor_len = DIM;
    frame.timestamp += 1.0;
    TRY(topoloc_localizer_process(localizer, &frame, &result));
    EXPECT(result.frame_index == 2 * PLACES);
    topoloc_localizer_free(localizer);

    if (failures != 0) {
        fprintf(stderr, "consumer (%s): %d checks failed\n", CONSUMER_VARIANT, failures);
        return 1;
    }
    printf("consumer (%s): ok\n", CONSUMER_VARIANT);
    return 0;
}
