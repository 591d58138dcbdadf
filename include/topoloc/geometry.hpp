/*
 * topoloc/geometry.hpp: positions and rigid poses as the C ABI lays them out (part of
 * topoloc.hpp, which has the overview).
 */

#ifndef TOPOLOC_GEOMETRY_HPP
#define TOPOLOC_GEOMETRY_HPP

#include <array>

namespace topoloc {

/// A position in metres (x, y, z).
using Position = std::array<double, 3>;

/// A rigid transform: 16 doubles, row-major 4x4 `[R t; 0 0 0 1]`, metres.
using Pose = std::array<double, 16>;

} // namespace topoloc

#endif // TOPOLOC_GEOMETRY_HPP
