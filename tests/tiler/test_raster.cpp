// Reading DEMs into tile rasters: bilinear sampling against GDAL's warper, nodata/NaN,
// scale/offset, void filling, the geoid, and bit-identical borders of neighbouring tiles.
#include "core/error.hpp"
#include "core/triangulate.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/gdal_source.hpp"
#include "tiler/geoid.hpp"
#include "tiler/layer.hpp"

#include <doctest/doctest.h>
#include <gdal_utils.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <random>
#include <set>

using namespace tb::tiler;
using tb_test::Fixture;
using tb_test::ScratchDir;

namespace {

// A geographic fixture of W x H pixels of 0.001 degree from (lon0, lat0) (north-west corner).
Fixture geographic(int w, int h, double lon0, double lat0, std::vector<double> values) {
    Fixture f;
    f.width = w, f.height = h;
    f.geotransform = std::array<double, 6>{lon0, 0.001, 0, lat0, 0, -0.001};
    f.epsg = 4326;
    f.values = std::move(values);
    return f;
}

// Shared border samples of two tile rasters, compared bit for bit; `vertical` = a's east
// column against b's west column, otherwise a's north row against b's south row.
void check_shared_border(const TileRaster& a, const TileRaster& b, bool vertical) {
    const int n = a.size;
    int differences = 0;
    for (int k = 0; k <= n; ++k) {
        const int ax = vertical ? n : k, ay = vertical ? k : 0;
        const int bx = vertical ? 0 : k, by = vertical ? k : n;
        const float ha = a.grid.at(ax, ay), hb = b.grid.at(bx, by);
        if (std::memcmp(&ha, &hb, sizeof ha) != 0 ||
            a.grid.is_valid(ax, ay) != b.grid.is_valid(bx, by)) {
            ++differences;
        }
    }
    CHECK(differences == 0);
}

// Vertices of a mesh on one border of the tile grid: (position along the border, height bits).
std::set<std::pair<int, std::uint32_t>>
border_vertices(const tb::core::Mesh& mesh, int n, char side) {
    std::set<std::pair<int, std::uint32_t>> out;
    for (std::size_t v = 0; v < mesh.points.size(); ++v) {
        const auto p = mesh.points[v];
        std::uint32_t bits = 0;
        std::memcpy(&bits, &mesh.z[v], sizeof bits);
        if ((side == 'E' && p.x == n) || (side == 'W' && p.x == 0)) {
            out.insert({p.y, bits});
        } else if ((side == 'N' && p.y == 0) || (side == 'S' && p.y == n)) {
            out.insert({p.x, bits});
        }
    }
    return out;
}

} // namespace

TEST_CASE("EGM96 undulation matches NGA's published test values") {
    // NGA/NIMA EGM96 test values (README of the EGM96 15' geoid package, "outintpt.dat";
    // also quoted in GeographicLib's Geoid documentation): lat, lon, N in metres.
    struct Point {
        double lat, lon, n;
    };
    const Point points[] = {
        {38.6281550, 269.7791550, -31.628},
        {-14.6212170, 305.0211140, -2.969},
        {46.8743190, 102.4487290, -43.575},
        {-23.6174460, 133.8747120, 15.871},
        {38.6254730, 359.9995000, 50.066},
        {-0.4667440, 0.0023000, 17.329},
    };
    if (!std::filesystem::exists(kEgm96GridPath)) {
        MESSAGE("skipped: " << kEgm96GridPath << " is missing (Debian package proj-data)");
        return;
    }
    for (const auto& p : points) {
        const double lon = p.lon > 180 ? p.lon - 360 : p.lon;
        // The 15' grid interpolated bilinearly stays within a few cm of the full model here.
        const double n = egm96_undulation(lon, p.lat);
        INFO("lat " << p.lat << " lon " << lon << ": " << n << " vs " << p.n);
        CHECK(std::abs(n - p.n) < 0.1);
        // Longitude wraps: the same point given 360 degrees further east.
        CHECK(egm96_undulation(lon + 360, p.lat) == doctest::Approx(n));
    }
}

