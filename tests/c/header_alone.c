/*
 * include/topoloc.h compiled on its own, in C11 with strict warnings (see tests/c/run.sh), and
 * included twice to exercise the include guard. Linked and run against the library: it also shows
 * that the library exports what this program references and that the ABI versions agree. The
 * checks it shares with header_alone.cpp are in header_alone.h.
 */
#include "topoloc.h"
#include "topoloc.h" /* twice: the include guard must make this a no-op */

#include "header_alone.h"

/* In C the status is a uint32_t. */
_Static_assert(sizeof(topoloc_status) == 4, "topoloc_status is 32 bits");

int main(void)
{
    if (topoloc_abi_version() != TOPOLOC_ABI_VERSION) {
        return 1;
    }
    return fill_defaults() ? 0 : 1;
}
