#pragma once
// Judging a decoded quantized-mesh tile against source pixels: the oracle's pixels
// (source_oracle.hpp) on the surface the quantized-mesh reader (qm_reader.hpp) decodes.
#include "qm_reader.hpp"
#include "source_oracle.hpp"
#include "tiler/tile_grid.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace tb_qm {

inline std::string metadata_of(const Tile& t) {
    const tb_qm::Extension* e = t.extension(4);
    REQUIRE(e != nullptr);
    return e->data.substr(4);
}

inline double published_error(const Tile& t) {
    const std::string json = metadata_of(t);
    const std::size_t at = json.find("\"geometricError\":");
    REQUIRE(at != std::string::npos);
    return std::stod(json.substr(at + 17));
}

// The surface a client interpolates (linear in u/v over each triangle) at every pixel under
// the tile: the largest |drawn - pixel| and how many pixels were judged.
inline std::pair<double, std::size_t> worst_pixel(const Tile& t,
                                                  const tb::tiler::LonLatBox& b,
                                                  const std::vector<tb_oracle::Pixel>& pixels) {
    constexpr int kCells = 32;
    std::vector<std::vector<std::uint32_t>> cells(kCells * kCells);
    const auto cell = [](double w) {
        return std::clamp(static_cast<int>(w / 32768.0 * kCells), 0, kCells - 1);
    };
    for (std::uint32_t tri = 0; tri * 3 < t.triangles.size(); ++tri) {
        int u0 = 99999, u1 = -1, v0 = 99999, v1 = -1;
        for (int k = 0; k < 3; ++k) {
            const std::uint32_t i = t.triangles[tri * 3 + static_cast<std::uint32_t>(k)];
            u0 = std::min<int>(u0, t.u[i]), u1 = std::max<int>(u1, t.u[i]);
            v0 = std::min<int>(v0, t.v[i]), v1 = std::max<int>(v1, t.v[i]);
        }
        for (int cy = cell(v0); cy <= cell(v1); ++cy) {
            for (int cx = cell(u0); cx <= cell(u1); ++cx) {
                cells[static_cast<std::size_t>(cy * kCells + cx)].push_back(tri);
            }
        }
    }
    double worst = 0;
    std::size_t judged = 0;
    for (const auto& p : pixels) {
        if (p.lon < b.west || p.lon > b.east || p.lat < b.south || p.lat > b.north) {
            continue;
        }
        const double pu = (p.lon - b.west) / (b.east - b.west) * 32767;
        const double pv = (p.lat - b.south) / (b.north - b.south) * 32767;
        bool found = false;
        for (std::uint32_t tri : cells[static_cast<std::size_t>(cell(pv) * kCells + cell(pu))]) {
            const std::uint32_t a = t.triangles[tri * 3], c1 = t.triangles[tri * 3 + 1],
                                c2 = t.triangles[tri * 3 + 2];
            const double ax = t.u[a], ay = t.v[a], bx = t.u[c1], by = t.v[c1], cx = t.u[c2],
                         cy = t.v[c2];
            const double det = (by - cy) * (ax - cx) + (cx - bx) * (ay - cy);
            if (det == 0) {
                continue;
            }
            const double l1 = ((by - cy) * (pu - cx) + (cx - bx) * (pv - cy)) / det;
            const double l2 = ((cy - ay) * (pu - cx) + (ax - cx) * (pv - cy)) / det;
            const double l3 = 1 - l1 - l2;
            if (l1 < -1e-9 || l2 < -1e-9 || l3 < -1e-9) {
                continue;
            }
            const double h = l1 * t.height(a) + l2 * t.height(c1) + l3 * t.height(c2);
            worst = std::max(worst, std::abs(h - p.h));
            found = true;
            break;
        }
        CHECK_MESSAGE(found, "pixel " << p.lon << " " << p.lat << " lies in no triangle");
        ++judged;
    }
    return {worst, judged};
}

} // namespace tb_qm