TEST_CASE("void filling never leaves the range of the valid samples and fills everything") {
    std::mt19937 rng(3);
    const int w = 60, h = 45;
    std::vector<double> heights(w * h);
    std::vector<std::uint8_t> valid(w * h, 1);
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
            heights[y * w + x] = 100 + 3 * x + 2 * y + (rng() % 7);
        }
    }
    // A big hole touching the border and a single-sample pit; void heights are garbage.
    for (int y = 0; y < 30; ++y) {
        for (int x = 20; x < 60; ++x) {
            valid[y * w + x] = 0, heights[y * w + x] = -32768;
        }
    }
    valid[40 * w + 5] = 0, heights[40 * w + 5] = -32768;
    std::vector<double> filled = heights;
    fill_voids(filled, valid, w, h, 0, 0.0);
    double lo = 1e9, hi = -1e9;
    for (int k = 0; k < w * h; ++k) {
        if (valid[k]) {
            lo = std::min(lo, heights[k]), hi = std::max(hi, heights[k]);
            CHECK(filled[k] == heights[k]); // measured samples are untouched
        }
    }
    for (int k = 0; k < w * h; ++k) {
        CHECK(filled[k] >= lo);
        CHECK(filled[k] <= hi);
    }
    // The pit is surrounded by valid samples: it takes their distance-weighted mean.
    CHECK(filled[40 * w + 5] == doctest::Approx(100 + 15 + 80 + 3).epsilon(0.05));
}

TEST_CASE("void filling of two overlapping tiles agrees on their shared border (seed 11)") {
    // One global field with voids; two tiles of 32 samples side by side, each with a 16-sample
    // margin, filled independently: the shared column must come out identical.
    std::mt19937 rng(11);
    const int n = 32, m = 16, gw = 2 * n + 1 + 2 * m, gh = n + 1 + 2 * m;
    std::vector<double> field(gw * gh);
    std::vector<std::uint8_t> valid(gw * gh, 1);
    for (int k = 0; k < gw * gh; ++k) {
        field[k] = 500 + static_cast<int>(rng() % 200);
    }
    // Voids straddling the shared column x = m + n, one of them wider than the margin.
    for (int y = 0; y < gh; ++y) {
        for (int x = 0; x < gw; ++x) {
            const bool hole1 = std::abs(x - (m + n)) < 5 && y > 20 && y < 30;
            const bool hole2 = std::abs(x - (m + n)) < 40 && y < m + 3;
            if (hole1 || hole2) {
                valid[y * gw + x] = 0;
            }
        }
    }
    const auto cut = [&](int x0, std::vector<double>& h, std::vector<std::uint8_t>& v) {
        const int w = n + 1 + 2 * m;
        h.resize(w * gh), v.resize(w * gh);
        for (int y = 0; y < gh; ++y) {
            for (int x = 0; x < w; ++x) {
                h[y * w + x] = field[y * gw + x0 + x];
                v[y * w + x] = valid[y * gw + x0 + x];
            }
        }
        fill_voids(h, v, w, gh, m, 0.0);
    };
    std::vector<double> left, right;
    std::vector<std::uint8_t> lv, rv;
    cut(0, left, lv);
    cut(n, right, rv);
    const int w = n + 1 + 2 * m;
    int voids_on_border = 0;
    for (int y = m; y <= m + n; ++y) {
        voids_on_border += lv[y * w + m + n] ? 0 : 1;
        CHECK(left[y * w + m + n] == right[y * w + m]);
    }
    CHECK(voids_on_border > 10);
}

