/*
 * C11 tests of the topoloc C ABI (include/topoloc.h), linked against the built library: the
 * test program's entry point.
 *
 * Built by tests/c/run.sh from main.c, harness.c and one test_<section>.c per section of the
 * header, with -std=c11 -Wall -Wextra -Werror -pedantic, and run plain, under AddressSanitizer +
 * UndefinedBehaviorSanitizer, under ThreadSanitizer, under valgrind, and linked statically.
 *
 * main builds the descriptor world (harness.h) and the image world, makes the temporary
 * directory, runs the sections in order, and checks at the end that every file the tests wrote
 * was removed. The last line printed is "N passed, M failed"; the exit status is non-zero when
 * anything failed.
 */
#include "harness.h"

#include <errno.h>
#include <unistd.h>

int main(void)
{
    topoloc_map *world, *image_map;

    setvbuf(stdout, NULL, _IOLBF, 0);
    printf("topoloc C ABI tests: library %s (ABI %u), header %s (ABI %d)\n", topoloc_version(),
           (unsigned)topoloc_abi_version(), TOPOLOC_VERSION_STRING, TOPOLOC_ABI_VERSION);
    init_world();
    init_image_world();
    if (!make_tmpdir()) {
        printf("0 passed, 1 failed\n");
        return 1;
    }

    world = build_world_map();
    CHECK(world != NULL);
    if (world != NULL) {
        run_versions_and_errors_tests(world);
        run_map_tests(world);
        run_localizer_tests(world);
        run_builder_tests();
        run_skeleton_tests();
        run_loop_tests();
        run_loop_contract_tests();
        run_trajectory_tests();
        run_thread_tests(world);
        run_logging_tests(world);
        image_map = run_image_tests(world);
        if (image_map != NULL) {
            run_describer_tests(image_map, world);
            run_loop_image_tests(image_map, world);
            run_readme_tests(image_map);
        }
        topoloc_map_free(image_map);
    }
    topoloc_map_free(world);

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
