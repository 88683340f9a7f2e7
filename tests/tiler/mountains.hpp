#pragma once
// The real mountain DEMs of ../shared/data as the terrain tests use them: the layer, and every
// valid pixel as the source oracle reads it (GDAL plus PROJ's EGM96), made once per process;
// and the meaning of a horizon occlusion point, checked against the vertices it must hide.
#include "source_oracle.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace tb_mountains {

// White Mountains (steep, no voids); "../shared/data/N46E008.tif" is the Swiss Alps (steeper,
// 7 % voids in the steepest parts).
inline const char* const kMountains = "../shared/data/N44W072.hgt";

struct Mountains {
    std::shared_ptr<const tb::tiler::Layer> layer;
    std::vector<tb_oracle::Pixel> pixels;
};

// The layer and the GDAL reading of a DEM of ../shared/data, made once; nullptr when absent.
inline const Mountains* mountains(const char* path = kMountains) {
    static std::map<std::string, std::unique_ptr<const Mountains>> made;
    auto& m = made[path];
    if (!m && std::filesystem::exists(path)) {
        tb::log::set_level(tb::log::Level::Warn);
        auto out = std::make_unique<Mountains>();
        tb::tiler::LayerOptions o;
        o.name = "mountains";
        o.sources = {path};
        out->layer = tb::tiler::Layer::open(o);
        out->pixels = tb_oracle::read_pixels(path, tb_oracle::Geoid{});
        m = std::move(out);
    }
    return m.get();
}

// Calls f(name, m) for White Mountains, then the Swiss Alps (N46E008.tif: steeper, 7 % voids in
// the steepest parts), each that is present; an absent one is skipped with a message.
template <typename F> void for_each_mountain(F f) {
    for (const char* path : {kMountains, "../shared/data/N46E008.tif"}) {
        const std::string name = path;
        CAPTURE(name);
        const Mountains* m = mountains(path);
        if (!m) {
            MESSAGE("skipped: " << std::string(path) << " is absent");
            continue;
        }
        f(name, *m);
    }
}

// Checks a horizon occlusion point p by its meaning, in the WGS84 scaled space (the ellipsoid is
// the unit sphere there): a camera sees p only from within the cone of tangents to the sphere
// through p, whose contact circle lies at angle acos(1/|p|) from p's direction. A vertex s, at
// angle a from that direction and with its own horizon at angle acos(1/|s|) around it, is then
// hidden whenever p is if a + acos(1/|s|) <= acos(1/|p|). Returns the smallest slack (0 for
// the smallest such p, which meets the bound at some vertex).
inline double check_horizon(const std::array<double, 3>& p,
                            const std::vector<tb_oracle::V3>& ecef) {
    const double ra = tb_oracle::kA, rb = tb_oracle::kA * (1 - tb_oracle::kF);
    const double pm = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    REQUIRE(pm > 1);
    double tightest = 1e9;
    for (const auto& e : ecef) {
        const std::array<double, 3> s{e[0] / ra, e[1] / ra, e[2] / rb};
        const double len = std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
        const double cosang =
            std::clamp((s[0] * p[0] + s[1] * p[1] + s[2] * p[2]) / (len * pm), -1.0, 1.0);
        const double slack =
            std::acos(1 / pm) - std::acos(1 / std::max(1.0, len)) - std::acos(cosang);
        CHECK(slack >= -1e-9);
        tightest = std::min(tightest, slack);
    }
    return tightest;
}

} // namespace tb_mountains
