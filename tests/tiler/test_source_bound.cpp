// The promise against the user's own DEM: for every tile at the finest and the coarsest zoom,
// every valid source pixel centre under the tile lies within the tile's published error
// (its tileset geometricError) of the surface a client draws, judged by tests/tiler/
// source_oracle.hpp, which reads the DEM with GDAL and decodes the tile with Draco itself.
// Coarse tiles are judged against the full-resolution pixels, as 3D Tiles' geometricError means.
#include "tests/tiler/source_oracle.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/layer.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <map>
#include <random>
#include <string>

using namespace tb::tiler;

namespace {

struct Published {
    double error = 0;
    std::array<double, 6> region{}; // west, south, east, north (radians), min_h, max_h
};

// Every content tile of the layer's tileset (the root document and its external tilesets), by
// its content URI.
void collect(const Layer& layer, const std::string& path, std::map<std::string, Published>& out) {
    std::string text;
    REQUIRE(layer.document(path, text));
    const nlohmann::json doc = nlohmann::json::parse(text);
    const std::string dir = path.substr(0, path.rfind('/') + 1);
    std::vector<const nlohmann::json*> stack{&doc["root"]};
    while (!stack.empty()) {
        const nlohmann::json& tile = *stack.back();
        stack.pop_back();
        if (tile.contains("content")) {
            const std::string uri = tile["content"]["uri"];
            if (uri.ends_with(".json")) {
                collect(layer, dir + uri, out);
            } else {
                Published p;
                p.error = tile["geometricError"];
                for (int k = 0; k < 6; ++k) {
                    p.region[static_cast<std::size_t>(k)] = tile["boundingVolume"]["region"][k];
                }
                out[dir + uri] = p;
            }
        }
        if (tile.contains("children")) {
            for (const auto& child : tile["children"]) {
                stack.push_back(&child);
            }
        }
    }
}

struct Summary {
    double worst_ratio = 0; // max over tiles of (worst error / published error)
    double worst = 0;
    std::int64_t pixels = 0, undrawn = 0, tiles = 0;
};

// Judges every tile of zoom z.
Summary judge_zoom(const Layer& layer,
                   const std::vector<tb_oracle::Pixel>& pixels,
                   const std::map<std::string, Published>& published,
                   int z) {
    Summary s;
    const TileRange r = layer.tiles_at(z);
    std::vector<std::uint8_t> drawn(pixels.size(), 0);
    // How far the quantization snap may move a vertex (s * sqrt(3) / 2), with room to spare.
    const double reach = 2 * error_budget(layer.eps_for_zoom(z)).quant_step;
    for (std::int64_t y = r.y0; y <= r.y1; ++y) {
        for (std::int64_t x = r.x0; x <= r.x1; ++x) {
            const TileId id{z, x, y};
            const std::string uri =
                std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y) + ".glb";
            CAPTURE(uri);
            const auto it = published.find(uri);
            REQUIRE(it != published.end());
            const tb_oracle::Drawn d =
                tb_oracle::decode_glb(layer.make_tile(layer.tile(id), Format::Glb));
            const LonLatBox b = tile_bounds(layer.options().scheme, id);
            const tb_oracle::Verdict v =
                tb_oracle::judge(d, pixels, b.west, b.south, b.east, b.north, drawn, reach);
            CHECK(v.worst <= it->second.error);
            // The bounding volume holds every decoded vertex.
            const auto& reg = it->second.region;
            for (const auto& e : d.ecef) {
                const tb_oracle::V3 g = tb_oracle::geodetic(e);
                const double lon = g[0] * tb_oracle::kPi / 180, lat = g[1] * tb_oracle::kPi / 180;
                CHECK(lon >= reg[0] - 1e-12);
                CHECK(lat >= reg[1] - 1e-12);
                CHECK(lon <= reg[2] + 1e-12);
                CHECK(lat <= reg[3] + 1e-12);
                CHECK(g[2] >= reg[4] - 1e-3);
                CHECK(g[2] <= reg[5] + 1e-3);
            }
            s.worst = std::max(s.worst, v.worst);
            s.worst_ratio = std::max(s.worst_ratio, v.worst / it->second.error);
            ++s.tiles;
        }
    }
    // Every pixel under the zoom's tiles is drawn by one of them.
    const LonLatBox first = tile_bounds(layer.options().scheme, {z, r.x0, r.y1});
    const LonLatBox last = tile_bounds(layer.options().scheme, {z, r.x1, r.y0});
    const double west = std::min(first.west, last.west), east = std::max(first.east, last.east);
    const double south = std::min(first.south, last.south);
    const double north = std::max(first.north, last.north);
    for (std::size_t k = 0; k < pixels.size(); ++k) {
        const tb_oracle::Pixel& p = pixels[k];
        if (p.lon >= west && p.lon <= east && p.lat >= south && p.lat <= north) {
            s.pixels += drawn[k];
            s.undrawn += drawn[k] ? 0 : 1;
            if (!drawn[k] && s.undrawn <= 3) {
                MESSAGE("undrawn pixel at lon " << p.lon << " lat " << p.lat);
            }
        }
    }
    return s;
}

