/*
 * The harness shared by the C11 tests of the topoloc C ABI (main.c and the test_<section>.c
 * files, one program built by tests/c/run.sh): the CHECK* macros and their pass/fail counters,
 * the last error message, the temporary directory, the generated descriptor world and its map
 * builder, the generated grey images, a few helpers that several sections use, and each
 * section's entry point.
 *
 * Every test file includes this header first (it selects POSIX.1-2008 for mkdtemp, unlink and
 * pthreads before any system header is read).
 */
#ifndef TOPOLOC_TESTS_C_HARNESS_H
#define TOPOLOC_TESTS_C_HARNESS_H

#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L
#endif

#include "topoloc.h"

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

/* ------------------------------------------------------------------------------------------ */
/* Checks: each CHECK* counts one pass or one failure (CHECK_NULL, CHECK_ERROR and CHECK_COUNTS  */
/* several, as said below); failures are printed with their file and line.                     */
/* ------------------------------------------------------------------------------------------ */

extern unsigned long g_passed;
extern unsigned long g_failed;

void check_impl(bool ok, const char *expr, const char *file, int line);
void check_status_impl(topoloc_status got, uint32_t want, const char *expr, const char *file,
                       int line);
void check_null_impl(topoloc_status got, const char *name, const char *expr, const char *file,
                     int line);
void check_message_impl(const char *text, const char *file, int line);
void check_counts_impl(const topoloc_map *map, size_t places, size_t views, size_t edges,
                       const char *file, int line);

/* Last error message of this thread, in a static buffer (the harness is single-threaded). */
const char *last_error(void);
/* Sets the last error to a known message, so that a following call can be shown to set its own. */
void prime_last_error(void);

