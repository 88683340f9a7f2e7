// The promise against the user's own DEM: for every tile at the finest and the coarsest zoom,
// every valid source pixel centre under the tile lies within the tile's published error
// (its tileset geometricError) of the surface a client draws, judged by tests/tiler/
// source_oracle.hpp, which reads the DEM with GDAL and decodes the tile with Draco itself.
// Coarse tiles are judged against the full-resolution pixels, as 3D Tiles' geometricError means.
#include "tests/tiler/qm_judge.hpp"
#include "tests/tiler/source_oracle.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/layer.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <random>
#include <set>
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
            // Nested tilesets reach their tiles up the tree ("../../../9/x/y.glb").
            const std::string at =
                std::filesystem::path(dir + uri).lexically_normal().generic_string();
            if (uri.ends_with(".json")) {
                collect(layer, at, out);
            } else {
                Published p;
                p.error = tile["geometricError"];
                for (int k = 0; k < 6; ++k) {
                    p.region[static_cast<std::size_t>(k)] = tile["boundingVolume"]["region"][k];
                }
                out[at] = p;
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

// Judges the finest and the coarsest zoom of a layer (every zoom with `every_zoom`) against
// `pixels`, the truth every tile must hold.
void judge_pixels(const LayerOptions& options,
                  const std::vector<tb_oracle::Pixel>& pixels,
                  Guarantee expected,
                  bool every_zoom) {
    const auto layer = Layer::open(options);
    CHECK(layer->guarantee() == expected);
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
        MESSAGE(options.sources.front()
                << " zoom " << z << " (" << std::string(to_string(layer->zoom_source(z)))
                << "): " << s.tiles << " tiles, " << s.pixels << " source pixels judged, worst "
                << s.worst << " m, worst / published " << s.worst_ratio << ", " << s.undrawn
                << " pixels undrawn");
        CHECK(s.pixels > 0);
        CHECK(s.worst_ratio <= 1.0);
        if (layer->zoom_source(z) == ZoomSource::Pixels) {
            CHECK(s.undrawn == 0); // every valid pixel lies under the drawn surface
        }
    }
}

