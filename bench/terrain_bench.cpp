// terrain_bench: quantized-mesh terrain tiles against glb tiles of the same zoom of a real SRTM
// cell, made one at a time (Layer::make_tile: read, mesh on two threads, encode), in the same
// run: ms per tile, bytes per tile (and gzip-compressed, as the server sends .terrain tiles),
// and how many terrain tiles had to be meshed again to keep the 15-bit quantization inside eps.
// Prints TSV; exits 1 if any terrain tile publishes more than its zoom's eps.
//
// Input: ../shared/data/N44W072.hgt by default (1201 x 1201 SRTM3, White Mountains: steep
// relief, where quantization matters most), or the DEM given as argv[1]; zoom argv[2] (default:
// the layer's max zoom); runs argv[3] (default 3, median).
#include "core/error.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"

#include <zlib.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

using namespace tb;
using Clock = std::chrono::steady_clock;

namespace {

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

std::size_t gzip_size(const std::string& bytes) {
    z_stream s{};
    deflateInit2(&s, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY);
    std::string out(deflateBound(&s, bytes.size()) + 32, '\0');
    s.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(bytes.data()));
    s.avail_in = static_cast<uInt>(bytes.size());
    s.next_out = reinterpret_cast<Bytef*>(out.data());
    s.avail_out = static_cast<uInt>(out.size());
    deflate(&s, Z_FINISH);
    const std::size_t n = s.total_out;
    deflateEnd(&s);
    return n;
}

double published(const std::string& tile) {
    const std::size_t at = tile.rfind("\"geometricError\":");
    return at == std::string::npos ? 0 : std::atof(tile.c_str() + at + 17);
}

} // namespace

int main(int argc, char** argv) {
    const std::string input = argc > 1 ? argv[1] : "../shared/data/N44W072.hgt";
    tb::log::set_level(tb::log::Level::Warn);
    tiler::LayerOptions options;
    options.sources = {input};
    const auto layer = tiler::Layer::open(options);
    const int z = argc > 2 ? std::atoi(argv[2]) : layer->max_zoom();
    const int runs = argc > 3 ? std::max(1, std::atoi(argv[3])) : 3;
    const tiler::TileRange range = layer->tiles_at(z);
    if (range.empty()) {
        std::fprintf(stderr,
                     "terrain_bench: %s has no tile at zoom %d (zooms %d..%d)\n",
                     input.c_str(),
                     z,
                     layer->min_zoom(),
                     layer->max_zoom());
        return 2;
    }
    std::vector<double> terrain_s, glb_s;
    double terrain_bytes = 0, gzip_bytes = 0, glb_bytes = 0, worst = 0;
    bool over = false;
    for (int run = 0; run < runs; ++run) {
        double t_sum = 0, g_sum = 0;
        terrain_bytes = gzip_bytes = glb_bytes = 0;
        for (std::int64_t y = range.y0; y <= range.y1; ++y) {
            for (std::int64_t x = range.x0; x <= range.x1; ++x) {
                const tiler::TileId id{z, x, y};
                auto t0 = Clock::now();
                const std::string terrain =
                    layer->make_tile(layer->tile(id), tiler::Format::Terrain);
                t_sum += std::chrono::duration<double>(Clock::now() - t0).count();
                t0 = Clock::now();
                std::string glb;
                try {
                    glb = layer->make_tile(layer->tile(id), tiler::Format::Glb);
                } catch (const NotFound&) {
                }
                g_sum += std::chrono::duration<double>(Clock::now() - t0).count();
                terrain_bytes += static_cast<double>(terrain.size());
                gzip_bytes += static_cast<double>(gzip_size(terrain));
                glb_bytes += static_cast<double>(glb.size());
                const double e = published(terrain);
                worst = std::max(worst, e / layer->eps_for_zoom(z));
                over = over || e > layer->eps_for_zoom(z) * (1 + 1e-9);
            }
        }
        terrain_s.push_back(t_sum);
        glb_s.push_back(g_sum);
    }
    const double n = static_cast<double>(range.count());
    std::printf("input\tzoom\ttiles\teps_m\tterrain_ms\tglb_ms\tratio\tterrain_bytes\t"
                "terrain_gzip_bytes\tglb_bytes\tpublished_over_eps\n");
    std::printf("%s\t%d\t%lld\t%.4g\t%.1f\t%.1f\t%.2f\t%.0f\t%.0f\t%.0f\t%.3f\n",
                input.c_str(),
                z,
                static_cast<long long>(range.count()),
                layer->eps_for_zoom(z),
                median(terrain_s) / n * 1e3,
                median(glb_s) / n * 1e3,
                median(terrain_s) / median(glb_s),
                terrain_bytes / n,
                gzip_bytes / n,
                glb_bytes / n,
                worst);
    return over ? 1 : 0;
}