#define CHECK(cond) check_impl((cond) ? true : false, #cond, __FILE__, __LINE__)
#define CHECK_OK(expr) check_status_impl((expr), TOPOLOC_OK, #expr, __FILE__, __LINE__)
#define CHECK_STATUS(expr, want)                                                                   \
    check_status_impl((expr), (uint32_t)(want), #expr, __FILE__, __LINE__)
#define CHECK_NEAR(a, b, tol) CHECK(((a) - (b)) <= (tol) && ((b) - (a)) <= (tol))

/* Checks that a failed call left a non-empty message. */
#define CHECK_HAS_MESSAGE() CHECK(last_error()[0] != '\0')

/* Two checks: `expr` returns `want`, and leaves a non-empty last error message. */
#define CHECK_ERROR(expr, want)                                                                    \
    do {                                                                                           \
        CHECK_STATUS(expr, want);                                                                  \
        CHECK_HAS_MESSAGE();                                                                       \
    } while (0)

/* The last error message contains `text` (the message is shown when it does not). */
#define CHECK_MESSAGE_HAS(text) check_message_impl((text), __FILE__, __LINE__)

/* Four checks: `expr` returns TOPOLOC_ERR_NULL_ARGUMENT, with a fresh, non-empty message that
 * names the argument `name`. */
#define CHECK_NULL(expr, name)                                                                     \
    do {                                                                                           \
        topoloc_status check_null_status_;                                                         \
        prime_last_error();                                                                        \
        check_null_status_ = (expr);                                                               \
        check_null_impl(check_null_status_, (name), #expr, __FILE__, __LINE__);                    \
    } while (0)

/* Six checks: a map's place, view and edge counts are read and are as given. */
#define CHECK_COUNTS(map, places, views, edges)                                                    \
    check_counts_impl((map), (places), (views), (edges), __FILE__, __LINE__)

/* Prints "-- <section>: <test>" for the test function it is called in: the section is the file
 * name without "test_" and ".c", the test the function's name with spaces for underscores. */
#define SECTION() section(__FILE__, __func__)
void section(const char *file, const char *function);

/* ------------------------------------------------------------------------------------------ */
/* The descriptor world: PLACES places on a line (with a loop edge from the last to the first), */
/* VIEWS_PER_PLACE views each, DIM-dimensional descriptors from a fixed-seed generator. Views of */
/* one place are close to each other, views of different places nearly orthogonal, and frames   */
/* are noisy copies of views, so the right answer is known for every frame.                    */
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

extern float g_view_desc[VIEWS][DIM]; /* as given to the builder (not unit norm) */
extern double g_place_pos[PLACES][3];
extern double g_view_pose[VIEWS][16]; /* world_T_camera, row-major */
extern char g_view_image[VIEWS][64];
/* Edges sorted by (a, b), as topoloc_map_edge reports them. */
extern const uint32_t g_edges[EDGES][2];
extern float g_edge_weight[EDGES];

/* Fills the world (descriptors, poses, image names, edge weights); called once, first. */
void init_world(void);
/* Restarts the noise generator: a test that draws noise seeds it first, so that what it draws
 * does not depend on the tests that ran before it. */
void rng_seed(uint64_t seed);
/* Zero-mean, roughly normal (Irwin-Hall of 4 uniforms). */
float rng_normalish(void);
/* A frame descriptor: view `v`'s descriptor plus noise of relative size `noise`. */
void noisy_copy(float out[DIM], uint32_t v, float noise);
/* Euclidean norm, without libm. */
double norm_of(const float *x, size_t n);
bool contains_u32(const uint32_t *xs, size_t n, uint32_t x);
/* NaN and infinity computed at run time (no constant-folding diagnostics). */
double make_nan(void);
float make_inf(void);

/* Builds the world with the builder, the last view without attributes when `bare_view`; NULL
 * on failure (each builder call is a check). */
topoloc_map *build_world(bool bare_view);
/* The world as the accessor checks expect it: its last view has no attributes. */
topoloc_map *build_world_map(void);

/* ------------------------------------------------------------------------------------------ */
/* Temporary files: everything a test writes goes to g_tmpdir and is removed by the test; main  */
/* checks at the end that the directory is empty.                                              */
/* ------------------------------------------------------------------------------------------ */

extern char g_tmpdir[4096];

bool make_tmpdir(void);
void tmp_path(char *out, size_t len, const char *name);
bool write_file(const char *path, const unsigned char *data, size_t len);
/* The cache's model files (scripts/setup-models.sh), relative to $TOPOLOC_CACHE or
 * ~/.cache/topoloc. */
#define ONNX_MODEL_FILE "models/mobilenetv2-mlf-int8.onnx"
#define XFEAT_MODEL_FILE "models/xfeat.onnx"
/* True when the cache's `file` exists (its path into `path`) and the run is not under valgrind
 * (ONNX Runtime takes minutes there, and its code is not ours to check); otherwise says which
 * `checks` are skipped and returns false. In CI (CI=true) the set-up installs the models: a
 * missing one fails the run. */
bool models_ready(const char *file, char *path, size_t len, const char *checks);
/* True under valgrind (its preload libraries are in LD_PRELOAD). */
bool under_valgrind(void);
/* Reads a whole file into a malloc'd buffer (NULL when it cannot). */
unsigned char *read_file(const char *path, size_t *len);
/* True when the n bytes at p all equal `value` (what a library must not have written). */
bool all_bytes(const unsigned char *p, size_t n, unsigned char value);

/* ------------------------------------------------------------------------------------------ */
/* Localizers and results                                                                      */
/* ------------------------------------------------------------------------------------------ */

/* topoloc_result_default (one check), then `capacity` candidates in `candidates`. */
void result_with_candidates(topoloc_result *result, topoloc_candidate *candidates, size_t capacity);
/* Two localizers with default options on `map`, one to see bad input and one not; false (and
 * neither) when either could not be made. Two checks. */
bool new_twin_localizers(const topoloc_map *map, topoloc_localizer **a, topoloc_localizer **b);
/* The candidate list is well formed: sorted by probability, the first is the result, each a
 * world place and one of its views. */
bool candidates_consistent(const topoloc_result *r);
/* No place is listed twice among the candidates. */
bool candidates_distinct(const topoloc_result *r);
/* Every field of two results is identical (fields, not bytes: padding may be uninitialised). */
bool identical_result(const topoloc_result *a, const topoloc_result *b);
/* Results of two localizers agree exactly, candidates included. */
bool same_result(const topoloc_result *a, const topoloc_result *b);

/* ------------------------------------------------------------------------------------------ */
/* The image world: IMG_PLACES small grey "places" (a horizontal ramp under random rectangles,  */
/* the C twin of tests/images.rs) and "revisits" of them (shifted by two pixels, 10% brighter,  */
/* with noise).                                                                                */
/* ------------------------------------------------------------------------------------------ */

#define IMG_W 160u
#define IMG_H 120u
#define IMG_PIXELS (IMG_W * IMG_H)
#define IMG_PLACES 8u

extern uint8_t g_place_px[IMG_PLACES][IMG_PIXELS];

/* Fills g_place_px; called once, first. */
void init_image_world(void);
/* The same place seen again: shifted by 2 pixels, brighter, with noise from `seed`. */
void make_revisit(const uint8_t *in, uint64_t seed, uint8_t *out);
/* An IMG_W x IMG_H grey image over `px`. */
topoloc_image gray_image(const uint8_t *px);

/* ------------------------------------------------------------------------------------------ */
/* Loop keyframes (test_loops.c): a scene of LOOP_POINTS points with binary descriptors         */
/* ------------------------------------------------------------------------------------------ */

#define LOOP_DIM 8
#define LOOP_POINTS 60

/* LOOP_POINTS scene points 3-8 m in front of a 300-pixel pinhole camera (320x240, centre
 * 160,120), seen from it (`first`) and from a camera moved by `tx` to the right and `tz` ahead
 * (metres) and turned `yaw_deg` about y (`second`); each point has the same random 32-byte
 * descriptor in both views (`descriptors`, 32 * LOOP_POINTS bytes). */
void loop_scene_points(float *first, float *second, uint8_t *descriptors, double tx, double tz,
                       double yaw_deg);
/* A LOOP_DIM global descriptor of scene `scene`. */
void loop_descriptor(float *d, int scene);

/* The scene seen twice (0.3 m right, 0.1 m ahead, 3 degrees), and a keyframe of it. */
struct loop_scene {
    float points[2 * LOOP_POINTS], seen_again[2 * LOOP_POINTS], d[LOOP_DIM];
    uint8_t descriptors[32 * LOOP_POINTS];
};

/* Fills `scene`, and `kf` (and `hint`) with their defaults (a check each) and the first view of
 * the scene: global descriptor of scene 1, its keypoints and their descriptors. */
void first_view_of_the_scene(struct loop_scene *scene, topoloc_loop_keyframe *kf,
                             topoloc_loop_hint *hint);
/* A detector of kind "test", model "loops", D = LOOP_DIM. */
topoloc_status new_detector(const topoloc_loop_options *options, topoloc_loop_detector **det);

/* ------------------------------------------------------------------------------------------ */
/* Sections, one file each, run by main.c in this order                                        */
/* ------------------------------------------------------------------------------------------ */

/* test_versions_and_errors.c */
void run_versions_and_errors_tests(const topoloc_map *world);
/* test_map.c */
void run_map_tests(const topoloc_map *world);
/* test_localizer.c */
void run_localizer_tests(const topoloc_map *world);
/* test_builder.c */
void run_builder_tests(void);
/* test_skeleton.c */
void run_skeleton_tests(void);
/* test_loops.c */
void run_loop_tests(void);
/* test_loop_contracts.c: what a new host trips over (issue 46) */
void run_loop_contract_tests(void);
/* test_trajectory.c */
void run_trajectory_tests(void);
/* test_threads.c */
void run_thread_tests(const topoloc_map *world);
/* test_logging.c */
void run_logging_tests(const topoloc_map *world);
/* test_images.c: returns the map built from g_place_px (the caller frees it), or NULL. */
topoloc_map *run_image_tests(const topoloc_map *world);
/* test_describer.c: `image_map` is run_image_tests' map. */
void run_describer_tests(const topoloc_map *image_map, const topoloc_map *world);
/* test_loop_images.c: `image_map` is run_image_tests' map. */
void run_loop_image_tests(const topoloc_map *image_map, const topoloc_map *world);
/* test_readme.c: the README's loop-closure function over two runs of the image world. */
void run_readme_tests(const topoloc_map *image_map);

#endif
