/*
 * Section "Skeleton graphs from occupancy grids" of topoloc.h: topological graphs built from
 * small hand-made occupancy grids (a T junction, a ring) through topoloc_graph_from_occupancy,
 * their options, places, edges and skeleton voxels, and the errors of each.
 */
#include "harness.h"

#include <stdlib.h>

#define SK_VOXEL 0.2
#define SK_NX 45u
#define SK_NY 35u
#define SK_NZ 10u
#define SK_CELLS (SK_NX * SK_NY * SK_NZ)

/* A T junction: a 7 m corridor along x and a 5 m stem along y, 1.2 m wide. */
static const unsigned g_sk_t[2][4] = {{5, 5, 40, 11}, {19, 5, 25, 30}};
/* A ring corridor 7 m x 5 m around a solid block. */
static const unsigned g_sk_ring[4][4] = {
    {5, 5, 40, 11}, {5, 24, 40, 30}, {5, 5, 11, 30}, {34, 5, 40, 30}};

static const size_t g_sk_dims[3] = {SK_NX, SK_NY, SK_NZ};
static const double g_sk_origin[3] = {0.0, 0.0, 0.0};

/* The grid of the checks that run. */
static uint8_t g_cells[SK_CELLS];

/* Makes g_cells a grid of SK_NX x SK_NY x SK_NZ voxels of SK_VOXEL m (2 m high), occupied except
 * for the `count` rectangles {x0, y0, x1, y1} (voxels, half-open) carved over the full height. */
static void sk_carve(const unsigned (*rects)[4], size_t count)
{
    size_t x, y, z, r;
    memset(g_cells, 1, SK_CELLS);
    for (z = 0; z < SK_NZ; z++) {
        for (y = 0; y < SK_NY; y++) {
            for (x = 0; x < SK_NX; x++) {
                for (r = 0; r < count; r++) {
                    if (x >= rects[r][0] && x < rects[r][2] && y >= rects[r][1] &&
                        y < rects[r][3]) {
                        g_cells[x + SK_NX * (y + SK_NY * z)] = 0;
                    }
                }
            }
        }
    }
}

/* The graph of g_cells with `opts`. */
static topoloc_status sk_graph(const topoloc_skeleton_options *opts, topoloc_graph **g)
{
    return topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, g_cells, SK_CELLS, opts,
                                        g);
}

/* Counts the places of each TOPOLOC_NODE_* kind and the degree of each place (<= 64 places). */
static bool sk_summary(const topoloc_graph *g, size_t kinds[4], size_t degree[64], size_t *places,
                       size_t *edges)
{
    size_t i;
    uint32_t a, b, kind;
    double xyz[3], length;
    memset(kinds, 0, 4 * sizeof kinds[0]);
    memset(degree, 0, 64 * sizeof degree[0]);
    if (topoloc_graph_place_count(g, places) != TOPOLOC_OK ||
        topoloc_graph_edge_count(g, edges) != TOPOLOC_OK || *places > 64) {
        return false;
    }
    for (i = 0; i < *places; i++) {
        if (topoloc_graph_place(g, (uint32_t)i, xyz, &kind) != TOPOLOC_OK || kind > 3) {
            return false;
        }
        kinds[kind]++;
    }
    for (i = 0; i < *edges; i++) {
        if (topoloc_graph_edge(g, i, &a, &b, &length) != TOPOLOC_OK || a >= b || b >= *places) {
            return false;
        }
        degree[a]++;
        degree[b]++;
    }
    return true;
}

