#pragma once
// Brute-force references for the core tests, sharing no code with core/.
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/mesh.hpp"

namespace brute {

// Every valid sample strictly between i and j lies within eps of the segment i-j, in long
// double from the raw heights (`valid` empty: all valid).
inline bool fits(
    const std::vector<float>& z, const std::vector<std::uint8_t>& valid, double eps, int i, int j) {
    for (int k = i + 1; k < j; ++k) {
        if (!valid.empty() && valid[static_cast<std::size_t>(k)] == 0) {
            continue;
        }
        const long double t = static_cast<long double>(k - i) / (j - i);
        const long double line =
            z[static_cast<std::size_t>(i)] * (1 - t) + z[static_cast<std::size_t>(j)] * t;
        if (std::abs(line - z[static_cast<std::size_t>(k)]) > eps) {
            return false;
        }
    }
    return true;
}

// Fewest breakpoints of a 1-D fit within eps, over all subsets containing both ends, with no
// step longer than max_step samples. Exponential: small n only.
inline int optimal_breakpoints(const std::vector<float>& z,
                               const std::vector<std::uint8_t>& valid,
                               double eps,
                               int max_step = INT_MAX) {
    const int n = static_cast<int>(z.size());
    int best = n;
    for (std::uint32_t mask = 0; mask < (1u << (n - 2)); ++mask) {
        std::vector<int> pts{0};
        for (int k = 1; k < n - 1; ++k) {
            if (mask & (1u << (k - 1))) {
                pts.push_back(k);
            }
        }
        pts.push_back(n - 1);
        if (static_cast<int>(pts.size()) >= best) {
            continue;
        }
        bool ok = true;
        for (std::size_t s = 1; s < pts.size() && ok; ++s) {
            ok = pts[s] - pts[s - 1] <= max_step && fits(z, valid, eps, pts[s - 1], pts[s]);
        }
        if (ok) {
            best = static_cast<int>(pts.size());
        }
    }
    return best;
}

// The w x h window of g whose top-left sample is (x0, y0).
inline tb::core::HeightGrid window(const tb::core::HeightGrid& g, int x0, int y0, int w, int h) {
    tb::core::HeightGrid out;
    out.width = w;
    out.height = h;
    for (int y = y0; y < y0 + h; ++y) {
        for (int x = x0; x < x0 + w; ++x) {
            out.heights.push_back(g.at(x, y));
        }
    }
    return out;
}

// Sorted positions of the mesh's vertices on column x (their rows) or on row y (their columns).
inline std::vector<int> on_column(const tb::core::Mesh& m, int x) {
    std::vector<int> out;
    for (const auto& p : m.points) {
        if (p.x == x) {
            out.push_back(p.y);
        }
    }
    std::sort(out.begin(), out.end());
    return out;
}
inline std::vector<int> on_row(const tb::core::Mesh& m, int y) {
    std::vector<int> out;
    for (const auto& p : m.points) {
        if (p.y == y) {
            out.push_back(p.x);
        }
    }
    std::sort(out.begin(), out.end());
    return out;
}

} // namespace brute
