/*
 * include/topoloc.h compiled on its own, in C11 with strict warnings (see tests/c/run.sh), and
 * included twice to exercise the include guard. Linked and run against the library: it also shows
 * that the library exports what this program references and that the ABI versions agree.
 */
#include "topoloc.h"
#include "topoloc.h" /* twice: the include guard must make this a no-op */

#include <stddef.h>

/* Layout promises of the header: versioned structs start with struct_size; array elements never
 * change layout. */
_Static_assert(offsetof(topoloc_view_attributes, struct_size) == 0, "struct_size first");
_Static_assert(offsetof(topoloc_keyframe_options, struct_size) == 0, "struct_size first");
_Static_assert(offsetof(topoloc_localizer_options, struct_size) == 0, "struct_size first");
_Static_assert(offsetof(topoloc_frame, struct_size) == 0, "struct_size first");
_Static_assert(offsetof(topoloc_result, struct_size) == 0, "struct_size first");
_Static_assert(offsetof(topoloc_map_load_options, struct_size) == 0, "struct_size first");
_Static_assert(offsetof(topoloc_view_info, struct_size) == 0, "struct_size first");
_Static_assert(sizeof(topoloc_candidate) == 16, "topoloc_candidate layout is fixed");
_Static_assert(sizeof(topoloc_status) == 4, "topoloc_status is 32 bits");
_Static_assert(TOPOLOC_OK == 0, "TOPOLOC_OK is 0");
_Static_assert(TOPOLOC_MODE_FILTER != TOPOLOC_MODE_SINGLE_FRAME, "distinct modes");

/* Every _default macro expands to a valid call. */
static topoloc_status fill_defaults(void)
{
    topoloc_view_attributes attributes;
    topoloc_keyframe_options keyframe_options;
    topoloc_localizer_options localizer_options;
    topoloc_frame frame;
    topoloc_result result;
    topoloc_map_load_options load_options;
    topoloc_view_info info;
    topoloc_status status = TOPOLOC_OK;
    status |= topoloc_view_attributes_default(&attributes);
    status |= topoloc_keyframe_options_default(&keyframe_options);
    status |= topoloc_localizer_options_default(&localizer_options);
    status |= topoloc_frame_default(&frame);
    status |= topoloc_result_default(&result);
    status |= topoloc_map_load_options_default(&load_options);
    status |= topoloc_view_info_default(&info);
    return status;
}

int main(void)
{
    if (topoloc_abi_version() != TOPOLOC_ABI_VERSION) {
        return 1;
    }
    return fill_defaults() == TOPOLOC_OK ? 0 : 1;
}
