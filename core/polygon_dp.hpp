#pragma once
// Lu & Yun §3.4: optimal re-triangulation of the hole left by a removed vertex (Klincsek's
// dynamic program over valid diagonals).
#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <vector>

#include "core/mesh.hpp"

namespace tb::core {

// The "closeness" of a triangle to the surface: error points first, then total error.
struct TriangleCost {
    std::int64_t error_points = 0;
    double error = 0.0;
    friend TriangleCost operator+(TriangleCost a, TriangleCost b) {
        return {a.error_points + b.error_points, a.error + b.error};
    }
    friend bool operator<(TriangleCost a, TriangleCost b) {
        return a.error_points != b.error_points ? a.error_points < b.error_points
                                                : a.error < b.error;
    }
};

// True when v[i] v[j] is a valid diagonal of the simple counter-clockwise polygon v: its
// interior lies strictly inside the polygon and it touches no other vertex (so it never runs
// along a polygon edge). Exact. O(n).
bool valid_diagonal(std::span<const GridPoint> v, int i, int j);

// The same test for a polygon that is star-shaped around `center`: every edge has center
// strictly on its left (the hole around a removed interior vertex), or center lies on the
// closing edge v[n-1] -> v[0] and strictly left of every other edge (a removed border vertex).
// Then the diagonal is valid exactly when the vertices on the side the segment faces (away
// from center) lie strictly beyond it. O(n), one orientation per vertex.
bool valid_diagonal_star(std::span<const GridPoint> v, GridPoint center, int i, int j);

// Working memory of triangulate_polygon, reusable across calls to save allocations.
struct PolygonDpScratch {
    std::vector<std::uint8_t> side;
    std::vector<std::optional<TriangleCost>> best;
    std::vector<int> apex;
};

// Minimum-cost triangulation of the simple counter-clockwise polygon v (n >= 3), where
// cost(i, j, k) for i < j < k is the cost of the triangle (v[i], v[j], v[k]) or nullopt when
// that triangle may not be used. Only valid diagonals are used and every triangle has positive
// area. Returns the triangles as index triples (counter-clockwise), or nullopt when no allowed
// triangulation exists. Ties go to the lowest apex index. O(n^3) cost calls at most (each
// triple once). With star_center the polygon must be star-shaped around it as
// valid_diagonal_star requires, and that faster test is used.
std::optional<std::vector<std::array<int, 3>>>
triangulate_polygon(std::span<const GridPoint> v,
                    const std::function<std::optional<TriangleCost>(int, int, int)>& cost,
                    TriangleCost* total = nullptr,
                    PolygonDpScratch* scratch = nullptr,
                    const GridPoint* star_center = nullptr);

} // namespace tb::core
