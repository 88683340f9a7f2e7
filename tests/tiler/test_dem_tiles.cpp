// Raster DEM tiles: the PNG writer against GDAL's PNG driver, and every pixel of real tiles
// against an independent bilinear reading of the DEM (GDAL RasterIO of band 1) at the pixel's
// centre.
#include "core/error.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/dem_tiles.hpp"
#include "tiler/formats/dem_png.hpp"
#include "tiler/layer.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/geoid.hpp"

#include <cpl_vsi.h>
#include <gdal_priv.h>

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <random>

using namespace tb::tiler;
using tb_test::Fixture;
using tb_test::ScratchDir;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kRadius = 6378137.0; // EPSG:3857's sphere

struct DecodedPng {
    int width = 0, height = 0, bands = 0;
    std::vector<std::uint32_t> codes; // R << 16 | G << 8 | B
};

// Decodes PNG bytes with GDAL's PNG driver (libpng), independent of our writer.
DecodedPng decode_png(const std::string& bytes) {
    GDALAllRegister();
    static int counter = 0;
    const std::string name = "/vsimem/tb_dem_test_" + std::to_string(++counter) + ".png";
    VSILFILE* f = VSIFileFromMemBuffer(name.c_str(),
                                       reinterpret_cast<GByte*>(const_cast<char*>(bytes.data())),
                                       static_cast<vsi_l_offset>(bytes.size()),
                                       FALSE);
    REQUIRE(f != nullptr);
    VSIFCloseL(f);
    DecodedPng out;
    {
        const char* drivers[] = {"PNG", nullptr};
        GDALDatasetUniquePtr ds(GDALDataset::Open(
            name.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, drivers, nullptr, nullptr));
        REQUIRE(ds != nullptr);
        out.width = ds->GetRasterXSize();
        out.height = ds->GetRasterYSize();
        out.bands = ds->GetRasterCount();
        REQUIRE(out.bands >= 3);
        const std::size_t n = static_cast<std::size_t>(out.width) * out.height;
        std::vector<GByte> rgb(n * 3);
        int band_map[3] = {1, 2, 3};
        REQUIRE(ds->RasterIO(GF_Read,
                             0,
                             0,
                             out.width,
                             out.height,
                             rgb.data(),
                             out.width,
                             out.height,
                             GDT_Byte,
                             3,
                             band_map,
                             3,
                             static_cast<GSpacing>(out.width) * 3,
                             1,
                             nullptr) == CE_None);
        out.codes.resize(n);
        for (std::size_t k = 0; k < n; ++k) {
            out.codes[k] = static_cast<std::uint32_t>(rgb[3 * k]) << 16 |
                           static_cast<std::uint32_t>(rgb[3 * k + 1]) << 8 | rgb[3 * k + 2];
        }
    }
    VSIUnlink(name.c_str());
    return out;
}

// Band 1 of a north-up geographic DEM read whole with GDAL, and bilinear sampling of it.
struct Reference {
    int width = 0, height = 0;
    double gt[6] = {};
    std::vector<double> values;
    std::vector<std::uint8_t> valid;

    explicit Reference(const std::string& path) {
        GDALAllRegister();
        GDALDatasetUniquePtr ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
        REQUIRE(ds != nullptr);
        REQUIRE(ds->GetGeoTransform(gt) == CE_None);
        REQUIRE(gt[2] == 0.0);
        REQUIRE(gt[4] == 0.0);
        width = ds->GetRasterXSize();
        height = ds->GetRasterYSize();
        GDALRasterBand* band = ds->GetRasterBand(1);
        values.resize(static_cast<std::size_t>(width) * height);
        REQUIRE(band->RasterIO(GF_Read,
                               0,
                               0,
                               width,
                               height,
                               values.data(),
                               width,
                               height,
                               GDT_Float64,
                               0,
                               0,
                               nullptr) == CE_None);
        int has_nodata = 0;
        const double nodata = band->GetNoDataValue(&has_nodata);
        valid.resize(values.size());
        for (std::size_t k = 0; k < values.size(); ++k) {
            valid[k] = std::isfinite(values[k]) && !(has_nodata && values[k] == nodata);
        }
    }