// Judges the finest and the coarsest zoom of a layer on `path` (every zoom with `every_zoom`).
void judge_layer(const std::string& path,
                 Guarantee expected,
                 LayerOptions options = {},
                 bool every_zoom = false) {
    options.sources = {path};
    const auto layer = Layer::open(options);
    CHECK(layer->guarantee() == expected);
    static const tb_oracle::Geoid geoid;
    const std::vector<tb_oracle::Pixel> pixels = tb_oracle::read_pixels(path, geoid);
    std::map<std::string, Published> published;
    collect(*layer, "tileset.json", published);
    std::vector<int> zooms{layer->max_zoom(), layer->min_zoom()};
    if (every_zoom) {
        zooms.clear();
        for (int z = layer->min_zoom(); z <= layer->max_zoom(); ++z) {
            zooms.push_back(z);
        }
    }
    for (int z : zooms) {
        CAPTURE(z);
        const Summary s = judge_zoom(*layer, pixels, published, z);
        MESSAGE(path << " zoom " << z << " (" << std::string(to_string(layer->zoom_source(z)))
                     << "): " << s.tiles << " tiles, " << s.pixels
                     << " source pixels judged, worst " << s.worst << " m, worst / published "
                     << s.worst_ratio << ", " << s.undrawn << " pixels undrawn");
        CHECK(s.pixels > 0);
        CHECK(s.worst_ratio <= 1.0);
        if (layer->zoom_source(z) == ZoomSource::Pixels) {
            CHECK(s.undrawn == 0); // every valid pixel lies under the drawn surface
        }
    }
}

} // namespace

TEST_CASE("spiky geographic DEM: every source pixel is within the published error at every zoom") {
    // Spikes one pixel wide between flat neighbours: what a resampled lattice averages away.
    tb_test::ScratchDir dir;
    tb_test::Fixture f;
    f.width = 481, f.height = 361;
    f.values.resize(static_cast<std::size_t>(f.width) * f.height);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> noise(0, 12);
    for (int j = 0; j < f.height; ++j) {
        for (int i = 0; i < f.width; ++i) {
            double h = 300 + 200 * std::sin(i / 37.0) * std::cos(j / 23.0) + noise(rng);
            if ((i * 7 + j * 13) % 97 == 0) {
                h += 48; // a lone spike
            }
            if (std::hypot(i - 300, j - 200) < 25) {
                h = -32768; // a void
            }
            f.values[static_cast<std::size_t>(j) * f.width + i] = h;
        }
    }
    f.type = GDT_Int16;
    f.nodata = -32768;
    f.geotransform = std::array<double, 6>{7.6, 1.0 / 1200, 0, 46.4, 0, -1.0 / 1200};
    f.epsg = 4326;
    const std::string path = tb_test::write_fixture(dir.file("spiky.tif"), f);
    judge_layer(path, Guarantee::SourcePixels);
    LayerOptions mercator;
    mercator.scheme = Scheme::Mercator;
    judge_layer(path, Guarantee::SourcePixels, mercator);
}

