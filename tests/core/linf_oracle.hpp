#pragma once
// Independent brute-force judge of a mesh, for tests only. It shares no code with core/: point
// location by its own exact orientation tests over each triangle's bounding box, and the error
// of a sample decided exactly in integers (heights and eps must be multiples of 1/1024 below
// 2^20, which every test terrain is), so no rounding can pass a mesh that misses a sample.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "core/mesh.hpp"
#include "core/triangulate.hpp"

namespace oracle {

__extension__ typedef __int128 Wide;

struct Verdict {
    std::string problem;       // empty when the mesh tiles the rectangle exactly
    std::int64_t over_eps = 0; // valid samples with |mesh - height| > eps, decided exactly
    long double max_error = 0; // largest |mesh - height| (long double, for messages)
    std::int64_t samples_checked = 0;
};

inline std::int64_t scaled(double v) {
    const double s = v * 1024.0;
    if (std::floor(s) != s || std::abs(s) >= 1099511627776.0) {
        return INT64_MIN;
    }
    return static_cast<std::int64_t>(s);
}

inline std::int64_t cross(std::int64_t ax,
                          std::int64_t ay,
                          std::int64_t bx,
                          std::int64_t by,
                          std::int64_t cx,
                          std::int64_t cy) {
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
}

inline Verdict judge(const tb::core::Mesh& m, const tb::core::HeightGrid& g, double eps) {
    Verdict v;
    const int w = g.width, h = g.height;
    const std::size_t nt = m.triangles.size() / 3;
    const std::int64_t eps_s = scaled(eps);
    if (eps_s == INT64_MIN) {
        v.problem = "oracle: eps is not a multiple of 1/1024";
        return v;
    }
    // Tiling: positive area, areas sum to the rectangle, every undirected edge used at most
    // once per direction, and an edge used once lies on the rectangle's boundary.
    std::int64_t area = 0;
    std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
    for (std::size_t t = 0; t < nt; ++t) {
        std::int64_t x[3], y[3];
        for (int k = 0; k < 3; ++k) {
            const auto p = m.points.at(m.triangles[3 * t + k]);
            x[k] = p.x;
            y[k] = p.y;
            if (p.x < 0 || p.y < 0 || p.x >= w || p.y >= h) {
                v.problem = "vertex off the grid";
                return v;
            }
            const double zv = m.z.at(m.triangles[3 * t + k]);
            if (zv != static_cast<double>(g.heights[static_cast<std::size_t>(p.y) * w + p.x])) {
                v.problem = "vertex height differs from the grid";
                return v;
            }
        }
        const std::int64_t a = cross(x[0], y[0], x[1], y[1], x[2], y[2]);
        if (a <= 0) {
            v.problem = "triangle " + std::to_string(t) + " is not counter-clockwise";
            return v;
        }
        area += a;
        for (int k = 0; k < 3; ++k) {
            const auto key =
                std::make_pair(m.triangles[3 * t + k], m.triangles[3 * t + (k + 1) % 3]);
            if (++directed[key] > 1) {
                v.problem = "a directed edge is used twice";
                return v;
            }
        }
    }
    if (area != 2 * std::int64_t{w - 1} * (h - 1)) {
        v.problem = "areas do not sum to the rectangle";
        return v;
    }
    for (const auto& [key, count] : directed) {
        if (directed.count({key.second, key.first}) != 0) {
            continue;
        }
        const auto a = m.points[key.first], b = m.points[key.second];
        const bool boundary = (a.x == 0 && b.x == 0) || (a.y == 0 && b.y == 0) ||
                              (a.x == w - 1 && b.x == w - 1) || (a.y == h - 1 && b.y == h - 1);
        if (!boundary) {
            v.problem = "unmatched edge inside the rectangle (T-junction or gap)";
            return v;
        }
    }
    // Point location: each sample's containing triangles; a sample strictly inside one
    // triangle must be covered by no other.
    std::vector<int> hits(static_cast<std::size_t>(w) * h, 0), inside(hits.size(), 0);
    for (std::size_t t = 0; t < nt; ++t) {
        std::int64_t x[3], y[3], z[3];
        for (int k = 0; k < 3; ++k) {
            const auto p = m.points[m.triangles[3 * t + k]];
            x[k] = p.x;
            y[k] = p.y;
            z[k] = scaled(m.z[m.triangles[3 * t + k]]);
            if (z[k] == INT64_MIN) {
                v.problem = "oracle: height is not a multiple of 1/1024";
                return v;
            }
        }
        const std::int64_t d = cross(x[0], y[0], x[1], y[1], x[2], y[2]);
        for (std::int64_t py = *std::min_element(y, y + 3); py <= *std::max_element(y, y + 3);
             ++py) {
            for (std::int64_t px = *std::min_element(x, x + 3); px <= *std::max_element(x, x + 3);
                 ++px) {
                const std::int64_t wa = cross(x[1], y[1], x[2], y[2], px, py);
                const std::int64_t wb = cross(x[2], y[2], x[0], y[0], px, py);
                const std::int64_t wc = cross(x[0], y[0], x[1], y[1], px, py);
                if (wa < 0 || wb < 0 || wc < 0) {
                    continue;
                }
                const std::size_t idx = static_cast<std::size_t>(py) * w + px;
                ++hits[idx];
                if (wa > 0 && wb > 0 && wc > 0) {
                    ++inside[idx];
                }
                if (!g.is_valid(static_cast<int>(px), static_cast<int>(py))) {
                    continue;
                }
                const std::int64_t hs = scaled(g.heights[idx]);
                if (hs == INT64_MIN) {
                    v.problem = "oracle: height is not a multiple of 1/1024";
                    return v;
                }
                const Wide num = Wide{wa} * z[0] + Wide{wb} * z[1] + Wide{wc} * z[2] - Wide{d} * hs;
                const Wide mag = num < 0 ? -num : num;
                ++v.samples_checked;
                if (mag > Wide{d} * eps_s) {
                    ++v.over_eps;
                }
                const long double e = static_cast<long double>(mag) / d / 1024.0L;
                v.max_error = std::max(v.max_error, e);
            }
        }
    }
    for (std::size_t i = 0; i < hits.size(); ++i) {
        if (hits[i] == 0 || (inside[i] > 0 && hits[i] != 1)) {
            v.problem = (hits[i] == 0 ? "sample uncovered at x=" : "sample covered twice at x=") +
                        std::to_string(i % w) + " y=" + std::to_string(i / w);
            return v;
        }
    }
    return v;
}

} // namespace oracle