TEST_CASE("a block with no valid sample is filled with the fallback (sea level)") {
    std::vector<double> h(10 * 10, -9999);
    std::vector<std::uint8_t> v(100, 0);
    fill_voids(h, v, 10, 10, 2, 0.0);
    for (int y = 2; y < 8; ++y) {
        for (int x = 2; x < 8; ++x) {
            CHECK(h[y * 10 + x] == 0.0);
        }
    }
}

TEST_CASE("sampling a tilted plane reproduces it, with scale and offset applied") {
    ScratchDir dir;
    // h = 2 * column - 3 * row + 7 stored as Int16 raw = (h - 100) / 0.5.
    const int w = 50, hgt = 40;
    std::vector<double> raw(w * hgt);
    for (int r = 0; r < hgt; ++r) {
        for (int c = 0; c < w; ++c) {
            raw[r * w + c] = ((2.0 * c - 3.0 * r + 7) - 100) / 0.5;
        }
    }
    Fixture f = geographic(w, hgt, 10.0, 45.0, raw);
    f.type = GDT_Int16;
    f.scale = 0.5;
    f.offset = 100;
    const auto source = DemSource::open({tb_test::write_fixture(dir.file("plane.tif"), f)});
    CHECK(source->info().scale == 0.5);
    // Zoom 14, 64-sample tiles: step 180/2^14/64 = 0.000172 degrees, finer than the pixels.
    const int z = 14, n = 64;
    const std::int64_t c0 =
        static_cast<std::int64_t>(std::ceil((10.0 + 180) / (180.0 / (1 << z) / n))) + 3;
    const std::int64_t r0 =
        static_cast<std::int64_t>(std::ceil((90 - 45.0) / (180.0 / (1 << z) / n))) + 3;
    const LatticeBlock block = source->sample(Scheme::Geodetic, z, n, c0, r0, 60, 60);
    int checked = 0;
    for (int j = 0; j < 60; ++j) {
        for (int i = 0; i < 60; ++i) {
            const double lon = lattice_x(Scheme::Geodetic, z, n, c0 + i);
            const double lat = lattice_y(Scheme::Geodetic, z, n, r0 + j);
            const double col = (lon - 10.0) / 0.001 - 0.5, row = (45.0 - lat) / 0.001 - 0.5;
            if (col < 0 || row < 0 || col > w - 1 || row > hgt - 1) {
                continue;
            }
            REQUIRE(block.valid[j * 60 + i]);
            CHECK(block.heights[j * 60 + i] ==
                  doctest::Approx(2 * col - 3 * row + 7).epsilon(1e-9));
            ++checked;
        }
    }
    CHECK(checked > 1000);
}

TEST_CASE("nodata and NaN samples are voids, and samples outside the raster too") {
    ScratchDir dir;
    std::vector<double> values(20 * 20, 50.0);
    values[5 * 20 + 5] = -9999;
    Fixture f = geographic(20, 20, 10.0, 45.0, values);
    f.nodata = -9999;
    const auto a = DemSource::open({tb_test::write_fixture(dir.file("nodata.tif"), f)});
    values[5 * 20 + 5] = NAN;
    f.values = values;
    f.nodata = NAN;
    const auto b = DemSource::open({tb_test::write_fixture(dir.file("nan.tif"), f)});
    for (const auto& source : {a, b}) {
        // Zoom 18 / 8-sample tiles: step 0.000086 degrees, ~12 samples per pixel. Pixel (5, 5)
        // spans lon 10.005..10.006, lat 44.995..44.994.
        const int z = 18, n = 8;
        const double step = 180.0 / (1 << z) / n;
        const std::int64_t c0 = static_cast<std::int64_t>(std::floor((10.0 + 180) / step)) - 5;
        const std::int64_t r0 = static_cast<std::int64_t>(std::floor((90 - 45.0) / step)) - 5;
        const int size = 260;
        const LatticeBlock block = source->sample(Scheme::Geodetic, z, n, c0, r0, size, size);
        int voids_inside = 0, outside = 0;
        for (int j = 0; j < size; ++j) {
            for (int i = 0; i < size; ++i) {
                const double lon = lattice_x(Scheme::Geodetic, z, n, c0 + i);
                const double lat = lattice_y(Scheme::Geodetic, z, n, r0 + j);
                const double col = (lon - 10.0) / 0.001 - 0.5, row = (45.0 - lat) / 0.001 - 0.5;
                const bool inside = col >= -0.5 && row >= -0.5 && col <= 19.5 && row <= 19.5;
                const bool near_hole = std::abs(col - 5) < 1 && std::abs(row - 5) < 1;
                const std::size_t k = static_cast<std::size_t>(j) * size + i;
                if (!inside) {
                    CHECK_FALSE(block.valid[k]);
                    ++outside;
                } else if (block.valid[k]) {
                    CHECK(block.heights[k] == 50.0); // never a -9999 or NaN blend
                } else {
                    CHECK(near_hole);
                    ++voids_inside;
                }
            }
        }
        CHECK(voids_inside > 0);
        CHECK(outside > 0);
    }
}

