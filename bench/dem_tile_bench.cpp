// dem_tile_bench: raster DEM tiles per second for every DEM tile of one zoom of a real SRTM
// cell (pixel-centre samples -> heights, then PNG in each encoding), with bytes per tile and
// the sampling's share of the time. One tile at a time (a server runs one per core).
// Prints TSV; exits 1 if any pixel's code decodes further than half a step from its height.
//
// Input: ../shared/data/N44W072.hgt by default (1201 x 1201 SRTM3, White Mountains: real
// relief from 115 to 1908 m), or the DEM given as argv[1]; zoom argv[2] (default: the DEM
// pyramid's max zoom, the most tiles); tile size argv[3] (default 512); runs argv[4]
// (default 3, median).
#include "tiler/dem_tiles.hpp"
#include "tiler/formats/dem_png.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

using namespace tb;
using Clock = std::chrono::steady_clock;

namespace {
double seconds_since(Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
}
} // namespace

int main(int argc, char** argv) {
    // Run from the repository root: ../shared/data is the shared DEM corpus.
    const std::string input = argc > 1 ? argv[1] : "../shared/data/N44W072.hgt";
    tb::log::set_level(tb::log::Level::Warn);
    tiler::LayerOptions options;
    options.sources = {input};
    options.dem_tile_size = argc > 3 ? std::atoi(argv[3]) : 512;
    const auto layer = tiler::Layer::open(options);
    const tiler::DemTilePlan plan = tiler::dem_tile_plan(*layer);
    const int z = argc > 2 ? std::atoi(argv[2]) : plan.max_zoom;
    const int runs = argc > 4 ? std::max(1, std::atoi(argv[4])) : 3;
    const tiler::TileRange range = tiler::dem_tiles_at(*layer, z);
    const tiler::Format formats[] = {tiler::Format::Terrarium, tiler::Format::Mapbox};

    struct Run {
        double sample = 0, encode[2] = {0, 0}, total = 0;
        std::size_t bytes[2] = {0, 0};
        double worst[2] = {0, 0}; // largest |decoded - height| / step
    };
    std::vector<Run> results;
    for (int k = 0; k < runs; ++k) {
        Run r;
        const auto start = Clock::now();
        for (std::int64_t y = range.y0; y <= range.y1; ++y) {
            for (std::int64_t x = range.x0; x <= range.x1; ++x) {
                auto t = Clock::now();
                const std::vector<double> heights = tiler::dem_tile_heights(
                    *layer, tiler::ValidTile::parse(tiler::Scheme::Mercator, {z, x, y}));
                r.sample += seconds_since(t);
                for (int f = 0; f < 2; ++f) {
                    t = Clock::now();
                    const std::string png =
                        tiler::encode_dem_png(heights, plan.tile_size, plan.tile_size, formats[f]);
                    r.encode[f] += seconds_since(t);
                    r.bytes[f] += png.size();
                    for (double h : heights) {
                        const double back =
                            tiler::decode_height(tiler::encode_height(h, formats[f]), formats[f]);
                        r.worst[f] = std::max(r.worst[f],
                                              std::abs(back - h) / tiler::height_step(formats[f]));
                    }
                }
            }
        }
        r.total = seconds_since(start);
        results.push_back(r);
    }
    std::sort(results.begin(), results.end(), [](const Run& a, const Run& b) {
        return a.total < b.total;
    });
    const Run& m = results[results.size() / 2];
    const double tiles = static_cast<double>(range.count());
    std::printf("input\tzoom\ttiles\tsize\tsample_ms_per_tile\tterrarium_ms_per_tile\t"
                "mapbox_ms_per_tile\tterrarium_bytes_per_tile\tmapbox_bytes_per_tile\t"
                "worst_error_in_steps\n");
    std::printf("%s\t%d\t%.0f\t%d\t%.1f\t%.1f\t%.1f\t%.0f\t%.0f\t%.3f\n",
                input.c_str(),
                z,
                tiles,
                plan.tile_size,
                1000 * m.sample / tiles,
                1000 * m.encode[0] / tiles,
                1000 * m.encode[1] / tiles,
                static_cast<double>(m.bytes[0]) / tiles,
                static_cast<double>(m.bytes[1]) / tiles,
                std::max(m.worst[0], m.worst[1]));
    return std::max(m.worst[0], m.worst[1]) > 0.5 + 1e-9 ? 1 : 0;
}