TEST_CASE("a DEM in EPSG:3857 meshed in the mercator scheme on its own pixels keeps every pixel "
          "within the published error") {
    tb_test::ScratchDir dir;
    tb_test::Fixture f;
    f.width = 300, f.height = 240;
    f.values.resize(static_cast<std::size_t>(f.width) * f.height);
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> noise(0, 8);
    for (int j = 0; j < f.height; ++j) {
        for (int i = 0; i < f.width; ++i) {
            f.values[static_cast<std::size_t>(j) * f.width + i] =
                900 + 400 * std::sin(i / 19.0 + j / 31.0) + noise(rng) +
                ((i * 5 + j * 11) % 53 == 0 ? 60 : 0);
        }
    }
    // 76.4 m pixels (EPSG:3857 metres) near 46 N, 8 E.
    f.geotransform = std::array<double, 6>{890555.9, 76.437, 0, 5780000.0, 0, -76.437};
    f.epsg = 3857;
    const std::string path = tb_test::write_fixture(dir.file("mercator.tif"), f);
    LayerOptions mercator;
    mercator.scheme = Scheme::Mercator;
    judge_layer(path, Guarantee::SourcePixels, mercator);
    // The geodetic scheme resamples it: measured.
    judge_layer(path, Guarantee::Measured);
}

TEST_CASE("real DEMs: every source pixel is within the published error at the finest and the "
          "coarsest zoom") {
    if (const auto p = tb_test::shared_dem("N44W072.hgt")) {
        judge_layer(*p, Guarantee::SourcePixels);
    }
    if (const auto p = tb_test::shared_dem("N46E008.tif")) { // steep, 7 % voids
        judge_layer(*p, Guarantee::SourcePixels);
    }
    if (const auto p = tb_test::shared_dem("qgis_dem1.tif")) { // NAD83 lon/lat, 10" pixels
        judge_layer(*p, Guarantee::SourcePixels);
    }
    if (const auto p = tb_test::shared_dem("elev_vinschgau.tif")) { // UTM 32N
        judge_layer(*p, Guarantee::Measured);
    }
}

TEST_CASE("a 4.3 Mpixel DEM: coarse tiles read from its summary keep every source pixel within "
          "the published error at every zoom") {
    // Smooth hills, steep planes, one-pixel spikes, noise and a void: what the summary's planes
    // must follow and its ranges must hold.
    tb_test::ScratchDir dir;
    tb_test::Fixture f;
    f.width = 2401, f.height = 1801;
    f.values.resize(static_cast<std::size_t>(f.width) * f.height);
    std::mt19937 rng(17);
    std::uniform_real_distribution<double> noise(0, 6);
    for (int j = 0; j < f.height; ++j) {
        for (int i = 0; i < f.width; ++i) {
            double h = 1200 + 700 * std::sin(i / 143.0) * std::cos(j / 97.0) + 0.8 * i +
                       40 * std::sin(i / 7.0 + j / 11.0) + noise(rng);
            if ((i * 7 + j * 13) % 211 == 0) {
                h += 90;
            }
            if (std::hypot(i - 1700, j - 600) < 60) {
                h = -32768;
            }
            f.values[static_cast<std::size_t>(j) * f.width + i] = h;
        }
    }
    f.type = GDT_Int16;
    f.nodata = -32768;
    f.geotransform = std::array<double, 6>{7.0, 1.0 / 1200, 0, 47.0, 0, -1.0 / 1200};
    f.epsg = 4326;
    const std::string path = tb_test::write_fixture(dir.file("large.tif"), f);
    LayerOptions options;
    options.sources = {path};
    const auto layer = Layer::open(options);
    CHECK(layer->zoom_source(layer->max_zoom()) == ZoomSource::Pixels);
    CHECK(layer->zoom_source(layer->min_zoom()) == ZoomSource::Summary);
    judge_layer(path, Guarantee::SourcePixels, {}, true);
}
