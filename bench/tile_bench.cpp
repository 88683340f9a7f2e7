// tile_bench: tiles per second for making every tile of one zoom of a real SRTM cell
// (Layer::mesh_tile_at: read + datum + mesh on two threads, two strips; then encode_tile glb),
// with bytes per tile and per triangle and each stage's share of the time. One tile at a time
// (the tiles are independent; a server runs one per core). Prints TSV; exits 1 if any tile
// publishes more than its zoom's eps (measured layers can; pixel tiles never do).
//
// Input: ../shared/data/N44W072.hgt by default (1201 x 1201 SRTM3, White Mountains: real
// relief from 115 to 1908 m, no voids), or the DEM given as argv[1]; zoom argv[2] (default:
// the layer's max zoom, the most tiles and the finest eps); runs argv[3] (default 3, median).
#include "core/triangulate.hpp"
#include "tiler/formats/encode.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"

#include <algorithm>
#include <chrono>
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
    const auto layer = tiler::Layer::open(options);
    const int z = argc > 2 ? std::atoi(argv[2]) : layer->max_zoom();
    const int runs = argc > 3 ? std::max(1, std::atoi(argv[3])) : 3;
    const tiler::TileRange range = layer->tiles_at(z);
    const double eps = layer->eps_for_zoom(z);
    struct Run {
        double read = 0, mesh = 0, encode = 0, total = 0;
        std::size_t bytes = 0, triangles = 0;
        double worst = 0;
    };
    std::vector<Run> results;
    double mesh_eps = 0;
    for (int k = 0; k < runs; ++k) {
        Run r;
        const auto start = Clock::now();
        for (std::int64_t y = range.y0; y <= range.y1; ++y) {
            for (std::int64_t x = range.x0; x <= range.x1; ++x) {
                auto t = Clock::now();
                const tiler::MeshedTile tile = layer->mesh_tile_at(layer->tile({z, x, y}), eps);
                r.read += seconds_since(t); // read and mesh
                t = Clock::now();
                tiler::EncodeReport report;
                const std::string bytes = tiler::encode_tile(tile.raster,
                                                             tile.mesh,
                                                             tiler::Format::Glb,
                                                             tile.budget,
                                                             tile.source_pixels,
                                                             &report);
                r.encode += seconds_since(t);
                r.bytes += bytes.size();
                r.triangles += tile.mesh.triangle_count();
                r.worst = std::max(r.worst, report.published);
                mesh_eps = tile.budget.mesh_eps;
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
    const double stages = m.read + m.mesh + m.encode;
    std::printf("input\tzoom\ttiles\tguarantee\teps\tmesh_eps\ttiles_per_s\tms_per_tile\t"
                "read_mesh_pct\tencode_pct\tbytes_per_tile\tbytes_per_triangle\t"
                "triangles_per_tile\tpublished_max\n");
    std::printf("%s\t%d\t%.0f\t%s\t%.4g\t%.4g\t%.2f\t%.1f\t%.1f\t%.1f\t%.0f\t%.2f\t%.0f\t%.4g\n",
                input.c_str(),
                z,
                tiles,
                tiler::to_string(layer->guarantee()),
                eps,
                mesh_eps,
                tiles / m.total,
                1000 * m.total / tiles,
                100 * m.read / stages,
                100 * m.encode / stages,
                m.bytes / tiles,
                static_cast<double>(m.bytes) / static_cast<double>(m.triangles),
                static_cast<double>(m.triangles) / tiles,
                m.worst);
    return m.worst > eps ? 1 : 0;
}