    // Bilinear height at (lon, lat), or nullopt outside the pixel centres' hull or where one of
    // the four pixels is nodata.
    std::optional<double> at(double lon, double lat) const {
        const double u = (lon - gt[0]) / gt[1] - 0.5, v = (lat - gt[3]) / gt[5] - 0.5;
        if (!(u >= 0 && v >= 0 && u <= width - 1 && v <= height - 1)) {
            return std::nullopt;
        }
        const int i = std::min(static_cast<int>(std::floor(u)), width - 2);
        const int j = std::min(static_cast<int>(std::floor(v)), height - 2);
        const double a = u - i, b = v - j;
        double h = 0;
        for (int q = 0; q < 4; ++q) {
            const std::size_t k = static_cast<std::size_t>(j + q / 2) * width + (i + q % 2);
            if (!valid[k]) {
                return std::nullopt;
            }
            h += (q % 2 ? a : 1 - a) * (q / 2 ? b : 1 - b) * values[k];
        }
        return h;
    }
};

// Lon/lat of the centre of pixel (i, j) of DEM tile `id` with `size` pixels per side, from the
// EPSG:3857 spherical formulas.
LonLat pixel_centre(const TileId& id, int size, int i, int j) {
    const double world = 2 * kPi * kRadius;
    const double pixel = world / (static_cast<double>(size) * std::ldexp(1.0, id.z));
    const double x = -world / 2 + (static_cast<double>(id.x * size + i) + 0.5) * pixel;
    const double y = world / 2 - (static_cast<double>(id.y * size + j) + 0.5) * pixel;
    return {x / kRadius * 180 / kPi, (2 * std::atan(std::exp(y / kRadius)) - kPi / 2) * 180 / kPi};
}

// Compares every pixel of the tile with the reference where that is defined; returns how many.
std::size_t
check_tile_against(const Layer& layer, const Reference& ref, const TileId& id, Format format) {
    const int p = layer.options().dem_tile_size;
    const DecodedPng png =
        decode_png(make_dem_tile(layer, ValidTile::parse(Scheme::Mercator, id), format));
    REQUIRE(png.width == p);
    REQUIRE(png.height == p);
    CHECK(png.bands == 3); // opaque: voids are filled, never transparent
    const double tolerance = height_step(format) / 2 + 1e-6;
    std::size_t compared = 0;
    double worst = 0;
    for (int j = 0; j < p; ++j) {
        for (int i = 0; i < p; ++i) {
            const LonLat c = pixel_centre(id, p, i, j);
            const auto expected = ref.at(c.lon, c.lat);
            if (!expected) {
                continue;
            }
            const double got =
                decode_height(png.codes[static_cast<std::size_t>(j) * p + i], format);
            worst = std::max(worst, std::abs(got - *expected));
            if (std::abs(got - *expected) > tolerance) {
                FAIL_CHECK("pixel " << i << "," << j << " of " << id.z << "/" << id.x << "/" << id.y
                                    << ": decoded " << got << ", DEM " << *expected);
                return compared;
            }
            ++compared;
        }
    }
    MESSAGE(std::string(format_name(format))
            << " " << id.z << "/" << id.x << "/" << id.y << ": " << compared
            << " pixels compared, worst " << worst << " m");
    return compared;
}

// A smooth Float32 DEM near 11 E 57 N, 240 x 240 pixels of 1/480 degree (7.5"), with a 12 x 12
// nodata hole in the middle.
std::string write_test_dem(const ScratchDir& dir) {
    Fixture f;
    f.width = f.height = 240;
    f.geotransform = std::array<double, 6>{11.0, 1.0 / 480, 0, 57.5, 0, -1.0 / 480};
    f.epsg = 4326;
    f.nodata = -9999;
    for (int j = 0; j < f.height; ++j) {
        for (int i = 0; i < f.width; ++i) {
            const bool hole = i >= 114 && i < 126 && j >= 114 && j < 126;
            f.values.push_back(hole ? -9999
                                    : 150 + 120 * std::sin(i * 0.071) * std::cos(j * 0.053) +
                                          7.3 * std::sin(i * 0.9 + j * 0.4));
        }
    }
    return tb_test::write_fixture(dir.file("dem.tif"), f);
}

