/*
 * topoloc/version.hpp: the version and ABI of the loaded library, and the ABI check a program
 * makes once at start-up (part of topoloc.hpp, which has the overview).
 */

#ifndef TOPOLOC_VERSION_HPP
#define TOPOLOC_VERSION_HPP

#include "../topoloc.h"

#include <cstdint>

namespace topoloc {

/// Version of the loaded library, "MAJOR.MINOR.PATCH" (static; never free it). The header's
/// version is `TOPOLOC_VERSION_STRING`.
[[nodiscard]] inline const char *version() noexcept { return topoloc_version(); }

/// ABI version of the loaded library.
[[nodiscard]] inline uint32_t abi_version() noexcept { return topoloc_abi_version(); }

/// ABI version of the header this program was compiled against.
constexpr uint32_t header_abi_version = TOPOLOC_ABI_VERSION;

/// True when the loaded library has the ABI of the header this program was compiled against.
/// Check it once at start-up; on false, do not use the library.
[[nodiscard]] inline bool abi_matches() noexcept
{
    return topoloc_abi_version() == TOPOLOC_ABI_VERSION;
}

} // namespace topoloc

#endif // TOPOLOC_VERSION_HPP