// Judges the finest and the coarsest zoom of a layer on `path` (every zoom with `every_zoom`).
void judge_layer(const std::string& path,
                 Guarantee expected,
                 LayerOptions options = {},
                 bool every_zoom = false) {
    options.sources = {path};
    static const tb_oracle::Geoid geoid;
    judge_pixels(options, tb_oracle::read_pixels(path, geoid), expected, every_zoom);
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

namespace {

// Heights of a rough test DEM at pixel (i, j): hills, a steep plane, one-pixel spikes, noise and
// a round void (nodata), as the 4.3 Mpixel case has them.
double rough_height(int i, int j, std::mt19937& rng) {
    std::uniform_real_distribution<double> noise(0, 6);
    double h = 1200 + 700 * std::sin(i / 143.0) * std::cos(j / 97.0) + 0.8 * i +
               40 * std::sin(i / 7.0 + j / 11.0) + noise(rng);
    if ((i * 7 + j * 13) % 211 == 0) {
        h += 90;
    }
    return std::hypot(i - 1100, j - 500) < 60 ? -32768 : h;
}

// Judges a projected DEM's layer at zooms 7..10 (its own coarsest is 10: the DEM spans 16 km;
// finer zooms read pixels as before) and its globe terrain at every zoom from 0 to 10: every source
// pixel within the published error, zooms 7..9 read from the summary, and no filler where there is
// data.
void judge_projected(const std::string& path) {
    LayerOptions options;
    options.sources = {path};
    options.min_zoom = 7;
    const auto layer = Layer::open(options);
    CHECK(layer->guarantee() == Guarantee::Measured);
    static const tb_oracle::Geoid geoid;
    const auto pixels = tb_oracle::read_pixels(path, geoid);
    std::map<std::string, Published> published;
    collect(*layer, "tileset.json", published);
    for (int z = 7; z <= 10; ++z) {
        CAPTURE(z);
        CHECK(layer->zoom_source(z) == (z < 10 ? ZoomSource::Summary : ZoomSource::Lattice));
        const Summary s = judge_zoom(*layer, pixels, published, z);
        MESSAGE(path << " zoom " << z << ": " << s.pixels << " pixels, worst " << s.worst
                     << " m, worst / published " << s.worst_ratio);
        CHECK(s.pixels > 0);
        CHECK(s.worst_ratio <= 1.0);
    }
    const LonLatBox box = DemSource::open({path})->footprint();
    options.min_zoom.reset();
    const auto natural = Layer::open(options);
    for (int z = 0; z <= natural->min_zoom(); ++z) {
        CAPTURE(z);
        const TileRange r = tiles_covering(Scheme::Geodetic, box, z);
        std::size_t judged = 0;
        for (std::int64_t y = r.y0; y <= r.y1; ++y) {
            for (std::int64_t x = r.x0; x <= r.x1; ++x) {
                const TileId id{z, x, y};
                const tb_qm::Tile t =
                    tb_qm::read(natural->make_tile(natural->tile(id), Format::Terrain));
                CHECK(tb_qm::metadata_of(t).find("\"filler\":true") == std::string::npos);
                const auto [worst, count] =
                    tb_qm::worst_pixel(t, tile_bounds(Scheme::Geodetic, id), pixels);
                judged += count;
                CHECK(worst <= tb_qm::published_error(t) + 1e-3);
            }
        }
        CHECK(judged == pixels.size());
    }
}

} // namespace

TEST_CASE("a 1.9 Mpixel UTM DEM, and one on a turned grid: coarse tiles read from the summary "
          "through the CRS keep every source pixel within the published error at every zoom, "
          "and globe terrain draws the data from zoom 0") {
    tb_test::ScratchDir dir;
    tb_test::Fixture f;
    f.width = 1601, f.height = 1201;
    f.type = GDT_Int16;
    f.nodata = -32768;
    std::mt19937 rng(23);
    for (int j = 0; j < f.height; ++j) {
        for (int i = 0; i < f.width; ++i) {
            f.values.push_back(rough_height(i, j, rng));
        }
    }
    // 10 m pixels in UTM 32N near 7.0 E 47.0 N.
    f.epsg = 32632;
    f.geotransform = std::array<double, 6>{340000, 10, 0, 5215000, 0, -10};
    judge_projected(tb_test::write_fixture(dir.file("utm.tif"), f));
    // The same grid turned by 20 degrees.
    const double c = 10 * std::cos(0.35), s = 10 * std::sin(0.35);
    f.geotransform = std::array<double, 6>{340000, c, s, 5215000, s, -c};
    judge_projected(tb_test::write_fixture(dir.file("turned.tif"), f));
}

namespace {

// The truth of a collection ranked `first` over `second`: every valid pixel of `first`, and
// each valid pixel of `second` whose centre lies in no valid pixel of `first` (read with GDAL,
// located with OGR).
std::vector<tb_oracle::Pixel>
ranked_pixels(const std::string& first, const std::string& second, const tb_oracle::Geoid& geoid) {
    std::vector<tb_oracle::Pixel> out = tb_oracle::read_pixels(first, geoid);
    GDALDatasetUniquePtr ds(GDALDataset::Open(first.c_str(), GDAL_OF_RASTER));
    REQUIRE(ds != nullptr);
    const int w = ds->GetRasterXSize(), h = ds->GetRasterYSize();
    double gt[6], inv[6];
    REQUIRE(ds->GetGeoTransform(gt) == CE_None);
    REQUIRE(GDALInvGeoTransform(gt, inv));
    GDALRasterBand* band = ds->GetRasterBand(1);
    int has_nodata = 0;
    const double nodata = band->GetNoDataValue(&has_nodata);
    std::vector<double> raw(static_cast<std::size_t>(w) * h);
    REQUIRE(band->RasterIO(GF_Read, 0, 0, w, h, raw.data(), w, h, GDT_Float64, 0, 0, nullptr) ==
            CE_None);
    OGRSpatialReference wgs84, src = *ds->GetSpatialRef();
    wgs84.importFromEPSG(4326);
    wgs84.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    src.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    std::unique_ptr<OGRCoordinateTransformation> ct(
        OGRCreateCoordinateTransformation(&wgs84, &src));
    REQUIRE(ct != nullptr);
    for (const tb_oracle::Pixel& p : tb_oracle::read_pixels(second, geoid)) {
        double x = p.lon, y = p.lat;
        REQUIRE(ct->Transform(1, &x, &y));
        const double u = std::floor(inv[0] + x * inv[1] + y * inv[2]);
        const double v = std::floor(inv[3] + x * inv[4] + y * inv[5]);
        const bool inside = u >= 0 && v >= 0 && u < w && v < h;
        const double value =
            inside ? raw[static_cast<std::size_t>(v) * w + static_cast<std::size_t>(u)] : NAN;
        if (std::isnan(value) || (has_nodata && value == nodata)) {
            out.push_back(p);
        }
    }
    return out;
}

double coarse_height(double lon, double lat) {
    return 1500 + 300 * std::sin(lon * 60) * std::cos(lat * 45);
}

// A 10 m UTM survey over the middle of a 3" geographic DEM, 2 to 10 m above it (ripples the
// coarse DEM misses), and a round void in its middle that the coarse DEM fills.
void write_collection(const tb_test::ScratchDir& dir, std::string& coarse, std::string& fine) {
    tb_test::Fixture c;
    c.width = 121, c.height = 121;
    c.type = GDT_Int16;
    c.epsg = 4326;
    c.geotransform = std::array<double, 6>{7.6, 1.0 / 1200, 0, 46.4, 0, -1.0 / 1200};
    for (int j = 0; j < c.height; ++j) {
        for (int i = 0; i < c.width; ++i) {
            c.values.push_back(coarse_height(7.6 + (i + 0.5) / 1200, 46.4 - (j + 0.5) / 1200));
        }
    }
    coarse = tb_test::write_fixture(dir.file("srtm.tif"), c);

    OGRSpatialReference wgs84, utm;
    wgs84.importFromEPSG(4326);
    utm.importFromEPSG(32632);
    wgs84.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    utm.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    std::unique_ptr<OGRCoordinateTransformation> to_utm(
        OGRCreateCoordinateTransformation(&wgs84, &utm));
    std::unique_ptr<OGRCoordinateTransformation> to_lonlat(
        OGRCreateCoordinateTransformation(&utm, &wgs84));
    double x = 7.65, y = 46.35;
    REQUIRE(to_utm->Transform(1, &x, &y));
    tb_test::Fixture f;
    f.width = 300, f.height = 300;
    f.type = GDT_Float32;
    f.epsg = 32632;
    f.nodata = -9999;
    f.geotransform = std::array<double, 6>{x - 1500, 10, 0, y + 1500, 0, -10};
    for (int j = 0; j < f.height; ++j) {
        for (int i = 0; i < f.width; ++i) {
            double lon = x - 1500 + (i + 0.5) * 10, lat = y + 1500 - (j + 0.5) * 10;
            REQUIRE(to_lonlat->Transform(1, &lon, &lat));
            const bool hole = std::hypot(i - 150, j - 150) < 40;
            f.values.push_back(hole ? -9999
                                    : coarse_height(lon, lat) + 6 +
                                          4 * std::sin(i / 7.0) * std::cos(j / 5.0));
        }
    }
    fine = tb_test::write_fixture(dir.file("lidar_utm.tif"), f);
}

// The collection's own lattice sample at (lon, lat), geodetic zoom z.
double sample_at(const DemSource& source, int z, double lon, double lat) {
    const double step = 180.0 / std::exp2(z) / 256;
    const auto column = static_cast<std::int64_t>(std::llround((lon + 180) / step));
    const auto row = static_cast<std::int64_t>(std::llround((90 - lat) / step));
    const LatticeBlock b = source.sample(Scheme::Geodetic, z, 256, column, row, 1, 1);
    REQUIRE(b.valid[0]);
    return b.heights[0];
}

} // namespace

TEST_CASE("a collection of a UTM survey over geographic SRTM: each keeps its resolution and "
          "CRS, the finer wins, the coarser fills its voids, and every tile holds the winning "
          "pixels within its published error") {
    tb_test::ScratchDir dir;
    std::string coarse, fine;
    write_collection(dir, coarse, fine);

    const auto alone = DemSource::open({coarse});
    const auto both = DemSource::open({coarse, fine});
    REQUIRE(both->parts().size() == 2);
    CHECK(both->parts()[0]->path == fine); // finest first, whatever the order given
    CHECK(both->parts()[1]->path == coarse);
    CHECK(both->pixels_per_sample(Scheme::Geodetic, 12, 256) >
          3 * alone->pixels_per_sample(Scheme::Geodetic, 12, 256));
    // In the survey: its heights, at least 2 m above the coarse DEM; in its void and outside it:
    // the coarse DEM's (bilinear between 3" samples rounded to 1 m: within 1 m).
    CHECK(sample_at(*both, 13, 7.66, 46.35) - coarse_height(7.66, 46.35) > 1.5);
    CHECK(std::abs(sample_at(*both, 13, 7.65, 46.35) - coarse_height(7.65, 46.35)) < 1);
    CHECK(std::abs(sample_at(*both, 13, 7.61, 46.39) - coarse_height(7.61, 46.39)) < 1);
    // --priority listed: the first given wins everywhere it has data.
    const auto listed = DemSource::open({coarse, fine}, std::nullopt, {}, SourcePriority::Listed);
    CHECK(listed->parts()[0]->path == coarse);
    CHECK(std::abs(sample_at(*listed, 13, 7.66, 46.35) - coarse_height(7.66, 46.35)) < 1);

    LayerOptions options;
    options.sources = {coarse, fine};
    // Depth follows the data: below the coarse DEM's own deepest zoom only the survey's tiles,
    // in the tilesets and in layer.json alike.
    const auto layer = Layer::open(options);
    LayerOptions coarse_only;
    coarse_only.sources = {coarse};
    const int coarse_deepest = Layer::open(coarse_only)->max_zoom();
    REQUIRE(layer->max_zoom() >= coarse_deepest + 2);
    const auto inside = [](const TileRange& r, std::int64_t x, std::int64_t y) {
        return !r.empty() && x >= r.x0 && x <= r.x1 && y >= r.y0 && y <= r.y1;
    };
    const LonLatBox survey = DemSource::open({fine})->footprint();
    for (int z = layer->min_zoom(); z <= layer->max_zoom(); ++z) {
        CAPTURE(z);
        const TileRange r = layer->tiles_at(z);
        const TileRange all = tiles_covering(Scheme::Geodetic, alone->footprint(), z);
        const TileRange deep = tiles_covering(Scheme::Geodetic, survey, z);
        if (z <= coarse_deepest) {
            CHECK((r.x0 == all.x0 && r.x1 == all.x1 && r.y0 == all.y0 && r.y1 == all.y1));
            continue;
        }
        // Only around the survey: every tile over it, and no more than its families hold.
        CHECK((inside(r, deep.x0, deep.y0) && inside(r, deep.x1, deep.y1)));
        CHECK(r.count() <= (deep.x1 - deep.x0 + 3) * (deep.y1 - deep.y0 + 3));
        // A parent refines into every child over data, or into none: replacing it never drops
        // the coarse data it drew (3D Tiles' REPLACE).
        for (std::int64_t y = r.y0; y <= r.y1; ++y) {
            for (std::int64_t x = r.x0; x <= r.x1; ++x) {
                CHECK((z == layer->min_zoom() || inside(layer->tiles_at(z - 1), x / 2, y / 2)));
                for (std::int64_t sy = y & ~1; sy <= (y | 1); ++sy) {
                    for (std::int64_t sx = x & ~1; sx <= (x | 1); ++sx) {
                        CHECK(inside(r, sx, sy) == inside(all, sx, sy));
                    }
                }
            }
        }
    }
    std::string layer_json;
    REQUIRE(layer->document("layer.json", layer_json));
    const auto available = nlohmann::json::parse(layer_json)["available"];
    const TileRange deepest = layer->tiles_at(layer->max_zoom());
    CHECK(available[static_cast<std::size_t>(layer->max_zoom())] ==
          nlohmann::json::parse(R"([{"startX":)" + std::to_string(deepest.x0) + R"(,"startY":)" +
                                std::to_string(deepest.y0) + R"(,"endX":)" +
                                std::to_string(deepest.x1) + R"(,"endY":)" +
                                std::to_string(deepest.y1) + "}]"));

    // Across the survey's edge, as across any tile border, neighbours draw the same vertices
    // on the line they share: no crack.
    const int zmax = layer->max_zoom();
    const std::int64_t row = (deepest.y0 + deepest.y1) / 2;
    for (std::int64_t x = deepest.x0; x < deepest.x1; ++x) {
        CAPTURE(x);
        const double edge = tile_bounds(Scheme::Geodetic, {zmax, x + 1, row}).west;
        const auto on_edge = [&](std::int64_t column) {
            const tb_oracle::Drawn d = tb_oracle::decode_glb(
                layer->make_tile(layer->tile({zmax, column, row}), Format::Glb));
            std::set<std::array<double, 3>> out;
            for (const auto& p : d.ecef) {
                if (std::abs(tb_oracle::geodetic(p)[0] - edge) < 1e-6) {
                    out.insert(p);
                }
            }
            return out;
        };
        const auto west = on_edge(x);
        CHECK(west.size() >= 2);
        CHECK(west == on_edge(x + 1));
    }

    static const tb_oracle::Geoid geoid;
    judge_pixels(options, ranked_pixels(fine, coarse, geoid), Guarantee::Measured, false);
}

TEST_CASE("a collection's coarse zooms read its geographic DEM's summary: globe terrain from "
          "zoom 0 and 3D Tiles from any zoom draw the data, every winning pixel within the "
          "published error") {
    tb_test::ScratchDir dir;
    std::string coarse, fine;
    write_collection(dir, coarse, fine);
    LayerOptions options;
    options.sources = {coarse, fine};
    options.min_zoom = 4;
    const auto layer = Layer::open(options);
    // Each summary serves the zooms whose lattice step spans 8 of its pixels: the 3" DEM's 6
    // and coarser, the 10 m UTM survey's (its blocks carried through its CRS) 9 and coarser.
    for (int z = 4; z <= 9; ++z) {
        CAPTURE(z);
        CHECK(layer->zoom_source(z) == ZoomSource::Summaries);
    }
    CHECK(layer->zoom_source(10) == ZoomSource::Lattice);

    static const tb_oracle::Geoid geoid;
    const auto pixels = ranked_pixels(fine, coarse, geoid);
    std::map<std::string, Published> published;
    collect(*layer, "tileset.json", published);
    for (int z = 4; z <= 10; ++z) {
        CAPTURE(z);
        const Summary s = judge_zoom(*layer, pixels, published, z);
        MESSAGE("3D Tiles zoom " << z << " (" << std::string(to_string(layer->zoom_source(z)))
                                 << "): " << s.pixels << " pixels, worst " << s.worst
                                 << " m, worst / published " << s.worst_ratio);
        CHECK(s.pixels > 0);
        CHECK(s.worst_ratio <= 1.0);
    }
    // Globe terrain over the data is meshed from it at every zoom from 0 (before, zooms coarser
    // than the collection's were flat filler on the geoid), within its published error.
    options.min_zoom.reset();
    const auto natural = Layer::open(options);
    natural->prepare(); // the 3" DEM's summary made now (as serve does), then read by the tiles
    int drawn = 0;      // zooms whose bound holds the data above 200 m
    for (int z = 0; z <= 6; ++z) {
        CAPTURE(z);
        const LonLatBox b = DemSource::open({coarse})->footprint();
        const TileRange r = tiles_covering(Scheme::Geodetic, b, z);
        REQUIRE(r.count() == 1);
        const TileId id{z, r.x0, r.y0};
        const tb_qm::Tile t = tb_qm::read(natural->make_tile(natural->tile(id), Format::Terrain));
        CHECK(tb_qm::metadata_of(t).find("\"filler\":true") == std::string::npos);
        // The data (1200 .. 1810 m) rise above the geoid (within 90 m) as far as the bound
        // demands; coarser lattices have no sample inside the 0.1 degree DEMs.
        if (z >= 3) {
            CHECK(t.max_height > 1200 - tb_qm::published_error(t));
            drawn += tb_qm::published_error(t) < 1000 ? 1 : 0;
        }
        const auto [worst, judged] =
            tb_qm::worst_pixel(t, tile_bounds(Scheme::Geodetic, id), pixels);
        CHECK(judged == pixels.size());
        CHECK(worst <= tb_qm::published_error(t) + 1e-3);
    }
    CHECK(drawn > 0);
}

TEST_CASE("two geographic DEMs that both read their summaries: where the finer has a void the "
          "coarser wins, and every winning pixel is within the published error at every zoom") {
    tb_test::ScratchDir dir;
    std::string coarse, unused;
    write_collection(dir, coarse, unused);
    // A 1" DEM over part of the 3" one, 2 to 10 m above it, with a round void the 3" DEM fills.
    tb_test::Fixture f;
    f.width = f.height = 180;
    f.type = GDT_Float32;
    f.epsg = 4326;
    f.nodata = -9999;
    f.geotransform = std::array<double, 6>{7.63, 1.0 / 3600, 0, 46.37, 0, -1.0 / 3600};
    for (int j = 0; j < f.height; ++j) {
        for (int i = 0; i < f.width; ++i) {
            const double lon = 7.63 + (i + 0.5) / 3600, lat = 46.37 - (j + 0.5) / 3600;
            const bool hole = std::hypot(i - 90, j - 90) < 40;
            f.values.push_back(hole ? -9999
                                    : coarse_height(lon, lat) + 6 +
                                          4 * std::sin(i / 7.0) * std::cos(j / 5.0));
        }
    }
    const std::string fine = tb_test::write_fixture(dir.file("fine_1s.tif"), f);
    LayerOptions options;
    options.sources = {coarse, fine};
    options.min_zoom = 4;
    const auto layer = Layer::open(options);
    layer->prepare();
    // Both DEMs' summaries serve zooms 4..6 (a lattice step spans 8 pixels of each or more),
    // the 1" DEM's alone 7 and 8.
    for (int z = 4; z <= 8; ++z) {
        CAPTURE(z);
        CHECK(layer->zoom_source(z) == ZoomSource::Summaries);
    }
    static const tb_oracle::Geoid geoid;
    const auto pixels = ranked_pixels(fine, coarse, geoid);
    std::map<std::string, Published> published;
    collect(*layer, "tileset.json", published);
    for (int z = 4; z <= layer->max_zoom(); ++z) {
        CAPTURE(z);
        const Summary s = judge_zoom(*layer, pixels, published, z);
        MESSAGE("zoom " << z << " (" << std::string(to_string(layer->zoom_source(z)))
                        << "): " << s.pixels << " pixels, worst " << s.worst
                        << " m, worst / published " << s.worst_ratio);
        CHECK(s.pixels > 0);
        CHECK(s.worst_ratio <= 1.0);
    }
}

TEST_CASE("a collection member's summary kept on disk is made again when its file changes, never "
          "read stale") {
    tb_test::ScratchDir dir;
    std::string coarse, fine;
    write_collection(dir, coarse, fine);
    LayerOptions options;
    options.sources = {coarse, fine};
    options.min_zoom = 4;
    options.summary_dir = dir.file("summaries");
    // Zoom 6's lattice point nearest 7.615 E 46.385 N: in the 3" DEM, north of the survey.
    const auto height = [&] {
        const auto layer = Layer::open(options);
        layer->prepare();
        REQUIRE(layer->zoom_source(6) == ZoomSource::Summaries);
        const double step = 180.0 / 64 / 256;
        const LatticeBlock b = layer->sample(Scheme::Geodetic,
                                             6,
                                             256,
                                             std::llround((7.615 + 180) / step),
                                             std::llround((90 - 46.385) / step),
                                             1,
                                             1);
        REQUIRE(b.valid[0]);
        return b.heights[0];
    };
    const double before = height();
    REQUIRE(!std::filesystem::is_empty(dir.file("summaries")));
    CHECK(height() == before); // the summary read back from disk
    // The 3" DEM raised 500 m in place: the same size, a later time.
    {
        GDALDatasetUniquePtr ds(GDALDataset::Open(coarse.c_str(), GDAL_OF_RASTER | GDAL_OF_UPDATE));
        REQUIRE(ds != nullptr);
        GDALRasterBand* band = ds->GetRasterBand(1);
        const int w = band->GetXSize(), h = band->GetYSize();
        std::vector<double> v(static_cast<std::size_t>(w) * h);
        REQUIRE(band->RasterIO(GF_Read, 0, 0, w, h, v.data(), w, h, GDT_Float64, 0, 0, nullptr) ==
                CE_None);
        for (double& x : v) {
            x += 500;
        }
        REQUIRE(band->RasterIO(GF_Write, 0, 0, w, h, v.data(), w, h, GDT_Float64, 0, 0, nullptr) ==
                CE_None);
    }
    std::filesystem::last_write_time(
        coarse, std::filesystem::last_write_time(coarse) + std::chrono::seconds(2));
    const double after = height();
    CHECK(after - before == doctest::Approx(500).epsilon(1e-3));
}

TEST_CASE("a mosaic's gaps between its files are voids, whichever file declares nodata") {
    tb_test::ScratchDir dir;
    // Two 3" cells of one grid with a gap of 0.05 degrees between them; only one declares nodata.
    const auto cell = [&](const std::string& name, double west, std::optional<double> nodata) {
        tb_test::Fixture f;
        f.width = 60, f.height = 60;
        f.type = GDT_Int16;
        f.epsg = 4326;
        f.nodata = nodata;
        f.geotransform = std::array<double, 6>{west, 1.0 / 1200, 0, 46.4, 0, -1.0 / 1200};
        f.values.assign(3600, 700);
        return tb_test::write_fixture(dir.file(name), f);
    };
    const std::string plain = cell("plain.tif", 7.6, std::nullopt);
    const std::string declared = cell("declared.tif", 7.7, -32768.0);
    for (const auto& order :
         {std::vector<std::string>{plain, declared}, std::vector<std::string>{declared, plain}}) {
        const auto mosaic = DemSource::open(order);
        CHECK(mosaic->parts().size() == 1); // one grid: one mosaic
        const double step = 180.0 / std::exp2(12) / 256;
        const auto column = [&](double lon) {
            return static_cast<std::int64_t>(std::llround((lon + 180) / step));
        };
        const auto row = static_cast<std::int64_t>(std::llround((90 - 46.375) / step));
        CHECK(mosaic->sample(Scheme::Geodetic, 12, 256, column(7.62), row, 1, 1).valid[0] == 1);
        CHECK(mosaic->sample(Scheme::Geodetic, 12, 256, column(7.675), row, 1, 1).valid[0] == 0);
        CHECK(mosaic->sample(Scheme::Geodetic, 12, 256, column(7.72), row, 1, 1).valid[0] == 1);
    }
}
