/*
 * topoloc/graph.hpp: `Graph`, the topological graph of the free space of an occupancy voxel grid
 * (skeleton map building; part of topoloc.hpp, which has the overview; its options are in
 * options.hpp).
 */

#ifndef TOPOLOC_GRAPH_HPP
#define TOPOLOC_GRAPH_HPP

#include "../topoloc.h"
#include "detail.hpp"
#include "error.hpp"
#include "options.hpp"
#include "geometry.hpp"

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace topoloc {

/// One place of a skeleton graph: its position in metres and its `TOPOLOC_NODE_*` kind.
struct GraphPlace {
    Position position{}; ///< Centre of the place's skeleton voxel, world metres.
    uint32_t kind = 0;   ///< `TOPOLOC_NODE_END`, `_CORNER`, `_BRANCH` or `_INTERMEDIATE`.
};

/// One undirected edge of a skeleton graph: places `a < b` and their straight distance.
struct GraphEdge {
    uint32_t a = 0;        ///< Smaller place index.
    uint32_t b = 0;        ///< Larger place index.
    double length_m = 0.0; ///< Straight-line distance between the places, metres.
};

/// Owner of a topological graph built from an occupancy voxel grid (`topoloc_graph*`, made by
/// `topoloc_graph_from_occupancy`). Move-only; the destructor calls `topoloc_graph_free`.
///
/// Thread safety: immutable; const methods may be called from many threads at once.
/// Errors: every method that calls the library throws `Error` on failure.
class Graph : public detail::Owner<topoloc_graph, &topoloc_graph_free> {
public:
    /// An empty owner (`!graph`).
    Graph() noexcept = default;

    /// Takes ownership of `raw` (from `topoloc_graph_from_occupancy`); null gives an empty owner.
    explicit Graph(topoloc_graph *raw) noexcept : Owner(raw) {}

    // Moves (noexcept; the source is left empty) and the destructor (calls `topoloc_graph_free`)
    // come from `detail::Owner`; copies are deleted.

    /// Builds the graph of the free space of an occupancy grid of `dims` voxels (x, y, z) of
    /// `voxel_size` metres whose voxel (0, 0, 0) starts at `origin`; `cells` holds one byte per
    /// voxel, x fastest (`cells[x + nx * (y + ny * z)]`), non-zero = occupied. Read during the
    /// call only. Throws `Error` (`TOPOLOC_ERR_INVALID_ARGUMENT` naming the field: `dims`,
    /// `voxel_size`, `origin`, `cells_len`, `cells` when every voxel is occupied, `z_band`,
    /// `min_clearance_m` or another option; `_STRUCT_SIZE`).
    [[nodiscard]] static Graph
    from_occupancy(const std::array<std::size_t, 3> &dims, double voxel_size,
                   const Position &origin, const uint8_t *cells, std::size_t cells_len,
                   const SkeletonOptions &options = default_skeleton_options())
    {
        topoloc_graph *raw = nullptr;
        check(topoloc_graph_from_occupancy(dims.data(), voxel_size, origin.data(), cells, cells_len,
                                           &options, &raw));
        return Graph(raw);
    }

    /// `from_occupancy` over a byte vector.
    [[nodiscard]] static Graph
    from_occupancy(const std::array<std::size_t, 3> &dims, double voxel_size,
                   const Position &origin, const std::vector<uint8_t> &cells,
                   const SkeletonOptions &options = default_skeleton_options())
    {
        return from_occupancy(dims, voxel_size, origin, cells.data(), cells.size(), options);
    }

    /// Number of places.
    [[nodiscard]] std::size_t place_count() const { return read_value(&topoloc_graph_place_count); }

    /// Number of undirected edges.
    [[nodiscard]] std::size_t edge_count() const { return read_value(&topoloc_graph_edge_count); }

    /// Place `index` (branches first, then ends, corners, intermediate places). Throws `Error`
    /// (`TOPOLOC_ERR_UNKNOWN_PLACE`).
    [[nodiscard]] GraphPlace place(uint32_t index) const
    {
        GraphPlace p;
        check(topoloc_graph_place(get(), index, p.position.data(), &p.kind));
        return p;
    }

    /// All places.
    [[nodiscard]] std::vector<GraphPlace> places() const
    {
        return detail::read_all<GraphPlace>(
            place_count(), [this](std::size_t i) { return place(static_cast<uint32_t>(i)); });
    }

    /// Edge number `index` (0..edge_count(), sorted by (a, b)). Throws `Error`
    /// (`TOPOLOC_ERR_INVALID_ARGUMENT` when out of range).
    [[nodiscard]] GraphEdge edge(std::size_t index) const
    {
        return read_edge(&topoloc_graph_edge, index, &GraphEdge::length_m);
    }

    /// All edges, sorted by (a, b).
    [[nodiscard]] std::vector<GraphEdge> edges() const
    {
        return detail::read_all<GraphEdge>(edge_count(), [this](std::size_t i) { return edge(i); });
    }

    /// The skeleton the graph was built on: voxel indices x0, y0, z0, x1, y1, z1, ... in grid
    /// order.
    [[nodiscard]] std::vector<uint32_t> skeleton() const
    {
        return detail::read_ids([this](uint32_t *buf, std::size_t len, std::size_t *count) {
            return topoloc_graph_skeleton(get(), buf, len, count);
        });
    }
};

} // namespace topoloc

#endif // TOPOLOC_GRAPH_HPP
