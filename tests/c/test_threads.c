/*
 * Threads and concurrency (the thread-safety rules of topoloc.h's conventions): a const map shared
 * by four threads, each with its own localizer and its own last error message; one localizer
 * used by two threads at once (a caller's bug), whose every call either runs alone or is refused
 * with TOPOLOC_ERR_CONCURRENT_USE. run.sh also runs these under ThreadSanitizer.
 */
#include "harness.h"

#include <pthread.h>
#include <stdlib.h>

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

static void
four_threads_share_a_map_each_with_its_localizer_and_its_own_last_error(const topoloc_map *map)
{
    enum { THREADS = 4 };
    pthread_t threads[THREADS];
    struct thread_job jobs[THREADS];
    bool started[THREADS];
    unsigned i;

    SECTION();
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

static void one_localizer_used_by_two_threads_at_once_is_refused_never_raced(const topoloc_map *map)
{
    pthread_t threads[2];
    struct shared_job jobs[2];
    topoloc_localizer *loc = NULL;
    uint64_t *all = malloc(2 * SHARED_CALLS * sizeof *all);
    unsigned i, ran = 0;
    bool consecutive = true;

    SECTION();
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

void run_thread_tests(const topoloc_map *world)
{
    four_threads_share_a_map_each_with_its_localizer_and_its_own_last_error(world);
    one_localizer_used_by_two_threads_at_once_is_refused_never_raced(world);
}
