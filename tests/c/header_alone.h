/*
 * The checks both header-alone programs make (header_alone.c as C11, header_alone.cpp as
 * C++17), included after include/topoloc.h: the layout promises of the header, and every
 * _default macro expanding to a valid call.
 */
#ifndef TOPOLOC_TESTS_C_HEADER_ALONE_H
#define TOPOLOC_TESTS_C_HEADER_ALONE_H

#include <stddef.h>

#ifdef __cplusplus
#define HEADER_ALONE_STATIC_ASSERT static_assert
#else
#define HEADER_ALONE_STATIC_ASSERT _Static_assert
#endif

/* Versioned structs start with struct_size; array elements never change layout. */
HEADER_ALONE_STATIC_ASSERT(offsetof(topoloc_view_attributes, struct_size) == 0,
                           "struct_size first");
HEADER_ALONE_STATIC_ASSERT(offsetof(topoloc_keyframe_options, struct_size) == 0,
                           "struct_size first");
HEADER_ALONE_STATIC_ASSERT(offsetof(topoloc_localizer_options, struct_size) == 0,
                           "struct_size first");
HEADER_ALONE_STATIC_ASSERT(offsetof(topoloc_frame, struct_size) == 0, "struct_size first");
HEADER_ALONE_STATIC_ASSERT(offsetof(topoloc_result, struct_size) == 0, "struct_size first");
HEADER_ALONE_STATIC_ASSERT(offsetof(topoloc_map_load_options, struct_size) == 0,
                           "struct_size first");
HEADER_ALONE_STATIC_ASSERT(offsetof(topoloc_view_info, struct_size) == 0, "struct_size first");
HEADER_ALONE_STATIC_ASSERT(sizeof(topoloc_candidate) == 16, "topoloc_candidate layout is fixed");
HEADER_ALONE_STATIC_ASSERT(TOPOLOC_OK == 0, "TOPOLOC_OK is 0");
HEADER_ALONE_STATIC_ASSERT(TOPOLOC_MODE_FILTER != TOPOLOC_MODE_SINGLE_FRAME, "distinct modes");

/* Every _default macro expands to a valid call; true when all of them succeed. */
static bool fill_defaults(void)
{
    topoloc_view_attributes attributes;
    topoloc_keyframe_options keyframe_options;
    topoloc_localizer_options localizer_options;
    topoloc_frame frame;
    topoloc_result result;
    topoloc_map_load_options load_options;
    topoloc_view_info info;
    return topoloc_view_attributes_default(&attributes) == TOPOLOC_OK &&
           topoloc_keyframe_options_default(&keyframe_options) == TOPOLOC_OK &&
           topoloc_localizer_options_default(&localizer_options) == TOPOLOC_OK &&
           topoloc_frame_default(&frame) == TOPOLOC_OK &&
           topoloc_result_default(&result) == TOPOLOC_OK &&
           topoloc_map_load_options_default(&load_options) == TOPOLOC_OK &&
           topoloc_view_info_default(&info) == TOPOLOC_OK;
}

#endif
