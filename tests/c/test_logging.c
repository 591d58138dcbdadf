/*
 * Section "Host logging" of topoloc.h (ABI 1.13): records reach the host's callback up to the
 * level it asked for, none when it is turned off, and the callback may not replace itself.
 * Nothing is written on stdout or stderr.
 */
#include "harness.h"

/* What the callback saw. */
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

static void records_reach_the_callback_up_to_its_level_and_none_when_off(const topoloc_map *map)
{
    struct log_sink sink;
    char path[4200];
    topoloc_map *loaded = NULL;

    SECTION();
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

void run_logging_tests(const topoloc_map *world)
{
    records_reach_the_callback_up_to_its_level_and_none_when_off(world);
}