static void skeleton_options_have_their_defaults_and_refuse_short_sizes_and_null(void)
{
    topoloc_skeleton_options opts;

    SECTION();
    CHECK_OK(topoloc_skeleton_options_default(&opts));
    CHECK(opts.struct_size == sizeof opts && !opts.use_z_band);
    CHECK(opts.merge_radius_m == 1.0 && opts.max_edge_m == 3.0 && opts.min_clearance_m == 0.0);
    CHECK(opts.corner_angle_deg == 40.0 && opts.corner_scale_m == 0.5 && opts.min_spur_m == 1.0);
    CHECK_STATUS(topoloc_skeleton_options_init(&opts, sizeof(size_t)), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_NULL(topoloc_skeleton_options_init(NULL, sizeof opts), "NULL");
}

/* One branch, three ends, a tree; the branch comes first and has three neighbours; edges have
 * a < b, are sorted, and measure the straight distance, at most max_edge_m. Returns the counts
 * of places and edges. */
static void a_t_junction_is_a_tree_with_a_branch_of_three_neighbours_and_three_ends(
    const topoloc_graph *g, const topoloc_skeleton_options *opts, size_t *places, size_t *edges)
{
    size_t kinds[4], degree[64], i;
    uint32_t a = 0, b = 0, kind = 0;
    double xyz[3], xyz2[3], length = 0.0;

    SECTION();
    CHECK(sk_summary(g, kinds, degree, places, edges));
    CHECK(kinds[TOPOLOC_NODE_BRANCH] == 1 && kinds[TOPOLOC_NODE_END] == 3);
    CHECK(kinds[TOPOLOC_NODE_CORNER] == 0 && kinds[TOPOLOC_NODE_INTERMEDIATE] >= 1);
    CHECK(*edges + 1 == *places);
    CHECK_OK(topoloc_graph_place(g, 0, xyz, &kind));
    CHECK(kind == TOPOLOC_NODE_BRANCH && degree[0] == 3);
    CHECK_NEAR(xyz[0], 4.5, 0.5);
    CHECK_NEAR(xyz[1], 1.6, 0.5);
    CHECK(xyz[2] > 0.0 && xyz[2] < 2.0);
    for (i = 0; i < *edges; i++) {
        uint32_t pa = a, pb = b;
        CHECK_OK(topoloc_graph_edge(g, i, &a, &b, &length));
        CHECK(i == 0 || pa < a || (pa == a && pb < b));
        CHECK_OK(topoloc_graph_place(g, a, xyz, &kind));
        CHECK_OK(topoloc_graph_place(g, b, xyz2, &kind));
        CHECK_NEAR(length * length,
                   (xyz[0] - xyz2[0]) * (xyz[0] - xyz2[0]) +
                       (xyz[1] - xyz2[1]) * (xyz[1] - xyz2[1]) +
                       (xyz[2] - xyz2[2]) * (xyz[2] - xyz2[2]),
                   1e-9);
        CHECK(length > 0.0 && length <= opts->max_edge_m);
    }
}

static void
the_skeleton_is_copied_after_asking_its_size_and_every_voxel_is_free(const topoloc_graph *g)
{
    size_t count = 0, n = 0, i;
    uint32_t *voxels;
    bool all_free = true;

    SECTION();
    CHECK_STATUS(topoloc_graph_skeleton(g, NULL, 0, &count), TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(count > 0 && count % 3 == 0);
    voxels = malloc(count * sizeof *voxels);
    CHECK(voxels != NULL);
    if (voxels == NULL) {
        return;
    }
    CHECK_STATUS(topoloc_graph_skeleton(g, voxels, count - 1, &n), TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(n == count);
    CHECK_OK(topoloc_graph_skeleton(g, voxels, count, &n));
    for (i = 0; i + 2 < count; i += 3) {
        all_free = all_free && voxels[i] < SK_NX && voxels[i + 1] < SK_NY &&
                   voxels[i + 2] < SK_NZ &&
                   g_cells[voxels[i] + SK_NX * (voxels[i + 1] + SK_NY * voxels[i + 2])] == 0;
    }
    CHECK(all_free);
    free(voxels);
}

/* Built again from the same grid (NULL options: the defaults), bit for bit. */
static void the_same_grid_gives_the_same_graph(const topoloc_graph *g, size_t places, size_t edges)
{
    topoloc_graph *again = NULL;
    size_t n = 0, i;
    uint32_t a = 0, b = 0, kind = 0;
    double xyz[3], xyz2[3], length = 0.0, length2 = 0.0;
    bool same;

    SECTION();
    CHECK_OK(sk_graph(NULL, &again));
    if (again == NULL) {
        return;
    }
    CHECK_OK(topoloc_graph_place_count(again, &n));
    same = n == places;
    for (i = 0; same && i < places; i++) {
        uint32_t k2 = 0;
        CHECK_OK(topoloc_graph_place(g, (uint32_t)i, xyz, &kind));
        CHECK_OK(topoloc_graph_place(again, (uint32_t)i, xyz2, &k2));
        same = memcmp(xyz, xyz2, sizeof xyz) == 0 && kind == k2;
    }
    for (i = 0; same && i < edges; i++) {
        uint32_t a2 = 0, b2 = 0;
        CHECK_OK(topoloc_graph_edge(g, i, &a, &b, &length));
        CHECK_OK(topoloc_graph_edge(again, i, &a2, &b2, &length2));
        same = a == a2 && b == b2 && memcmp(&length, &length2, sizeof length) == 0;
    }
    CHECK(same);
    topoloc_graph_free(again);
}

/* UNKNOWN_PLACE for a place, INVALID_ARGUMENT for an edge; outputs untouched. */
static void places_and_edges_out_of_range_or_null_are_refused(const topoloc_graph *g, size_t places,
                                                              size_t edges)
{
    uint32_t a = 77, b = 0, kind = 77;
    double xyz[3], length = 0.0;
    size_t n = 0;

    SECTION();
    CHECK_ERROR(topoloc_graph_place(g, (uint32_t)places, xyz, &kind), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK(kind == 77);
    CHECK_STATUS(topoloc_graph_edge(g, edges, &a, &b, &length), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(a == 77);
    CHECK_NULL(topoloc_graph_place_count(NULL, &n), "graph");
    CHECK_NULL(topoloc_graph_edge_count(g, NULL), "out");
    CHECK_NULL(topoloc_graph_place(g, 0, NULL, &kind), "xyz");
    CHECK_NULL(topoloc_graph_place(g, 0, xyz, NULL), "kind");
    CHECK_NULL(topoloc_graph_edge(g, 0, &a, &b, NULL), "length_m");
    CHECK_NULL(topoloc_graph_skeleton(NULL, NULL, 0, &n), "graph");
}

/* Sets a height band in `opts`. */
static void a_height_band_keeps_every_place_in_it(topoloc_skeleton_options *opts)
{
    topoloc_graph *g = NULL;
    size_t places = 0, i;
    uint32_t kind = 0;
    double xyz[3];

    SECTION();
    opts->use_z_band = true;
    opts->z_min_m = 0.5;
    opts->z_max_m = 0.9;
    CHECK_OK(sk_graph(opts, &g));
    if (g != NULL) {
        CHECK_OK(topoloc_graph_place_count(g, &places));
        for (i = 0; i < places; i++) {
            CHECK_OK(topoloc_graph_place(g, (uint32_t)i, xyz, &kind));
            CHECK(xyz[2] >= 0.5 && xyz[2] <= 0.9);
        }
    }
    topoloc_graph_free(g);
}

/* A cycle (every place has two neighbours) with four corners. Sets `opts` to the defaults. */
static void a_ring_is_a_cycle_with_four_corners(topoloc_skeleton_options *opts)
{
    topoloc_graph *g = NULL;
    size_t kinds[4], degree[64], places = 0, edges = 0, i;
    bool two = true;

    SECTION();
    CHECK_OK(topoloc_skeleton_options_default(opts));
    sk_carve(g_sk_ring, 4);
    CHECK_OK(sk_graph(opts, &g));
    if (g == NULL) {
        return;
    }
    CHECK(sk_summary(g, kinds, degree, &places, &edges));
    CHECK(edges == places && places >= 4);
    for (i = 0; i < places; i++) {
        two = two && degree[i] == 2;
    }
    CHECK(two);
    CHECK(kinds[TOPOLOC_NODE_CORNER] == 4 && kinds[TOPOLOC_NODE_END] == 0 &&
          kinds[TOPOLOC_NODE_BRANCH] == 0);
    topoloc_graph_free(g);
}

/* NULLs, sizes, a full grid and options out of range, each named; the out-parameter untouched.
 * `opts` start at the defaults. */
static void bad_grids_and_options_are_refused_naming_them(topoloc_skeleton_options *opts)
{
    topoloc_graph *const sentinel = (topoloc_graph *)(void *)opts;
    topoloc_graph *g = sentinel;

    SECTION();
    CHECK_NULL(
        topoloc_graph_from_occupancy(NULL, SK_VOXEL, g_sk_origin, g_cells, SK_CELLS, opts, &g),
        "dims");
    CHECK_NULL(topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, NULL, g_cells, SK_CELLS, opts, &g),
               "origin");
    CHECK_NULL(
        topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, NULL, SK_CELLS, opts, &g),
        "cells");
    CHECK_NULL(sk_graph(opts, NULL), "out");
    CHECK_STATUS(topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, g_cells,
                                              SK_CELLS - 1, opts, &g),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("cells_len");
    CHECK_STATUS(
        topoloc_graph_from_occupancy(g_sk_dims, 0.0, g_sk_origin, g_cells, SK_CELLS, opts, &g),
        TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("voxel_size");
    opts->merge_radius_m = -1.0;
    CHECK_STATUS(sk_graph(opts, &g), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("merge_radius_m");
    CHECK_OK(topoloc_skeleton_options_default(opts));
    opts->max_edge_m = 0.3; /* under two voxels */
    CHECK_STATUS(sk_graph(opts, &g), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("max_edge_m");
    CHECK_OK(topoloc_skeleton_options_default(opts));
    opts->use_z_band = true;
    opts->z_min_m = 5.0;
    opts->z_max_m = 6.0;
    CHECK_STATUS(sk_graph(opts, &g), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("z_band");
    CHECK_OK(topoloc_skeleton_options_default(opts));
    opts->struct_size = 3;
    CHECK_STATUS(sk_graph(opts, &g), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_OK(topoloc_skeleton_options_default(opts));
    memset(g_cells, 1, SK_CELLS);
    CHECK_STATUS(sk_graph(opts, &g), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("cells");
    CHECK(g == sentinel);
}

void run_skeleton_tests(void)
{
    topoloc_skeleton_options opts;
    topoloc_graph *g = NULL;
    size_t places = 0, edges = 0;

    skeleton_options_have_their_defaults_and_refuse_short_sizes_and_null();
    CHECK_OK(topoloc_skeleton_options_default(&opts));
    sk_carve(g_sk_t, 2);
    CHECK_OK(sk_graph(&opts, &g));
    if (g == NULL) {
        return;
    }
    a_t_junction_is_a_tree_with_a_branch_of_three_neighbours_and_three_ends(g, &opts, &places,
                                                                            &edges);
    the_skeleton_is_copied_after_asking_its_size_and_every_voxel_is_free(g);
    the_same_grid_gives_the_same_graph(g, places, edges);
    places_and_edges_out_of_range_or_null_are_refused(g, places, edges);
    topoloc_graph_free(g);
    topoloc_graph_free(NULL);

    a_height_band_keeps_every_place_in_it(&opts);
    a_ring_is_a_cycle_with_four_corners(&opts);
    bad_grids_and_options_are_refused_naming_them(&opts);
}