TEST_CASE("complex and colour rasters are rejected with a clear error") {
    ScratchDir dir;
    Fixture complex_fixture = geographic(4, 4, 0, 1, {});
    complex_fixture.type = GDT_CFloat32;
    const std::string c = tb_test::write_fixture(dir.file("complex.tif"), complex_fixture);
    Fixture rgb = geographic(4, 4, 0, 1, {});
    rgb.type = GDT_Byte;
    rgb.bands = 3;
    const std::string r = tb_test::write_fixture(dir.file("rgb.tif"), rgb);
    CHECK_THROWS_WITH_AS(
        DemSource::open({c}), doctest::Contains("complex numbers"), tb::InputError);
    CHECK_THROWS_WITH_AS(DemSource::open({r}), doctest::Contains("colour image"), tb::InputError);
    if (auto fuji = tb_test::shared_dem("fuji.png")) {
        CHECK_THROWS_WITH_AS(
            DemSource::open({*fuji}), doctest::Contains("Terrain-RGB"), tb::InputError);
    }
}

TEST_CASE("the tile raster of N44W072.hgt matches GDAL's bilinear warp of the same grid") {
    const auto path = tb_test::shared_dem("N44W072.hgt");
    if (!path) {
        return;
    }
    LayerOptions options;
    options.sources = {*path};
    options.datum = VerticalDatum::Ellipsoid; // compare the source heights themselves
    const auto layer = Layer::open(options);
    REQUIRE(layer->max_zoom() == 10);
    const TileId id{10, 617, 765}; // around 71.5 W 44.5 N, inside the cell
    const TileRaster raster = layer->make_raster(id);
    REQUIRE(raster.grid.valid.empty());

    // gdalwarp -r bilinear -et 0 onto the tile's samples as pixel centres.
    const double step = (raster.bounds.east - raster.bounds.west) / raster.size;
    char buffer[4][64];
    for (int k = 0; k < 4; ++k) {
        std::snprintf(buffer[k],
                      sizeof buffer[k],
                      "%.15f",
                      k == 0   ? raster.bounds.west - step / 2
                      : k == 1 ? raster.bounds.south - step / 2
                      : k == 2 ? raster.bounds.east + step / 2
                               : raster.bounds.north + step / 2);
    }
    const std::string size = std::to_string(raster.size + 1);
    const char* argv[] = {"-r",
                          "bilinear",
                          "-et",
                          "0",
                          "-te",
                          buffer[0],
                          buffer[1],
                          buffer[2],
                          buffer[3],
                          "-ts",
                          size.c_str(),
                          size.c_str(),
                          "-ot",
                          "Float64",
                          "-of",
                          "MEM",
                          nullptr};
    GDALWarpAppOptions* warp_options = GDALWarpAppOptionsNew(const_cast<char**>(argv), nullptr);
    REQUIRE(warp_options != nullptr);
    GDALDatasetH src = GDALOpen(path->c_str(), GA_ReadOnly);
    REQUIRE(src != nullptr);
    int usage_error = 0;
    GDALDatasetH warped = GDALWarp("", nullptr, 1, &src, warp_options, &usage_error);
    GDALWarpAppOptionsFree(warp_options);
    REQUIRE(warped != nullptr);
    const int w = raster.size + 1;
    std::vector<double> expected(static_cast<std::size_t>(w) * w);
    REQUIRE(GDALRasterIO(GDALGetRasterBand(warped, 1),
                         GF_Read,
                         0,
                         0,
                         w,
                         w,
                         expected.data(),
                         w,
                         w,
                         GDT_Float64,
                         0,
                         0) == CE_None);
    GDALClose(warped);
    GDALClose(src);
    double worst = 0;
    for (std::size_t k = 0; k < expected.size(); ++k) {
        worst = std::max(worst, std::abs(raster.grid.heights[k] - expected[k]));
    }
    MESSAGE("largest difference to gdalwarp: " << worst << " m");
    CHECK(worst < 0.01);
}

