#pragma once
// An independent brute-force L-infinity checker for tiler tests (shares no code with core/):
// the surface is a set of triangles whose vertices are (column, row, height) in tile grid
// coordinates, fractional allowed (decoded, quantized vertices are slightly off the grid).
// Each grid sample is located by brute force over every triangle's bounding box and evaluated
// by barycentric interpolation. Samples on an edge take the worst of the triangles holding
// them. Samples that no triangle holds (quantization can pull a border vertex a hair inside)
// use the nearest triangle's plane, extrapolated, if it is within `reach` (grid units).
#include "core/mesh.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace tb::test {

struct OracleVertex {
    double column = 0, row = 0, h = 0;
};

struct OracleResult {
    double max_error = 0; // max |surface - sample| over valid samples
    int worst_column = -1, worst_row = -1;
    std::int64_t checked = 0;      // valid samples evaluated
    std::int64_t extrapolated = 0; // held by no triangle, evaluated on the nearest one
    std::int64_t uncovered = 0;    // held by no triangle, none within reach
};

inline OracleResult linf_error(const std::vector<OracleVertex>& vertices,
                               const std::vector<std::uint32_t>& indices,
                               const core::HeightGrid& grid,
                               double reach) {
    const std::size_t count = static_cast<std::size_t>(grid.width) * grid.height;
    constexpr double kInside = -1e-9; // barycentric slack for samples exactly on an edge
    // Per sample: distance (grid units) outside the nearest triangle so far; <= 0 inside.
    std::vector<double> best_out(count, std::numeric_limits<double>::infinity());
    std::vector<double> error(count, 0.0);
    for (std::size_t t = 0; t + 2 < indices.size(); t += 3) {
        const OracleVertex& a = vertices[indices[t]];
        const OracleVertex& b = vertices[indices[t + 1]];
        const OracleVertex& c = vertices[indices[t + 2]];
        const double det =
            (b.column - a.column) * (c.row - a.row) - (c.column - a.column) * (b.row - a.row);
        if (det == 0) {
            continue;
        }
        const int x0 =
            std::max(0, static_cast<int>(std::floor(std::min({a.column, b.column, c.column}))) - 1);
        const int x1 =
            std::min(grid.width - 1,
                     static_cast<int>(std::ceil(std::max({a.column, b.column, c.column}))) + 1);
        const int y0 =
            std::max(0, static_cast<int>(std::floor(std::min({a.row, b.row, c.row}))) - 1);
        const int y1 = std::min(grid.height - 1,
                                static_cast<int>(std::ceil(std::max({a.row, b.row, c.row}))) + 1);
        for (int y = y0; y <= y1; ++y) {
            for (int x = x0; x <= x1; ++x) {
                // Barycentric weights: sub-triangle areas opposite each vertex over the whole.
                const double la =
                    ((b.column - x) * (c.row - y) - (c.column - x) * (b.row - y)) / det;
                const double lb =
                    ((c.column - x) * (a.row - y) - (a.column - x) * (c.row - y)) / det;
                const double lc = 1.0 - la - lb;
                const std::size_t k = static_cast<std::size_t>(y) * grid.width + x;
                const double e = std::abs(la * a.h + lb * b.h + lc * c.h - double(grid.at(x, y)));
                // Distance outside the triangle: past the edge opposite the most negative
                // weight by weight * (twice the area) / edge length.
                double out = kInside;
                if (std::min({la, lb, lc}) < kInside) {
                    const OracleVertex* p0 = la <= lb && la <= lc ? &b : lb <= lc ? &c : &a;
                    const OracleVertex* p1 = la <= lb && la <= lc ? &c : lb <= lc ? &a : &b;
                    out = -std::min({la, lb, lc}) * std::abs(det) /
                          std::hypot(p1->column - p0->column, p1->row - p0->row);
                }
                if (out <= kInside) {
                    // Held by this triangle: worst over every triangle holding the sample.
                    error[k] = best_out[k] <= kInside ? std::max(error[k], e) : e;
                    best_out[k] = kInside;
                } else if (out < best_out[k]) {
                    best_out[k] = out;
                    error[k] = e;
                }
            }
        }
    }
    OracleResult r;
    for (int y = 0; y < grid.height; ++y) {
        for (int x = 0; x < grid.width; ++x) {
            if (!grid.is_valid(x, y)) {
                continue;
            }
            const std::size_t k = static_cast<std::size_t>(y) * grid.width + x;
            ++r.checked;
            if (best_out[k] > reach) {
                ++r.uncovered;
                continue;
            }
            if (best_out[k] > kInside) {
                ++r.extrapolated;
            }
            if (error[k] > r.max_error) {
                r.max_error = error[k];
                r.worst_column = x;
                r.worst_row = y;
            }
        }
    }
    return r;
}

} // namespace tb::test
