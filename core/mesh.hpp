#pragma once
// Core data types: a grid of heights in, an index-based triangle mesh out.
#include <cstdint>
#include <vector>

namespace tb::core {

using Index = std::uint32_t;
inline constexpr Index kNone = ~Index{0};

// A grid sample position: x = column, y = row. Exact integers.
struct GridPoint {
    std::int32_t x, y;
    friend bool operator==(const GridPoint&, const GridPoint&) = default;
};

// W x H heights, row-major, row 0 first. `valid` is empty (every sample constrains the mesh)
// or has W*H entries, 0 = nodata: that sample constrains nothing, and its height (which must
// still be finite) is only used where a vertex lands on it.
struct HeightGrid {
    int width = 0;
    int height = 0;
    std::vector<float> heights;
    std::vector<std::uint8_t> valid;

    float at(int x, int y) const { return heights[static_cast<std::size_t>(y) * width + x]; }
    bool is_valid(int x, int y) const {
        return valid.empty() || valid[static_cast<std::size_t>(y) * width + x] != 0;
    }
};

// A triangulation of [0,W-1] x [0,H-1] whose vertices are grid samples.
// Half-edge layout as in delaunator: half-edge e starts at vertex triangles[e], triangle
// t = e / 3 has half-edges 3t, 3t+1, 3t+2 (counter-clockwise in (x, y) with y pointing up the
// rows, i.e. positive signed area in (x, y)), halfedges[e] is the twin or kNone on the border.
struct Mesh {
    std::vector<GridPoint> points; // vertex v
    std::vector<float> z;          // height of vertex v, taken exactly from the grid
    std::vector<Index> triangles;  // half-edge e -> its start vertex
    std::vector<Index> halfedges;  // twin of e, or kNone on the grid border

    std::size_t triangle_count() const { return triangles.size() / 3; }
};

inline Index next_edge(Index e) {
    return e % 3 == 2 ? e - 2 : e + 1;
}
inline Index prev_edge(Index e) {
    return e % 3 == 0 ? e + 2 : e - 1;
}

} // namespace tb::core