std::shared_ptr<const Layer>
open_dem_layer(const std::string& path, DemHeights heights = DemHeights::SeaLevel, int size = 512) {
    LayerOptions o;
    o.sources = {path};
    o.dem_heights = heights;
    o.dem_tile_size = size;
    return Layer::open(o);
}

} // namespace

TEST_CASE("the DEM PNG writer's pixels decode with GDAL's PNG driver to the nearest step") {
    std::mt19937 rng(20261201);
    std::uniform_real_distribution<double> any(-11000.0, 9000.0);
    for (const auto& [w, h] : {std::pair{37, 23}, std::pair{1, 1}, std::pair{256, 3}}) {
        std::vector<double> heights(static_cast<std::size_t>(w) * h);
        for (std::size_t k = 0; k < heights.size(); ++k) {
            // Smooth runs (what filters are for) mixed with noise and exact steps.
            heights[k] = k % 5 == 0 ? any(rng) : 100.0 + 0.37 * static_cast<double>(k % 97);
        }
        for (Format f : {Format::Terrarium, Format::Mapbox}) {
            CAPTURE(std::string(format_name(f)));
            CAPTURE(w);
            // Heights below -10000 m are out of mapbox's range and clamp to it.
            const double lowest = decode_height(0, f), highest = decode_height((1u << 24) - 1, f);
            const DecodedPng png = decode_png(encode_dem_png(heights, w, h, f));
            REQUIRE(png.width == w);
            REQUIRE(png.height == h);
            CHECK(png.bands == 3);
            for (std::size_t k = 0; k < heights.size(); ++k) {
                REQUIRE(png.codes[k] == encode_height(heights[k], f));
                REQUIRE(std::abs(decode_height(png.codes[k], f) -
                                 std::clamp(heights[k], lowest, highest)) <=
                        height_step(f) / 2 + 1e-9);
            }
        }
    }
}

TEST_CASE("DEM height codes follow the terrarium and mapbox formulas and clamp to their range") {
    // terrarium 0 m = 32768 * 256 = 0x800000; mapbox 0 m = 100000 = 0x0186a0.
    CHECK(encode_height(0.0, Format::Terrarium) == 0x800000u);
    CHECK(encode_height(0.0, Format::Mapbox) == 0x0186a0u);
    CHECK(decode_height(0x800000u, Format::Terrarium) == 0.0);
    CHECK(decode_height(0x0186a0u, Format::Mapbox) == doctest::Approx(0.0).epsilon(1e-12));
    CHECK(decode_height(encode_height(-424.5, Format::Terrarium), Format::Terrarium) == -424.5);
    CHECK(encode_height(-40000.0, Format::Terrarium) == 0u);
    CHECK(encode_height(-10001.0, Format::Mapbox) == 0u);
    CHECK(encode_height(40000.0, Format::Terrarium) == (1u << 24) - 1);
    CHECK(height_step(Format::Terrarium) == 1.0 / 256);
    CHECK(height_step(Format::Mapbox) == 0.1);
}

TEST_CASE("every DEM tile pixel is the DEM's bilinear sample at its centre within half a step") {
    ScratchDir dir;
    const std::string path = write_test_dem(dir);
    const Reference ref(path);
    const auto layer = open_dem_layer(path);
    const DemTilePlan plan = dem_tile_plan(*layer);
    // 7.5" is about 126 m east-west and 232 m north-south at 57.25 N, geometric mean 171 m;
    // a 512-pixel tile's pixel is 40075 km * cos(57.25 deg) / 512 / 2^z: 165 m at z = 8.
    CHECK(plan.max_zoom == 8);
    // From zoom 0: clients draw no terrain below a raster-dem source's minzoom.
    CHECK(plan.min_zoom == 0);
    CHECK(dem_tiles_at(*layer, 0).count() == 1);
    // 256-pixel tiles reach one zoom deeper, so their zooms 8 and 9 both read band 1 whole.
    const auto small = open_dem_layer(path, DemHeights::SeaLevel, 256);
    for (int z : {plan.max_zoom, plan.max_zoom + 1}) {
        const Layer& layer_z = z == plan.max_zoom ? *layer : *small;
        const TileRange r = dem_tiles_at(layer_z, z);
        REQUIRE_FALSE(r.empty());
        std::size_t compared = 0;
        for (std::int64_t y = r.y0; y <= r.y1; ++y) {
            for (std::int64_t x = r.x0; x <= r.x1; ++x) {
                for (Format f : {Format::Terrarium, Format::Mapbox}) {
                    compared += check_tile_against(layer_z, ref, TileId{z, x, y}, f);
                }
            }
        }
        // The DEM covers 0.5 x 0.5 degrees: at z 8, about 182 x 337 pixels per encoding.
        CHECK(compared > (z == plan.max_zoom ? 2 * 55000u : 2 * 13000u));
    }
}

