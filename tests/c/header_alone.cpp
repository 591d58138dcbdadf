// include/topoloc.h compiled on its own as C++17 with strict warnings (see tests/c/run.sh), and
// included twice to exercise the include guard. Linked and run against the library.
#include "topoloc.h"
#include "topoloc.h" // twice: the include guard must make this a no-op

#include <cstddef>
#include <cstdint>
#include <type_traits>

static_assert(offsetof(topoloc_view_attributes, struct_size) == 0, "struct_size first");
static_assert(offsetof(topoloc_keyframe_options, struct_size) == 0, "struct_size first");
static_assert(offsetof(topoloc_localizer_options, struct_size) == 0, "struct_size first");
static_assert(offsetof(topoloc_frame, struct_size) == 0, "struct_size first");
static_assert(offsetof(topoloc_result, struct_size) == 0, "struct_size first");
static_assert(offsetof(topoloc_map_load_options, struct_size) == 0, "struct_size first");
static_assert(offsetof(topoloc_view_info, struct_size) == 0, "struct_size first");
static_assert(sizeof(topoloc_candidate) == 16, "topoloc_candidate layout is fixed");
// In C++ the status is an enum with a fixed 32-bit underlying type, as uint32_t is in C.
static_assert(std::is_same<std::underlying_type<topoloc_status>::type, std::uint32_t>::value,
              "topoloc_status is a uint32_t enum");
static_assert(std::is_standard_layout<topoloc_result>::value, "C layout");
static_assert(std::is_trivially_copyable<topoloc_frame>::value, "C layout");

namespace {

bool fill_defaults()
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

} // namespace

int main()
{
    if (topoloc_abi_version() != TOPOLOC_ABI_VERSION) {
        return 1;
    }
    return fill_defaults() ? 0 : 1;
}
