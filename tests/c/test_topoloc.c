/*
 * C11 tests of the topoloc C ABI (include/topoloc.h), linked against the built library.
 *
 * Built by tests/c/run.sh with -std=c11 -Wall -Wextra -Werror -pedantic, and run plain, under
 * AddressSanitizer + UndefinedBehaviorSanitizer, under valgrind, and linked statically.
 *
 * Self-contained harness: CHECK* macros count passes and failures; the last line printed is
 * "N passed, M failed" and the exit status is non-zero when anything failed.
 *
 * The world used throughout: PLACES places on a line (with a loop edge), VIEWS_PER_PLACE views
 * each, DIM-dimensional descriptors from a fixed-seed generator. Views of one place are close to
 * each other, views of different places nearly orthogonal, and frames are noisy copies of views,
 * so the right answer is known for every frame.
 *
 * Skeleton graphs (their own section): topological graphs built from small hand-made occupancy
 * grids (a T junction, a ring) through topoloc_graph_from_occupancy, their accessors and errors.
 *
 * Images (the last section): maps built with the VLAD backend from small synthetic grey images
 * in memory and in PGM files, image frames of "revisits", bad and uninformative images, progress
 * and cancellation. The ONNX checks that need the model run only when scripts/setup-models.sh
 * has installed it, and not under valgrind.
 */
#define _POSIX_C_SOURCE 200809L

#include "topoloc.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

/* ------------------------------------------------------------------------------------------ */
/* Harness                                                                                     */
/* ------------------------------------------------------------------------------------------ */

static unsigned long g_passed;
static unsigned long g_failed;

static void check_impl(bool ok, const char *expr, const char *file, int line)
{
    if (ok) {
        g_passed++;
        return;
    }
    g_failed++;
    fprintf(stderr, "FAIL %s:%d: %s\n", file, line, expr);
}

/* Last error message of this thread, in a static buffer (the harness is single-threaded). */
static const char *last_error(void)
{
    static char buf[1024];
    size_t needed = 0;
    buf[0] = '\0';
    if (topoloc_last_error_message(buf, sizeof buf, &needed) != TOPOLOC_OK) {
        snprintf(buf, sizeof buf, "<message of %zu bytes does not fit>", needed);
    }
    return buf;
}

static void check_status_impl(topoloc_status got, uint32_t want, const char *expr, const char *file,
                              int line)
{
    if ((uint32_t)got == want) {
        g_passed++;
        return;
    }
    g_failed++;
    fprintf(stderr, "FAIL %s:%d: %s\n    returned %u (%s), expected %u (%s); last error: \"%s\"\n",
            file, line, expr, (unsigned)got, topoloc_status_str((uint32_t)got), (unsigned)want,
            topoloc_status_str(want), last_error());
}

