#pragma once
// Test terrains. Heights are multiples of 1/1024 below 2^13 in magnitude, so the oracle can
// judge them exactly. Seeds are explicit; the generator is a fixed LCG (portable bits).
#include <cmath>
#include <cstdint>
#include <string>

#include "core/triangulate.hpp"

namespace terrain {

inline float quantize(double v) {
    return static_cast<float>(std::round(v * 1024.0) / 1024.0);
}

struct Lcg {
    std::uint64_t s;
    explicit Lcg(std::uint64_t seed) : s(seed * 2862933555777941757ULL + 3037000493ULL) {}
    double next() { // [0, 1)
        s = s * 6364136223846793005ULL + 1442695040888963407ULL;
        return static_cast<double>(s >> 11) / 9007199254740992.0;
    }
};

template <class F> tb::core::HeightGrid make(int w, int h, F f) {
    tb::core::HeightGrid g;
    g.width = w;
    g.height = h;
    g.heights.reserve(static_cast<std::size_t>(w) * h);
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
            g.heights.push_back(quantize(f(x, y)));
        }
    }
    return g;
}

// Smooth value noise of a few octaves plus white noise of amplitude `grain`.
inline tb::core::HeightGrid noise(int w, int h, std::uint64_t seed, double amp, double grain) {
    Lcg r(seed);
    const int cells = 6;
    std::vector<double> lat((cells + 2) * (cells + 2));
    for (auto& v : lat) {
        v = r.next() * amp;
    }
    return make(w, h, [&](int x, int y) {
        const double fx = static_cast<double>(x) * cells / std::max(w - 1, 1);
        const double fy = static_cast<double>(y) * cells / std::max(h - 1, 1);
        const int ix = std::min(static_cast<int>(fx), cells),
                  iy = std::min(static_cast<int>(fy), cells);
        const double tx = fx - ix, ty = fy - iy;
        auto L = [&](int i, int j) { return lat[static_cast<std::size_t>(j * (cells + 2) + i)]; };
        const double v = (L(ix, iy) * (1 - tx) + L(ix + 1, iy) * tx) * (1 - ty) +
                         (L(ix, iy + 1) * (1 - tx) + L(ix + 1, iy + 1) * tx) * ty;
        return v + (r.next() - 0.5) * grain;
    });
}

inline tb::core::HeightGrid named(const std::string& kind, int w, int h, std::uint64_t seed) {
    const double cx = (w - 1) / 2.0, cy = (h - 1) / 2.0;
    if (kind == "flat") {
        return make(w, h, [](int, int) { return 12.5; });
    }
    if (kind == "plane") {
        return make(w, h, [](int x, int y) { return 3.0 + 0.25 * x - 0.5 * y; });
    }
    if (kind == "saddle") { // the paper's z = x^2 - y^2 on [-1, 1]^2, scaled to +-100
        return make(w, h, [=](int x, int y) {
            const double u = (x - cx) / std::max(cx, 1.0), v = (y - cy) / std::max(cy, 1.0);
            return 100.0 * (u * u - v * v);
        });
    }
    if (kind == "ridge") {
        return make(
            w, h, [=](int x, int y) { return 50.0 - 3.0 * std::abs(x - 0.7 * y - 0.3 * cx); });
    }
    if (kind == "cliff") {
        return make(w, h, [=](int x, int y) { return (x + 0.3 * y > cx ? 80.0 : 0.0) + 0.1 * y; });
    }
    if (kind == "spikes") {
        Lcg r(seed);
        return make(w, h, [&](int, int) { return r.next() < 0.02 ? 40.0 * r.next() : 0.0; });
    }
    return noise(w, h, seed, 60.0, 4.0); // "noise"
}

} // namespace terrain
