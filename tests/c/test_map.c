/*
 * Section "Maps: load, save, query" of topoloc.h: every accessor of the descriptor world after
 * building, saving, loading and loading from memory; a localizer that keeps a loaded map alive;
 * map files that are missing, foreign, truncated, corrupt, of a newer format or of another
 * descriptor; NULL arguments, buffers too small and unknown place and view ids.
 */
#include "harness.h"

#include <stdlib.h>

/* Reads every accessor of the world's map and compares with what was built. */
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

/* Builds the world, saves it to `path` (twice: the second replaces the file) and loads it back
 * from the file and from memory; every accessor answers as built each time. Returns the map
 * loaded from the file, or NULL. */
static topoloc_map *a_map_reads_back_as_built_after_save_load_and_load_from_memory(const char *path)
{
    topoloc_map *built = NULL, *loaded = NULL, *from_memory = NULL;
    unsigned char *bytes;
    size_t len = 0;

    SECTION();
    built = build_world_map();
    CHECK(built != NULL);
    if (built == NULL) {
        return NULL;
    }
    check_world_accessors(built);

    CHECK_OK(topoloc_map_save(built, path));
    CHECK_OK(topoloc_map_save(built, path)); /* replacing an existing file */
    topoloc_map_free(built);

    CHECK_OK(topoloc_map_load(path, NULL, &loaded));
    if (loaded == NULL) {
        return NULL;
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
    return loaded;
}

/* A localizer keeps its own reference to `loaded` (freed here right after the localizer is made)
 * and localizes a walk along the places and back over the loop edge; after a reset the frame
 * index restarts; the candidates are min(top_k, places, capacity); the map saved at `path` is
 * still valid after its localizers are gone. */
static void
a_localizer_keeps_a_loaded_map_alive_and_localizes_a_walk_over_the_loop(topoloc_map *loaded,
                                                                        const char *path)
{
    topoloc_localizer *loc = NULL;
    topoloc_localizer_options options;
    topoloc_frame frame;
    topoloc_result result;
    topoloc_candidate candidates[8];
    size_t count = 0;
    float desc[DIM];
    double odometry[16] = {1, 0, 0, 2, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    double t = 100.0;
    uint64_t expected_index = 0;
    uint32_t k, rep;

    SECTION();
    rng_seed(1);
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
        float sum = 0.0f;
        size_t i;
        result.candidates = candidates;
        result.candidates_capacity = 8;
        CHECK_OK(topoloc_localizer_process(loc, &frame, &result));
        CHECK(result.candidates_len == PLACES);
        CHECK(candidates_consistent(&result));
        CHECK(candidates_distinct(&result));
        for (i = 0; i < result.candidates_len; i++) {
            sum += result.candidates[i].probability;
        }
        /* Every place is listed: the place probabilities and off-map add up to 1. */
        CHECK_NEAR(sum + result.off_map_probability, 1.0f, 1e-4f);
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
}

/* ------------------------------------------------------------------------------------------ */
/* Map files                                                                                   */
/* ------------------------------------------------------------------------------------------ */

/* A saved map: its path, its bytes, and a scratch copy with room for 16 more bytes. */
struct saved_map {
    char path[4200];
    unsigned char *bytes, *copy;
    size_t len;
    size_t header_end; /* safetensors: 8-byte little-endian header length, JSON header, data */
};

static void
saving_where_no_file_can_be_written_fails_with_io_or_invalid_utf8(const topoloc_map *built)
{
    char other[4200];
    SECTION();
    tmp_path(other, sizeof other, "no-such-dir/map.topoloc");
    CHECK_ERROR(topoloc_map_save(built, other), TOPOLOC_ERR_IO);
    CHECK_STATUS(topoloc_map_save(built, "\xff.topoloc"), TOPOLOC_ERR_INVALID_UTF8);
}

static void loading_a_missing_file_or_a_directory_fails_with_io_naming_it(void)
{
    topoloc_map *m = NULL;
    topoloc_status st;
    char other[4200];
    SECTION();
    tmp_path(other, sizeof other, "missing.topoloc");
    CHECK_ERROR(topoloc_map_load(other, NULL, &m), TOPOLOC_ERR_IO);
    CHECK_MESSAGE_HAS("missing.topoloc");
    st = topoloc_map_load(g_tmpdir, NULL, &m);
    CHECK(st != TOPOLOC_OK);
    CHECK(st == TOPOLOC_ERR_IO || st == TOPOLOC_ERR_NOT_A_MAP);
    CHECK_STATUS(topoloc_map_load("\xff\xfe", NULL, &m), TOPOLOC_ERR_INVALID_UTF8);
}

static void loading_a_text_file_an_empty_file_or_no_bytes_fails_with_not_a_map(void)
{
    static const char not_a_map[] = "hello, this is a text file and not a topoloc map\n";
    topoloc_map *m = NULL;
    char other[4200];
    SECTION();
    tmp_path(other, sizeof other, "text.txt");
    CHECK(write_file(other, (const unsigned char *)not_a_map, sizeof not_a_map - 1));
    CHECK_ERROR(topoloc_map_load(other, NULL, &m), TOPOLOC_ERR_NOT_A_MAP);
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
}

/* From memory at every offset, from a file at a few offsets. */
static void
a_map_truncated_anywhere_fails_and_past_its_header_with_truncated(const struct saved_map *saved)
{
    topoloc_map *m = NULL;
    char other[4200];
    size_t off, tested = 0;
    SECTION();
    tmp_path(other, sizeof other, "truncated.topoloc");
    for (off = 0; off < saved->len; off++) {
        topoloc_status st = topoloc_map_load_from_memory(saved->bytes, off, NULL, &m);
        bool ok =
            st == TOPOLOC_ERR_TRUNCATED || st == TOPOLOC_ERR_NOT_A_MAP || st == TOPOLOC_ERR_CORRUPT;
        if (!ok) {
            fprintf(stderr, "    truncated at %zu of %zu: status %u\n", off, saved->len,
                    (unsigned)st);
        }
        CHECK(ok);
        if (off > saved->header_end) {
            CHECK(st == TOPOLOC_ERR_TRUNCATED); /* the header promises more data */
        }
        if (off == 0 || off == 1 || off == 7 || off == 8 || off == 9 ||
            off == saved->header_end / 2 || off == saved->header_end || off == saved->len / 2 ||
            off == saved->len - 1) {
            CHECK(write_file(other, saved->bytes, off));
            st = topoloc_map_load(other, NULL, &m);
            CHECK(st == TOPOLOC_ERR_TRUNCATED || st == TOPOLOC_ERR_NOT_A_MAP ||
                  st == TOPOLOC_ERR_CORRUPT);
            CHECK_HAS_MESSAGE();
            tested++;
        }
    }
    CHECK(tested == 9);
    CHECK(m == NULL);
    remove(other);
}

/* The bit flipped varies with the offset; in the data, the checksum catches it. */
static void one_flipped_bit_anywhere_in_a_map_is_never_loaded(struct saved_map *saved)
{
    topoloc_map *m = NULL;
    unsigned char *copy = saved->copy;
    char other[4200];
    size_t off, len = saved->len, undetected = 0;
    SECTION();
    for (off = 0; off < len; off++) {
        topoloc_status st;
        memcpy(copy, saved->bytes, len);
        copy[off] ^= (unsigned char)(1u << (off % 8));
        st = topoloc_map_load_from_memory(copy, len, NULL, &m);
        if (st == TOPOLOC_OK) {
            undetected++;
            fprintf(stderr, "    flipped bit %zu of byte %zu (of %zu) not detected\n", off % 8, off,
                    len);
            topoloc_map_free(m);
            m = NULL;
        } else if (off >= saved->header_end) {
            CHECK(st == TOPOLOC_ERR_CORRUPT); /* data bytes: the checksum catches them */
        }
    }
    CHECK(undetected == 0);
    /* And through a file. */
    tmp_path(other, sizeof other, "flipped.topoloc");
    memcpy(copy, saved->bytes, len);
    copy[len - 3] ^= 0x40;
    CHECK(write_file(other, copy, len));
    CHECK_ERROR(topoloc_map_load(other, NULL, &m), TOPOLOC_ERR_CORRUPT);
    memcpy(copy, saved->bytes, len);
    copy[saved->header_end - 20] ^= 0x01;
    CHECK(write_file(other, copy, len));
    CHECK(topoloc_map_load(other, NULL, &m) != TOPOLOC_OK);
    CHECK(m == NULL);
    remove(other);
}

static void bytes_after_the_end_of_a_map_are_corrupt(struct saved_map *saved)
{
    topoloc_map *m = NULL;
    SECTION();
    memcpy(saved->copy, saved->bytes, saved->len);
    memset(saved->copy + saved->len, 0, 16);
    CHECK_STATUS(topoloc_map_load_from_memory(saved->copy, saved->len + 16, NULL, &m),
                 TOPOLOC_ERR_CORRUPT);
}

static void a_newer_major_format_version_is_unsupported(struct saved_map *saved)
{
    static const char key[] = "version\\\":\\\"";
    topoloc_map *m = NULL;
    unsigned char *copy = saved->copy;
    size_t klen = sizeof key - 1, found = 0, off;
    SECTION();
    memcpy(copy, saved->bytes, saved->len);
    for (off = 8; off + klen < saved->header_end; off++) {
        if (memcmp(copy + off, key, klen) == 0) {
            found = off + klen;
            break;
        }
    }
    CHECK(found != 0);
    if (found != 0) {
        CHECK(copy[found] == '1');
        copy[found] = '9';
        CHECK_ERROR(topoloc_map_load_from_memory(copy, saved->len, NULL, &m),
                    TOPOLOC_ERR_UNSUPPORTED_VERSION);
    }
}

static void a_map_of_another_descriptor_is_refused_at_load(const struct saved_map *saved)
{
    topoloc_map_load_options options;
    topoloc_map *m = NULL;
    const char *path = saved->path;
    SECTION();
    CHECK_OK(topoloc_map_load_options_default(&options));
    CHECK(options.struct_size == sizeof options);
    CHECK(options.expected_descriptor_kind == NULL && options.expected_descriptor_dim == 0);
    options.expected_descriptor_kind = "another-desc";
    CHECK_ERROR(topoloc_map_load(path, &options, &m), TOPOLOC_ERR_DESCRIPTOR_MISMATCH);
    CHECK_STATUS(topoloc_map_load_from_memory(saved->bytes, saved->len, &options, &m),
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
    CHECK_ERROR(topoloc_map_load(path, &options, &m), TOPOLOC_ERR_STRUCT_SIZE);
    CHECK_STATUS(topoloc_map_load_from_memory(saved->bytes, saved->len, &options, &m),
                 TOPOLOC_ERR_STRUCT_SIZE);
    CHECK(m == NULL);
}

/* The map file checks, on the world saved to a file of their own. */
static void map_files(void)
{
    topoloc_map *built = build_world_map();
    struct saved_map saved;
    size_t off;

    if (built == NULL) {
        return;
    }
    memset(&saved, 0, sizeof saved);
    tmp_path(saved.path, sizeof saved.path, "files.topoloc");
    CHECK_OK(topoloc_map_save(built, saved.path));
    saving_where_no_file_can_be_written_fails_with_io_or_invalid_utf8(built);
    topoloc_map_free(built);
    loading_a_missing_file_or_a_directory_fails_with_io_naming_it();
    loading_a_text_file_an_empty_file_or_no_bytes_fails_with_not_a_map();

    saved.bytes = read_file(saved.path, &saved.len);
    CHECK(saved.bytes != NULL && saved.len > 16);
    saved.copy = saved.bytes != NULL && saved.len > 16 ? malloc(saved.len + 16) : NULL;
    CHECK(saved.copy != NULL);
    if (saved.copy != NULL) {
        saved.header_end = 8;
        for (off = 0; off < 8; off++) {
            saved.header_end += (size_t)saved.bytes[off] << (8 * off);
        }
        CHECK(saved.header_end < saved.len);
        a_map_truncated_anywhere_fails_and_past_its_header_with_truncated(&saved);
        one_flipped_bit_anywhere_in_a_map_is_never_loaded(&saved);
        bytes_after_the_end_of_a_map_are_corrupt(&saved);
        a_newer_major_format_version_is_unsupported(&saved);
        a_map_of_another_descriptor_is_refused_at_load(&saved);
    }
    remove(saved.path);
    free(saved.copy);
    free(saved.bytes);
}

/* ------------------------------------------------------------------------------------------ */
/* Bad arguments                                                                               */
/* ------------------------------------------------------------------------------------------ */

static void loading_saving_and_accessors_refuse_null_arguments_naming_them(const topoloc_map *map)
{
    topoloc_map *m = NULL;
    topoloc_view_info info;
    char buf[64];
    float desc[DIM];
    uint32_t u = 0, u2 = 0, ids[8];
    size_t n = 0;
    float w = 0.0f;
    double xyz[3];
    bool has = false;
    unsigned char bytes[16] = {0};

    SECTION();
    CHECK_NULL(topoloc_map_load_options_init(NULL, sizeof(topoloc_map_load_options)), "NULL");
    CHECK_NULL(topoloc_view_info_init(NULL, sizeof(topoloc_view_info)), "NULL");

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
}

static void
accessors_say_what_they_need_when_a_buffer_is_too_small_and_write_nothing(const topoloc_map *map)
{
    char buf[256];
    char small[4];
    size_t needed = 0, count = 0;
    uint32_t ids[1] = {4242};
    float desc[DIM];

    SECTION();
    /* Descriptor kind and model, view image. */
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

static void unknown_place_and_view_ids_are_refused_and_outputs_left_alone(const topoloc_map *map)
{
    uint32_t ids[8], a = 0, b = 0;
    size_t count = 12345;
    double xyz[3] = {7.0, 7.0, 7.0};
    bool has = true;
    float w = 0.0f, desc[DIM];
    char buf[64];
    topoloc_view_info info;

    SECTION();
    CHECK_ERROR(topoloc_map_neighbours(map, PLACES, ids, 8, &count), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_STATUS(topoloc_map_neighbours(map, 0xFFFFFFFFu, ids, 8, &count),
                 TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_STATUS(topoloc_map_place_views(map, PLACES, ids, 8, &count), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK_STATUS(topoloc_map_place_position(map, PLACES, xyz, &has), TOPOLOC_ERR_UNKNOWN_PLACE);
    CHECK(xyz[0] == 7.0 && has); /* untouched */
    CHECK_OK(topoloc_view_info_default(&info));
    CHECK_ERROR(topoloc_map_view_info(map, VIEWS, &info), TOPOLOC_ERR_UNKNOWN_VIEW);
    CHECK_STATUS(topoloc_map_view_image(map, VIEWS, buf, sizeof buf, NULL),
                 TOPOLOC_ERR_UNKNOWN_VIEW);
    CHECK_STATUS(topoloc_map_view_descriptor(map, VIEWS, desc, DIM), TOPOLOC_ERR_UNKNOWN_VIEW);
    CHECK_STATUS(topoloc_map_view_descriptor(map, 0xFFFFFFFFu, desc, DIM),
                 TOPOLOC_ERR_UNKNOWN_VIEW);
    CHECK_ERROR(topoloc_map_edge(map, EDGES, &a, &b, &w), TOPOLOC_ERR_INVALID_ARGUMENT);
    CHECK_STATUS(topoloc_map_edge(map, (size_t)-1, &a, &b, &w), TOPOLOC_ERR_INVALID_ARGUMENT);
    info.struct_size = 0;
    CHECK_ERROR(topoloc_map_view_info(map, 0, &info), TOPOLOC_ERR_STRUCT_SIZE);
    info.struct_size = sizeof info - 1;
    CHECK_STATUS(topoloc_map_view_info(map, 0, &info), TOPOLOC_ERR_STRUCT_SIZE);
}

void run_map_tests(const topoloc_map *world)
{
    char path[4200];
    topoloc_map *loaded;

    tmp_path(path, sizeof path, "world.topoloc");
    loaded = a_map_reads_back_as_built_after_save_load_and_load_from_memory(path);
    if (loaded != NULL) {
        a_localizer_keeps_a_loaded_map_alive_and_localizes_a_walk_over_the_loop(loaded, path);
    }
    remove(path);
    map_files();
    loading_saving_and_accessors_refuse_null_arguments_naming_them(world);
    accessors_say_what_they_need_when_a_buffer_is_too_small_and_write_nothing(world);
    unknown_place_and_view_ids_are_refused_and_outputs_left_alone(world);
}