TEST_CASE("DEM tiles fill voids and the area beyond the DEM from the data, and stay opaque") {
    ScratchDir dir;
    const std::string path = write_test_dem(dir);
    const auto layer = open_dem_layer(path, DemHeights::SeaLevel, 256);
    const DemTilePlan plan = dem_tile_plan(*layer);
    CHECK(plan.max_zoom == 9); // half the pixels per tile: one zoom deeper
    const TileRange r = dem_tiles_at(*layer, plan.max_zoom);
    double lo = INFINITY, hi = -INFINITY;
    std::size_t tiles = 0;
    for (std::int64_t y = r.y0; y <= r.y1; ++y) {
        for (std::int64_t x = r.x0; x <= r.x1; ++x) {
            const auto heights = dem_tile_heights(
                *layer, ValidTile::parse(Scheme::Mercator, TileId{plan.max_zoom, x, y}));
            REQUIRE(heights.size() == 256u * 256u);
            for (double h : heights) {
                REQUIRE(std::isfinite(h));
                lo = std::min(lo, h), hi = std::max(hi, h);
            }
            ++tiles;
        }
    }
    CHECK(tiles == static_cast<std::size_t>(r.count()));
    // The fixture spans 22.7 .. 277.3 m; fills are means of data or sea level (0 m).
    CHECK(lo >= 0.0);
    CHECK(hi <= 277.3 + 1e-9);
}

TEST_CASE("DEM tile pixels beyond the DEM's footprint carry the height of the nearest pixel "
          "inside it: no cliff down to sea level around the data") {
    ScratchDir dir;
    const auto layer = open_dem_layer(write_test_dem(dir), DemHeights::SeaLevel, 256);
    const int z = dem_tile_plan(*layer).max_zoom, p = 256;
    const TileRange r = dem_tiles_at(*layer, z);
    // Every pixel of the zoom's tiles, by global column and row.
    const std::int64_t c0 = r.x0 * p, r0 = r.y0 * p;
    const std::int64_t cols = (r.x1 - r.x0 + 1) * p, rows = (r.y1 - r.y0 + 1) * p;
    std::vector<double> h(static_cast<std::size_t>(cols * rows));
    for (std::int64_t y = r.y0; y <= r.y1; ++y) {
        for (std::int64_t x = r.x0; x <= r.x1; ++x) {
            const auto tile =
                dem_tile_heights(*layer, ValidTile::parse(Scheme::Mercator, TileId{z, x, y}));
            for (int j = 0; j < p; ++j) {
                for (int i = 0; i < p; ++i) {
                    h[static_cast<std::size_t>((y * p + j - r0) * cols + (x * p + i - c0))] =
                        tile[static_cast<std::size_t>(j) * p + i];
                }
            }
        }
    }
    // The footprint (11..11.5 E, 57..57.5 N) in pixel centres, from the mercator formulas.
    const double n = static_cast<double>(p) * std::exp2(z);
    const auto lon_of = [&](std::int64_t c) {
        return (static_cast<double>(c) + 0.5) / n * 360 - 180;
    };
    const auto lat_of = [&](std::int64_t row) {
        const double m = kPi * (1 - 2 * (static_cast<double>(row) + 0.5) / n);
        return std::atan(std::sinh(m)) * 180 / kPi;
    };
    std::int64_t first_c = c0, last_c = c0 + cols - 1, first_r = r0, last_r = r0 + rows - 1;
    while (lon_of(first_c) < 11.0)
        ++first_c;
    while (lon_of(last_c) > 11.5)
        --last_c;
    while (lat_of(first_r) > 57.5)
        ++first_r;
    while (lat_of(last_r) < 57.0)
        --last_r;
    REQUIRE(first_c > c0);
    REQUIRE(first_r > r0);
    std::size_t outside = 0, same = 0;
    double lo = INFINITY;
    for (std::int64_t row = r0; row < r0 + rows; ++row) {
        for (std::int64_t c = c0; c < c0 + cols; ++c) {
            const std::int64_t cc = std::clamp(c, first_c, last_c),
                               rr = std::clamp(row, first_r, last_r);
            if (cc == c && rr == row) {
                continue;
            }
            ++outside;
            const double here = h[static_cast<std::size_t>((row - r0) * cols + (c - c0))];
            const double nearest = h[static_cast<std::size_t>((rr - r0) * cols + (cc - c0))];
            same += here == nearest ? 1 : 0;
            lo = std::min(lo, here);
        }
    }
    MESSAGE(outside << " pixels beyond the footprint, " << same
                    << " equal to their nearest inside");
    CHECK(outside > 10000u);
    CHECK(same == outside);
    CHECK(lo >= 22.7); // the fixture's lowest height: nothing drops to sea level
}