#define CHECK(cond) check_impl((cond) ? true : false, #cond, __FILE__, __LINE__)
#define CHECK_OK(expr) check_status_impl((expr), TOPOLOC_OK, #expr, __FILE__, __LINE__)
#define CHECK_STATUS(expr, want)                                                                   \
    check_status_impl((expr), (uint32_t)(want), #expr, __FILE__, __LINE__)
#define CHECK_NEAR(a, b, tol) CHECK(((a) - (b)) <= (tol) && ((b) - (a)) <= (tol))

/* Sets the last error to a known message, so that a following call can be shown to set its own. */
static char g_primed[512];
static void prime_last_error(void)
{
    topoloc_map_builder *b = NULL;
    topoloc_status st = topoloc_map_builder_new("", NULL, 4, &b);
    if (st != TOPOLOC_ERR_INVALID_ARGUMENT || b != NULL) {
        fprintf(stderr, "harness: could not prime the last error (status %u)\n", (unsigned)st);
        topoloc_map_builder_free(b);
    }
    snprintf(g_primed, sizeof g_primed, "%s", last_error());
}

/* Checks that `got` is TOPOLOC_ERR_NULL_ARGUMENT, with a fresh, non-empty message naming `name`. */
static void check_null_impl(topoloc_status got, const char *name, const char *expr,
                            const char *file, int line)
{
    const char *msg;
    check_status_impl(got, TOPOLOC_ERR_NULL_ARGUMENT, expr, file, line);
    msg = last_error();
    check_impl(msg[0] != '\0', "last error message is not empty", file, line);
    check_impl(strcmp(msg, g_primed) != 0, "the call set its own last error message", file, line);
    if (strstr(msg, name) == NULL) {
        g_failed++;
        fprintf(stderr, "FAIL %s:%d: %s\n    message \"%s\" does not name '%s'\n", file, line, expr,
                msg, name);
    } else {
        g_passed++;
    }
}

#define CHECK_NULL(expr, name)                                                                     \
    do {                                                                                           \
        topoloc_status check_null_status_;                                                         \
        prime_last_error();                                                                        \
        check_null_status_ = (expr);                                                               \
        check_null_impl(check_null_status_, (name), #expr, __FILE__, __LINE__);                    \
    } while (0)

/* Checks that a failed call left a non-empty message. */
#define CHECK_HAS_MESSAGE() CHECK(last_error()[0] != '\0')

static bool contains_text(const char *haystack, const char *needle)
{
    return strstr(haystack, needle) != NULL;
}

/* CHECK that the last error message contains `text`, showing the message when it does not. */
#define CHECK_MESSAGE_HAS(text)                                                                    \
    do {                                                                                           \
        const char *check_msg_ = last_error();                                                     \
        if (!contains_text(check_msg_, (text))) {                                                  \
            fprintf(stderr, "    message \"%s\" does not contain \"%s\"\n", check_msg_, (text));   \
        }                                                                                          \
        CHECK(contains_text(check_msg_, (text)));                                                  \
    } while (0)

/* Checks a map's place, view and edge counts (each a check of its own). */
static void check_counts_impl(const topoloc_map *map, size_t places, size_t views, size_t edges,
                              const char *file, int line)
{
    size_t n = 0;
    check_status_impl(topoloc_map_place_count(map, &n), TOPOLOC_OK, "place_count", file, line);
    check_impl(n == places, "place count", file, line);
    check_status_impl(topoloc_map_view_count(map, &n), TOPOLOC_OK, "view_count", file, line);
    check_impl(n == views, "view count", file, line);
    check_status_impl(topoloc_map_edge_count(map, &n), TOPOLOC_OK, "edge_count", file, line);
    check_impl(n == edges, "edge count", file, line);
}

#define CHECK_COUNTS(map, places, views, edges)                                                    \
    check_counts_impl((map), (places), (views), (edges), __FILE__, __LINE__)

static void section(const char *name)
{
    printf("-- %s\n", name);
    fflush(stdout);
}

/* ------------------------------------------------------------------------------------------ */
/* Test world                                                                                  */
/* ------------------------------------------------------------------------------------------ */

#define DIM 32u
#define PLACES 6u
#define VIEWS_PER_PLACE 4u
#define VIEWS (PLACES * VIEWS_PER_PLACE)
#define EDGES 6u
#define KIND "test-desc"
#define MODEL "test-model-v1"
/* The last view is added without attributes, to exercise "absent" answers. */
#define BARE_VIEW (VIEWS - 1u)

static float g_view_desc[VIEWS][DIM]; /* as given to the builder (not unit norm) */
static double g_place_pos[PLACES][3];
static double g_view_pose[VIEWS][16]; /* world_T_camera, row-major */
static char g_view_image[VIEWS][64];
/* Edges sorted by (a, b), as topoloc_map_edge reports them. */
static const uint32_t g_edges[EDGES][2] = {{0, 1}, {0, 5}, {1, 2}, {2, 3}, {3, 4}, {4, 5}};
static float g_edge_weight[EDGES];

static uint64_t g_rng = 0x9E3779B97F4A7C15u;

static double rng_uniform(void)
{
    /* xorshift64* */
    g_rng ^= g_rng >> 12;
    g_rng ^= g_rng << 25;
    g_rng ^= g_rng >> 27;
    return (double)((g_rng * 2685821657736338717u) >> 11) * (1.0 / 9007199254740992.0);
}

/* Zero-mean, roughly normal (Irwin-Hall of 4 uniforms). */
static float rng_normalish(void)
{
    return (float)(rng_uniform() + rng_uniform() + rng_uniform() + rng_uniform() - 2.0);
}

static void init_world(void)
{
    static const double c[4] = {1.0, 0.0, -1.0, 0.0};
    static const double s[4] = {0.0, 1.0, 0.0, -1.0};
    uint32_t p, j, d, e;
    float base[DIM];
    for (p = 0; p < PLACES; p++) {
        g_place_pos[p][0] = 2.0 * p;
        g_place_pos[p][1] = 1.0;
        g_place_pos[p][2] = 0.5;
        for (d = 0; d < DIM; d++) {
            base[d] = rng_normalish();
        }
        for (j = 0; j < VIEWS_PER_PLACE; j++) {
            uint32_t v = p * VIEWS_PER_PLACE + j;
            float scale = (float)(1 + v % 3); /* not unit norm: the builder normalises */
            double *m = g_view_pose[v];
            for (d = 0; d < DIM; d++) {
                g_view_desc[v][d] = scale * (base[d] + 0.3f * rng_normalish());
            }
            /* Yaw j * 90 degrees about z at the place's position. */
            memset(m, 0, sizeof g_view_pose[v]);
            m[0] = c[j];
            m[1] = -s[j];
            m[4] = s[j];
            m[5] = c[j];
            m[10] = 1.0;
            m[3] = g_place_pos[p][0];
            m[7] = g_place_pos[p][1];
            m[11] = g_place_pos[p][2];
            m[15] = 1.0;
            snprintf(g_view_image[v], sizeof g_view_image[v], "images/place_%u/view_%u.png",
                     (unsigned)p, (unsigned)j);
        }
    }
    for (e = 0; e < EDGES; e++) {
        g_edge_weight[e] = 1.0f + 0.5f * (float)e;
    }
}

/* NaN and infinity computed at run time (no libm, no constant-folding diagnostics). */
static double make_nan(void)
{
    volatile double zero = 0.0;
    return zero / zero;
}

static float make_inf(void)
{
    volatile float big = 1e30f;
    return big * big;
}

static double norm_of(const float *x, size_t n)
{
    double sum = 0.0;
    size_t i;
    for (i = 0; i < n; i++) {
        sum += (double)x[i] * (double)x[i];
    }
    /* Newton iterations instead of libm's sqrt, to keep the link line minimal. */
    {
        double r = sum > 1.0 ? sum : 1.0;
        int k;
        for (k = 0; k < 60; k++) {
            r = 0.5 * (r + sum / r);
        }
        return r;
    }
}

/* A frame descriptor: view `v`'s descriptor plus noise of relative size `noise`. */
static void noisy_copy(float out[DIM], uint32_t v, float noise)
{
    uint32_t d;
    double n = norm_of(g_view_desc[v], DIM) / 5.66; /* ~ per-component scale */
    for (d = 0; d < DIM; d++) {
        out[d] = g_view_desc[v][d] + noise * (float)n * rng_normalish();
    }
}

static bool contains_u32(const uint32_t *xs, size_t n, uint32_t x)
{
    size_t i;
    for (i = 0; i < n; i++) {
        if (xs[i] == x) {
            return true;
        }
    }
    return false;
}

/* Builds the test world with the builder, the last view without attributes when
 * `bare_view`; NULL on failure (failures are counted). */
static topoloc_map *build_world(bool bare_view)
{
    topoloc_map_builder *b = NULL;
    topoloc_map *map = NULL;
    uint32_t p, j, e;
    CHECK_OK(topoloc_map_builder_new(KIND, MODEL, DIM, &b));
    if (b == NULL) {
        return NULL;
    }
    for (p = 0; p < PLACES; p++) {
        uint32_t id = 12345;
        CHECK_OK(topoloc_map_builder_add_place(b, g_place_pos[p], &id));
        CHECK(id == p);
    }
    for (p = 0; p < PLACES; p++) {
        for (j = 0; j < VIEWS_PER_PLACE; j++) {
            uint32_t v = p * VIEWS_PER_PLACE + j;
            uint32_t id = 12345;
            topoloc_view_attributes attributes;
            CHECK_OK(topoloc_view_attributes_default(&attributes));
            CHECK(attributes.struct_size == sizeof attributes);
            CHECK(!attributes.has_keyframe_id && attributes.world_T_camera == NULL &&
                  attributes.image == NULL);
            attributes.has_keyframe_id = true;
            attributes.keyframe_id = 1000u + v;
            attributes.world_T_camera = g_view_pose[v];
            attributes.image = g_view_image[v];
            CHECK_OK(topoloc_map_builder_add_view(
                b, p, g_view_desc[v], DIM, (bare_view && v == BARE_VIEW) ? NULL : &attributes,
                &id));
            CHECK(id == v);
        }
    }
    for (e = 0; e < EDGES; e++) {
        /* Give some edges as (b, a): the map stores a < b. */
        uint32_t a = g_edges[e][e % 2], c = g_edges[e][1 - e % 2];
        CHECK_OK(topoloc_map_builder_add_edge(b, a, c, g_edge_weight[e]));
    }
    CHECK_OK(topoloc_map_builder_build(b, &map));
    topoloc_map_builder_free(b);
    return map;
}

/* The test world as the accessor checks expect it: its last view has no attributes. */
static topoloc_map *build_world_map(void) { return build_world(true); }

/* ------------------------------------------------------------------------------------------ */
/* Temporary files                                                                             */
/* ------------------------------------------------------------------------------------------ */

static char g_tmpdir[4096];

static void tmp_path(char *out, size_t len, const char *name)
{
    snprintf(out, len, "%s/%s", g_tmpdir, name);
}

static bool write_file(const char *path, const unsigned char *data, size_t len)
{
    FILE *f = fopen(path, "wb");
    bool ok;
    if (f == NULL) {
        return false;
    }
    ok = fwrite(data, 1, len, f) == len;
    return fclose(f) == 0 && ok;
}

/* Reads a whole file into a malloc'd buffer. */
static unsigned char *read_file(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    unsigned char *data = NULL;
    long size;
    if (f == NULL) {
        return NULL;
    }
    if (fseek(f, 0, SEEK_END) == 0 && (size = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0) {
        data = malloc((size_t)size + 1);
        if (data != NULL && fread(data, 1, (size_t)size, f) != (size_t)size) {
            free(data);
            data = NULL;
        }
        *len = (size_t)size;
    }
    fclose(f);
    return data;
}

/* ------------------------------------------------------------------------------------------ */
/* Tests                                                                                       */
/* ------------------------------------------------------------------------------------------ */

static void test_version(void)
{
    char composed[64];
    section("version and ABI");
    CHECK(topoloc_version() != NULL);
    CHECK(strcmp(topoloc_version(), TOPOLOC_VERSION_STRING) == 0);
    snprintf(composed, sizeof composed, "%d.%d.%d", TOPOLOC_VERSION_MAJOR, TOPOLOC_VERSION_MINOR,
             TOPOLOC_VERSION_PATCH);
    CHECK(strcmp(composed, TOPOLOC_VERSION_STRING) == 0);
    CHECK(topoloc_version() == topoloc_version()); /* static string */
    CHECK(topoloc_abi_version() == TOPOLOC_ABI_VERSION);
    CHECK(TOPOLOC_OK == 0);
}

static void test_status_str(void)
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
    section("topoloc_status_str");
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

/* Reads every accessor of the test world's map and compares with what was built. */
static void check_world_accessors(const topoloc_map *map)
{
    size_t count = 0, needed = 0;
    uint32_t dim = 0, p, v, e;
    char text[128];
    size_t n_neighbours[PLACES] = {0};

    CHECK_COUNTS(map, PLACES, VIEWS, EDGES);
    CHECK_OK(topoloc_map_descriptor_dim(map, &dim));
    CHECK(dim == DIM);

    memset(text, 'x', sizeof text);
    CHECK_OK(topoloc_map_descriptor_kind(map, text, sizeof text, &needed));
    CHECK(strcmp(text, KIND) == 0);
    CHECK(needed == strlen(KIND) + 1);
    CHECK_OK(topoloc_map_descriptor_kind(map, text, strlen(KIND) + 1, NULL)); /* exact fit */
    CHECK(strcmp(text, KIND) == 0);
    CHECK_OK(topoloc_map_descriptor_model(map, text, sizeof text, &needed));
    CHECK(strcmp(text, MODEL) == 0);
    CHECK(needed == strlen(MODEL) + 1);

    for (e = 0; e < EDGES; e++) {
        n_neighbours[g_edges[e][0]]++;
        n_neighbours[g_edges[e][1]]++;
    }
    for (p = 0; p < PLACES; p++) {
        uint32_t ids[16];
        double xyz[3] = {-1.0, -1.0, -1.0};
        bool has_position = false;
        size_t i;
        count = 999;
        CHECK_OK(topoloc_map_neighbours(map, p, ids, 16, &count));
        CHECK(count == n_neighbours[p]);
        for (e = 0; e < EDGES; e++) {
            if (g_edges[e][0] == p) {
                CHECK(contains_u32(ids, count, g_edges[e][1]));
            } else if (g_edges[e][1] == p) {
                CHECK(contains_u32(ids, count, g_edges[e][0]));
            }
        }
        count = 999;
        CHECK_OK(topoloc_map_place_views(map, p, ids, 16, &count));
        CHECK(count == VIEWS_PER_PLACE);
        for (i = 0; i < VIEWS_PER_PLACE; i++) {
            CHECK(contains_u32(ids, count, p * VIEWS_PER_PLACE + (uint32_t)i));
        }
        CHECK_OK(topoloc_map_place_views(map, p, ids, 16, NULL)); /* count is optional */
        CHECK_OK(topoloc_map_place_position(map, p, xyz, &has_position));
        CHECK(has_position);
        CHECK(xyz[0] == g_place_pos[p][0] && xyz[1] == g_place_pos[p][1] &&
              xyz[2] == g_place_pos[p][2]);
    }

    for (e = 0; e < EDGES; e++) {
        uint32_t a = 99, b = 99;
        float w = -1.0f;
        CHECK_OK(topoloc_map_edge(map, e, &a, &b, &w));
        CHECK(a == g_edges[e][0] && b == g_edges[e][1]);
        CHECK(a < b);
        CHECK(w == g_edge_weight[e]);
    }

    for (v = 0; v < VIEWS; v++) {
        topoloc_view_info info;
        float desc[DIM];
        double n = norm_of(g_view_desc[v], DIM);
        uint32_t d;
        int k;
        memset(&info, 0xAB, sizeof info);
        CHECK_OK(topoloc_view_info_default(&info));
        CHECK_OK(topoloc_map_view_info(map, v, &info));
        CHECK(info.struct_size == sizeof info);
        CHECK(info.place == v / VIEWS_PER_PLACE);
        if (v == BARE_VIEW) {
            CHECK(!info.has_keyframe_id);
            CHECK(!info.has_pose);
            for (k = 0; k < 16; k++) {
                CHECK(info.world_T_camera[k] == ((k % 5 == 0) ? 1.0 : 0.0)); /* identity */
            }
        } else {
            CHECK(info.has_keyframe_id);
            CHECK(info.keyframe_id == 1000u + v);
            CHECK(info.has_pose);
            for (k = 0; k < 16; k++) {
                CHECK_NEAR(info.world_T_camera[k], g_view_pose[v][k], 1e-9);
            }
        }

        memset(text, 'x', sizeof text);
        needed = 0;
        CHECK_OK(topoloc_map_view_image(map, v, text, sizeof text, &needed));
        if (v == BARE_VIEW) {
            CHECK(text[0] == '\0');
            CHECK(needed == 1);
        } else {
            CHECK(strcmp(text, g_view_image[v]) == 0);
            CHECK(needed == strlen(g_view_image[v]) + 1);
        }

        CHECK_OK(topoloc_map_view_descriptor(map, v, desc, DIM));
        for (d = 0; d < DIM; d++) {
            CHECK_NEAR((double)desc[d], (double)g_view_desc[v][d] / n, 1e-6);
        }
        CHECK_NEAR(norm_of(desc, DIM), 1.0, 1e-5);
        CHECK_OK(topoloc_map_view_descriptor(map, v, desc, DIM + 5)); /* larger buffer is fine */
    }
}

/* True when the candidate list is well formed: sorted by probability, the first is the result. */
static bool candidates_consistent(const topoloc_result *r)
{
    size_t i;
    if (r->candidates_len == 0) {
        return true;
    }
    if (r->candidates[0].place != r->place || r->candidates[0].view != r->view ||
        r->candidates[0].probability != r->confidence ||
        r->candidates[0].similarity != r->similarity) {
        return false;
    }
    for (i = 0; i < r->candidates_len; i++) {
        const topoloc_candidate *c = &r->candidates[i];
        if (!(c->probability >= 0.0f && c->probability <= 1.0f) || c->place >= PLACES ||
            c->view >= VIEWS || c->view / VIEWS_PER_PLACE != c->place) {
            return false;
        }
        if (i > 0 && c->probability > r->candidates[i - 1].probability) {
            return false;
        }
    }
    return true;
}

static bool candidates_distinct(const topoloc_result *r)
{
    size_t i, j;
    for (i = 0; i < r->candidates_len; i++) {
        for (j = 0; j < i; j++) {
            if (r->candidates[i].place == r->candidates[j].place) {
                return false;
            }
        }
    }
    return true;
}

static void test_full_flow(void)
{
    topoloc_map *built = NULL, *loaded = NULL, *from_memory = NULL;
    topoloc_localizer *loc = NULL;
    topoloc_localizer_options options;
    topoloc_frame frame;
    topoloc_result result;
    topoloc_candidate candidates[8];
    char path[4200];
    unsigned char *bytes;
    size_t len = 0, count = 0;
    float desc[DIM];
    double odometry[16] = {1, 0, 0, 2, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    double t = 100.0;
    uint64_t expected_index = 0;
    uint32_t k, rep;

    section("full flow: builder -> build -> save -> load -> accessors -> localize -> reset");
    built = build_world_map();
    CHECK(built != NULL);
    if (built == NULL) {
        return;
    }
    check_world_accessors(built);

    tmp_path(path, sizeof path, "world.topoloc");
    CHECK_OK(topoloc_map_save(built, path));
    CHECK_OK(topoloc_map_save(built, path)); /* replacing an existing file */
    topoloc_map_free(built);

    CHECK_OK(topoloc_map_load(path, NULL, &loaded));
    if (loaded == NULL) {
        return;
    }
    check_world_accessors(loaded);

    bytes = read_file(path, &len);
    CHECK(bytes != NULL && len > 0);
    if (bytes != NULL) {
        CHECK_OK(topoloc_map_load_from_memory(bytes, len, NULL, &from_memory));
        memset(bytes, 0, len); /* the map copied what it needs */
        free(bytes);
        if (from_memory != NULL) {
            check_world_accessors(from_memory);
        }
        topoloc_map_free(from_memory);
    }

    CHECK_OK(topoloc_localizer_options_default(&options));
    CHECK(options.struct_size == sizeof options);
    CHECK(options.mode == TOPOLOC_MODE_FILTER);
    CHECK(options.top_k == 5);
    CHECK(options.expected_descriptor_kind == NULL && options.expected_descriptor_model == NULL);
    CHECK_OK(topoloc_localizer_new(loaded, &options, &loc));
    /* The localizer keeps its own reference: the caller's handle may go now. */
    topoloc_map_free(loaded);
    if (loc == NULL) {
        return;
    }

    CHECK_OK(topoloc_frame_default(&frame));
    CHECK(frame.struct_size == sizeof frame);
    CHECK(frame.descriptor == NULL && frame.descriptor_len == 0 && frame.odometry == NULL);
    CHECK_OK(topoloc_result_default(&result));
    CHECK(result.struct_size == sizeof result);
    CHECK(result.candidates == NULL && result.candidates_capacity == 0);
    result.candidates = candidates;
    result.candidates_capacity = sizeof candidates / sizeof candidates[0];

    /* Walk along the line of places and back over the loop edge to place 0. */
    for (k = 0; k <= PLACES; k++) {
        uint32_t place = k % PLACES;
        for (rep = 0; rep < 3; rep++) {
            uint32_t source = place * VIEWS_PER_PLACE + (rep + k) % VIEWS_PER_PLACE;
            noisy_copy(desc, source, 0.02f);
            frame.timestamp = t;
            t += 0.1;
            frame.descriptor = desc;
            frame.descriptor_len = DIM;
            frame.odometry = (rep == 0 && k > 0) ? odometry : NULL;
            CHECK_OK(topoloc_localizer_process(loc, &frame, &result));
            CHECK(result.struct_size == sizeof result);
            CHECK(result.frame_index == expected_index);
            expected_index++;
            CHECK(result.place == place);
            CHECK(result.view == source);
            CHECK(result.similarity > 0.99f && result.similarity <= 1.0001f);
            CHECK(result.confidence > 0.5f && result.confidence <= 1.0f);
            CHECK(!result.off_map);
            CHECK(result.off_map_probability >= 0.0f && result.off_map_probability < 0.5f);
            CHECK(result.candidates == candidates);
            CHECK(result.candidates_capacity == 8);
            CHECK(result.candidates_len == 5); /* min(top_k = 5, places = 6, capacity = 8) */
            CHECK(candidates_consistent(&result));
            CHECK(candidates_distinct(&result));
        }
    }

    /* Reset: history forgotten, the frame index restarts and earlier timestamps are fine. */
    CHECK_OK(topoloc_localizer_reset(loc));
    noisy_copy(desc, 3 * VIEWS_PER_PLACE + 1, 0.02f);
    frame.timestamp = 0.0;
    frame.odometry = NULL;
    CHECK_OK(topoloc_localizer_process(loc, &frame, &result));
    CHECK(result.frame_index == 0);
    CHECK(result.place == 3);
    CHECK(candidates_consistent(&result));
    frame.timestamp = 0.0; /* equal timestamps are allowed */
    CHECK_OK(topoloc_localizer_process(loc, &frame, &result));
    CHECK(result.frame_index == 1);
    CHECK(result.place == 3);

    /* Smaller candidate buffers: min(top_k, capacity). */
    frame.timestamp = 1.0;
    result.candidates_capacity = 2;
    CHECK_OK(topoloc_localizer_process(loc, &frame, &result));
    CHECK(result.candidates_len == 2);
    CHECK(candidates_consistent(&result));
    result.candidates = NULL;
    result.candidates_capacity = 0;
    CHECK_OK(topoloc_localizer_process(loc, &frame, &result));
    CHECK(result.candidates_len == 0);
    CHECK(result.place == 3);
    CHECK(result.frame_index == 3);
    topoloc_localizer_free(loc);

    /* top_k above the number of places: every place is a candidate. */
    CHECK_OK(topoloc_map_load(path, NULL, &loaded));
    options.top_k = 10;
    loc = NULL;
    CHECK_OK(topoloc_localizer_new(loaded, &options, &loc));
    if (loc != NULL) {
        result.candidates = candidates;
        result.candidates_capacity = 8;
        CHECK_OK(topoloc_localizer_process(loc, &frame, &result));
        CHECK(result.candidates_len == PLACES);
        CHECK(candidates_consistent(&result));
        CHECK(candidates_distinct(&result));
        {
            float sum = 0.0f;
            size_t i;
            for (i = 0; i < result.candidates_len; i++) {
                sum += result.candidates[i].probability;
            }
            /* Every place is listed: the place probabilities and off-map add up to 1. */
            CHECK_NEAR(sum + result.off_map_probability, 1.0f, 1e-4f);
        }
    }
    topoloc_localizer_free(loc);

    /* Localizer with expected descriptor that matches (and "" meaning any). */
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.expected_descriptor_kind = KIND;
    options.expected_descriptor_model = "";
    loc = NULL;
    CHECK_OK(topoloc_localizer_new(loaded, &options, &loc));
    topoloc_localizer_free(loc);
    count = 0;
    CHECK_OK(topoloc_map_place_count(loaded, &count)); /* still valid */
    CHECK(count == PLACES);
    topoloc_map_free(loaded);
    remove(path);
}

static void test_single_frame(void)
{
    topoloc_map *map = build_world_map();
    topoloc_localizer *single = NULL, *fresh = NULL;
    topoloc_localizer_options options;
    topoloc_frame frame;
    topoloc_result r1, r2;
    topoloc_candidate c1[5], c2[5];
    float desc[DIM];
    uint32_t places[] = {4, 0, 2, 5, 1}; /* jumps between non-neighbours */
    size_t i;

    section("single-frame mode");
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
    CHECK_OK(topoloc_result_default(&r1));
    CHECK_OK(topoloc_result_default(&r2));
    r1.candidates = c1;
    r1.candidates_capacity = 5;
    r2.candidates = c2;
    r2.candidates_capacity = 5;
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

static void test_from_keyframes(void)
{
    /* With poses: 5 spots 3 m apart, visited out and back; the way back sees new appearances. */
    enum { SPOTS = 5, KEYFRAMES = 2 * SPOTS };
    static float desc[KEYFRAMES][DIM];
    static double poses[KEYFRAMES][16];
    topoloc_keyframe keyframes[KEYFRAMES];
    topoloc_keyframe_options options;
    topoloc_map *map = NULL;
    size_t count = 0, i;
    uint32_t d, v;
    char kind[32];

    section("map from keyframes");
    for (i = 0; i < KEYFRAMES; i++) {
        size_t spot = i < SPOTS ? i : KEYFRAMES - 1 - i;
        double *m = poses[i];
        for (d = 0; d < DIM; d++) {
            desc[i][d] = rng_normalish();
        }
        memset(m, 0, sizeof poses[i]);
        m[0] = m[5] = m[10] = m[15] = 1.0;
        m[3] = 3.0 * (double)spot + (i < SPOTS ? 0.0 : 0.1);
        keyframes[i].id = 500u + i;
        keyframes[i].descriptor = desc[i];
        keyframes[i].descriptor_len = DIM;
        keyframes[i].world_T_camera = poses[i];
    }
    CHECK_OK(topoloc_keyframe_options_default(&options));
    CHECK(options.struct_size == sizeof options);
    CHECK(options.place_spacing_m == 2.0);
    CHECK(options.max_views_per_place == 4);
    options.neighbour_radius_m = 2.5; /* below the 3 m spot spacing: only consecutive edges */
    CHECK_OK(
        topoloc_map_from_keyframes("kf-desc", NULL, DIM, keyframes, KEYFRAMES, &options, &map));
    if (map != NULL) {
        CHECK_COUNTS(map, SPOTS, KEYFRAMES, SPOTS - 1);
        CHECK_OK(topoloc_map_descriptor_kind(map, kind, sizeof kind, NULL));
        CHECK(strcmp(kind, "kf-desc") == 0);
        CHECK_OK(topoloc_map_descriptor_model(map, kind, sizeof kind, &count));
        CHECK(strcmp(kind, "") == 0 && count == 1);
        for (v = 0; v < KEYFRAMES; v++) {
            topoloc_view_info info;
            double xyz[3];
            bool has_position = false;
            CHECK_OK(topoloc_view_info_default(&info));
            CHECK_OK(topoloc_map_view_info(map, v, &info));
            CHECK(info.has_keyframe_id && info.keyframe_id >= 500u && info.keyframe_id < 510u);
            CHECK(info.has_pose);
            /* The view's keyframe and its place sit at the same spot. */
            CHECK_OK(topoloc_map_place_position(map, info.place, xyz, &has_position));
            CHECK(has_position);
            CHECK_NEAR(xyz[0], poses[info.keyframe_id - 500u][3], 0.1 + 1e-9);
        }
        /* A keyframe's own descriptor localizes to its place. */
        {
            topoloc_localizer *loc = NULL;
            topoloc_frame frame;
            topoloc_result result;
            topoloc_view_info info;
            CHECK_OK(topoloc_localizer_new(map, NULL, &loc));
            CHECK_OK(topoloc_frame_default(&frame));
            CHECK_OK(topoloc_result_default(&result));
            frame.descriptor = desc[7];
            frame.descriptor_len = DIM;
            if (loc != NULL) {
                CHECK_OK(topoloc_localizer_process(loc, &frame, &result));
                CHECK_OK(topoloc_view_info_default(&info));
                CHECK_OK(topoloc_map_view_info(map, result.view, &info));
                CHECK(info.keyframe_id == 507u);
                CHECK(result.candidates_len == 0); /* no buffer given */
            }
            topoloc_localizer_free(loc);
        }
        topoloc_map_free(map);
        map = NULL;
    }

    /* Without poses: a new place whenever the appearance changes; duplicates are dropped. */
    {
        topoloc_keyframe plain[6];
        double xyz[3];
        bool has_position = true;
        for (i = 0; i < 6; i++) {
            plain[i].id = i;
            plain[i].descriptor = desc[i / 2]; /* pairs of identical keyframes */
            plain[i].descriptor_len = DIM;
            plain[i].world_T_camera = NULL;
        }
        CHECK_OK(topoloc_map_from_keyframes("kf-desc", "m", DIM, plain, 6, NULL, &map));
        if (map != NULL) {
            CHECK_COUNTS(map, 3, 3, 2);
            CHECK_OK(topoloc_map_place_position(map, 0, xyz, &has_position));
            CHECK(!has_position);
            CHECK(xyz[0] == 0.0 && xyz[1] == 0.0 && xyz[2] == 0.0);
        }
        topoloc_map_free(map);
        map = NULL;

        /* Errors. */
        CHECK_STATUS(topoloc_map_from_keyframes("k", NULL, DIM, NULL, 0, NULL, &map),
                     TOPOLOC_ERR_EMPTY_MAP);
        CHECK_HAS_MESSAGE();
        plain[3].world_T_camera = poses[0]; /* a mix of keyframes with and without poses */
        CHECK_STATUS(topoloc_map_from_keyframes("k", NULL, DIM, plain, 6, NULL, &map),
                     TOPOLOC_ERR_INVALID_ARGUMENT);
        CHECK_HAS_MESSAGE();
        plain[3].world_T_camera = NULL;
        plain[2].descriptor_len = DIM - 1;
        CHECK_STATUS(topoloc_map_from_keyframes("k", NULL, DIM, plain, 6, NULL, &map),
                     TOPOLOC_ERR_INVALID_ARGUMENT);
        CHECK(strstr(last_error(), "keyframe 2") != NULL);
        plain[2].descriptor_len = DIM;
        CHECK_OK(topoloc_keyframe_options_default(&options));
        options.max_views_per_place = 0;
        CHECK_STATUS(topoloc_map_from_keyframes("k", NULL, DIM, plain, 6, &options, &map),
                     TOPOLOC_ERR_INVALID_ARGUMENT);
        CHECK(strstr(last_error(), "max_views_per_place") != NULL);
        options.struct_size = 0;
        CHECK_STATUS(topoloc_map_from_keyframes("k", NULL, DIM, plain, 6, &options, &map),
                     TOPOLOC_ERR_STRUCT_SIZE);
        CHECK_HAS_MESSAGE();
        CHECK(map == NULL); /* never written on error */
    }
}

static void test_builder_errors(void)
{
    topoloc_map_builder *b = NULL;
    topoloc_map *map = NULL;
    topoloc_view_attributes attributes;
    uint32_t place = 77, view = 77;
    float desc[DIM];
    double bad_pose[16] = {2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}; /* a scale */
    double nan_position[3];
    size_t count = 0;
    uint32_t d;

    section("builder errors");
    memcpy(desc, g_view_desc[0], sizeof desc);
    nan_position[0] = 0.0;
    nan_position[1] = make_nan();
    nan_position[2] = 0.0;

    CHECK_STATUS(topoloc_map_builder_new("", NULL, DIM, &b), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_builder_new(KIND, NULL, 0, &b), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_builder_new("\xff\xfe", NULL, DIM, &b), TOPOLOC_ERR_INVALID_UTF8);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_builder_new(KIND, "\xc3", DIM, &b), TOPOLOC_ERR_INVALID_UTF8);
    CHECK(b == NULL);

    CHECK_OK(topoloc_map_builder_new(KIND, NULL, DIM, &b));
    if (b == NULL) {
        return;
    }
    CHECK_STATUS(topoloc_map_builder_build(b, &map), TOPOLOC_ERR_EMPTY_MAP);
    CHECK_HAS_MESSAGE();
    CHECK_OK(topoloc_map_builder_add_place(b, NULL, &place));
    CHECK(place == 0);
    CHECK_STATUS(topoloc_map_builder_build(b, &map), TOPOLOC_ERR_INVALID_MAP); /* no views */
    CHECK_HAS_MESSAGE();
    CHECK(map == NULL);

    CHECK_STATUS(topoloc_map_builder_add_view(b, 1, desc, DIM, NULL, &view),
                 TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM - 1, NULL, &view),
                 TOPOLOC_ERR_DIMENSION_MISMATCH);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM + 1, NULL, &view),
                 TOPOLOC_ERR_DIMENSION_MISMATCH);
    desc[5] = (float)nan_position[1];
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM, NULL, &view),
                 TOPOLOC_ERR_NON_FINITE);
    CHECK_HAS_MESSAGE();
    desc[5] = make_inf();
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM, NULL, &view),
                 TOPOLOC_ERR_NON_FINITE);
    for (d = 0; d < DIM; d++) {
        desc[d] = 0.0f;
    }
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM, NULL, &view),
                 TOPOLOC_ERR_ZERO_DESCRIPTOR);
    CHECK_HAS_MESSAGE();
    memcpy(desc, g_view_desc[0], sizeof desc);
    CHECK_OK(topoloc_view_attributes_default(&attributes));
    attributes.world_T_camera = bad_pose;
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM, &attributes, &view),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_HAS_MESSAGE();
    bad_pose[0] = 1.0;
    bad_pose[15] = 2.0; /* last row not 0 0 0 1 */
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM, &attributes, &view),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    bad_pose[15] = 1.0;
    bad_pose[3] = nan_position[1];
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM, &attributes, &view),
                 TOPOLOC_ERR_NON_FINITE);
    attributes.world_T_camera = NULL;
    attributes.image = "\xff";
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM, &attributes, &view),
                 TOPOLOC_ERR_INVALID_UTF8);
    attributes.image = NULL;
    attributes.struct_size = 0;
    CHECK_STATUS(topoloc_map_builder_add_view(b, 0, desc, DIM, &attributes, &view),
                 TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_HAS_MESSAGE();
    CHECK(view == 77); /* never written on error */

    /* After all those errors the builder is unchanged: the next view is view 0. */
    CHECK_OK(topoloc_view_attributes_default(&attributes));
    CHECK_OK(topoloc_map_builder_add_view(b, 0, desc, DIM, &attributes, &view));
    CHECK(view == 0);

    /* A NaN position is refused as a non-finite value, like NaN poses and descriptors. */
    CHECK_STATUS(topoloc_map_builder_add_place(b, nan_position, &place), TOPOLOC_ERR_NON_FINITE);
    CHECK_HAS_MESSAGE();
    CHECK_OK(topoloc_map_builder_add_place(b, NULL, &place));
    CHECK(place == 1);
    CHECK_OK(topoloc_map_builder_add_view(b, 1, g_view_desc[5], DIM, NULL, &view));
    CHECK(view == 1);

    CHECK_STATUS(topoloc_map_builder_add_edge(b, 0, 0, 1.0f), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_builder_add_edge(b, 0, 2, 1.0f), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_builder_add_edge(b, 9, 0, 1.0f), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_STATUS(topoloc_map_builder_add_edge(b, 0, 1, 0.0f), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_STATUS(topoloc_map_builder_add_edge(b, 0, 1, -1.0f), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_STATUS(topoloc_map_builder_add_edge(b, 0, 1, (float)nan_position[1]),
                 TOPOLOC_ERR_NON_FINITE);
    CHECK_OK(topoloc_map_builder_add_edge(b, 1, 0, 0.5f));
    CHECK_STATUS(topoloc_map_builder_add_edge(b, 0, 1, 0.5f), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(strstr(last_error(), "exists") != NULL);

    /* The builder stays usable after build: two maps from it. */
    CHECK_OK(topoloc_map_builder_build(b, &map));
    if (map != NULL) {
        topoloc_map *second = NULL;
        CHECK_OK(topoloc_map_place_count(map, &count));
        CHECK(count == 2);
        CHECK_OK(topoloc_map_edge_count(map, &count));
        CHECK(count == 1);
        CHECK_OK(topoloc_map_builder_add_place(b, NULL, &place));
        CHECK_OK(topoloc_map_builder_add_view(b, 2, g_view_desc[9], DIM, NULL, &view));
        CHECK_OK(topoloc_map_builder_build(b, &second));
        if (second != NULL) {
            CHECK_OK(topoloc_map_place_count(second, &count));
            CHECK(count == 3);
        }
        CHECK_OK(topoloc_map_place_count(map, &count));
        CHECK(count == 2); /* the first map is unaffected */
        topoloc_map_free(second);
    }
    topoloc_map_free(map);
    topoloc_map_builder_free(b);
}

static void test_null_arguments(const topoloc_map *map)
{
    topoloc_map_builder *b = NULL;
    topoloc_map *m = NULL;
    topoloc_localizer *loc = NULL;
    topoloc_frame frame;
    topoloc_result result;
    topoloc_view_info info;
    topoloc_keyframe keyframe;
    char buf[64];
    float desc[DIM];
    uint32_t u = 0, u2 = 0, ids[8];
    size_t n = 0;
    float w = 0.0f;
    double xyz[3];
    bool has = false;
    unsigned char bytes[16] = {0};
    topoloc_map_builder *const sentinel_builder = (topoloc_map_builder *)&u;

    section("NULL arguments");
    memcpy(desc, g_view_desc[0], sizeof desc);

    /* _free(NULL) is a no-op. */
    topoloc_map_builder_free(NULL);
    topoloc_map_free(NULL);
    topoloc_localizer_free(NULL);
    CHECK(true);

    /* The _init functions behind the _default(p) macros refuse NULL. */
    CHECK_NULL(topoloc_view_attributes_init(NULL, sizeof(topoloc_view_attributes)), "NULL");
    CHECK_NULL(topoloc_keyframe_options_init(NULL, sizeof(topoloc_keyframe_options)), "NULL");
    CHECK_NULL(topoloc_localizer_options_init(NULL, sizeof(topoloc_localizer_options)), "NULL");
    CHECK_NULL(topoloc_frame_init(NULL, sizeof(topoloc_frame)), "NULL");
    CHECK_NULL(topoloc_result_init(NULL, sizeof(topoloc_result)), "NULL");
    CHECK_NULL(topoloc_map_load_options_init(NULL, sizeof(topoloc_map_load_options)), "NULL");
    CHECK_NULL(topoloc_view_info_init(NULL, sizeof(topoloc_view_info)), "NULL");

    /* Builder. */
    b = sentinel_builder;
    CHECK_NULL(topoloc_map_builder_new(NULL, NULL, DIM, &b), "kind");
    CHECK(b == sentinel_builder); /* out-parameter untouched */
    CHECK_NULL(topoloc_map_builder_new(KIND, NULL, DIM, NULL), "out");
    b = NULL;
    CHECK_OK(topoloc_map_builder_new(KIND, NULL, DIM, &b)); /* model may be NULL */
    CHECK_NULL(topoloc_map_builder_add_place(NULL, NULL, &u), "builder");
    CHECK_NULL(topoloc_map_builder_add_place(b, NULL, NULL), "place_out");
    CHECK_OK(topoloc_map_builder_add_place(b, NULL, &u)); /* position may be NULL */
    CHECK_NULL(topoloc_map_builder_add_view(NULL, 0, desc, DIM, NULL, &u), "builder");
    CHECK_NULL(topoloc_map_builder_add_view(b, 0, NULL, DIM, NULL, &u), "descriptor");
    CHECK_NULL(topoloc_map_builder_add_view(b, 0, desc, DIM, NULL, NULL), "view_out");
    CHECK_OK(topoloc_map_builder_add_view(b, 0, desc, DIM, NULL, &u)); /* attributes may be NULL */
    CHECK_NULL(topoloc_map_builder_add_edge(NULL, 0, 1, 1.0f), "builder");
    m = (topoloc_map *)&u;
    CHECK_NULL(topoloc_map_builder_build(NULL, &m), "builder");
    CHECK(m == (topoloc_map *)&u);
    CHECK_NULL(topoloc_map_builder_build(b, NULL), "out");
    topoloc_map_builder_free(b);

    /* Keyframes. */
    keyframe.id = 1;
    keyframe.descriptor = desc;
    keyframe.descriptor_len = DIM;
    keyframe.world_T_camera = NULL;
    m = NULL;
    CHECK_NULL(topoloc_map_from_keyframes(NULL, NULL, DIM, &keyframe, 1, NULL, &m), "kind");
    CHECK_NULL(topoloc_map_from_keyframes(KIND, NULL, DIM, NULL, 1, NULL, &m), "keyframes");
    CHECK_NULL(topoloc_map_from_keyframes(KIND, NULL, DIM, &keyframe, 1, NULL, NULL), "out");
    keyframe.descriptor = NULL;
    CHECK_NULL(topoloc_map_from_keyframes(KIND, NULL, DIM, &keyframe, 1, NULL, &m),
               "keyframes[0].descriptor");
    CHECK(m == NULL);

    /* Loading and saving. */
    CHECK_NULL(topoloc_map_load(NULL, NULL, &m), "path");
    CHECK_NULL(topoloc_map_load("/nonexistent/map", NULL, NULL), "out");
    CHECK_NULL(topoloc_map_load_from_memory(NULL, sizeof bytes, NULL, &m), "data");
    CHECK_NULL(topoloc_map_load_from_memory(bytes, sizeof bytes, NULL, NULL), "out");
    CHECK_NULL(topoloc_map_save(NULL, "/tmp/never-written.topoloc"), "map");
    CHECK_NULL(topoloc_map_save(map, NULL), "path");
    CHECK(m == NULL);

    /* Accessors. */
    CHECK_NULL(topoloc_map_place_count(NULL, &n), "map");
    CHECK_NULL(topoloc_map_place_count(map, NULL), "out");
    CHECK_NULL(topoloc_map_view_count(NULL, &n), "map");
    CHECK_NULL(topoloc_map_view_count(map, NULL), "out");
    CHECK_NULL(topoloc_map_edge_count(NULL, &n), "map");
    CHECK_NULL(topoloc_map_edge_count(map, NULL), "out");
    CHECK_NULL(topoloc_map_descriptor_dim(NULL, &u), "map");
    CHECK_NULL(topoloc_map_descriptor_dim(map, NULL), "out");
    CHECK_NULL(topoloc_map_descriptor_kind(NULL, buf, sizeof buf, &n), "map");
    CHECK_NULL(topoloc_map_descriptor_kind(map, NULL, sizeof buf, &n), "buf");
    CHECK_NULL(topoloc_map_descriptor_model(NULL, buf, sizeof buf, &n), "map");
    CHECK_NULL(topoloc_map_descriptor_model(map, NULL, sizeof buf, &n), "buf");
    CHECK_NULL(topoloc_map_neighbours(NULL, 0, ids, 8, &n), "map");
    CHECK_NULL(topoloc_map_neighbours(map, 0, NULL, 8, &n), "buf");
    CHECK_NULL(topoloc_map_place_views(NULL, 0, ids, 8, &n), "map");
    CHECK_NULL(topoloc_map_place_views(map, 0, NULL, 8, &n), "buf");
    CHECK_NULL(topoloc_map_place_position(NULL, 0, xyz, &has), "map");
    CHECK_NULL(topoloc_map_place_position(map, 0, NULL, &has), "xyz");
    CHECK_NULL(topoloc_map_place_position(map, 0, xyz, NULL), "has_position");
    CHECK_NULL(topoloc_map_edge(NULL, 0, &u, &u2, &w), "map");
    CHECK_NULL(topoloc_map_edge(map, 0, NULL, &u2, &w), "a");
    CHECK_NULL(topoloc_map_edge(map, 0, &u, NULL, &w), "b");
    CHECK_NULL(topoloc_map_edge(map, 0, &u, &u2, NULL), "weight");
    CHECK_OK(topoloc_view_info_default(&info));
    CHECK_NULL(topoloc_map_view_info(NULL, 0, &info), "map");
    CHECK_NULL(topoloc_map_view_info(map, 0, NULL), "out");
    CHECK_NULL(topoloc_map_view_image(NULL, 0, buf, sizeof buf, &n), "map");
    CHECK_NULL(topoloc_map_view_image(map, 0, NULL, sizeof buf, &n), "buf");
    CHECK_NULL(topoloc_map_view_descriptor(NULL, 0, desc, DIM), "map");
    CHECK_NULL(topoloc_map_view_descriptor(map, 0, NULL, DIM), "buf");

    /* Localizer. */
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

    /* The last error message: a NULL buffer with room claimed is refused, the message kept. */
    {
        char before[512];
        snprintf(before, sizeof before, "%s", last_error());
        CHECK(topoloc_last_error_message(NULL, 100, NULL) == TOPOLOC_ERR_NULL_ARGUMENT);
        CHECK(strcmp(before, last_error()) == 0);
    }
}

static void test_buffers_too_small(const topoloc_map *map)
{
    char buf[256];
    char small[4];
    size_t needed = 0, count = 0, len;
    uint32_t ids[1] = {4242};
    float desc[DIM];

    section("buffers too small");
    /* Last error message. */
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

    /* Descriptor kind and model. */
    memset(small, 'z', sizeof small);
    needed = 0;
    CHECK_STATUS(topoloc_map_descriptor_kind(map, small, sizeof small, &needed),
                 TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(needed == strlen(KIND) + 1);
    CHECK(small[0] == 'z' && small[3] == 'z');
    CHECK_HAS_MESSAGE();
    needed = 0;
    CHECK_STATUS(topoloc_map_descriptor_kind(map, NULL, 0, &needed), TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(needed == strlen(KIND) + 1);
    CHECK_STATUS(topoloc_map_descriptor_kind(map, buf, strlen(KIND), NULL),
                 TOPOLOC_ERR_BUFFER_TOO_SMALL); /* no room for the NUL */
    needed = 0;
    CHECK_STATUS(topoloc_map_descriptor_model(map, small, sizeof small, &needed),
                 TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(needed == strlen(MODEL) + 1);
    needed = 0;
    CHECK_STATUS(topoloc_map_view_image(map, 0, small, sizeof small, &needed),
                 TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(needed == strlen(g_view_image[0]) + 1);

    /* Neighbours and place views. */
    count = 0;
    CHECK_STATUS(topoloc_map_neighbours(map, 2, ids, 1, &count), TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(count == 2);
    CHECK(ids[0] == 4242);
    CHECK_HAS_MESSAGE();
    count = 0;
    CHECK_STATUS(topoloc_map_neighbours(map, 0, NULL, 0, &count), TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(count == 2);
    count = 0;
    CHECK_STATUS(topoloc_map_place_views(map, 1, ids, 1, &count), TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(count == VIEWS_PER_PLACE);
    CHECK_STATUS(topoloc_map_place_views(map, 1, ids, 1, NULL), TOPOLOC_ERR_BUFFER_TOO_SMALL);

    /* View descriptor. */
    desc[0] = 42.0f;
    CHECK_STATUS(topoloc_map_view_descriptor(map, 0, desc, DIM - 1), TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(desc[0] == 42.0f);
    CHECK_HAS_MESSAGE();
}

static void test_unknown_ids(const topoloc_map *map)
{
    uint32_t ids[8], a = 0, b = 0;
    size_t count = 12345;
    double xyz[3] = {7.0, 7.0, 7.0};
    bool has = true;
    float w = 0.0f, desc[DIM];
    char buf[64];
    topoloc_view_info info;

    section("unknown place and view ids");
    CHECK_STATUS(topoloc_map_neighbours(map, PLACES, ids, 8, &count), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_neighbours(map, 0xFFFFFFFFu, ids, 8, &count),
                 TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_STATUS(topoloc_map_place_views(map, PLACES, ids, 8, &count), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_STATUS(topoloc_map_place_position(map, PLACES, xyz, &has), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK(xyz[0] == 7.0 && has); /* untouched */
    CHECK_OK(topoloc_view_info_default(&info));
    CHECK_STATUS(topoloc_map_view_info(map, VIEWS, &info), TOPOLOC_ERR_UNKNOWN_VIEW);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_view_image(map, VIEWS, buf, sizeof buf, NULL),
                 TOPOLOC_ERR_UNKNOWN_VIEW);
    CHECK_STATUS(topoloc_map_view_descriptor(map, VIEWS, desc, DIM), TOPOLOC_ERR_UNKNOWN_VIEW);
    CHECK_STATUS(topoloc_map_view_descriptor(map, 0xFFFFFFFFu, desc, DIM),
                 TOPOLOC_ERR_UNKNOWN_VIEW);
    CHECK_STATUS(topoloc_map_edge(map, EDGES, &a, &b, &w), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_edge(map, (size_t)-1, &a, &b, &w), TOPOLOC_ERR_INVALID_ARGUMENT);
    info.struct_size = 0;
    CHECK_STATUS(topoloc_map_view_info(map, 0, &info), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_HAS_MESSAGE();
    info.struct_size = sizeof info - 1;
    CHECK_STATUS(topoloc_map_view_info(map, 0, &info), TOPOLOC_ERR_STRUCT_SIZE);
}

/* Every field of two results is identical (fields, not bytes: padding may be uninitialised). */
/* Two localizers with default options on `map`, one to see bad input and one not; false (and
 * neither) when either could not be made. */
static bool new_twin_localizers(const topoloc_map *map, topoloc_localizer **a,
                                topoloc_localizer **b)
{
    CHECK_OK(topoloc_localizer_new(map, NULL, a));
    CHECK_OK(topoloc_localizer_new(map, NULL, b));
    if (*a == NULL || *b == NULL) {
        topoloc_localizer_free(*a);
        topoloc_localizer_free(*b);
        *a = *b = NULL;
        return false;
    }
    return true;
}

static bool identical_result(const topoloc_result *a, const topoloc_result *b)
{
    return a->struct_size == b->struct_size && a->frame_index == b->frame_index &&
           a->place == b->place && a->view == b->view && a->confidence == b->confidence &&
           a->similarity == b->similarity && a->off_map_probability == b->off_map_probability &&
           a->off_map == b->off_map && a->candidates == b->candidates &&
           a->candidates_capacity == b->candidates_capacity &&
           a->candidates_len == b->candidates_len;
}

/* Results of two localizers agree exactly. */
static bool same_result(const topoloc_result *a, const topoloc_result *b)
{
    size_t i;
    if (a->frame_index != b->frame_index || a->place != b->place || a->view != b->view ||
        a->confidence != b->confidence || a->similarity != b->similarity ||
        a->off_map_probability != b->off_map_probability || a->off_map != b->off_map ||
        a->candidates_len != b->candidates_len) {
        return false;
    }
    for (i = 0; i < a->candidates_len; i++) {
        const topoloc_candidate *x = &a->candidates[i], *y = &b->candidates[i];
        if (x->place != y->place || x->view != y->view || x->probability != y->probability ||
            x->similarity != y->similarity) {
            return false;
        }
    }
    return true;
}

static void test_bad_frames(const topoloc_map *map)
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

    section("bad frames leave the localizer and the result unchanged");
    nan = make_nan();
    if (!new_twin_localizers(map, &a, &b)) {
        return;
    }
    memset(ca, 0, sizeof ca);
    memset(cb, 0, sizeof cb);
    CHECK_OK(topoloc_frame_default(&good));
    CHECK_OK(topoloc_result_default(&ra));
    CHECK_OK(topoloc_result_default(&rb));
    ra.candidates = ca;
    ra.candidates_capacity = 5;
    rb.candidates = cb;
    rb.candidates_capacity = 5;
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

static void test_options_errors(const topoloc_map *map)
{
    topoloc_localizer_options options;
    topoloc_localizer *loc = NULL;

    section("localizer options: struct_size, invalid options, descriptor mismatch");
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.struct_size = 0;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_HAS_MESSAGE();
    /* One byte short of the first published (ABI 1.0) layout, which ends before image_backend. */
    options.struct_size = offsetof(topoloc_localizer_options, image_backend) - 1;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK(loc == NULL);

    CHECK_OK(topoloc_localizer_options_default(&options));
    options.mode = 7;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_HAS_MESSAGE();
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.top_k = 0;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.temperature = 0.0f;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.stay_probability = 1.5f;
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_INVALID_OPTION);

    CHECK_OK(topoloc_localizer_options_default(&options));
    options.expected_descriptor_kind = "another-desc";
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    CHECK_HAS_MESSAGE();
    options.expected_descriptor_kind = KIND;
    options.expected_descriptor_model = "another-model";
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    options.expected_descriptor_model = "\xff";
    CHECK_STATUS(topoloc_localizer_new(map, &options, &loc), TOPOLOC_ERR_INVALID_UTF8);
    CHECK(loc == NULL);
    options.expected_descriptor_model = MODEL;
    CHECK_OK(topoloc_localizer_new(map, &options, &loc));
    topoloc_localizer_free(loc);
    loc = NULL;

    /* ABI 1.9: off-map evidence from verification; negative = the map's kind's default. */
    CHECK(topoloc_abi_version_minor() >= 9);
    CHECK_OK(topoloc_localizer_options_default(&options));
    CHECK(options.verify_off_map_inliers == -1.0 && options.verify_off_map_inlier_scale == 4.0);
    options.verify_off_map_inliers = NAN;
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

static void test_files(void)
{
    topoloc_map *built = build_world_map(), *m = NULL;
    topoloc_map_load_options options;
    char path[4200], other[4200];
    unsigned char *bytes = NULL, *copy = NULL;
    size_t len = 0, off, header_end;
    size_t tested = 0;
    static const char not_a_map[] = "hello, this is a text file and not a topoloc map\n";

    section("map files: missing, foreign, truncated, corrupt, mismatched");
    if (built == NULL) {
        return;
    }
    tmp_path(path, sizeof path, "files.topoloc");
    CHECK_OK(topoloc_map_save(built, path));

    /* Saving where that is impossible. */
    tmp_path(other, sizeof other, "no-such-dir/map.topoloc");
    CHECK_STATUS(topoloc_map_save(built, other), TOPOLOC_ERR_IO);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_save(built, "\xff.topoloc"), TOPOLOC_ERR_INVALID_UTF8);

    /* Missing file, directory, invalid UTF-8 path. */
    tmp_path(other, sizeof other, "missing.topoloc");
    CHECK_STATUS(topoloc_map_load(other, NULL, &m), TOPOLOC_ERR_IO);
    CHECK_HAS_MESSAGE();
    CHECK(strstr(last_error(), "missing.topoloc") != NULL);
    {
        topoloc_status st = topoloc_map_load(g_tmpdir, NULL, &m);
        CHECK(st != TOPOLOC_OK);
        CHECK(st == TOPOLOC_ERR_IO || st == TOPOLOC_ERR_NOT_A_MAP);
    }
    CHECK_STATUS(topoloc_map_load("\xff\xfe", NULL, &m), TOPOLOC_ERR_INVALID_UTF8);

    /* Not a map: a text file, an empty file, no bytes. */
    tmp_path(other, sizeof other, "text.txt");
    CHECK(write_file(other, (const unsigned char *)not_a_map, sizeof not_a_map - 1));
    CHECK_STATUS(topoloc_map_load(other, NULL, &m), TOPOLOC_ERR_NOT_A_MAP);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(
        topoloc_map_load_from_memory((const uint8_t *)not_a_map, sizeof not_a_map - 1, NULL, &m),
        TOPOLOC_ERR_NOT_A_MAP);
    CHECK(write_file(other, (const unsigned char *)"", 0));
    CHECK_STATUS(topoloc_map_load(other, NULL, &m), TOPOLOC_ERR_NOT_A_MAP);
    CHECK_STATUS(topoloc_map_load_from_memory((const uint8_t *)not_a_map, 0, NULL, &m),
                 TOPOLOC_ERR_NOT_A_MAP);
    CHECK_STATUS(topoloc_map_load_from_memory(NULL, 0, NULL, &m), TOPOLOC_ERR_NOT_A_MAP);
    remove(other);
    CHECK(m == NULL);

    bytes = read_file(path, &len);
    CHECK(bytes != NULL && len > 16);
    if (bytes == NULL || len <= 16) {
        free(bytes);
        topoloc_map_free(built);
        remove(path);
        return;
    }
    copy = malloc(len + 16);
    CHECK(copy != NULL);
    if (copy == NULL) {
        free(bytes);
        topoloc_map_free(built);
        return;
    }
    /* safetensors: 8-byte little-endian header length, JSON header, data. */
    header_end = 8;
    for (off = 0; off < 8; off++) {
        header_end += (size_t)bytes[off] << (8 * off);
    }
    CHECK(header_end < len);

    /* Truncated at every offset: from memory everywhere, from a file at a few offsets. */
    tmp_path(other, sizeof other, "truncated.topoloc");
    for (off = 0; off < len; off++) {
        topoloc_status st = topoloc_map_load_from_memory(bytes, off, NULL, &m);
        bool ok =
            st == TOPOLOC_ERR_TRUNCATED || st == TOPOLOC_ERR_NOT_A_MAP || st == TOPOLOC_ERR_CORRUPT;
        if (!ok) {
            fprintf(stderr, "    truncated at %zu of %zu: status %u\n", off, len, (unsigned)st);
        }
        CHECK(ok);
        if (off > header_end) {
            CHECK(st == TOPOLOC_ERR_TRUNCATED); /* the header promises more data */
        }
        if (off == 0 || off == 1 || off == 7 || off == 8 || off == 9 || off == header_end / 2 ||
            off == header_end || off == len / 2 || off == len - 1) {
            CHECK(write_file(other, bytes, off));
            st = topoloc_map_load(other, NULL, &m);
            CHECK(st == TOPOLOC_ERR_TRUNCATED || st == TOPOLOC_ERR_NOT_A_MAP ||
                  st == TOPOLOC_ERR_CORRUPT);
            CHECK_HAS_MESSAGE();
            tested++;
        }
    }
    CHECK(tested == 9);
    CHECK(m == NULL);

    /* One flipped bit at every offset (the bit varies with the offset): never OK. */
    {
        size_t undetected = 0;
        for (off = 0; off < len; off++) {
            topoloc_status st;
            memcpy(copy, bytes, len);
            copy[off] ^= (unsigned char)(1u << (off % 8));
            st = topoloc_map_load_from_memory(copy, len, NULL, &m);
            if (st == TOPOLOC_OK) {
                undetected++;
                fprintf(stderr, "    flipped bit %zu of byte %zu (of %zu) not detected\n", off % 8,
                        off, len);
                topoloc_map_free(m);
                m = NULL;
            } else if (off >= header_end) {
                CHECK(st == TOPOLOC_ERR_CORRUPT); /* data bytes: the checksum catches them */
            }
        }
        CHECK(undetected == 0);
        /* And through a file. */
        memcpy(copy, bytes, len);
        copy[len - 3] ^= 0x40;
        CHECK(write_file(other, copy, len));
        CHECK_STATUS(topoloc_map_load(other, NULL, &m), TOPOLOC_ERR_CORRUPT);
        CHECK_HAS_MESSAGE();
        memcpy(copy, bytes, len);
        copy[header_end - 20] ^= 0x01;
        CHECK(write_file(other, copy, len));
        CHECK(topoloc_map_load(other, NULL, &m) != TOPOLOC_OK);
        CHECK(m == NULL);
    }

    /* Trailing garbage. */
    memcpy(copy, bytes, len);
    memset(copy + len, 0, 16);
    CHECK_STATUS(topoloc_map_load_from_memory(copy, len + 16, NULL, &m), TOPOLOC_ERR_CORRUPT);

    /* A newer major format version. */
    {
        static const char key[] = "version\\\":\\\"";
        size_t klen = sizeof key - 1, found = 0;
        memcpy(copy, bytes, len);
        for (off = 8; off + klen < header_end; off++) {
            if (memcmp(copy + off, key, klen) == 0) {
                found = off + klen;
                break;
            }
        }
        CHECK(found != 0);
        if (found != 0) {
            CHECK(copy[found] == '1');
            copy[found] = '9';
            CHECK_STATUS(topoloc_map_load_from_memory(copy, len, NULL, &m),
                         TOPOLOC_ERR_UNSUPPORTED_VERSION);
            CHECK_HAS_MESSAGE();
        }
    }

    /* Descriptor mismatch at load. */
    CHECK_OK(topoloc_map_load_options_default(&options));
    CHECK(options.struct_size == sizeof options);
    CHECK(options.expected_descriptor_kind == NULL && options.expected_descriptor_dim == 0);
    options.expected_descriptor_kind = "another-desc";
    CHECK_STATUS(topoloc_map_load(path, &options, &m), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_load_from_memory(bytes, len, &options, &m),
                 TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    options.expected_descriptor_kind = KIND;
    options.expected_descriptor_model = "another-model";
    CHECK_STATUS(topoloc_map_load(path, &options, &m), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    options.expected_descriptor_model = MODEL;
    options.expected_descriptor_dim = DIM + 1;
    CHECK_STATUS(topoloc_map_load(path, &options, &m), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    CHECK(m == NULL);
    options.expected_descriptor_dim = DIM;
    CHECK_OK(topoloc_map_load(path, &options, &m));
    topoloc_map_free(m);
    m = NULL;
    options.expected_descriptor_kind = "";
    options.expected_descriptor_model = NULL;
    options.expected_descriptor_dim = 0;
    CHECK_OK(topoloc_map_load(path, &options, &m));
    topoloc_map_free(m);
    m = NULL;
    options.struct_size = 0;
    CHECK_STATUS(topoloc_map_load(path, &options, &m), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_map_load_from_memory(bytes, len, &options, &m), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK(m == NULL);

    remove(other);
    remove(path);
    free(copy);
    free(bytes);
    topoloc_map_free(built);
}

static bool all_bytes(const unsigned char *p, size_t n, unsigned char value)
{
    size_t i;
    for (i = 0; i < n; i++) {
        if (p[i] != value) {
            return false;
        }
    }
    return true;
}

/* The versioned structs: _init sizes, and callers built against a newer (larger) or broken
 * struct_size. A library must never write past the caller's struct. */
static void test_versioned_structs(const topoloc_map *map)
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
    topoloc_frame frame;
    topoloc_result result;
    topoloc_localizer_options options;
    topoloc_keyframe_options kf_options;
    topoloc_map_load_options load_options;
    topoloc_view_attributes attributes;
    topoloc_view_info info;
    topoloc_localizer *loc = NULL;
    float desc[DIM];

    section("versioned structs: _init sizes, larger and smaller struct_size");
    /* Defaults. */
    CHECK_OK(topoloc_frame_default(&frame));
    CHECK(frame.struct_size == sizeof frame && frame.timestamp == 0.0);
    CHECK_OK(topoloc_result_default(&result));
    CHECK(result.struct_size == sizeof result && result.candidates_len == 0);
    CHECK_OK(topoloc_localizer_options_default(&options));
    CHECK(options.struct_size == sizeof options);
    CHECK(options.temperature > 0.0f && options.stay_probability > 0.0f);
    CHECK_OK(topoloc_keyframe_options_default(&kf_options));
    CHECK(kf_options.struct_size == sizeof kf_options && kf_options.neighbour_radius_m == 3.0);
    CHECK_OK(topoloc_map_load_options_default(&load_options));
    CHECK(load_options.struct_size == sizeof load_options);
    CHECK_OK(topoloc_view_attributes_default(&attributes));
    CHECK(attributes.struct_size == sizeof attributes);
    CHECK_OK(topoloc_view_info_default(&info));
    CHECK(info.struct_size == sizeof info && !info.has_pose && !info.has_keyframe_id);

    /* Sizes below the published layout are refused, and nothing is written. */
    memset(&frame, 0x5A, sizeof frame);
    CHECK_STATUS(topoloc_frame_init(&frame, 0), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_HAS_MESSAGE();
    CHECK(all_bytes((const unsigned char *)&frame, sizeof frame, 0x5A));
    /* The first published (ABI 1.0) frame ends before `image`. */
    CHECK_STATUS(topoloc_frame_init(&frame, offsetof(topoloc_frame, image) - 1),
                 TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_localizer_options_init(
                     &options, offsetof(topoloc_localizer_options, image_backend) - 1),
                 TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_result_init(&result, sizeof(size_t)), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_localizer_options_init(&options, 1), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_keyframe_options_init(&kf_options, 0), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_map_load_options_init(&load_options, 0), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_view_attributes_init(&attributes, 0), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_view_info_init(&info, 0), TOPOLOC_ERR_STRUCT_SIZE);

    /* A newer caller's larger struct: the library fills what it knows, says so in struct_size,
     * and leaves the rest alone. */
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

/* Threads: a shared const map, one localizer per thread, per-thread last errors. */
struct thread_job {
    const topoloc_map *map;
    unsigned id;
    unsigned failures;
    char first_failure[160];
};

static void job_fail(struct thread_job *job, const char *what)
{
    if (job->failures++ == 0) {
        snprintf(job->first_failure, sizeof job->first_failure, "%s", what);
    }
}

static void *thread_main(void *arg)
{
    struct thread_job *job = arg;
    topoloc_localizer *loc = NULL;
    topoloc_frame frame;
    topoloc_result result;
    topoloc_candidate candidates[3];
    float desc[DIM];
    char msg[256], expect[32];
    size_t needed = 0, count = 0;
    uint32_t ids[4];
    unsigned round, k;

    /* A new thread has no last error. */
    if (topoloc_last_error_message(msg, sizeof msg, &needed) != TOPOLOC_OK || msg[0] != '\0' ||
        needed != 1) {
        job_fail(job, "fresh thread's last error is not empty");
    }
    if (topoloc_localizer_new(job->map, NULL, &loc) != TOPOLOC_OK) {
        job_fail(job, "localizer_new");
        return NULL;
    }
    if (topoloc_frame_default(&frame) != TOPOLOC_OK ||
        topoloc_result_default(&result) != TOPOLOC_OK) {
        job_fail(job, "_default");
    }
    result.candidates = candidates;
    result.candidates_capacity = 3;
    for (round = 0; round < 20; round++) {
        /* Each thread's own error, read back after other threads have set theirs. */
        uint32_t bad_place = 1000u + job->id * 100u + round;
        snprintf(expect, sizeof expect, "%u", (unsigned)bad_place);
        if (topoloc_map_neighbours(job->map, bad_place, ids, 4, &count) !=
            TOPOLOC_ERR_UNKNOWN_PLACE) {
            job_fail(job, "unknown place not refused");
        }
        for (k = 0; k < PLACES; k++) {
            /* Deterministic per thread: no shared generator. */
            uint32_t source = k * VIEWS_PER_PLACE + (job->id + round) % VIEWS_PER_PLACE, d;
            for (d = 0; d < DIM; d++) {
                desc[d] = g_view_desc[source][d] * (1.0f + 0.01f * (float)((d + job->id) % 3));
            }
            frame.descriptor = desc;
            frame.descriptor_len = DIM;
            frame.timestamp = (double)(round * PLACES + k);
            if (topoloc_localizer_process(loc, &frame, &result) != TOPOLOC_OK) {
                job_fail(job, "process");
            } else if (result.place != k || result.view != source ||
                       result.frame_index != (uint64_t)(round * PLACES + k) ||
                       result.candidates_len != 3) {
                job_fail(job, "wrong localization");
            }
        }
        if (topoloc_last_error_message(msg, sizeof msg, NULL) != TOPOLOC_OK ||
            strstr(msg, expect) == NULL) {
            job_fail(job, "last error message overwritten by another thread");
        }
    }
    topoloc_localizer_free(loc);
    return NULL;
}

static void test_threads(const topoloc_map *map)
{
    enum { THREADS = 4 };
    pthread_t threads[THREADS];
    struct thread_job jobs[THREADS];
    bool started[THREADS];
    unsigned i;

    section("threads: shared map, one localizer per thread, thread-local last error");
    for (i = 0; i < THREADS; i++) {
        memset(&jobs[i], 0, sizeof jobs[i]);
        jobs[i].map = map;
        jobs[i].id = i;
        started[i] = pthread_create(&threads[i], NULL, thread_main, &jobs[i]) == 0;
        CHECK(started[i]);
    }
    for (i = 0; i < THREADS; i++) {
        if (started[i]) {
            CHECK(pthread_join(threads[i], NULL) == 0);
            if (jobs[i].failures != 0) {
                fprintf(stderr, "    thread %u: %u failures, first: %s\n", i, jobs[i].failures,
                        jobs[i].first_failure);
            }
            CHECK(jobs[i].failures == 0);
        }
    }
}

/* Two threads on ONE localizer (a caller's bug): every call either runs alone or is refused
 * with TOPOLOC_ERR_CONCURRENT_USE; the calls that ran got distinct, consecutive frame indices. */
enum { SHARED_CALLS = 3000 };

struct shared_job {
    topoloc_localizer *loc;
    unsigned id;
    unsigned ok, busy, other;
    uint64_t *indices; /* frame indices of the calls that ran, SHARED_CALLS slots */
    bool busy_message_ok;
};

static void *shared_main(void *arg)
{
    struct shared_job *job = arg;
    topoloc_frame frame;
    topoloc_result result;
    topoloc_candidate candidates[3];
    char msg[256];
    unsigned i;

    topoloc_frame_default(&frame);
    topoloc_result_default(&result);
    result.candidates = candidates;
    result.candidates_capacity = 3;
    frame.descriptor = g_view_desc[job->id];
    frame.descriptor_len = DIM;
    frame.timestamp = 0.0; /* equal timestamps: neither thread's frames go backwards */
    job->busy_message_ok = true;
    for (i = 0; i < SHARED_CALLS; i++) {
        topoloc_status status = topoloc_localizer_process(job->loc, &frame, &result);
        if (status == TOPOLOC_OK) {
            job->indices[job->ok++] = result.frame_index;
        } else if (status == TOPOLOC_ERR_CONCURRENT_USE) {
            job->busy++;
            if (topoloc_last_error_message(msg, sizeof msg, NULL) != TOPOLOC_OK ||
                strstr(msg, "'localizer' is in use by another call") == NULL) {
                job->busy_message_ok = false;
            }
        } else {
            job->other++;
        }
    }
    return NULL;
}

static int compare_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : x > y;
}

static void test_shared_localizer(const topoloc_map *map)
{
    pthread_t threads[2];
    struct shared_job jobs[2];
    topoloc_localizer *loc = NULL;
    uint64_t *all = malloc(2 * SHARED_CALLS * sizeof *all);
    unsigned i, ran = 0;
    bool consecutive = true;

    section("threads: one localizer used by two threads at once is refused, never raced");
    CHECK(all != NULL);
    CHECK_OK(topoloc_localizer_new(map, NULL, &loc));
    if (all == NULL || loc == NULL) {
        free(all);
        topoloc_localizer_free(loc);
        return;
    }
    for (i = 0; i < 2; i++) {
        memset(&jobs[i], 0, sizeof jobs[i]);
        jobs[i].loc = loc;
        jobs[i].id = i;
        jobs[i].indices = all + i * SHARED_CALLS;
    }
    CHECK(pthread_create(&threads[0], NULL, shared_main, &jobs[0]) == 0);
    CHECK(pthread_create(&threads[1], NULL, shared_main, &jobs[1]) == 0);
    CHECK(pthread_join(threads[0], NULL) == 0);
    CHECK(pthread_join(threads[1], NULL) == 0);
    for (i = 0; i < 2; i++) {
        CHECK(jobs[i].other == 0);
        CHECK(jobs[i].ok + jobs[i].busy == SHARED_CALLS);
        CHECK(jobs[i].busy_message_ok);
    }
    /* The calls that ran are the localizer's frames 0, 1, 2, ...: no index twice, none lost. */
    memmove(all + jobs[0].ok, all + SHARED_CALLS, jobs[1].ok * sizeof *all);
    ran = jobs[0].ok + jobs[1].ok;
    qsort(all, ran, sizeof *all, compare_u64);
    for (i = 0; i < ran; i++) {
        consecutive = consecutive && all[i] == i;
    }
    CHECK(consecutive);
    printf("    %u calls ran, %u refused as concurrent\n", ran, jobs[0].busy + jobs[1].busy);
    free(all);
    topoloc_localizer_free(loc);
}

/* ------------------------------------------------------------------------------------------ */
/* Host logging                                                                                */
/* ------------------------------------------------------------------------------------------ */

struct log_sink {
    unsigned records, info_map_records, above_level;
    uint32_t max_level;
    char last_message[512];
    char last_target[64];
};

static void collect_log(topoloc_log_level level, const char *target, const char *message,
                        void *user_data)
{
    struct log_sink *sink = user_data;
    sink->records++;
    if (level > sink->max_level || level < TOPOLOC_LOG_ERROR) {
        sink->above_level++;
    }
    if (level == TOPOLOC_LOG_INFO && strcmp(target, "topoloc::map::file") == 0) {
        sink->info_map_records++;
    }
    snprintf(sink->last_message, sizeof sink->last_message, "%s", message);
    snprintf(sink->last_target, sizeof sink->last_target, "%s", target);
    /* The callback may not replace itself. */
    if (topoloc_set_log_callback(NULL, TOPOLOC_LOG_OFF, NULL) != TOPOLOC_ERR_CONCURRENT_USE) {
        sink->above_level++;
    }
}

static void test_logging(const topoloc_map *map)
{
    struct log_sink sink;
    char path[4200];
    topoloc_map *loaded = NULL;

    section("host logging: records reach the callback up to its level, none when off");
    memset(&sink, 0, sizeof sink);
    tmp_path(path, sizeof path, "logged.topoloc");
    CHECK_STATUS(topoloc_set_log_callback(collect_log, 6, &sink), TOPOLOC_ERR_INVALID_ARGUMENT);
    sink.max_level = TOPOLOC_LOG_INFO;
    CHECK_OK(topoloc_set_log_callback(collect_log, TOPOLOC_LOG_INFO, &sink));
    CHECK_OK(topoloc_map_save(map, path));
    CHECK(sink.info_map_records == 1);
    CHECK(strncmp(sink.last_message, "saved ", 6) == 0);
    CHECK_OK(topoloc_map_load(path, NULL, &loaded));
    topoloc_map_free(loaded);
    CHECK(sink.info_map_records == 2);
    CHECK(strncmp(sink.last_message, "loaded ", 7) == 0 && strstr(sink.last_message, path) != NULL);
    CHECK(strcmp(sink.last_target, "topoloc::map::file") == 0);

    /* WARN: the map records (INFO) are dropped. */
    sink.max_level = TOPOLOC_LOG_WARN;
    CHECK_OK(topoloc_set_log_callback(collect_log, TOPOLOC_LOG_WARN, &sink));
    CHECK_OK(topoloc_map_load(path, NULL, &loaded));
    topoloc_map_free(loaded);
    CHECK(sink.info_map_records == 2);

    /* Off: nothing more, at any level. */
    CHECK_OK(topoloc_set_log_callback(NULL, TOPOLOC_LOG_TRACE, &sink));
    CHECK_OK(topoloc_map_load(path, NULL, &loaded));
    topoloc_map_free(loaded);
    CHECK(sink.info_map_records == 2);
    CHECK(sink.records == 2);
    CHECK(sink.above_level == 0);
    CHECK(remove(path) == 0);
}

/* ------------------------------------------------------------------------------------------ */
/* Images                                                                                      */
/* ------------------------------------------------------------------------------------------ */

/*
 * The image world: IMG_PLACES small grey "places" (a horizontal ramp under random rectangles,
 * the C twin of tests/images.rs) and "revisits" of them (shifted by two pixels, 10% brighter,
 * with noise). Maps are built with VLAD (no model needed), a small codebook and one describing
 * thread, so that the whole section stays fast under valgrind.
 */
#define IMG_W 160u
#define IMG_H 120u
#define IMG_PIXELS (IMG_W * IMG_H)
#define IMG_PLACES 8u
#define IMG_CLUSTERS 16u
#define IMG_FILES 4u

static uint8_t g_place_px[IMG_PLACES][IMG_PIXELS];

/* True under valgrind (its preload libraries are in LD_PRELOAD). */
static bool under_valgrind(void)
{
    const char *preload = getenv("LD_PRELOAD");
    return preload != NULL && strstr(preload, "vgpreload") != NULL;
}

static uint64_t lcg_next(uint64_t *state)
{
    *state = *state * 6364136223846793005u + 1442695040888963407u;
    return *state;
}

static uint32_t lcg_below(uint64_t *state, uint32_t m)
{
    return (uint32_t)((lcg_next(state) >> 33) % m);
}

/* A deterministic place: a grey ramp under 80 rectangles of random shades. */
static void make_place_image(uint64_t seed, uint8_t *px)
{
    uint64_t state = seed * 0x9E3779B97F4A7C15u + 7u;
    uint32_t i, k, x, y;
    for (i = 0; i < IMG_PIXELS; i++) {
        px[i] = (uint8_t)((i % IMG_W) * 255u / IMG_W / 2u + 40u);
    }
    for (k = 0; k < 80; k++) {
        uint32_t x0 = lcg_below(&state, IMG_W), y0 = lcg_below(&state, IMG_H);
        uint32_t w = 4 + lcg_below(&state, 30), h = 4 + lcg_below(&state, 30);
        uint8_t shade = (uint8_t)lcg_below(&state, 256);
        for (y = y0; y < y0 + h && y < IMG_H; y++) {
            for (x = x0; x < x0 + w && x < IMG_W; x++) {
                px[y * IMG_W + x] = shade;
            }
        }
    }
}

/* The same place seen again: shifted by 2 pixels, brighter, with noise. */
static void make_revisit(const uint8_t *in, uint64_t seed, uint8_t *out)
{
    uint64_t state = seed;
    uint32_t x, y;
    for (y = 0; y < IMG_H; y++) {
        for (x = 0; x < IMG_W; x++) {
            uint32_t sx = x + 2 < IMG_W ? x + 2 : IMG_W - 1;
            int noise = (int)(lcg_next(&state) >> 60) - 8;
            int v = in[y * IMG_W + sx] * 11 / 10 + 10 + noise;
            out[y * IMG_W + x] = (uint8_t)(v < 0 ? 0 : v > 255 ? 255 : v);
        }
    }
}

static void init_image_world(void)
{
    uint32_t p;
    for (p = 0; p < IMG_PLACES; p++) {
        make_place_image(p, g_place_px[p]);
    }
}

static topoloc_image gray_image(const uint8_t *px)
{
    topoloc_image image;
    memset(&image, 0, sizeof image);
    image.data = px;
    image.data_len = IMG_PIXELS;
    image.width = IMG_W;
    image.height = IMG_H;
    image.stride = IMG_W;
    image.format = TOPOLOC_PIXEL_GRAY8;
    return image;
}

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

static void vlad_options(topoloc_image_map_options *options, uint32_t images)
{
    CHECK_OK(topoloc_image_map_options_default(options));
    options->backend = TOPOLOC_BACKEND_VLAD_ORB;
    options->dim = images - 1;
    options->threads = 1;
    options->vlad_clusters = IMG_CLUSTERS;
}

/* Progress callback log. */
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

static void test_image_defaults(void)
{
    topoloc_image_map_options options;
    topoloc_localizer_options lo;
    topoloc_frame frame;
    topoloc_image zero;

    section("images: constants and defaults of the image structs");
    /* Values are part of the ABI. */
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
    memset(&zero, 0, sizeof zero);
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
    CHECK_STATUS(topoloc_image_map_options_init(&options, 0), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_image_map_options_init(&options, sizeof options - 1),
                 TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_NULL(topoloc_image_map_options_init(NULL, sizeof options), "options");
}

/* Builds the image map (progress recorded), checks cancellation, saves and reloads the map:
 * returns the reloaded map, or NULL. */
static topoloc_map *test_image_map_build(void)
{
    topoloc_image images[IMG_PLACES];
    topoloc_image_map_options options;
    struct progress_log log;
    topoloc_map *built = NULL, *loaded = NULL, *out;
    char path[4200], kind[64], model[512], kind2[64], model2[512];
    size_t n = 0;
    uint32_t i, dim = 0;

    section("images: map from in-memory images, progress, cancel, save and load");
    for (i = 0; i < IMG_PLACES; i++) {
        images[i] = gray_image(g_place_px[i]);
    }
    vlad_options(&options, IMG_PLACES);

    /* Cancelled while describing: no map. */
    progress_log_init(&log, TOPOLOC_STAGE_DESCRIBING, IMG_PLACES);
    out = untouched_map();
    CHECK_STATUS(
        topoloc_map_build_from_images(images, IMG_PLACES, &options, record_progress, &log, &out),
        TOPOLOC_ERR_CANCELLED);
    CHECK_HAS_MESSAGE();
    CHECK(out == untouched_map());
    CHECK(log.cancelled && log.calls >= 1 && !log.other_thread);
    CHECK(!log.saw_fitting); /* nothing after the describing stage */

    /* Cancelled when fitting starts (every image described): no map either. */
    progress_log_init(&log, TOPOLOC_STAGE_FITTING, IMG_PLACES);
    CHECK_STATUS(
        topoloc_map_build_from_images(images, IMG_PLACES, &options, record_progress, &log, &out),
        TOPOLOC_ERR_CANCELLED);
    CHECK(out == untouched_map());
    CHECK(log.cancelled && log.saw_describing_all && log.saw_fitting && !log.saw_fitting_done);

    /* The real build, with progress. */
    progress_log_init(&log, -1, IMG_PLACES);
    CHECK_OK(
        topoloc_map_build_from_images(images, IMG_PLACES, &options, record_progress, &log, &built));
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

    /* A sequence map: one place per image, chained, views know their image's index. */
    CHECK_COUNTS(built, IMG_PLACES, IMG_PLACES, IMG_PLACES - 1);
    CHECK_OK(topoloc_map_descriptor_dim(built, &dim));
    CHECK(dim == IMG_PLACES - 1);
    CHECK_OK(topoloc_map_descriptor_kind(built, kind, sizeof kind, NULL));
    CHECK(strcmp(kind, "vlad-orb") == 0);
    CHECK_OK(topoloc_map_descriptor_model(built, model, sizeof model, NULL));
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

    /* Without a progress callback (NULL) and with two threads: the same map. */
    options.threads = 2;
    CHECK_OK(topoloc_map_build_from_images(images, IMG_PLACES, &options, NULL, NULL, &loaded));
    if (loaded != NULL) {
        float a[IMG_PLACES], b[IMG_PLACES];
        CHECK_OK(topoloc_map_view_descriptor(built, 3, a, IMG_PLACES));
        CHECK_OK(topoloc_map_view_descriptor(loaded, 3, b, IMG_PLACES));
        CHECK(memcmp(a, b, sizeof(float) * (IMG_PLACES - 1)) == 0); /* deterministic */
        CHECK_OK(topoloc_map_descriptor_model(loaded, model2, sizeof model2, NULL));
        CHECK(strcmp(model, model2) == 0);
        topoloc_map_free(loaded);
        loaded = NULL;
    }
    options.threads = 1;

    /* f32 PCA rows on request (another identity); an unknown precision is refused. */
    options.pca_precision = TOPOLOC_PCA_F32;
    CHECK_OK(topoloc_map_build_from_images(images, IMG_PLACES, &options, NULL, NULL, &loaded));
    if (loaded != NULL) {
        CHECK_OK(topoloc_map_descriptor_model(loaded, model2, sizeof model2, NULL));
        CHECK(strstr(model2, "/i8") == NULL && strcmp(model, model2) != 0);
        topoloc_map_free(loaded);
        loaded = NULL;
    }
    options.pca_precision = 2;
    out = untouched_map();
    CHECK_STATUS(topoloc_map_build_from_images(images, IMG_PLACES, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(strstr(last_error(), "pca_precision") != NULL);
    CHECK(out == untouched_map());
    options.pca_precision = TOPOLOC_PCA_I8;

    /* The describer survives the file. */
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
    /* The map is memory-mapped: unlinking the file keeps it readable (POSIX). */
    CHECK(unlink(path) == 0);
    topoloc_map_free(built);
    return loaded;
}

/* Localizes the revisit of `place` with `loc` at time `t`; returns the status. */
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

static void test_image_localize(const topoloc_map *map, const topoloc_map *world)
{
    static uint8_t revisit[IMG_PLACES][IMG_PIXELS];
    topoloc_localizer_options options;
    topoloc_localizer *single = NULL, *filter = NULL, *loc = NULL;
    topoloc_result r, snapshot;
    topoloc_candidate candidates[3];
    topoloc_frame frame;
    topoloc_image image;
    float view5[IMG_PLACES];
    unsigned correct_single = 0, correct_filter = 0;
    uint32_t p;

    section("images: localizing image frames (AUTO, explicit backends, NONE, formats)");
    for (p = 0; p < IMG_PLACES; p++) {
        make_revisit(g_place_px[p], 100u + p, revisit[p]);
    }
    CHECK_OK(topoloc_result_default(&r));
    r.candidates = candidates;
    r.candidates_capacity = 3;

    /* AUTO loads the map's describer: revisits find their place. */
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.mode = TOPOLOC_MODE_SINGLE_FRAME;
    CHECK_OK(topoloc_localizer_new(map, &options, &single));
    CHECK_OK(topoloc_localizer_new(map, NULL, &filter)); /* NULL options: AUTO, filter mode */
    if (single == NULL || filter == NULL) {
        topoloc_localizer_free(single);
        topoloc_localizer_free(filter);
        return;
    }
    for (p = 0; p < IMG_PLACES; p++) {
        image = gray_image(revisit[p]);
        CHECK_OK(localize_image(single, &image, (double)p, &r));
        correct_single += r.place == p;
        CHECK(r.frame_index == p && r.candidates_len == 3 && r.candidates[0].place == r.place);
        CHECK(r.similarity > 0.0f && r.similarity <= 1.0001f);
        CHECK_OK(localize_image(filter, &image, (double)p, &r));
        correct_filter += r.place == p;
    }
    printf("   revisits localized: %u/%u single-frame, %u/%u filter\n", correct_single, IMG_PLACES,
           correct_filter, IMG_PLACES);
    CHECK(correct_single >= IMG_PLACES - 1);
    CHECK(correct_filter >= IMG_PLACES - 1);

    /* Every pixel format, with padded rows, describes like the grey original. */
    {
        static const uint32_t formats[4] = {TOPOLOC_PIXEL_RGB8, TOPOLOC_PIXEL_BGR8,
                                            TOPOLOC_PIXEL_RGBA8, TOPOLOC_PIXEL_BGRA8};
        static const uint32_t channels[4] = {3, 3, 4, 4};
        topoloc_result reference;
        size_t k;
        CHECK_OK(topoloc_localizer_reset(single));
        image = gray_image(revisit[4]);
        CHECK_OK(topoloc_result_default(&reference));
        CHECK_OK(localize_image(single, &image, 0.0, &reference));
        /* A grey view into a larger buffer (stride > width, like a cv::Mat ROI). */
        {
            uint8_t *padded = NULL;
            topoloc_image roi = repack(revisit[4], TOPOLOC_PIXEL_GRAY8, 1, IMG_W + 40, &padded);
            CHECK(roi.data != NULL);
            if (roi.data != NULL) {
                CHECK_OK(localize_image(single, &roi, 0.0, &r));
                CHECK(r.place == reference.place);
                CHECK_NEAR(r.similarity, reference.similarity, 1e-4f);
            }
            free(padded);
        }
        for (k = 0; k < 4; k++) {
            uint8_t *buffer = NULL;
            topoloc_image colour =
                repack(revisit[4], formats[k], channels[k], IMG_W * channels[k] + 13, &buffer);
            CHECK(colour.data != NULL);
            if (colour.data != NULL) {
                CHECK_OK(localize_image(single, &colour, 0.0, &r));
                CHECK(r.place == reference.place);
                CHECK_NEAR(r.similarity, reference.similarity, 1e-3f);
                /* The exact minimum length (no padding after the last row) is accepted. */
                colour.data_len = colour.stride * (IMG_H - 1) + (size_t)IMG_W * channels[k];
                CHECK_OK(localize_image(single, &colour, 0.0, &r));
                colour.data_len -= 1;
                CHECK_STATUS(localize_image(single, &colour, 0.0, &r), TOPOLOC_ERR_INVALID_IMAGE);
            }
            free(buffer);
        }
    }

    /* A frame with both a descriptor and an image: the descriptor is used. */
    CHECK_OK(topoloc_map_view_descriptor(map, 5, view5, IMG_PLACES - 1));
    CHECK_OK(topoloc_frame_default(&frame));
    frame.timestamp = 0.0;
    frame.descriptor = view5;
    frame.descriptor_len = IMG_PLACES - 1;
    frame.image = gray_image(revisit[2]);
    CHECK_OK(topoloc_localizer_process(single, &frame, &r));
    CHECK(r.place == 5 && r.view == 5);
    topoloc_localizer_free(single);
    topoloc_localizer_free(filter);

    /* Asking for the map's own backend works; another backend is a mismatch. */
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.image_backend = TOPOLOC_BACKEND_VLAD_ORB;
    check_new_localizer_finds(map, &options, revisit[6], 6);
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

    /* ABI 1.0 options (no image fields) on an image map: AUTO, so image frames work. */
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.struct_size = offsetof(topoloc_localizer_options, image_backend);
    options.image_backend = TOPOLOC_BACKEND_NONE; /* beyond struct_size: not read */
    check_new_localizer_finds(map, &options, revisit[1], 1);

    /* BACKEND_NONE: descriptor frames only; an image frame is refused, state unchanged. */
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.image_backend = TOPOLOC_BACKEND_NONE;
    CHECK_OK(topoloc_localizer_new(map, &options, &loc));
    if (loc != NULL) {
        frame.image = gray_image(g_place_px[0]); /* with the descriptor of view 5: fine */
        CHECK_OK(topoloc_localizer_process(loc, &frame, &r));
        CHECK(r.place == 5 && r.frame_index == 0);
        snapshot = r;
        image = gray_image(revisit[3]);
        CHECK_STATUS(localize_image(loc, &image, 1.0, &r), TOPOLOC_ERR_NO_DESCRIBER);
        CHECK_HAS_MESSAGE();
        CHECK(identical_result(&snapshot, &r));
        frame.timestamp = 1.0;
        CHECK_OK(topoloc_localizer_process(loc, &frame, &r));
        CHECK(r.frame_index == 1);
    }
    topoloc_localizer_free(loc);
    loc = NULL;

    /* A map built from descriptors has no describer. */
    CHECK_OK(topoloc_localizer_new(world, NULL, &loc)); /* AUTO: fine, descriptors only */
    if (loc != NULL) {
        image = gray_image(revisit[0]);
        CHECK_STATUS(localize_image(loc, &image, 0.0, &r), TOPOLOC_ERR_NO_DESCRIBER);
        CHECK_HAS_MESSAGE();
    }
    topoloc_localizer_free(loc);
    loc = NULL;
    CHECK_OK(topoloc_localizer_options_default(&options));
    options.image_backend = TOPOLOC_BACKEND_VLAD_ORB;
    CHECK_STATUS(topoloc_localizer_new(world, &options, &loc), TOPOLOC_ERR_NO_DESCRIBER);
    CHECK_HAS_MESSAGE();
    CHECK(loc == NULL);
}

static void test_bad_images(const topoloc_map *map)
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
    topoloc_image_map_options options;
    topoloc_image images[3];
    topoloc_map *out;
    struct progress_log log;
    size_t k;

    section("images: bad and uninformative images leave the localizer unchanged");
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

    /* Bad input to a build: refused before any describing (the callback is never called). */
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
    CHECK_STATUS(topoloc_map_build_from_images(images, 1, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_ARGUMENT); /* fewer than 2 images */
    CHECK_HAS_MESSAGE();
    options.backend = 77;
    CHECK_STATUS(topoloc_map_build_from_images(images, 3, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("77");
    options.backend = TOPOLOC_BACKEND_NONE; /* a localizer-only choice */
    CHECK_STATUS(topoloc_map_build_from_images(images, 3, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    vlad_options(&options, 3);
    options.views_per_place = 0;
    CHECK_STATUS(topoloc_map_build_from_images(images, 3, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    vlad_options(&options, 3);
    options.threads = 100000; /* more than 256: refused, not a hang */
    CHECK_STATUS(topoloc_map_build_from_images(images, 3, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_MESSAGE_HAS("threads");
    vlad_options(&options, 3);
    options.vlad_clusters = 1;
    CHECK_STATUS(topoloc_map_build_from_images(images, 3, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    vlad_options(&options, 3);
    options.struct_size = 0;
    CHECK_STATUS(topoloc_map_build_from_images(images, 3, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_STRUCT_SIZE);
    CHECK(out == untouched_map());
    vlad_options(&options, 3);
    CHECK_NULL(topoloc_map_build_from_images(NULL, 3, &options, NULL, NULL, &out), "images");
    CHECK_NULL(topoloc_map_build_from_images(images, 3, &options, NULL, NULL, NULL), "out");
    CHECK(out == untouched_map());
}

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

static void test_image_files(void)
{
    static uint8_t revisit[IMG_PIXELS];
    char paths[IMG_FILES][4200], missing[4200], text[4200], tum[4200], short_tum[4200];
    const char *list[IMG_FILES];
    topoloc_image_map_options options;
    struct progress_log log;
    topoloc_map *map = NULL, *out;
    topoloc_localizer *loc = NULL;
    topoloc_localizer_options lo;
    topoloc_result r;
    topoloc_image image;
    size_t n = 0;
    uint32_t i;
    bool written = true;
    FILE *f;

    section("images: maps from image files (PGM), poses, missing and unreadable files");
    for (i = 0; i < IMG_FILES; i++) {
        char name[32];
        snprintf(name, sizeof name, "place_%u.pgm", (unsigned)i);
        tmp_path(paths[i], sizeof paths[i], name);
        written = write_pgm(paths[i], g_place_px[i], IMG_W, IMG_H) && written;
        list[i] = paths[i];
    }
    CHECK(written);
    vlad_options(&options, IMG_FILES);
    progress_log_init(&log, -1, IMG_FILES);
    CHECK_OK(
        topoloc_map_build_from_image_files(list, IMG_FILES, &options, record_progress, &log, &map));
    CHECK(log.saw_describing_all && log.saw_fitting_done && !log.bad_values);
    if (map != NULL) {
        CHECK_OK(topoloc_map_place_count(map, &n));
        CHECK(n == IMG_FILES);
        for (i = 0; i < IMG_FILES; i++) {
            char image_ref[4200];
            topoloc_view_info info;
            CHECK_OK(topoloc_map_view_image(map, i, image_ref, sizeof image_ref, NULL));
            CHECK(strcmp(image_ref, paths[i]) == 0); /* views record their file */
            CHECK_OK(topoloc_view_info_default(&info));
            CHECK_OK(topoloc_map_view_info(map, i, &info));
            CHECK(info.has_keyframe_id && info.keyframe_id == i);
        }
        /* Files read by OpenCV (as colour) and grey pixels in memory describe alike. */
        CHECK_OK(topoloc_localizer_options_default(&lo));
        lo.mode = TOPOLOC_MODE_SINGLE_FRAME;
        CHECK_OK(topoloc_localizer_new(map, &lo, &loc));
        CHECK_OK(topoloc_result_default(&r));
        if (loc != NULL) {
            make_revisit(g_place_px[2], 7, revisit);
            image = gray_image(revisit);
            CHECK_OK(localize_image(loc, &image, 0.0, &r));
            CHECK(r.place == 2);
        }
        topoloc_localizer_free(loc);
        topoloc_map_free(map);
        map = NULL;
    }

    /* With one pose per image (TUM), places come from the poses and carry positions. */
    tmp_path(tum, sizeof tum, "poses.tum");
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
        map = NULL;
    }
    /* Fewer poses than images, a missing poses file. */
    tmp_path(short_tum, sizeof short_tum, "short.tum");
    CHECK(write_file(short_tum, (const unsigned char *)"0 0 0 0 0 0 0 1\n", 16));
    options.poses_tum_path = short_tum;
    out = untouched_map();
    CHECK_STATUS(topoloc_map_build_from_image_files(list, IMG_FILES, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_HAS_MESSAGE();
    tmp_path(missing, sizeof missing, "no-such-poses.tum");
    options.poses_tum_path = missing;
    CHECK_STATUS(topoloc_map_build_from_image_files(list, IMG_FILES, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_IO);
    CHECK_MESSAGE_HAS(missing);
    options.poses_tum_path = NULL;

    /* A missing file and a file that is no image: INVALID_IMAGE naming the path. */
    tmp_path(missing, sizeof missing, "no-such-image.pgm");
    list[2] = missing;
    CHECK_STATUS(topoloc_map_build_from_image_files(list, IMG_FILES, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_MESSAGE_HAS(missing);
    tmp_path(text, sizeof text, "not-an-image.pgm");
    CHECK(write_file(text, (const unsigned char *)"hello\n", 6));
    list[2] = text;
    CHECK_STATUS(topoloc_map_build_from_image_files(list, IMG_FILES, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_IMAGE);
    CHECK_MESSAGE_HAS(text);
    list[2] = NULL;
    CHECK_NULL(topoloc_map_build_from_image_files(list, IMG_FILES, &options, NULL, NULL, &out),
               "paths[2]");
    list[2] = "\xff\xfe.pgm";
    CHECK_STATUS(topoloc_map_build_from_image_files(list, IMG_FILES, &options, NULL, NULL, &out),
                 TOPOLOC_ERR_INVALID_UTF8);
    CHECK_NULL(topoloc_map_build_from_image_files(NULL, IMG_FILES, &options, NULL, NULL, &out),
               "paths");
    CHECK(out == untouched_map());

    CHECK(unlink(text) == 0 && unlink(tum) == 0 && unlink(short_tum) == 0);
    for (i = 0; i < IMG_FILES; i++) {
        CHECK(unlink(paths[i]) == 0);
    }
}

/* The default ONNX model file (scripts/setup-models.sh): $TOPOLOC_CACHE or ~/.cache/topoloc. */
static bool onnx_model_file(char *path, size_t len)
{
    const char *cache = getenv("TOPOLOC_CACHE");
    const char *home = getenv("HOME");
    if (cache != NULL && cache[0] != '\0') {
        snprintf(path, len, "%s/models/mobilenetv2-mlf.onnx", cache);
    } else {
        snprintf(path, len, "%s/.cache/topoloc/models/mobilenetv2-mlf.onnx",
                 home != NULL ? home : "");
    }
    return access(path, R_OK) == 0;
}

static void test_onnx(void)
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

    section("images: ONNX backend (missing model always; the model itself when installed)");
    for (i = 0; i < ONNX_IMAGES; i++) {
        images[i] = gray_image(g_place_px[i]);
    }
    /* A model path that does not exist: BACKEND_UNAVAILABLE naming it, for ONNX and AUTO. */
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

    if (!onnx_model_file(model_path, sizeof model_path)) {
        printf("   ONNX map checks skipped: no model at %s (run scripts/setup-models.sh)\n",
               model_path);
        return;
    }
    if (under_valgrind()) {
        /* ONNX Runtime takes minutes there, and its own code is not ours to check. */
        printf("   ONNX map checks skipped under valgrind (ONNX Runtime is not ours to check)\n");
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

/* ABI 1.0 callers: a frame without the image field still works. */
static void test_abi_1_0_frame(const topoloc_map *world)
{
    /* The ABI 1.0 layout of topoloc_frame, followed by bytes that are not an image. */
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

    section("images: an ABI 1.0-sized frame (no image field) still localizes descriptors");
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
    /* The 0xEE bytes after the 1.0 layout would be an invalid image if they were read. */
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

/* Geometric verification (ABI 1.2): maps built from images store keypoints; the top place of a
 * revisit is verified with many inliers; a map without keypoints refuses the option; a frame
 * without its image is refused with the state unchanged; an ABI 1.1 result is still filled. */
static void test_verification(const topoloc_map *map, const topoloc_map *world)
{
    static uint8_t revisit[IMG_PIXELS];
    static float descriptor[1024];
    topoloc_localizer_options options;
    topoloc_localizer *loc = NULL;
    topoloc_result r;
    topoloc_frame frame;
    topoloc_image image;
    uint32_t dim = 0;

    section("images: geometric verification (keypoints, inliers, refusals)");
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

static void test_pose_fix(const topoloc_map *map)
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

    section("pose fixes: keypoint scene points from the host, a metric camera pose");
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
    xyz[1] = NAN; /* neither finite nor all NaN */
    CHECK_STATUS(topoloc_map_with_keypoint_points(map, xyz, 3 * total, &posed),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    xyz[1] = (float)((xy[1] - cy) / PF_FOCAL); /* overwritten below anyway */
    xyz[0] = xyz[1] = xyz[2] = NAN;            /* unknown: allowed */
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

static void test_metric_mode(const topoloc_map *world)
{
    topoloc_localizer_options options;
    topoloc_localizer *loc = NULL;
    topoloc_map *posed = NULL;
    topoloc_frame frame;
    topoloc_result r;
    float desc[DIM];
    double forward[16] = {1, 0, 0, 2, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    uint32_t p, placed = 0;

    section("metric mode: particles moved by odometry, maps without poses refused");
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

/* A describer from the image map describes each map image as its view was described, refuses
 * what it cannot describe and leaves its buffer untouched on errors. */
static void test_describer(const topoloc_map *map, const topoloc_map *world)
{
    topoloc_describer_options options;
    topoloc_describer *describer = NULL, *untouched = (topoloc_describer *)0x1;
    topoloc_image image, none;
    float got[IMG_PLACES], view[IMG_PLACES], small[2] = {7.0f, 7.0f};
    size_t dim = 0, len = 0;
    uint32_t i, map_dim = 0;

    section("describers: images to the map's descriptors (ABI 1.12)");
    memset(&options, 0x5A, sizeof options);
    CHECK_OK(topoloc_describer_options_default(&options));
    CHECK(options.struct_size == sizeof options && options.backend == TOPOLOC_BACKEND_AUTO &&
          options.onnx_model_path == NULL && options.onnx_runtime_path == NULL &&
          options.threads == 1);
    CHECK_STATUS(topoloc_describer_options_init(&options, 3), TOPOLOC_ERR_STRUCT_SIZE);

    /* A map built from descriptors stores no describer. */
    CHECK_STATUS(topoloc_describer_new(world, NULL, &untouched), TOPOLOC_ERR_NO_DESCRIBER);
    CHECK_HAS_MESSAGE();
    CHECK(untouched == (topoloc_describer *)0x1);
    /* Options it cannot honour. */
    options.backend = TOPOLOC_BACKEND_NONE;
    CHECK_STATUS(topoloc_describer_new(map, &options, &untouched), TOPOLOC_ERR_INVALID_OPTION);
    options.backend = TOPOLOC_BACKEND_ONNX; /* the map is VLAD-ORB */
    CHECK_STATUS(topoloc_describer_new(map, &options, &untouched), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    options.backend = TOPOLOC_BACKEND_AUTO;
    options.threads = 0;
    CHECK_STATUS(topoloc_describer_new(map, &options, &untouched), TOPOLOC_ERR_INVALID_OPTION);
    options.threads = 1;
    CHECK(untouched == (topoloc_describer *)0x1);
    CHECK_NULL(topoloc_describer_new(NULL, &options, &describer), "map");
    CHECK_NULL(topoloc_describer_new(map, &options, NULL), "out");

    CHECK_OK(topoloc_describer_new(map, &options, &describer));
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

static void test_images(const topoloc_map *world)
{
    topoloc_map *map;
    init_image_world();
    test_image_defaults();
    test_abi_1_0_frame(world);
    map = test_image_map_build();
    CHECK(map != NULL);
    if (map != NULL) {
        test_image_localize(map, world);
        test_describer(map, world);
        test_verification(map, world);
        test_pose_fix(map);
        test_bad_images(map);
    }
    topoloc_map_free(map);
    test_image_files();
    test_onnx();
}

/* ------------------------------------------------------------------------------------------ */
/* Skeleton graphs from occupancy grids                                                        */
/* ------------------------------------------------------------------------------------------ */

#define SK_VOXEL 0.2
#define SK_NX 45u
#define SK_NY 35u
#define SK_NZ 10u
#define SK_CELLS (SK_NX * SK_NY * SK_NZ)

/* An occupancy grid of SK_NX x SK_NY x SK_NZ voxels of SK_VOXEL m (2 m high), occupied except
 * for the `count` rectangles {x0, y0, x1, y1} (voxels, half-open) carved over the full height. */
static void sk_carve(uint8_t *cells, const unsigned (*rects)[4], size_t count)
{
    size_t x, y, z, r;
    memset(cells, 1, SK_CELLS);
    for (z = 0; z < SK_NZ; z++) {
        for (y = 0; y < SK_NY; y++) {
            for (x = 0; x < SK_NX; x++) {
                for (r = 0; r < count; r++) {
                    if (x >= rects[r][0] && x < rects[r][2] && y >= rects[r][1] &&
                        y < rects[r][3]) {
                        cells[x + SK_NX * (y + SK_NY * z)] = 0;
                    }
                }
            }
        }
    }
}

/* A T junction: a 7 m corridor along x and a 5 m stem along y, 1.2 m wide. */
static const unsigned g_sk_t[2][4] = {{5, 5, 40, 11}, {19, 5, 25, 30}};
/* A ring corridor 7 m x 5 m around a solid block. */
static const unsigned g_sk_ring[4][4] = {
    {5, 5, 40, 11}, {5, 24, 40, 30}, {5, 5, 11, 30}, {34, 5, 40, 30}};

static const size_t g_sk_dims[3] = {SK_NX, SK_NY, SK_NZ};
static const double g_sk_origin[3] = {0.0, 0.0, 0.0};

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

static void test_skeleton_graphs(void)
{
    static uint8_t cells[SK_CELLS];
    topoloc_skeleton_options opts;
    topoloc_graph *g = NULL, *again = NULL;
    topoloc_graph *const sentinel = (topoloc_graph *)(void *)&opts;
    size_t kinds[4], degree[64], places = 0, edges = 0, i, n = 0, count = 0;
    uint32_t a = 0, b = 0, kind = 0, *voxels;
    double xyz[3], xyz2[3], length = 0.0, length2 = 0.0;
    bool all_free = true, same = true;

    section("skeleton graphs: options, T junction, ring, skeleton voxels, errors");
    CHECK_OK(topoloc_skeleton_options_default(&opts));
    CHECK(opts.struct_size == sizeof opts && !opts.use_z_band);
    CHECK(opts.merge_radius_m == 1.0 && opts.max_edge_m == 3.0 && opts.min_clearance_m == 0.0);
    CHECK(opts.corner_angle_deg == 40.0 && opts.corner_scale_m == 0.5 && opts.min_spur_m == 1.0);
    CHECK_STATUS(topoloc_skeleton_options_init(&opts, sizeof(size_t)), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_NULL(topoloc_skeleton_options_init(NULL, sizeof opts), "NULL");
    CHECK_OK(topoloc_skeleton_options_default(&opts));

    /* T junction: one branch, three ends, a tree; the branch has three neighbours. */
    sk_carve(cells, g_sk_t, 2);
    CHECK_OK(
        topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, cells, SK_CELLS, &opts, &g));
    if (g == NULL) {
        return;
    }
    CHECK(sk_summary(g, kinds, degree, &places, &edges));
    CHECK(kinds[TOPOLOC_NODE_BRANCH] == 1 && kinds[TOPOLOC_NODE_END] == 3);
    CHECK(kinds[TOPOLOC_NODE_CORNER] == 0 && kinds[TOPOLOC_NODE_INTERMEDIATE] >= 1);
    CHECK(edges + 1 == places);
    /* Places come branches first. */
    CHECK_OK(topoloc_graph_place(g, 0, xyz, &kind));
    CHECK(kind == TOPOLOC_NODE_BRANCH && degree[0] == 3);
    CHECK_NEAR(xyz[0], 4.5, 0.5);
    CHECK_NEAR(xyz[1], 1.6, 0.5);
    CHECK(xyz[2] > 0.0 && xyz[2] < 2.0);
    /* Edges: a < b, sorted, their straight length, at most max_edge_m. */
    for (i = 0; i < edges; i++) {
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
        CHECK(length > 0.0 && length <= opts.max_edge_m);
    }

    /* The skeleton: ask for the size, then copy; every voxel is free. */
    CHECK_STATUS(topoloc_graph_skeleton(g, NULL, 0, &count), TOPOLOC_ERR_BUFFER_TOO_SMALL);
    CHECK(count > 0 && count % 3 == 0);
    voxels = malloc(count * sizeof *voxels);
    CHECK(voxels != NULL);
    if (voxels != NULL) {
        CHECK_STATUS(topoloc_graph_skeleton(g, voxels, count - 1, &n),
                     TOPOLOC_ERR_BUFFER_TOO_SMALL);
        CHECK(n == count);
        CHECK_OK(topoloc_graph_skeleton(g, voxels, count, &n));
        for (i = 0; i + 2 < count; i += 3) {
            all_free = all_free && voxels[i] < SK_NX && voxels[i + 1] < SK_NY &&
                       voxels[i + 2] < SK_NZ &&
                       cells[voxels[i] + SK_NX * (voxels[i + 1] + SK_NY * voxels[i + 2])] == 0;
        }
        CHECK(all_free);
        free(voxels);
    }

    /* The same grid gives the same graph (NULL options: the defaults). */
    CHECK_OK(topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, cells, SK_CELLS, NULL,
                                          &again));
    if (again != NULL) {
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
    }
    topoloc_graph_free(again);

    /* Out of range: UNKNOWN_PLACE for a place, INVALID_ARGUMENT for an edge; outputs untouched. */
    kind = 77;
    CHECK_STATUS(topoloc_graph_place(g, (uint32_t)places, xyz, &kind), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK(kind == 77);
    CHECK_HAS_MESSAGE();
    a = 77;
    CHECK_STATUS(topoloc_graph_edge(g, edges, &a, &b, &length), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(a == 77);
    /* NULL arguments. */
    CHECK_NULL(topoloc_graph_place_count(NULL, &n), "graph");
    CHECK_NULL(topoloc_graph_edge_count(g, NULL), "out");
    CHECK_NULL(topoloc_graph_place(g, 0, NULL, &kind), "xyz");
    CHECK_NULL(topoloc_graph_place(g, 0, xyz, NULL), "kind");
    CHECK_NULL(topoloc_graph_edge(g, 0, &a, &b, NULL), "length_m");
    CHECK_NULL(topoloc_graph_skeleton(NULL, NULL, 0, &n), "graph");
    topoloc_graph_free(g);
    topoloc_graph_free(NULL);

    /* A height band: every place in it. */
    opts.use_z_band = true;
    opts.z_min_m = 0.5;
    opts.z_max_m = 0.9;
    g = NULL;
    CHECK_OK(
        topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, cells, SK_CELLS, &opts, &g));
    if (g != NULL) {
        CHECK_OK(topoloc_graph_place_count(g, &places));
        for (i = 0; i < places; i++) {
            CHECK_OK(topoloc_graph_place(g, (uint32_t)i, xyz, &kind));
            CHECK(xyz[2] >= 0.5 && xyz[2] <= 0.9);
        }
    }
    topoloc_graph_free(g);
    CHECK_OK(topoloc_skeleton_options_default(&opts));

    /* A ring: a cycle (every place has two neighbours) with four corners. */
    sk_carve(cells, g_sk_ring, 4);
    g = NULL;
    CHECK_OK(
        topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, cells, SK_CELLS, &opts, &g));
    if (g != NULL) {
        bool two = true;
        CHECK(sk_summary(g, kinds, degree, &places, &edges));
        CHECK(edges == places && places >= 4);
        for (i = 0; i < places; i++) {
            two = two && degree[i] == 2;
        }
        CHECK(two);
        CHECK(kinds[TOPOLOC_NODE_CORNER] == 4 && kinds[TOPOLOC_NODE_END] == 0 &&
              kinds[TOPOLOC_NODE_BRANCH] == 0);
    }
    topoloc_graph_free(g);

    /* Errors: NULLs, sizes, a full grid and options out of range, each named; out untouched. */
    g = sentinel;
    CHECK_NULL(
        topoloc_graph_from_occupancy(NULL, SK_VOXEL, g_sk_origin, cells, SK_CELLS, &opts, &g),
        "dims");
    CHECK_NULL(topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, NULL, cells, SK_CELLS, &opts, &g),
               "origin");
    CHECK_NULL(
        topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, NULL, SK_CELLS, &opts, &g),
        "cells");
    CHECK_NULL(topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, cells, SK_CELLS,
                                            &opts, NULL),
               "out");
    CHECK_STATUS(topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, cells, SK_CELLS - 1,
                                              &opts, &g),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(strstr(last_error(), "cells_len") != NULL);
    CHECK_STATUS(
        topoloc_graph_from_occupancy(g_sk_dims, 0.0, g_sk_origin, cells, SK_CELLS, &opts, &g),
        TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(strstr(last_error(), "voxel_size") != NULL);
    opts.merge_radius_m = -1.0;
    CHECK_STATUS(
        topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, cells, SK_CELLS, &opts, &g),
        TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(strstr(last_error(), "merge_radius_m") != NULL);
    CHECK_OK(topoloc_skeleton_options_default(&opts));
    opts.max_edge_m = 0.3; /* under two voxels */
    CHECK_STATUS(
        topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, cells, SK_CELLS, &opts, &g),
        TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(strstr(last_error(), "max_edge_m") != NULL);
    CHECK_OK(topoloc_skeleton_options_default(&opts));
    opts.use_z_band = true;
    opts.z_min_m = 5.0;
    opts.z_max_m = 6.0;
    CHECK_STATUS(
        topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, cells, SK_CELLS, &opts, &g),
        TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(strstr(last_error(), "z_band") != NULL);
    CHECK_OK(topoloc_skeleton_options_default(&opts));
    opts.struct_size = 3;
    CHECK_STATUS(
        topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, cells, SK_CELLS, &opts, &g),
        TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_OK(topoloc_skeleton_options_default(&opts));
    memset(cells, 1, SK_CELLS);
    CHECK_STATUS(
        topoloc_graph_from_occupancy(g_sk_dims, SK_VOXEL, g_sk_origin, cells, SK_CELLS, &opts, &g),
        TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(strstr(last_error(), "cells") != NULL);
    CHECK(g == sentinel);
}

static bool make_tmpdir(void)
{
    const char *base = getenv("TMPDIR");
    if (base == NULL || base[0] == '\0') {
        base = "/tmp";
    }
    snprintf(g_tmpdir, sizeof g_tmpdir, "%s/topoloc-c-test-XXXXXX", base);
    if (mkdtemp(g_tmpdir) == NULL) {
        fprintf(stderr, "mkdtemp(%s): %s\n", g_tmpdir, strerror(errno));
        return false;
    }
    return true;
}

/* Loop closure (ABI 1.5): keyframes in, gated hints out. Two keyframes see the same 60
 * keypoints (same binary descriptors), so the second's candidate verifies with all of them;
 * bad keyframes are refused with the state unchanged. */
#define LOOP_DIM 8
#define LOOP_POINTS 60
/* LOOP_POINTS scene points 3-8 m in front of a 300-pixel pinhole camera, seen from it
 * (`first`) and from a camera 0.3 m to the right and 0.1 m ahead, turned 3 degrees
 * (`second`); each point has the same random 32-byte descriptor in both views. */
static void loop_keypoints(float *first, float *second, uint8_t *descriptors)
{
    uint32_t state = 12345u;
    const double c = 0.99862953475, s = 0.05233595624; /* cos, sin of 3 degrees */
    int i = 0;
    while (i < LOOP_POINTS) {
        double x, y, z, qx, qz, u1, v1, u2, v2;
        state = state * 1664525u + 1013904223u;
        z = 3.0 + 5.0 * (double)(state >> 8) / 16777216.0;
        state = state * 1664525u + 1013904223u;
        x = ((double)(state >> 8) / 16777216.0 - 0.5) * z;
        state = state * 1664525u + 1013904223u;
        y = ((double)(state >> 8) / 16777216.0 - 0.5) * 0.7 * z;
        /* The second camera: p' = R^T (p - t), R a yaw about y. */
        qx = c * (x - 0.3) - s * (z - 0.1);
        qz = s * (x - 0.3) + c * (z - 0.1);
        u1 = 300.0 * x / z + 160.0;
        v1 = 300.0 * y / z + 120.0;
        u2 = 300.0 * qx / qz + 160.0;
        v2 = 300.0 * y / qz + 120.0;
        if (qz < 0.5 || u1 < 0 || u1 > 319 || v1 < 0 || v1 > 239 || u2 < 0 || u2 > 319 || v2 < 0 ||
            v2 > 239)
            continue;
        first[2 * i] = (float)u1;
        first[2 * i + 1] = (float)v1;
        second[2 * i] = (float)u2;
        second[2 * i + 1] = (float)v2;
        for (int b = 0; b < 32; b++) {
            state = state * 1664525u + 1013904223u;
            descriptors[32 * i + b] = (uint8_t)(state >> 24);
        }
        i++;
    }
}

static void loop_descriptor(float *d, int scene)
{
    for (int i = 0; i < LOOP_DIM; i++)
        d[i] = (i == scene % LOOP_DIM) ? 1.0f : 0.05f * (float)i;
}

/* `old` holds a bad value in a field at or beyond `size`: a caller of that older layout gets
 * the default there (the detector is made), a caller of the whole struct is refused. */
static void check_loop_fields_beyond(topoloc_loop_options *old, size_t size)
{
    topoloc_loop_detector *det = NULL;
    old->struct_size = size;
    CHECK_STATUS(topoloc_loop_detector_new("test", "loops", LOOP_DIM, old, &det), TOPOLOC_OK);
    topoloc_loop_detector_free(det);
    det = NULL;
    old->struct_size = sizeof *old;
    CHECK_STATUS(topoloc_loop_detector_new("test", "loops", LOOP_DIM, old, &det),
                 TOPOLOC_ERR_INVALID_OPTION);
    CHECK(det == NULL);
}

static void test_loop_closure(void)
{
    topoloc_loop_options options;
    topoloc_loop_detector *det = NULL;
    topoloc_loop_keyframe kf;
    topoloc_loop_hint hint;
    float points[2 * LOOP_POINTS], seen_again[2 * LOOP_POINTS], d[LOOP_DIM];
    uint8_t descriptors[32 * LOOP_POINTS];
    topoloc_loop_candidate found[4];
    size_t count = 0, len = 0;
    char path[4200];

    CHECK(topoloc_abi_version_minor() >= 5);
    CHECK_STATUS(topoloc_loop_options_default(&options), TOPOLOC_OK);
    CHECK(options.struct_size == sizeof options && options.candidates == 5 &&
          options.min_inliers == 30 && options.consistent_keyframes == 3 && options.fx == 0.0);
    CHECK(options.candidate_id_gap == 10u); /* ABI 1.6 */
    CHECK(options.odometry_max_translation_m == 1.0 &&
          options.odometry_max_translation_per_m == 0.02 &&
          options.pose_reprojection_px == 5.0); /* ABI 1.7 */
    CHECK(topoloc_abi_version_minor() >= 8 && options.odometry_candidates == 1u &&
          options.odometry_search_m == 2.0); /* ABI 1.8 */
    {
        /* A caller of ABI 1.5 gets the 1.6 fields' defaults. */
        topoloc_loop_options old;
        topoloc_loop_detector *old_det = NULL;
        CHECK_STATUS(topoloc_loop_options_default(&old), TOPOLOC_OK);
        old.struct_size = offsetof(topoloc_loop_options, candidate_id_gap);
        old.candidate_id_gap = 0u; /* beyond its size: the default (10) is used */
        CHECK_STATUS(topoloc_loop_detector_new("test", "loops", LOOP_DIM, &old, &old_det),
                     TOPOLOC_OK);
        topoloc_loop_detector_free(old_det);
        old.struct_size = offsetof(topoloc_loop_options, candidate_id_gap) - 1;
        CHECK_STATUS(topoloc_loop_detector_new("test", "loops", LOOP_DIM, &old, &old_det),
                     TOPOLOC_ERR_STRUCT_SIZE);
        /* A caller of ABI 1.6 gets the 1.7 fields' defaults; a bad 1.7 field is refused. */
        old.pose_reprojection_px = -1.0;
        check_loop_fields_beyond(&old,
                                 offsetof(topoloc_loop_options, odometry_max_translation_per_m));
        /* A caller of ABI 1.7 gets the 1.8 fields' defaults; a bad 1.8 field is refused. */
        CHECK_STATUS(topoloc_loop_options_default(&old), TOPOLOC_OK);
        old.odometry_candidates = 65u;
        check_loop_fields_beyond(&old, offsetof(topoloc_loop_options, odometry_search_m));
    }
    options.exclude_recent_ids = 5;
    options.exclude_recent_s = 0.0;
    options.consistent_keyframes = 1;
    CHECK_NULL(topoloc_loop_detector_new("test", "loops", LOOP_DIM, &options, NULL), "out");
    CHECK_STATUS(topoloc_loop_detector_new("", "loops", LOOP_DIM, &options, &det),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(det == NULL);
    options.candidates = 0;
    CHECK_STATUS(topoloc_loop_detector_new("test", "loops", LOOP_DIM, &options, &det),
                 TOPOLOC_ERR_INVALID_OPTION);
    options.candidates = 5;
    CHECK_STATUS(topoloc_loop_detector_new("test", "loops", LOOP_DIM, &options, &det), TOPOLOC_OK);
    if (det == NULL)
        return;

    loop_keypoints(points, seen_again, descriptors);
    CHECK_STATUS(topoloc_loop_keyframe_default(&kf), TOPOLOC_OK);
    CHECK_STATUS(topoloc_loop_hint_default(&hint), TOPOLOC_OK);
    loop_descriptor(d, 1);
    kf.id = 0;
    kf.timestamp = 0.0;
    kf.descriptor = d;
    kf.descriptor_len = LOOP_DIM;
    kf.keypoint_count = LOOP_POINTS;
    kf.keypoints = points;
    kf.keypoint_descriptors = descriptors;
    CHECK_STATUS(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_OK);
    CHECK(hint.query_id == 0 && !hint.has_match && !hint.accepted &&
          hint.gate == TOPOLOC_GATE_NO_CANDIDATE);

    /* Bad keyframes: the detector keeps one keyframe and the hint is untouched. */
    kf.id = 10;
    kf.timestamp = 10.0;
    kf.descriptor_len = LOOP_DIM - 1;
    CHECK_STATUS(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_ERR_DIMENSION_MISMATCH);
    kf.descriptor_len = LOOP_DIM;
    kf.keypoint_descriptors = NULL;
    CHECK_NULL(topoloc_loop_detector_add(det, &kf, &hint), "keyframe.keypoint_descriptors");
    kf.keypoint_descriptors = descriptors;
    kf.id = 0;
    CHECK_STATUS(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_HAS_MESSAGE();
    kf.id = 10;
    kf.timestamp = make_nan();
    CHECK_STATUS(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_ERR_NON_FINITE);
    kf.timestamp = 10.0;
    kf.struct_size = 3;
    CHECK_STATUS(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_ERR_STRUCT_SIZE);
    kf.struct_size = sizeof kf;
    CHECK_STATUS(topoloc_loop_detector_len(det, &len), TOPOLOC_OK);
    CHECK(len == 1 && hint.query_id == 0);

    /* The revisit from another pose: every keypoint matches, the hint names keyframe 0. */
    kf.keypoints = seen_again;
    CHECK_STATUS(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_OK);
    CHECK(hint.query_id == 10 && hint.has_match && hint.accepted);
    CHECK(hint.gate == TOPOLOC_GATE_ACCEPTED && hint.matched_id == 0);
    CHECK(hint.inliers >= 30 && hint.confidence > 0.99f && !hint.has_pose);

    CHECK_STATUS(topoloc_loop_detector_query(det, d, LOOP_DIM, found, 4, &count), TOPOLOC_OK);
    CHECK(count == 2 && found[0].similarity > 0.99f);
    CHECK_NULL(topoloc_loop_detector_query(det, d, LOOP_DIM, found, 4, NULL), "count");

    tmp_path(path, sizeof path, "loops.topoloc");
    CHECK_STATUS(topoloc_loop_detector_save(det, path), TOPOLOC_OK);
    CHECK_STATUS(topoloc_loop_detector_erase(det, 77), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_STATUS(topoloc_loop_detector_erase(det, 10), TOPOLOC_OK);
    CHECK_STATUS(topoloc_loop_detector_len(det, &len), TOPOLOC_OK);
    CHECK(len == 1);
    topoloc_loop_detector_free(det);
    topoloc_loop_detector_free(NULL);

    /* A second session from the saved map: its keyframes are there, without features. */
    {
        topoloc_map *saved = NULL;
        topoloc_loop_detector *again = NULL;
        CHECK_STATUS(topoloc_map_load(path, NULL, &saved), TOPOLOC_OK);
        CHECK_STATUS(topoloc_loop_detector_from_map(saved, NULL, &again), TOPOLOC_OK);
        CHECK_STATUS(topoloc_loop_detector_len(again, &len), TOPOLOC_OK);
        CHECK(len == 2);
        kf.id = 20;
        kf.timestamp = 20.0;
        CHECK_STATUS(topoloc_loop_detector_add(again, &kf, &hint), TOPOLOC_OK);
        CHECK(hint.query_id == 20 && hint.gate == TOPOLOC_GATE_NO_CANDIDATE);
        topoloc_loop_detector_free(again);
        topoloc_map_free(saved);
    }
    CHECK(remove(path) == 0);
}

/* Confirmed hints (ABI 1.10): with a streak of 3, keyframes 10 and 11 revisit keyframe 0 but
 * are refused as inconsistent; keyframe 12 completes the streak and confirms both. */
static void test_loop_confirmed(void)
{
    topoloc_loop_options options;
    topoloc_loop_detector *det = NULL;
    topoloc_loop_keyframe kf;
    topoloc_loop_hint hint, confirmed;
    float points[2 * LOOP_POINTS], seen_again[2 * LOOP_POINTS], d[LOOP_DIM];
    uint8_t descriptors[32 * LOOP_POINTS];
    size_t count = 99;
    const uint64_t ids[] = {0, 10, 11, 12, 13};

    CHECK(topoloc_abi_version_minor() >= 10);
    CHECK_STATUS(topoloc_loop_options_default(&options), TOPOLOC_OK);
    options.exclude_recent_ids = 5;
    options.exclude_recent_s = 0.0;
    CHECK_STATUS(topoloc_loop_detector_new("test", "loops", LOOP_DIM, &options, &det), TOPOLOC_OK);
    if (det == NULL)
        return;
    CHECK_STATUS(topoloc_loop_detector_confirmed_count(det, &count), TOPOLOC_OK);
    CHECK(count == 0);
    loop_keypoints(points, seen_again, descriptors);
    loop_descriptor(d, 1);
    CHECK_STATUS(topoloc_loop_keyframe_default(&kf), TOPOLOC_OK);
    CHECK_STATUS(topoloc_loop_hint_default(&hint), TOPOLOC_OK);
    CHECK_STATUS(topoloc_loop_hint_default(&confirmed), TOPOLOC_OK);
    kf.descriptor = d;
    kf.descriptor_len = LOOP_DIM;
    kf.keypoint_count = LOOP_POINTS;
    kf.keypoint_descriptors = descriptors;
    for (size_t k = 0; k < sizeof ids / sizeof ids[0]; k++) {
        kf.id = ids[k];
        kf.timestamp = (double)ids[k];
        kf.keypoints = k == 0 ? points : seen_again;
        CHECK_STATUS(topoloc_loop_detector_add(det, &kf, &hint), TOPOLOC_OK);
        CHECK_STATUS(topoloc_loop_detector_confirmed_count(det, &count), TOPOLOC_OK);
        if (k == 1 || k == 2)
            CHECK(hint.gate == TOPOLOC_GATE_INCONSISTENT && count == 0);
        if (k == 3) {
            CHECK(hint.accepted && hint.query_id == 12 && count == 2);
            CHECK_STATUS(topoloc_loop_detector_confirmed(det, 0, &confirmed), TOPOLOC_OK);
            CHECK(confirmed.query_id == 10 && confirmed.matched_id == 0 && confirmed.accepted &&
                  confirmed.gate == TOPOLOC_GATE_ACCEPTED && confirmed.inliers >= 30);
            CHECK_STATUS(topoloc_loop_detector_confirmed(det, 1, &confirmed), TOPOLOC_OK);
            CHECK(confirmed.query_id == 11 && confirmed.accepted);
            /* Out of range: refused, *hint unchanged. */
            CHECK_STATUS(topoloc_loop_detector_confirmed(det, 2, &confirmed),
                         TOPOLOC_ERR_INVALID_ARGUMENT);
            CHECK_HAS_MESSAGE();
            CHECK(confirmed.query_id == 11);
            CHECK_NULL(topoloc_loop_detector_confirmed(det, 0, NULL), "hint");
            CHECK_NULL(topoloc_loop_detector_confirmed_count(det, NULL), "count");
            confirmed.struct_size = 3;
            CHECK_STATUS(topoloc_loop_detector_confirmed(det, 0, &confirmed),
                         TOPOLOC_ERR_STRUCT_SIZE);
            confirmed.struct_size = sizeof confirmed;
        }
        if (k == 4)
            CHECK(hint.accepted && count == 0); /* the streak goes on: nothing pending */
    }
    CHECK_NULL(topoloc_loop_detector_confirmed_count(NULL, &count), "detector");
    topoloc_loop_detector_free(det);
}

/* Trajectory metrics (ABI 1.11): a scaled, moved copy of a circle aligns back exactly with
 * TOPOLOC_ALIGN_SIM3; bad input is refused with the report unchanged. */
#define TRAJ_N 40
static void circle_trajectory(double *stamps, double *poses, double scale, double dx)
{
    for (int i = 0; i < TRAJ_N; i++) {
        double a = 6.283185307179586 * i / TRAJ_N;
        double *p = poses + 7 * i;
        stamps[i] = 0.1 * i;
        p[0] = scale * 3.0 * cos(a) + dx;
        p[1] = scale * 2.0 * sin(a);
        p[2] = scale * 0.2 * i / TRAJ_N;
        p[3] = 0.0; /* qx qy qz qw: a yaw of a */
        p[4] = 0.0;
        p[5] = sin(a / 2);
        p[6] = cos(a / 2);
    }
}

static void test_trajectory_metrics(void)
{
    double ref_t[TRAJ_N], ref_p[7 * TRAJ_N], est_t[TRAJ_N], est_p[7 * TRAJ_N];
    topoloc_trajectory_options options;
    topoloc_trajectory_report report;
    char ref_path[4200], est_path[4200];
    FILE *f;

    CHECK(topoloc_abi_version_minor() >= 11);
    circle_trajectory(ref_t, ref_p, 1.0, 0.0);
    circle_trajectory(est_t, est_p, 0.5, 4.0);
    CHECK_STATUS(topoloc_trajectory_options_default(&options), TOPOLOC_OK);
    CHECK(options.alignment == TOPOLOC_ALIGN_SIM3 && options.max_diff_s == 0.01 &&
          options.offset_s == 0.0 && options.rpe_delta == 1);
    CHECK_STATUS(topoloc_trajectory_report_default(&report), TOPOLOC_OK);
    CHECK_STATUS(
        topoloc_trajectory_evaluate(ref_t, ref_p, TRAJ_N, est_t, est_p, TRAJ_N, &options, &report),
        TOPOLOC_OK);
    CHECK(report.pairs == TRAJ_N && report.ate_m.rmse < 1e-9 && report.are_deg.max < 1e-6);
    CHECK(fabs(report.scale - 2.0) < 1e-9 && fabs(report.length_ratio - 1.0) < 1e-9);
    CHECK(fabs(report.alignment[15] - 1.0) < 1e-12);
    options.alignment = TOPOLOC_ALIGN_SE3;
    CHECK_STATUS(
        topoloc_trajectory_evaluate(ref_t, ref_p, TRAJ_N, est_t, est_p, TRAJ_N, &options, &report),
        TOPOLOC_OK);
    CHECK(report.scale == 1.0 && report.ate_m.rmse > 0.5);

    /* Bad input: a status, and the report as it was. */
    options.alignment = 7;
    CHECK_STATUS(
        topoloc_trajectory_evaluate(ref_t, ref_p, TRAJ_N, est_t, est_p, TRAJ_N, &options, &report),
        TOPOLOC_ERR_INVALID_OPTION);
    options.alignment = TOPOLOC_ALIGN_SIM3;
    est_p[7 * 5 + 1] = make_nan();
    CHECK_STATUS(
        topoloc_trajectory_evaluate(ref_t, ref_p, TRAJ_N, est_t, est_p, TRAJ_N, &options, &report),
        TOPOLOC_ERR_NON_FINITE);
    est_p[7 * 5 + 1] = 0.0;
    est_t[3] = -1.0; /* earlier than the one before */
    CHECK_STATUS(
        topoloc_trajectory_evaluate(ref_t, ref_p, TRAJ_N, est_t, est_p, TRAJ_N, &options, &report),
        TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_HAS_MESSAGE();
    est_t[3] = 0.3;
    CHECK_STATUS(
        topoloc_trajectory_evaluate(ref_t, ref_p, TRAJ_N, est_t, est_p, 2, &options, &report),
        TOPOLOC_ERR_INVALID_ARGUMENT); /* too few pairs to align */
    CHECK_NULL(
        topoloc_trajectory_evaluate(ref_t, NULL, TRAJ_N, est_t, est_p, TRAJ_N, &options, &report),
        "reference_poses");
    CHECK_NULL(
        topoloc_trajectory_evaluate(ref_t, ref_p, TRAJ_N, est_t, est_p, TRAJ_N, &options, NULL),
        "report");
    report.struct_size = 3;
    CHECK_STATUS(
        topoloc_trajectory_evaluate(ref_t, ref_p, TRAJ_N, est_t, est_p, TRAJ_N, NULL, &report),
        TOPOLOC_ERR_STRUCT_SIZE);
    report.struct_size = sizeof report;
    CHECK(report.scale == 1.0 && report.pairs == TRAJ_N); /* the SE3 run's, untouched */

    /* Files: TUM text, its format detected. */
    tmp_path(ref_path, sizeof ref_path, "ref.tum");
    tmp_path(est_path, sizeof est_path, "est.tum");
    f = fopen(ref_path, "w");
    CHECK(f != NULL);
    if (f == NULL)
        return;
    fprintf(f, "# timestamp tx ty tz qx qy qz qw\n");
    for (int i = 0; i < TRAJ_N; i++)
        fprintf(f, "%.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n", ref_t[i], ref_p[7 * i],
                ref_p[7 * i + 1], ref_p[7 * i + 2], ref_p[7 * i + 3], ref_p[7 * i + 4],
                ref_p[7 * i + 5], ref_p[7 * i + 6]);
    fclose(f);
    f = fopen(est_path, "w");
    CHECK(f != NULL);
    if (f == NULL)
        return;
    fprintf(f, "0.0 1 2 3 0 0 0 1\nnot a pose\n");
    fclose(f);
    CHECK_STATUS(topoloc_trajectory_evaluate_files(ref_path, ref_path, TOPOLOC_TRAJECTORY_DETECT,
                                                   NULL, &report),
                 TOPOLOC_OK);
    CHECK(report.pairs == TRAJ_N && report.ate_m.rmse < 1e-9);
    CHECK_STATUS(topoloc_trajectory_evaluate_files(ref_path, est_path, TOPOLOC_TRAJECTORY_TUM, NULL,
                                                   &report),
                 TOPOLOC_ERR_INVALID_ARGUMENT); /* line 2 is malformed */
    CHECK_HAS_MESSAGE();
    CHECK_STATUS(topoloc_trajectory_evaluate_files(ref_path, ref_path, 9, NULL, &report),
                 TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK(remove(est_path) == 0);
    CHECK_STATUS(topoloc_trajectory_evaluate_files(ref_path, est_path, TOPOLOC_TRAJECTORY_TUM, NULL,
                                                   &report),
                 TOPOLOC_ERR_IO);
    CHECK(remove(ref_path) == 0);
}

int main(void)
{
    topoloc_map *map;

    setvbuf(stdout, NULL, _IOLBF, 0);
    printf("topoloc C ABI tests: library %s (ABI %u), header %s (ABI %d)\n", topoloc_version(),
           (unsigned)topoloc_abi_version(), TOPOLOC_VERSION_STRING, TOPOLOC_ABI_VERSION);
    init_world();
    if (!make_tmpdir()) {
        printf("0 passed, 1 failed\n");
        return 1;
    }

    test_version();
    test_status_str();
    test_full_flow();
    test_single_frame();
    test_from_keyframes();
    test_builder_errors();
    test_files();
    test_skeleton_graphs();
    test_loop_closure();
    test_loop_confirmed();
    test_trajectory_metrics();

    map = build_world_map();
    CHECK(map != NULL);
    if (map != NULL) {
        test_null_arguments(map);
        test_buffers_too_small(map);
        test_unknown_ids(map);
        test_bad_frames(map);
        test_options_errors(map);
        test_versioned_structs(map);
        test_threads(map);
        test_shared_localizer(map);
        test_logging(map);
        test_metric_mode(map);
        test_images(map);
    }
    topoloc_map_free(map);

    /* Everything written went to the temporary directory and was removed: rmdir must succeed
     * (this also shows that saving leaves no temporary files behind). */
    if (rmdir(g_tmpdir) != 0) {
        fprintf(stderr, "rmdir(%s): %s\n", g_tmpdir, strerror(errno));
        CHECK(!"temporary directory is empty at the end");
    } else {
        CHECK(true);
    }

    printf("%lu passed, %lu failed\n", g_passed, g_failed);
    return g_failed == 0 ? 0 : 1;
}