TEST_CASE("neighbouring tiles of N44W072.hgt share border samples and border vertices exactly") {
    const auto path = tb_test::shared_dem("N44W072.hgt");
    if (!path) {
        return;
    }
    LayerOptions options;
    options.sources = {*path};
    const auto layer = Layer::open(options);
    const int z = layer->max_zoom() - 1;
    const TileRange r = layer->tiles_at(z);
    const TileId a{z, r.x0 + 1, r.y0};
    const TileId east{z, a.x + 1, a.y}, north{z, a.x, a.y + 1}; // geodetic: y + 1 is north
    const TileRaster ra = layer->make_raster(a);
    const TileRaster re = layer->make_raster(east);
    const TileRaster rn = layer->make_raster(north);
    check_shared_border(ra, re, true);
    check_shared_border(ra, rn, false);
    const ErrorBudget budget = tile_error_budget(layer->eps_for_zoom(z), ra.scheme, z, ra.size);
    const auto ma = mesh_tile(ra, budget), me = mesh_tile(re, budget), mn = mesh_tile(rn, budget);
    const int n = ra.size;
    CHECK(border_vertices(ma, n, 'E') == border_vertices(me, n, 'W'));
    CHECK(border_vertices(ma, n, 'N') == border_vertices(mn, n, 'S'));
    CHECK(border_vertices(ma, n, 'E').size() >= 2);
}

TEST_CASE("tiles with voids on their shared border fill it identically (N46E008.tif)") {
    const auto path = tb_test::shared_dem("N46E008.tif");
    if (!path) {
        return;
    }
    LayerOptions options;
    options.sources = {*path};
    options.tile_size = 64;
    const auto layer = Layer::open(options);
    const int z = layer->max_zoom();
    const TileRange r = layer->tiles_at(z);
    // Walk a row of tiles through the middle of the cell until some shared borders hold voids.
    int borders_with_voids = 0;
    const std::int64_t y = (r.y0 + r.y1) / 2;
    TileRaster previous = layer->make_raster({z, r.x0 + 1, y});
    for (std::int64_t x = r.x0 + 2; x < r.x1 && borders_with_voids < 3; ++x) {
        TileRaster next = layer->make_raster({z, x, y});
        bool voids = false;
        for (int k = 0; k <= next.size; ++k) {
            voids = voids || !next.grid.is_valid(0, k);
        }
        check_shared_border(previous, next, true);
        if (voids) {
            ++borders_with_voids;
            const ErrorBudget budget =
                tile_error_budget(layer->eps_for_zoom(z), next.scheme, z, next.size);
            CHECK(border_vertices(mesh_tile(previous, budget), next.size, 'E') ==
                  border_vertices(mesh_tile(next, budget), next.size, 'W'));
        }
        previous = std::move(next);
    }
    CHECK(borders_with_voids > 0);
}
