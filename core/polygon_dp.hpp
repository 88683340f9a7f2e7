#pragma once
// Lu & Yun §3.4: optimal re-triangulation of the hole left by a removed vertex (Klincsek's
// dynamic program over valid diagonals).
#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "core/mesh.hpp"
#include "core/predicates.hpp"

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
    // side[i * n + k], i < k: 1 when v_i v_k may be a side of a sub-polygon (a polygon edge or
    // a valid diagonal), 0 when not, -1 while unknown; filled as the program needs it. A
    // caller that has filled some entries itself for this polygon (n * n entries, the rest -1)
    // sets side_ready before the call, and the program keeps them; it clears side_ready, so the
    // next call starts afresh unless its caller sets it again.
    std::vector<std::int8_t> side;
    bool side_ready = false;
    // Whether v_i v_k (i < k) may be a side of a sub-polygon of v: a polygon edge, or a valid
    // diagonal (valid_diagonal_star around star_center when given, else valid_diagonal); tested
    // once per pair and kept in `side`, which must hold v.size()^2 entries.
    bool side_ok(std::span<const GridPoint> v, const GridPoint* star_center, int i, int k) {
        const int n = static_cast<int>(v.size());
        std::int8_t& known = side[static_cast<std::size_t>(i * n + k)];
        if (known < 0) {
            const bool edge = k == i + 1 || (i == 0 && k == n - 1);
            known = edge || (star_center != nullptr ? valid_diagonal_star(v, *star_center, i, k)
                                                    : valid_diagonal(v, i, k))
                        ? 1
                        : 0;
        }
        return known == 1;
    }
    std::vector<std::optional<TriangleCost>> best;
    std::vector<int> apex;
};

// Minimum-cost triangulation of the simple counter-clockwise polygon v (n >= 3), where
// cost(i, j, k) for i < j < k is the cost of the triangle (v[i], v[j], v[k]) or nullopt when
// that triangle may not be used (any callable (int, int, int) -> std::optional<TriangleCost>).
// Only valid diagonals are used and every triangle has positive area. Returns the triangles as
// index triples (counter-clockwise), or nullopt when no allowed triangulation exists. Ties go to
// the lowest apex index. O(n^3) cost calls at most (each triple once). With star_center the polygon
// must be star-shaped around it as valid_diagonal_star requires, and that faster test is used.
template <typename Cost>
std::optional<std::vector<std::array<int, 3>>>
triangulate_polygon(std::span<const GridPoint> v,
                    const Cost& cost,
                    TriangleCost* total = nullptr,
                    PolygonDpScratch* scratch = nullptr,
                    const GridPoint* star_center = nullptr);

// ---- implementation (a template: the cost is inlined into the program's inner loop) ----

template <typename Cost>
std::optional<std::vector<std::array<int, 3>>> triangulate_polygon(std::span<const GridPoint> v,
                                                                   const Cost& cost,
                                                                   TriangleCost* total,
                                                                   PolygonDpScratch* scratch,
                                                                   const GridPoint* star_center) {
    const int n = static_cast<int>(v.size());
    if (n < 3) {
        return std::nullopt;
    }
    const auto idx = [n](int i, int k) { return static_cast<std::size_t>(i * n + k); };
    PolygonDpScratch local;
    PolygonDpScratch& mem = scratch != nullptr ? *scratch : local;
    if (!mem.side_ready) {
        mem.side.assign(static_cast<std::size_t>(n * n), -1);
    }
    mem.side_ready = false;
    auto& best = mem.best;
    best.assign(static_cast<std::size_t>(n * n), std::nullopt);
    auto& apex = mem.apex;
    apex.assign(static_cast<std::size_t>(n * n), -1);
    for (int i = 0; i + 1 < n; ++i) {
        best[idx(i, i + 1)] = TriangleCost{};
    }
    for (int len = 2; len < n; ++len) {
        for (int i = 0; i + len < n; ++i) {
            const int k = i + len;
            for (int j = i + 1; j < k; ++j) {
                const auto& left = best[idx(i, j)];
                const auto& right = best[idx(j, k)];
                if (!left || !right) {
                    continue;
                }
                // Tested only for the pairs (i, k) that some apex j could close: most diagonals of
                // a hole that cannot be triangulated never are.
                if (!mem.side_ok(v, star_center, i, k)) {
                    break;
                }
                if (orient2d(v[static_cast<std::size_t>(i)],
                             v[static_cast<std::size_t>(j)],
                             v[static_cast<std::size_t>(k)]) <= 0) {
                    continue;
                }
                const auto c = cost(i, j, k);
                if (!c) {
                    continue;
                }
                const TriangleCost sum = *left + *right + *c;
                auto& cell = best[idx(i, k)];
                if (!cell || sum < *cell) {
                    cell = sum;
                    apex[idx(i, k)] = j;
                }
            }
        }
    }
    if (!best[idx(0, n - 1)]) {
        return std::nullopt;
    }
    if (total != nullptr) {
        *total = *best[idx(0, n - 1)];
    }
    std::vector<std::array<int, 3>> out;
    std::vector<std::array<int, 2>> todo{{0, n - 1}};
    while (!todo.empty()) {
        const auto [i, k] = todo.back();
        todo.pop_back();
        if (k - i < 2) {
            continue;
        }
        const int j = apex[idx(i, k)];
        out.push_back({i, j, k});
        todo.push_back({i, j});
        todo.push_back({j, k});
    }
    return out;
}

} // namespace tb::core