TEST_CASE("DEM tiles in ellipsoidal heights are the sea-level ones plus the EGM96 undulation") {
    ScratchDir dir;
    const std::string path = write_test_dem(dir);
    const auto sea = open_dem_layer(path, DemHeights::SeaLevel);
    const auto ellipsoid = open_dem_layer(path, DemHeights::Ellipsoid);
    const int z = dem_tile_plan(*sea).max_zoom;
    const TileRange r = dem_tiles_at(*sea, z);
    const TileId id{z, r.x0, r.y0};
    const auto a = dem_tile_heights(*sea, ValidTile::parse(Scheme::Mercator, id));
    const auto b = dem_tile_heights(*ellipsoid, ValidTile::parse(Scheme::Mercator, id));
    REQUIRE(a.size() == b.size());
    double worst = 0;
    for (int j = 0; j < 512; j += 7) {
        for (int i = 0; i < 512; i += 7) {
            const LonLat c = pixel_centre(id, 512, i, j);
            const std::size_t k = static_cast<std::size_t>(j) * 512 + i;
            worst = std::max(worst, std::abs(b[k] - a[k] - egm96_undulation(c.lon, c.lat)));
        }
    }
    CHECK(worst < 1e-6);
    // The geoid lies 30..40 m above the ellipsoid in southern Sweden.
    CHECK(b[0] - a[0] > 25);
    CHECK(b[0] - a[0] < 45);
}

TEST_CASE("an ellipsoidal source loses the undulation at sea level and keeps its heights as is") {
    ScratchDir dir;
    const std::string path = write_test_dem(dir);
    const auto egm96 = open_dem_layer(path, DemHeights::SeaLevel);
    LayerOptions o = egm96->options();
    o.datum = VerticalDatum::Ellipsoid; // the same numbers, taken as ellipsoidal heights
    const auto sea = Layer::open(o);
    o.dem_heights = DemHeights::Ellipsoid;
    const auto ellipsoid = Layer::open(o);
    const int z = dem_tile_plan(*egm96).max_zoom;
    const TileRange r = dem_tiles_at(*egm96, z);
    const TileId id{z, r.x1, r.y1};
    const auto source = dem_tile_heights(
        *egm96, ValidTile::parse(Scheme::Mercator, id)); // the source's own numbers
    const auto a = dem_tile_heights(*sea, ValidTile::parse(Scheme::Mercator, id));
    const auto b = dem_tile_heights(*ellipsoid, ValidTile::parse(Scheme::Mercator, id));
    const Reference ref(path);
    std::size_t measured = 0;
    for (int j = 0; j < 512; ++j) {
        for (int i = 0; i < 512; ++i) {
            const LonLat c = pixel_centre(id, 512, i, j);
            const std::size_t k = static_cast<std::size_t>(j) * 512 + i;
            if (!ref.at(c.lon, c.lat)) {
                continue; // filled: no source height to keep
            }
            ++measured;
            REQUIRE(b[k] == source[k]);
            REQUIRE(std::abs(a[k] - (source[k] - egm96_undulation(c.lon, c.lat))) < 1e-6);
        }
    }
    CHECK(measured > 10000u);
}

