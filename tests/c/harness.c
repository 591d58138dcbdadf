/*
 * The shared harness of the C ABI tests (declared and described in harness.h): check counters
 * and reports, the last error message, the descriptor world and its builder, the temporary
 * directory and files, result helpers and the grey image world.
 */
#include "harness.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* ------------------------------------------------------------------------------------------ */
/* Checks                                                                                      */
/* ------------------------------------------------------------------------------------------ */

unsigned long g_passed;
unsigned long g_failed;

void check_impl(bool ok, const char *expr, const char *file, int line)
{
    if (ok) {
        g_passed++;
        return;
    }
    g_failed++;
    fprintf(stderr, "FAIL %s:%d: %s\n", file, line, expr);
}

const char *last_error(void)
{
    static char buf[1024];
    size_t needed = 0;
    buf[0] = '\0';
    if (topoloc_last_error_message(buf, sizeof buf, &needed) != TOPOLOC_OK) {
        snprintf(buf, sizeof buf, "<message of %zu bytes does not fit>", needed);
    }
    return buf;
}

void check_status_impl(topoloc_status got, uint32_t want, const char *expr, const char *file,
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

static char g_primed[512];

void prime_last_error(void)
{
    topoloc_map_builder *b = NULL;
    topoloc_status st = topoloc_map_builder_new("", NULL, 4, &b);
    if (st != TOPOLOC_ERR_INVALID_ARGUMENT || b != NULL) {
        fprintf(stderr, "harness: could not prime the last error (status %u)\n", (unsigned)st);
        topoloc_map_builder_free(b);
    }
    snprintf(g_primed, sizeof g_primed, "%s", last_error());
}

void check_null_impl(topoloc_status got, const char *name, const char *expr, const char *file,
                     int line)
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

void check_message_impl(const char *text, const char *file, int line)
{
    const char *msg = last_error();
    bool found = strstr(msg, text) != NULL;
    if (!found) {
        fprintf(stderr, "    message \"%s\" does not contain \"%s\"\n", msg, text);
    }
    check_impl(found, "the last error message contains the text", file, line);
}

void check_counts_impl(const topoloc_map *map, size_t places, size_t views, size_t edges,
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

void section(const char *file, const char *function)
{
    const char *base = strrchr(file, '/');
    size_t len, i;
    base = base != NULL ? base + 1 : file;
    if (strncmp(base, "test_", 5) == 0) {
        base += 5;
    }
    len = strcspn(base, ".");
    fputs("-- ", stdout);
    for (i = 0; i < len; i++) {
        putchar(base[i] == '_' ? ' ' : base[i]);
    }
    fputs(": ", stdout);
    for (i = 0; function[i] != '\0'; i++) {
        putchar(function[i] == '_' ? ' ' : function[i]);
    }
    putchar('\n');
    fflush(stdout);
}

/* ------------------------------------------------------------------------------------------ */
/* The descriptor world                                                                        */
/* ------------------------------------------------------------------------------------------ */

float g_view_desc[VIEWS][DIM];
double g_place_pos[PLACES][3];
double g_view_pose[VIEWS][16];
char g_view_image[VIEWS][64];
const uint32_t g_edges[EDGES][2] = {{0, 1}, {0, 5}, {1, 2}, {2, 3}, {3, 4}, {4, 5}};
float g_edge_weight[EDGES];

static uint64_t g_rng = 0x9E3779B97F4A7C15u;

void rng_seed(uint64_t seed)
{
    /* One splitmix64 step: nearby seeds give unrelated (and never zero) xorshift states. */
    uint64_t z = seed + 0x9E3779B97F4A7C15u;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9u;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBu;
    z ^= z >> 31;
    g_rng = z != 0 ? z : 1;
}

static double rng_uniform(void)
{
    /* xorshift64* */
    g_rng ^= g_rng >> 12;
    g_rng ^= g_rng << 25;
    g_rng ^= g_rng >> 27;
    return (double)((g_rng * 2685821657736338717u) >> 11) * (1.0 / 9007199254740992.0);
}

float rng_normalish(void)
{
    return (float)(rng_uniform() + rng_uniform() + rng_uniform() + rng_uniform() - 2.0);
}

void init_world(void)
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

double make_nan(void)
{
    volatile double zero = 0.0;
    return zero / zero;
}

float make_inf(void)
{
    volatile float big = 1e30f;
    return big * big;
}

double norm_of(const float *x, size_t n)
{
    double sum = 0.0, r;
    size_t i;
    int k;
    for (i = 0; i < n; i++) {
        sum += (double)x[i] * (double)x[i];
    }
    /* Newton iterations instead of libm's sqrt. */
    r = sum > 1.0 ? sum : 1.0;
    for (k = 0; k < 60; k++) {
        r = 0.5 * (r + sum / r);
    }
    return r;
}

void noisy_copy(float out[DIM], uint32_t v, float noise)
{
    uint32_t d;
    double n = norm_of(g_view_desc[v], DIM) / 5.66; /* ~ per-component scale */
    for (d = 0; d < DIM; d++) {
        out[d] = g_view_desc[v][d] + noise * (float)n * rng_normalish();
    }
}

bool contains_u32(const uint32_t *xs, size_t n, uint32_t x)
{
    size_t i;
    for (i = 0; i < n; i++) {
        if (xs[i] == x) {
            return true;
        }
    }
    return false;
}

topoloc_map *build_world(bool bare_view)
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

topoloc_map *build_world_map(void) { return build_world(true); }

/* ------------------------------------------------------------------------------------------ */
/* Temporary files                                                                             */
/* ------------------------------------------------------------------------------------------ */

char g_tmpdir[4096];

bool make_tmpdir(void)
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

void tmp_path(char *out, size_t len, const char *name)
{
    snprintf(out, len, "%s/%s", g_tmpdir, name);
}

bool write_file(const char *path, const unsigned char *data, size_t len)
{
    FILE *f = fopen(path, "wb");
    bool ok;
    if (f == NULL) {
        return false;
    }
    ok = fwrite(data, 1, len, f) == len;
    return fclose(f) == 0 && ok;
}

unsigned char *read_file(const char *path, size_t *len)
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

bool all_bytes(const unsigned char *p, size_t n, unsigned char value)
{
    size_t i;
    for (i = 0; i < n; i++) {
        if (p[i] != value) {
            return false;
        }
    }
    return true;
}

/* ------------------------------------------------------------------------------------------ */
/* Localizers and results                                                                      */
/* ------------------------------------------------------------------------------------------ */

void result_with_candidates(topoloc_result *result, topoloc_candidate *candidates, size_t capacity)
{
    CHECK_OK(topoloc_result_default(result));
    result->candidates = candidates;
    result->candidates_capacity = capacity;
}

bool new_twin_localizers(const topoloc_map *map, topoloc_localizer **a, topoloc_localizer **b)
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

bool candidates_consistent(const topoloc_result *r)
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

bool candidates_distinct(const topoloc_result *r)
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

bool identical_result(const topoloc_result *a, const topoloc_result *b)
{
    return a->struct_size == b->struct_size && a->frame_index == b->frame_index &&
           a->place == b->place && a->view == b->view && a->confidence == b->confidence &&
           a->similarity == b->similarity && a->off_map_probability == b->off_map_probability &&
           a->off_map == b->off_map && a->candidates == b->candidates &&
           a->candidates_capacity == b->candidates_capacity &&
           a->candidates_len == b->candidates_len;
}

bool same_result(const topoloc_result *a, const topoloc_result *b)
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

/* ------------------------------------------------------------------------------------------ */
/* The image world                                                                             */
/* ------------------------------------------------------------------------------------------ */

uint8_t g_place_px[IMG_PLACES][IMG_PIXELS];

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

void make_revisit(const uint8_t *in, uint64_t seed, uint8_t *out)
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

void init_image_world(void)
{
    uint32_t p;
    for (p = 0; p < IMG_PLACES; p++) {
        make_place_image(p, g_place_px[p]);
    }
}

topoloc_image gray_image(const uint8_t *px)
{
    const topoloc_image image = {.data = px,
                                 .data_len = IMG_PIXELS,
                                 .width = IMG_W,
                                 .height = IMG_H,
                                 .stride = IMG_W,
                                 .format = TOPOLOC_PIXEL_GRAY8};
    return image;
}

bool under_valgrind(void)
{
    const char *preload = getenv("LD_PRELOAD");
    return preload != NULL && strstr(preload, "vgpreload") != NULL;
}

bool models_ready(const char *file, char *path, size_t len, const char *checks)
{
    const char *cache = getenv("TOPOLOC_CACHE");
    const char *home = getenv("HOME");
    const char *ci = getenv("CI");
    if (cache != NULL && cache[0] != '\0') {
        snprintf(path, len, "%s/%s", cache, file);
    } else {
        snprintf(path, len, "%s/.cache/topoloc/%s", home != NULL ? home : "", file);
    }
    if (access(path, R_OK) != 0) {
        CHECK(ci == NULL || strcmp(ci, "true") != 0);
        printf("   %s checks skipped: no model at %s (run scripts/setup-models.sh)\n", checks,
               path);
        return false;
    }
    if (under_valgrind()) {
        printf("   %s checks skipped under valgrind (ONNX Runtime is not ours to check)\n", checks);
        return false;
    }
    return true;
}
