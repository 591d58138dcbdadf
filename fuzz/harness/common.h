/* Shared by topoloc's libFuzzer harnesses: status checks that turn a caught panic (or an
 * out-parameter written on failure) into a crash libFuzzer records, and seed-map loading. */
#ifndef TOPOLOC_FUZZ_COMMON_H
#define TOPOLOC_FUZZ_COMMON_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <topoloc.h>

/* The support library (fuzz/src/lib.rs). */
size_t topoloc_fuzz_mutate_map(uint8_t *data, size_t size, size_t max_size, unsigned int seed);
uint8_t *topoloc_fuzz_splice_describer(const uint8_t *base, size_t base_len, const uint8_t *spec,
                                       size_t spec_len, size_t *out_len);
void topoloc_fuzz_free(uint8_t *ptr, size_t len);

/* A status the C ABI must never return to these inputs: TOPOLOC_ERR_PANIC means a Rust panic
 * was caught at the boundary, i.e. a bug (overflow, index out of range, failed assertion). */
static inline topoloc_status fuzz_check(topoloc_status status, const char *call)
{
    if (status == TOPOLOC_ERR_PANIC) {
        char msg[1024];
        topoloc_last_error_message(msg, sizeof msg, NULL);
        fprintf(stderr, "%s: caught panic: %s\n", call, msg);
        abort();
    }
    return status;
}
#define CHECK(call) fuzz_check((call), #call)

/* Out-parameters are written only on success (an ABI rule): a failed call leaves them NULL. */
#define EXPECT_NULL_ON_ERROR(status, ptr)                                                          \
    do {                                                                                           \
        if ((status) != TOPOLOC_OK && (ptr) != NULL) {                                             \
            fprintf(stderr, "%s:%d: out-parameter written on failure\n", __FILE__, __LINE__);      \
            abort();                                                                               \
        }                                                                                          \
    } while (0)

/* Reads a whole file (a seed map named by fuzz/run.sh through the environment). */
static inline uint8_t *fuzz_read_file(const char *env, size_t *len)
{
    const char *path = getenv(env);
    if (!path) {
        fprintf(stderr, "set %s to a map file (fuzz/run.sh does)\n", env);
        exit(2);
    }
    FILE *f = fopen(path, "rb");
    if (!f) {
        fprintf(stderr, "cannot open %s='%s'\n", env, path);
        exit(2);
    }
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    uint8_t *buf = malloc((size_t)n);
    if (!buf || fread(buf, 1, (size_t)n, f) != (size_t)n) {
        fprintf(stderr, "cannot read %s\n", path);
        exit(2);
    }
    fclose(f);
    *len = (size_t)n;
    return buf;
}

/* Loads a map that must load (a seed named by the environment). */
static inline topoloc_map *fuzz_load_seed(const char *env)
{
    size_t len = 0;
    uint8_t *bytes = fuzz_read_file(env, &len);
    topoloc_map *map = NULL;
    if (topoloc_map_load_from_memory(bytes, len, NULL, &map) != TOPOLOC_OK) {
        char msg[512];
        topoloc_last_error_message(msg, sizeof msg, NULL);
        fprintf(stderr, "seed map %s does not load: %s\n", getenv(env), msg);
        exit(2);
    }
    free(bytes);
    return map;
}

/* Reads the input as a little stream of fields. */
typedef struct {
    const uint8_t *p;
    size_t n;
} fuzz_reader;

static inline uint8_t fuzz_u8(fuzz_reader *r)
{
    if (r->n == 0)
        return 0;
    r->n--;
    return *r->p++;
}
static inline uint32_t fuzz_u16(fuzz_reader *r)
{
    uint32_t lo = fuzz_u8(r);
    return lo | ((uint32_t)fuzz_u8(r) << 8);
}
/* A float that is mostly ordinary (a byte scaled to [-4, 4)), sometimes NaN, infinite, huge or
 * subnormal: the values a broken host or a corrupt file would pass. */
static inline float fuzz_f32(fuzz_reader *r)
{
    uint8_t b = fuzz_u8(r);
    switch (b) {
    case 0xF8:
        return __builtin_nanf("");
    case 0xF9:
        return __builtin_inff();
    case 0xFA:
        return -__builtin_inff();
    case 0xFB:
        return 3.0e38f;
    case 0xFC:
        return 1.0e-40f;
    default:
        return ((float)b - 128.0f) / 32.0f;
    }
}

#endif