TEST_CASE("a DEM tile stops with Cancelled at a checkpoint once its CancelFn says so, and is the "
          "same tile when it never does") {
    ScratchDir dir;
    const auto layer = open_dem_layer(write_test_dem(dir), DemHeights::SeaLevel);
    const int z = dem_tile_plan(*layer).max_zoom;
    const TileRange r = dem_tiles_at(*layer, z);
    const ValidTile tile = ValidTile::parse(Scheme::Mercator, TileId{z, r.x0, r.y0});
    const std::string whole = make_dem_tile(*layer, tile, Format::Terrarium);
    int asked = 0;
    const auto never = [&] { return ++asked, false; };
    CHECK(make_dem_tile(*layer, tile, Format::Terrarium, never) == whole);
    // Before reading, every 32 of the 512 + 2 margin rows, and before encoding.
    CHECK(asked == (512 + 2 * kDemFillMargin + 31) / 32 + 1);
    for (const int stop_at : {1, 3, asked}) {
        CAPTURE(stop_at);
        int n = 0;
        const auto at = [&] { return ++n == stop_at; };
        CHECK_THROWS_AS(make_dem_tile(*layer, tile, Format::Terrarium, at), Cancelled);
        CHECK(n == stop_at);
    }
}

TEST_CASE("DEM tiles outside EPSG:3857, the zooms or the data are refused with the right error") {
    ScratchDir dir;
    const auto layer = open_dem_layer(write_test_dem(dir));
    const DemTilePlan plan = dem_tile_plan(*layer);
    const TileRange r = dem_tiles_at(*layer, plan.max_zoom);
    CHECK_THROWS_AS(dem_tile_heights(*layer, ValidTile::parse(Scheme::Mercator, TileId{3, 8, 0})),
                    tb::InputError);
    CHECK_THROWS_AS(dem_tile_heights(*layer, ValidTile::parse(Scheme::Mercator, TileId{25, 0, 0})),
                    tb::InputError);
    CHECK_THROWS_AS(
        dem_tile_heights(
            *layer,
            ValidTile::parse(Scheme::Mercator, TileId{plan.max_zoom + 1, 2 * r.x0, 2 * r.y0})),
        tb::NotFound);
    CHECK_THROWS_AS(
        dem_tile_heights(*layer, ValidTile::parse(Scheme::Mercator, TileId{plan.max_zoom, 0, 0})),
        tb::NotFound);
    if (plan.min_zoom > 0) {
        CHECK_THROWS_AS(
            dem_tile_heights(*layer, ValidTile::parse(Scheme::Mercator, TileId{0, 0, 0})),
            tb::NotFound);
    }
    LayerOptions o = layer->options();
    o.dem_tile_size = 300;
    const auto odd = Layer::open(o);
    CHECK_THROWS_WITH_AS(dem_tile_plan(*odd),
                         doctest::Contains("DEM tile size 300 is not supported; use 256 or 512"),
                         tb::InputError);
}

TEST_CASE("a real SRTM GeoTIFF with voids gives DEM tiles equal to GDAL's reading of it") {
    const auto path = tb_test::shared_dem("N46E008.tif");
    if (!path) {
        return;
    }
    const Reference ref(*path);
    const auto layer = open_dem_layer(*path);
    const DemTilePlan plan = dem_tile_plan(*layer);
    // 8.5 E 46.5 N, in the Alps.
    const TileRange r = tiles_covering(Scheme::Mercator, LonLatBox{8.5, 46.5, 8.501, 46.501}, 10);
    CHECK(plan.max_zoom >= 10);
    for (Format f : {Format::Terrarium, Format::Mapbox}) {
        CHECK(check_tile_against(*layer, ref, TileId{10, r.x0, r.y0}, f) > 200000u);
    }
}
