// include/topoloc.h compiled on its own as C++17 with strict warnings (see tests/c/run.sh), and
// included twice to exercise the include guard. Linked and run against the library. The checks
// it shares with header_alone.c are in header_alone.h.
#include "topoloc.h"
#include "topoloc.h" // twice: the include guard must make this a no-op

#include "header_alone.h"

#include <cstdint>
#include <type_traits>

// In C++ the status is an enum with a fixed 32-bit underlying type, as uint32_t is in C.
static_assert(std::is_same<std::underlying_type<topoloc_status>::type, std::uint32_t>::value,
              "topoloc_status is a uint32_t enum");
static_assert(std::is_standard_layout<topoloc_result>::value, "C layout");
static_assert(std::is_trivially_copyable<topoloc_frame>::value, "C layout");

int main()
{
    if (topoloc_abi_version() != TOPOLOC_ABI_VERSION) {
        return 1;
    }
    return fill_defaults() ? 0 : 1;
}
