/*
 * The README's loop-closure path, as a new host copies it: run.sh extracts the README's C
 * block that defines `close_loops` into the build directory and compiles it into this program
 * unchanged; these tests run it over two runs of the generated places. The first run starts
 * empty and finds no loop (it never revisits); the second, reloaded from the file the first
 * saved, closes a loop at every place. A describer map built from the first run's own images
 * is fine for describing: the detector never starts from it, so nothing matches itself.
 */
#include "harness.h"

#include <stdio.h>

/* The README's function (README.md, section "Keyframe database and loop hints"). */
int close_loops(const topoloc_map *describer_map, const char *earlier, const char *save_to,
                const uint8_t *const *images, uint32_t width, uint32_t height, const double *times,
                const double intrinsics[4], size_t count);

static void the_readmes_two_runs_close_a_loop_at_every_place(const topoloc_map *image_map)
{
    static uint8_t revisits[IMG_PLACES][IMG_PIXELS];
    const uint8_t *first[IMG_PLACES], *second[IMG_PLACES];
    const double intrinsics[4] = {150.0, 150.0, 79.5, 59.5};
    double times[IMG_PLACES];
    char xfeat[4200], run1[4200], run2[4200];
    topoloc_map *saved = NULL;
    size_t views = 0;
    uint32_t p;
    int edges;

    SECTION();
    /* The README's describer takes the default local features (XFeat). */
    if (!models_ready(XFEAT_MODEL_FILE, xfeat, sizeof xfeat, "README loop path")) {
        return;
    }
    for (p = 0; p < IMG_PLACES; p++) {
        make_revisit(g_place_px[p], 500u + p, revisits[p]);
        first[p] = g_place_px[p];
        second[p] = revisits[p];
        times[p] = 2.0 * p; /* keyframes 2 s apart, each run's clock from 0 */
    }
    tmp_path(run1, sizeof run1, "readme-run1.topoloc");
    tmp_path(run2, sizeof run2, "readme-run2.topoloc");

    edges = close_loops(image_map, NULL, run1, first, IMG_W, IMG_H, times, intrinsics, IMG_PLACES);
    CHECK(edges == 0); /* one pass: no revisit, and no place matches its own image */
    edges = close_loops(image_map, run1, run2, second, IMG_W, IMG_H, times, intrinsics, IMG_PLACES);
    printf("   the README's second run found %d loop edges over %u places\n", edges,
           (unsigned)IMG_PLACES);
    CHECK(edges >= (int)IMG_PLACES - 1 && edges <= (int)IMG_PLACES);
    /* The second run saved both runs' keyframes, its ids after the first run's. */
    CHECK_OK(topoloc_map_load(run2, NULL, &saved));
    if (saved != NULL) {
        topoloc_view_info info;
        CHECK_OK(topoloc_map_view_count(saved, &views));
        CHECK(views == 2u * IMG_PLACES);
        CHECK_OK(topoloc_view_info_default(&info));
        CHECK_OK(topoloc_map_view_info(saved, (uint32_t)views - 1u, &info));
        CHECK(info.keyframe_id == 2u * IMG_PLACES - 1u);
    }
    topoloc_map_free(saved);
    /* A missing earlier run is a typed error, reported and returned as -1. */
    CHECK(close_loops(image_map, "/nonexistent/run.topoloc", run2, second, IMG_W, IMG_H, times,
                      intrinsics, IMG_PLACES) == -1);
    CHECK(remove(run1) == 0 && remove(run2) == 0);
}

void run_readme_tests(const topoloc_map *image_map)
{
    the_readmes_two_runs_close_a_loop_at_every_place(image_map);
}
