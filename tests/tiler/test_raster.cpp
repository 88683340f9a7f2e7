// Reading DEMs into tile rasters: bilinear sampling against GDAL's warper, nodata/NaN,
// scale/offset, void filling, the geoid, bit-identical borders of neighbouring tiles, and
// coarse zooms read from overviews (which level, their values, shared samples, `info`).
#include "core/error.hpp"
#include "core/triangulate.hpp"
#include "tests/tiler/qm_reader.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/layer.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/geoid.hpp"
#include "tiler/sources/lattice_raster.hpp"

#include <cpl_string.h>
#include <cpl_vsi.h>
#include <doctest/doctest.h>
#include <gdal_utils.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
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

// ---- Overview fixtures ----

// The fixture: kSide x kSide Float32 pixels of kPixel degrees from (kLon0, kLat0), north-west
// corner. kPixel = 180 / 2^20 makes the lattice spacing of 256-sample tiles exactly 2^(12 - z)
// pixels, so zoom 12 is native and each zoom above doubles pixels_per_sample. The origin is
// off the lattice, so samples fall between pixel centres.
constexpr int kSide = 2049;
constexpr double kPixel = 180.0 / (1 << 20);
constexpr double kLon0 = 10.0, kLat0 = 46.0;
constexpr int kNative = 12;

// A smooth surface at source pixel-centre coordinates (u, v): bilinear interpolation at a
// spacing of L pixels is within about 3e-4 L^2 m of it.
double surface(double u, double v) {
    return 300 + 100 * std::sin(u / 250) * std::cos(v / 350) + 0.05 * u - 0.03 * v;
}

// Pixel-centre coordinates of a lon/lat in the fixture.
double source_u(double lon) {
    return (lon - kLon0) / kPixel - 0.5;
}
double source_v(double lat) {
    return (kLat0 - lat) / kPixel - 0.5;
}

// Writes the fixture with AVERAGE overviews of factors 2, 4, 8 and 16 (1025, 513, 257 and 129
// pixels wide), optionally with nodata pixels where `hole` says so.
std::string write_surface(const std::string& path, bool (*hole)(int, int) = nullptr) {
    Fixture f;
    f.width = f.height = kSide;
    f.geotransform = std::array<double, 6>{kLon0, kPixel, 0, kLat0, 0, -kPixel};
    f.epsg = 4326;
    f.values.resize(static_cast<std::size_t>(kSide) * kSide);
    for (int r = 0; r < kSide; ++r) {
        for (int c = 0; c < kSide; ++c) {
            const bool void_pixel = hole && hole(c, r);
            f.values[static_cast<std::size_t>(r) * kSide + c] = void_pixel ? -9999 : surface(c, r);
        }
    }
    if (hole) {
        f.nodata = -9999;
    }
    tb_test::write_fixture(path, f);
    GDALDatasetUniquePtr ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_UPDATE));
    REQUIRE(ds != nullptr);
    const int factors[] = {2, 4, 8, 16};
    REQUIRE(ds->BuildOverviews("AVERAGE", 4, factors, 0, nullptr, nullptr, nullptr) == CE_None);
    REQUIRE(ds->GetRasterBand(1)->GetOverviewCount() == 4);
    return path;
}

// Adds `delta` to every pixel of every overview of band 1, so values read from an overview
// are recognizably not the full-resolution ones.
void shift_overviews(const std::string& path, double delta) {
    GDALDatasetUniquePtr ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_UPDATE));
    REQUIRE(ds != nullptr);
    GDALRasterBand* band = ds->GetRasterBand(1);
    for (int k = 0; k < band->GetOverviewCount(); ++k) {
        GDALRasterBand* o = band->GetOverview(k);
        const int w = o->GetXSize(), h = o->GetYSize();
        std::vector<double> values(static_cast<std::size_t>(w) * h);
        REQUIRE(o->RasterIO(GF_Read, 0, 0, w, h, values.data(), w, h, GDT_Float64, 0, 0, nullptr) ==
                CE_None);
        for (double& value : values) {
            value += delta;
        }
        REQUIRE(
            o->RasterIO(GF_Write, 0, 0, w, h, values.data(), w, h, GDT_Float64, 0, 0, nullptr) ==
            CE_None);
    }
}

// The lattice block of (geodetic, z, 256) covering the whole fixture.
LatticeBlock sample_all(const DemSource& source, int z) {
    const double step = 180.0 / (1 << z) / 256;
    const auto c0 = static_cast<std::int64_t>(std::floor((kLon0 + 180) / step));
    const auto r0 = static_cast<std::int64_t>(std::floor((90 - kLat0) / step));
    const int n = static_cast<int>(std::ceil(kSide * kPixel / step)) + 2;
    return source.sample(Scheme::Geodetic, z, 256, c0, r0, n, n);
}

// Calls f(k, u, v) for every sample k of a block of (geodetic, z, 256) whose lattice point lies
// within the fixture's pixel area, (u, v) being that point in source pixel-centre coordinates;
// returns how many samples lie outside it.
template <class F> int for_each_inside(const LatticeBlock& block, int z, F f) {
    int outside = 0;
    for (int j = 0; j < block.height; ++j) {
        for (int i = 0; i < block.width; ++i) {
            const std::size_t k = static_cast<std::size_t>(j) * block.width + i;
            const double u = source_u(lattice_x(Scheme::Geodetic, z, 256, block.column0 + i));
            const double v = source_v(lattice_y(Scheme::Geodetic, z, 256, block.row0 + j));
            if (u < -0.5 || v < -0.5 || u > kSide - 0.5 || v > kSide - 0.5) {
                CHECK_FALSE(block.valid[k]);
                ++outside;
                continue;
            }
            f(k, u, v);
        }
    }
    return outside;
}

// The tile of zoom z containing the fixture's centre.
// Metres between two points a few kilometres apart (an equirectangular approximation).
double metres_between(const LonLat& a, const LonLat& b) {
    const double c = std::cos((a.lat + b.lat) * M_PI / 360.0);
    return std::hypot((a.lon - b.lon) * c * 111320.0, (a.lat - b.lat) * 110574.0);
}

// A 1,000 m plateau of 0.2 x 0.2 degrees (200 x 200 pixels) from (lon0, lat0), its north-west
// corner, written under `dir`.
std::string write_plateau(const ScratchDir& dir, double lon0, double lat0) {
    const Fixture f = geographic(200, 200, lon0, lat0, std::vector<double>(200 * 200, 1000.0));
    return tb_test::write_fixture(dir.file("plateau.tif"), f);
}

TileId centre_tile(int z) {
    const double lon = kLon0 + kSide * kPixel / 2, lat = kLat0 - kSide * kPixel / 2;
    const double width = 180.0 / (1 << z); // geodetic tiles are square, y counted from the south
    return {z,
            static_cast<std::int64_t>(std::floor((lon + 180) / width)),
            static_cast<std::int64_t>(std::floor((lat + 90) / width))};
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
        MESSAGE("skipped: " << std::string(kEgm96GridPath)
                            << " is missing (Debian package proj-data)");
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

TEST_CASE("read_pixels gives each pixel's height, NaN for nodata and off the raster, any window") {
    ScratchDir dir;
    const int w = 13, h = 9;
    std::vector<double> values(static_cast<std::size_t>(w) * h);
    for (int j = 0; j < h; ++j) {
        for (int i = 0; i < w; ++i) {
            values[static_cast<std::size_t>(j) * w + i] = 100.0 * j + i + 0.25;
        }
    }
    values[3 * w + 4] = -9999;
    Fixture f = geographic(w, h, 10.0, 45.0, values);
    f.nodata = -9999;
    f.scale = 2.0; // heights are 2 * raw + 1
    f.offset = 1.0;
    const auto source = DemSource::open({tb_test::write_fixture(dir.file("window.tif"), f)});
    const auto expected = [&](std::int64_t i, std::int64_t j) -> double {
        if (i < 0 || j < 0 || i >= w || j >= h || (i == 4 && j == 3)) {
            return NAN;
        }
        return 2.0 * values[static_cast<std::size_t>(j) * w + i] + 1.0;
    };
    // Inside; over each side and corner; larger than the raster; wholly off it.
    const std::array<std::array<std::int64_t, 4>, 9> windows{{{2, 1, 5, 4},
                                                              {-3, 2, 6, 3},
                                                              {9, 2, 7, 3},
                                                              {1, -2, 4, 5},
                                                              {1, 6, 4, 6},
                                                              {-2, -2, 5, 5},
                                                              {10, 7, 6, 5},
                                                              {-4, -3, 21, 15},
                                                              {20, 0, 3, 3}}};
    for (const auto& [c0, r0, ww, wh] : windows) {
        CAPTURE(c0);
        CAPTURE(r0);
        const std::vector<double> got =
            source->read_pixels(c0, r0, static_cast<int>(ww), static_cast<int>(wh));
        REQUIRE(got.size() == static_cast<std::size_t>(ww * wh));
        for (std::int64_t j = 0; j < wh; ++j) {
            for (std::int64_t i = 0; i < ww; ++i) {
                const double want = expected(c0 + i, r0 + j);
                const double v = got[static_cast<std::size_t>(j * ww + i)];
                if (std::isnan(want)) {
                    CHECK(std::isnan(v));
                } else {
                    CHECK(v == want);
                }
            }
        }
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
    const TileRaster raster = layer->make_raster(layer->tile(id));
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
    const TileRaster ra = layer->make_raster(layer->tile(a));
    const TileRaster re = layer->make_raster(layer->tile(east));
    const TileRaster rn = layer->make_raster(layer->tile(north));
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
    TileRaster previous = layer->make_raster(layer->tile({z, r.x0 + 1, y}));
    for (std::int64_t x = r.x0 + 2; x < r.x1 && borders_with_voids < 3; ++x) {
        TileRaster next = layer->make_raster(layer->tile({z, x, y}));
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

TEST_CASE("beyond the DEM's footprint, lattice tiles carry its edge outward on a gentle slope") {
    // A plateau across the corner of four zoom-9 tiles (lon 10.1953, lat 45.7031). Its edge
    // carried outward and lowered at kEdgeGrade reaches sea level 2 km out;
    // a cliff would drop 1,000 m between two samples.
    ScratchDir dir;
    LayerOptions options;
    options.sources = {write_plateau(dir, 10.1, 45.8)};
    options.min_zoom = 5;
    const auto layer = Layer::open(options);
    const LonLatBox box = layer->data_bounds(); // its pixel centres
    const auto metres = metres_between;
    const auto ortho = [](const TileRaster& r, int i, int j) {
        const LonLat p = grid_to_lonlat(r, i, j);
        return r.grid.at(i, j) - egm96_undulation(p.lon, p.lat);
    };
    for (const int z : {7, 9}) {
        CAPTURE(z);
        REQUIRE(layer->zoom_source(z) != ZoomSource::Pixels);
        const TileRange range = tiles_covering(Scheme::Geodetic, box, z);
        int outside = 0, far = 0, steep = 0;
        for (std::int64_t y = range.y0; y <= range.y1; ++y) {
            for (std::int64_t x = range.x0; x <= range.x1; ++x) {
                const TileRaster r = layer->make_terrain_raster(layer->tile({z, x, y}));
                // The edge is carried from the lattice points inside the box of the outermost
                // pixel centres, and its slope starts a lattice step beyond them; samples up to
                // half a pixel beyond the box are the DEM's own. Next to those, the slope may
                // start up to a diagonal lattice step further out.
                const double slack = metres(grid_to_lonlat(r, 0, 0), grid_to_lonlat(r, 1, 1));
                for (int j = 0; j <= r.size; ++j) {
                    for (int i = 0; i <= r.size; ++i) {
                        const LonLat p = grid_to_lonlat(r, i, j);
                        const LonLat q{std::clamp(p.lon, box.west, box.east),
                                       std::clamp(p.lat, box.south, box.north)};
                        if ((q.lon == p.lon && q.lat == p.lat) || r.grid.is_valid(i, j)) {
                            continue; // inside the box of pixel centres, or measured
                        }
                        ++outside;
                        const double h = ortho(r, i, j);
                        CHECK(h >= -0.01);
                        CHECK(h <= 1000.01);
                        if (metres(p, q) > 1000.0 / kEdgeGrade * 1.02 + 1000.0) {
                            ++far;
                            CHECK(std::abs(h) < 0.01); // sea level, no plateau invented
                        }
                        // Against the next sample east and south: no steeper than the grade.
                        for (const auto& [di, dj] : {std::pair{1, 0}, std::pair{0, 1}}) {
                            if (i + di <= r.size && j + dj <= r.size) {
                                const double run = metres(p, grid_to_lonlat(r, i + di, j + dj));
                                const double rise = std::abs(ortho(r, i + di, j + dj) - h);
                                steep += rise > kEdgeGrade * (run + slack) * 1.02 + 0.01;
                            }
                        }
                    }
                }
            }
        }
        CHECK(outside > 0);
        CHECK(far > 0);
        CHECK(steep == 0);
    }
    // The pixels next to the edge stay within each zoom's eps: in glb tiles, which leave the
    // voids out but keep the triangles that reach into the first of them, and in globe terrain.
    for (const int z : {7, 9}) {
        const TileRange range = tiles_covering(Scheme::Geodetic, box, z);
        for (std::int64_t y = range.y0; y <= range.y1; ++y) {
            for (std::int64_t x = range.x0; x <= range.x1; ++x) {
                const ValidTile tile = layer->tile({z, x, y});
                CHECK(layer->tile_error(tile) <= layer->eps_for_zoom(z) + 1e-9);
                layer->make_tile(tile, Format::Terrain);
            }
        }
    }
    CHECK(layer->tiles_over_eps() == 0);
    // The four zoom-9 tiles around the corner agree on their shared borders, carried samples
    // included.
    const TileRange r9 = tiles_covering(Scheme::Geodetic, box, 9);
    REQUIRE(r9.x1 == r9.x0 + 1);
    REQUIRE(r9.y1 == r9.y0 + 1);
    const auto raster = [&](std::int64_t x, std::int64_t y) {
        return layer->make_terrain_raster(layer->tile({9, x, y}));
    };
    check_shared_border(raster(r9.x0, r9.y0), raster(r9.x1, r9.y0), true);
    check_shared_border(raster(r9.x0, r9.y0), raster(r9.x0, r9.y1), false);
    check_shared_border(raster(r9.x1, r9.y0), raster(r9.x1, r9.y1), false);
}

TEST_CASE("globe terrain tiles at the pixel zoom carry the DEM's edge to their corners beyond it") {
    // Tiles meshed off the pixels end at the DEM's outline; cover_rectangle joins it to the
    // tile's corners, which take the lattice's carried height (sea level 2 km out), not the
    // geoid next to a 1,000 m edge. The plateau's north-east pixel centre lies 0.0003 degrees
    // west and 0.0049 south of a zoom-10 tile corner (lon 10.9453, lat 45.8789).
    ScratchDir dir;
    LayerOptions options;
    options.sources = {write_plateau(dir, 10.7455, 45.8745)};
    const auto layer = Layer::open(options);
    const int z = layer->max_zoom();
    REQUIRE(layer->zoom_source(z) == ZoomSource::Pixels);
    const LonLatBox box = layer->data_bounds(); // its pixel centres
    const TileRange range = tiles_covering(Scheme::Geodetic, box, z);
    int corners = 0, carried = 0;
    for (std::int64_t y = range.y0; y <= range.y1; ++y) {
        for (std::int64_t x = range.x0; x <= range.x1; ++x) {
            const TileId id{z, x, y};
            const tb_qm::Tile t = tb_qm::read(layer->make_tile(layer->tile(id), Format::Terrain));
            const LonLatBox b = tile_bounds(Scheme::Geodetic, id);
            // A diagonal lattice step: the carried height starts from the lattice point
            // nearest the box, up to that far inside it, and drops from a step beyond it.
            const double step = (b.east - b.west) / 256;
            const double slack = metres_between({b.west, b.south}, {b.west + step, b.south + step});
            for (std::size_t i = 0; i < t.vertex_count; ++i) {
                if ((t.u[i] != 0 && t.u[i] != 32767) || (t.v[i] != 0 && t.v[i] != 32767)) {
                    continue;
                }
                const LonLat p{t.lon(i, b.west, b.east), t.lat(i, b.south, b.north)};
                const LonLat q{std::clamp(p.lon, box.west, box.east),
                               std::clamp(p.lat, box.south, box.north)};
                if (q.lon == p.lon && q.lat == p.lat) {
                    continue; // a corner over the data
                }
                ++corners;
                const double ortho = t.height(i) - egm96_undulation(p.lon, p.lat);
                const double d = metres_between(p, q);
                // The slope starts one lattice step beyond the footprint's lattice points.
                CHECK(ortho <= std::max(0.0, 1000.0 - kEdgeGrade * (d - slack)) + 0.1);
                CHECK(ortho >= std::max(0.0, 1000.0 - kEdgeGrade * (d + slack)) - 0.1);
                carried += ortho > 0.1 ? 1 : 0;
            }
        }
    }
    MESSAGE(corners << " tile corners beyond the DEM, " << carried << " within 2 km of it");
    CHECK(carried > 0);
}

TEST_CASE("each zoom reads the coarsest overview no coarser than its samples, then decimates") {
    ScratchDir dir;
    const auto source = DemSource::open({write_surface(dir.file("surface.tif"))});
    struct Expected {
        int z, overview, width, step;
    };
    // pixels_per_sample is 2^(12 - z); overview k has factor 2049 / width, just under 2^(k+1).
    const Expected expected[] = {{13, -1, kSide, 1},
                                 {12, -1, kSide, 1},
                                 {11, 0, 1025, 1},
                                 {10, 1, 513, 1},
                                 {9, 2, 257, 1},
                                 {8, 3, 129, 1},
                                 {7, 3, 129, 2},
                                 {6, 3, 129, 4}};
    for (const auto& e : expected) {
        INFO("zoom " << e.z);
        CHECK(source->pixels_per_sample(Scheme::Geodetic, e.z, 256) ==
              std::ldexp(1.0, kNative - e.z));
        const ReadLevel level = source->read_level(Scheme::Geodetic, e.z, 256);
        CHECK(level.overview == e.overview);
        CHECK(level.width == e.width);
        CHECK(level.height == e.width);
        CHECK(level.factor == doctest::Approx(static_cast<double>(kSide) / e.width));
        CHECK(level.step == e.step);
    }

    // Without overviews the same zooms decimate band 1, as before overviews were read.
    Fixture plain;
    plain.width = plain.height = 64;
    plain.geotransform = std::array<double, 6>{kLon0, kPixel, 0, kLat0, 0, -kPixel};
    plain.epsg = 4326;
    const auto bare = DemSource::open({tb_test::write_fixture(dir.file("plain.tif"), plain)});
    const ReadLevel level = bare->read_level(Scheme::Geodetic, 9, 256);
    CHECK(level.overview == -1);
    CHECK(level.width == 64);
    CHECK(level.factor == 1.0);
    CHECK(level.step == 8);
}

TEST_CASE("coarse zooms take their heights from the overview, the native zoom from band 1") {
    ScratchDir dir;
    const std::string path = write_surface(dir.file("surface.tif"));
    shift_overviews(path, 1000); // overview values are the surface + 1000 m
    const auto source = DemSource::open({path});
    for (int z = 6; z <= kNative; ++z) {
        const ReadLevel level = source->read_level(Scheme::Geodetic, z, 256);
        const LatticeBlock block = sample_all(*source, z);
        // Spacing of the values interpolated, in source pixels: the interpolation error grows
        // with its square; clamping beyond the outer pixel centres spoils one spacing at the
        // edges, so those are left out.
        const double spacing = level.factor * level.step;
        const double tolerance = level.overview < 0 ? 0.01 : 0.3 + 5e-4 * spacing * spacing;
        const double shift = level.overview < 0 ? 0.0 : 1000.0;
        int checked = 0;
        double worst = 0;
        const int outside = for_each_inside(block, z, [&](std::size_t k, double u, double v) {
            REQUIRE(block.valid[k]);
            if (std::min({u, v, kSide - 1 - u, kSide - 1 - v}) < spacing) {
                return;
            }
            worst = std::max(worst, std::abs(block.heights[k] - (surface(u, v) + shift)));
            ++checked;
        });
        INFO("zoom " << z << ": overview " << level.overview << ", step " << level.step
                     << ", largest error " << worst << " m over " << checked << " samples");
        CHECK(worst <= tolerance);
        CHECK(checked >= 500);
        CHECK(outside > 0);
    }
}

TEST_CASE("overview zooms keep shared samples bit-identical across blocks and tiles") {
    ScratchDir dir;
    const std::string path = write_surface(dir.file("surface.tif"));
    const auto source = DemSource::open({path});
    // Blocks of 33 x 33 samples sharing their edges, and one block spanning all four: every
    // lattice point must get the same bits and validity in each block that holds it.
    for (int z : {11, 9, 7}) {
        const double step = 180.0 / (1 << z) / 256;
        const auto c0 = static_cast<std::int64_t>(std::floor((kLon0 + 180) / step)) + 3;
        const auto r0 = static_cast<std::int64_t>(std::floor((90 - kLat0) / step)) + 3;
        REQUIRE(source->read_level(Scheme::Geodetic, z, 256).overview >= 0);
        const LatticeBlock all = source->sample(Scheme::Geodetic, z, 256, c0, r0, 65, 65);
        int compared = 0, differences = 0;
        for (int by = 0; by < 2; ++by) {
            for (int bx = 0; bx < 2; ++bx) {
                const LatticeBlock part =
                    source->sample(Scheme::Geodetic, z, 256, c0 + 32 * bx, r0 + 32 * by, 33, 33);
                for (int j = 0; j < 33; ++j) {
                    for (int i = 0; i < 33; ++i) {
                        const std::size_t a = static_cast<std::size_t>(j) * 33 + i;
                        const std::size_t b =
                            static_cast<std::size_t>(j + 32 * by) * 65 + (i + 32 * bx);
                        if (std::memcmp(&part.heights[a], &all.heights[b], sizeof(double)) != 0 ||
                            part.valid[a] != all.valid[b]) {
                            ++differences;
                        }
                        compared += part.valid[a];
                    }
                }
            }
        }
        INFO("zoom " << z);
        CHECK(differences == 0);
        CHECK(compared > 1000);
    }

    // Neighbouring tiles of a layer (64-sample tiles: zoom 11 reads the 257-pixel overview).
    LayerOptions options;
    options.sources = {path};
    options.tile_size = 64;
    options.min_zoom = 10; // zoom 9 tiles would hold the whole 2049-pixel DEM, over the limit
    options.datum = VerticalDatum::Ellipsoid;
    const auto layer = Layer::open(options);
    for (int z : {11, 10}) {
        INFO("zoom " << z);
        const TileId a = centre_tile(z);
        const TileId east{z, a.x + 1, a.y}, north{z, a.x, a.y + 1}; // geodetic: y + 1 is north
        const TileRaster ra = layer->make_raster(layer->tile(a));
        check_shared_border(ra, layer->make_raster(layer->tile(east)), true);
        check_shared_border(ra, layer->make_raster(layer->tile(north)), false);
    }
}

TEST_CASE("an overview zoom's tile raster is the bilinear interpolation of the overview pixels") {
    ScratchDir dir;
    const std::string path = write_surface(dir.file("surface.tif"));
    LayerOptions options;
    options.sources = {path};
    options.tile_size = 64;
    options.min_zoom = 10;
    options.datum = VerticalDatum::Ellipsoid; // the source's own heights, no geoid
    const auto layer = Layer::open(options);

    // The overviews read directly, as GDAL stores them.
    GDALDatasetUniquePtr ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
    REQUIRE(ds != nullptr);
    GDALRasterBand* band = ds->GetRasterBand(1);
    // With 64-sample tiles zoom 14 is native: pixels_per_sample = 2^(14 - z), and the overview
    // of factor 2049 / width just below it is read, undecimated.
    // Zooms whose lattice step spans 8 pixels or more read the summary instead (checked below).
    const struct { int z, width; } zooms[] = {{13, 1025}, {12, 513}};
    CHECK(layer->zoom_source(11) == ZoomSource::Summary);
    CHECK(layer->zoom_source(10) == ZoomSource::Summary);
    for (const auto& zoom : zooms) {
        GDALRasterBand* overview = nullptr;
        for (int k = 0; k < band->GetOverviewCount(); ++k) {
            if (band->GetOverview(k)->GetXSize() == zoom.width) {
                overview = band->GetOverview(k);
            }
        }
        REQUIRE(overview != nullptr);
        const int wo = overview->GetXSize(), ho = overview->GetYSize();
        const auto pixel = [&](int i, int j) {
            float value = 0;
            REQUIRE(overview->RasterIO(
                        GF_Read, i, j, 1, 1, &value, 1, 1, GDT_Float32, 0, 0, nullptr) == CE_None);
            return static_cast<double>(value);
        };

        const TileId id = centre_tile(zoom.z);
        const TileRaster raster = layer->make_raster(layer->tile(id));
        const std::int64_t c0 = tile_first_column(Scheme::Geodetic, id, 64);
        const std::int64_t r0 = tile_first_row(Scheme::Geodetic, id, 64);
        int checked = 0;
        double worst = 0;
        for (int j = 0; j <= 64; j += 8) {
            for (int i = 0; i <= 64; i += 8) {
                const double lon = lattice_x(Scheme::Geodetic, zoom.z, 64, c0 + i);
                const double lat = lattice_y(Scheme::Geodetic, zoom.z, 64, r0 + j);
                // Pixel-centre coordinates in the overview, which spans the source's extent.
                const double uo = (source_u(lon) + 0.5) * wo / kSide - 0.5;
                const double vo = (source_v(lat) + 0.5) * ho / kSide - 0.5;
                if (uo < 0 || vo < 0 || uo > wo - 1 || vo > ho - 1) {
                    continue; // beyond the outer pixel centres, where the reader clamps
                }
                const int iu = std::min(static_cast<int>(uo), wo - 2);
                const int iv = std::min(static_cast<int>(vo), ho - 2);
                const double a = uo - iu, b = vo - iv;
                const double expected =
                    (1 - a) * (1 - b) * pixel(iu, iv) + a * (1 - b) * pixel(iu + 1, iv) +
                    (1 - a) * b * pixel(iu, iv + 1) + a * b * pixel(iu + 1, iv + 1);
                REQUIRE(raster.grid.is_valid(i, j));
                worst = std::max(worst, std::abs(raster.grid.at(i, j) - expected));
                ++checked;
            }
        }
        INFO("zoom " << zoom.z << ": largest difference " << worst << " m over " << checked
                     << " samples");
        CHECK(checked >= 40);
        CHECK(worst < 1e-4); // float32 rounding of heights near 300 m is 3e-5 m
    }
}

TEST_CASE("overviews keep nodata voids that cover whole overview pixels") {
    ScratchDir dir;
    // A 300 x 300 pixel nodata square in the middle of the surface.
    const auto hole = [](int c, int r) { return c >= 900 && c < 1200 && r >= 900 && r < 1200; };
    const auto source = DemSource::open({write_surface(dir.file("holes.tif"), hole)});
    const int z = 9; // the 257-pixel overview, pixels of 8 source pixels
    REQUIRE(source->read_level(Scheme::Geodetic, z, 256).overview == 2);
    const LatticeBlock block = sample_all(*source, z);
    int voids = 0, valid = 0;
    for_each_inside(block, z, [&](std::size_t k, double u, double v) {
        // Well inside the hole: void. Well away from it: valid, never a -9999 blend.
        const double inside = std::min({u - 900, 1199 - u, v - 900, 1199 - v});
        if (inside > 16) {
            CHECK_FALSE(block.valid[k]);
            ++voids;
        } else if (inside < -16) {
            REQUIRE(block.valid[k]);
            CHECK(std::abs(block.heights[k] - surface(u, v)) < 2.0);
            ++valid;
        }
    });
    CHECK(voids > 100);
    CHECK(valid > 10000);
}

TEST_CASE("overviews in an external .ovr file and a mosaic's implicit overviews are read") {
    ScratchDir dir;
    // Three 1024 x 1024 tiles of 100 m: external.tif gets its overviews in external.tif.ovr
    // (GTiff writes them there when the file is opened read-only); west.tif and east.tif get
    // internal ones, and a mosaic of the two gets implicit ones from GDAL's VRT.
    const auto write_flat = [&](const std::string& name, int column0, bool external) {
        Fixture f;
        f.width = f.height = 1024;
        f.geotransform =
            std::array<double, 6>{kLon0 + column0 * kPixel, kPixel, 0, kLat0, 0, -kPixel};
        f.epsg = 4326;
        f.values.assign(static_cast<std::size_t>(1024) * 1024, 100.0);
        const std::string path = tb_test::write_fixture(dir.file(name), f);
        GDALDatasetUniquePtr ds(GDALDataset::Open(
            path.c_str(), GDAL_OF_RASTER | (external ? GDAL_OF_READONLY : GDAL_OF_UPDATE)));
        REQUIRE(ds != nullptr);
        const int factors[] = {2, 4};
        REQUIRE(ds->BuildOverviews("AVERAGE", 2, factors, 0, nullptr, nullptr, nullptr) == CE_None);
        ds.reset();
        shift_overviews(path, 1000);
        return path;
    };
    const std::string external = write_flat("external.tif", 0, true);
    REQUIRE(std::filesystem::exists(external + ".ovr"));
    const std::string west = write_flat("west.tif", 0, false);
    const std::string east = write_flat("east.tif", 1024, false);

    struct Case {
        std::vector<std::string> paths;
        int width, height;
    };
    // A mosaic's VRT is a file in GDAL's memory file system while its source lives, no longer.
    const auto memory_files = [] {
        const CPLStringList names(VSIReadDir("/vsimem/terrabound"));
        return names.size();
    };
    const int memory_files_before = memory_files();
    for (const Case& c : {Case{{external}, 256, 256}, Case{{west, east}, 512, 256}}) {
        INFO(c.paths.size() << " file(s)");
        const auto source = DemSource::open(c.paths);
        CHECK(memory_files() == memory_files_before + (c.paths.size() > 1 ? 1 : 0));
        // Zoom 9: 8 pixels per sample, so the factor-4 overview read every 2nd pixel.
        const ReadLevel level = source->read_level(Scheme::Geodetic, 9, 256);
        CHECK(level.overview == 1);
        CHECK(level.width == c.width);
        CHECK(level.height == c.height);
        CHECK(level.step == 2);
        const LatticeBlock block = sample_all(*source, 9);
        int valid = 0;
        for (std::size_t k = 0; k < block.heights.size(); ++k) {
            if (block.valid[k]) {
                CHECK(block.heights[k] == doctest::Approx(1100).epsilon(1e-12));
                ++valid;
            }
        }
        CHECK(valid > 100 * static_cast<int>(c.paths.size()));
    }
    CHECK(memory_files() == memory_files_before);
}

TEST_CASE(
    "info says what each zoom reads, and a large DEM without overviews gets a gdaladdo hint") {
    ScratchDir dir;
    const std::string surface = write_surface(dir.file("surface.tif"));
    // 5000 x 5000 pixels never written (sparse: a few KB), no overviews.
    {
        GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("GTiff");
        const char* options[] = {"SPARSE_OK=TRUE", "TILED=YES", nullptr};
        GDALDatasetUniquePtr ds(driver->Create(
            dir.file("large.tif").c_str(), 5000, 5000, 1, GDT_Int16, const_cast<char**>(options)));
        REQUIRE(ds != nullptr);
        double gt[6] = {kLon0, kPixel, 0, kLat0, 0, -kPixel};
        OGRSpatialReference srs;
        srs.importFromEPSG(4326);
        REQUIRE(ds->SetGeoTransform(gt) == CE_None);
        REQUIRE(ds->SetSpatialRef(&srs) == CE_None);
    }
    const auto run = [&](const std::string& arguments, std::string& out, std::string& err) {
        const std::string command = std::string(TB_BINARY) + " " + arguments + " >" +
                                    dir.file("out.txt") + " 2>" + dir.file("err.txt");
        const int status = std::system(command.c_str());
        std::ifstream o(dir.file("out.txt")), e(dir.file("err.txt"));
        out.assign(std::istreambuf_iterator<char>(o), {});
        err.assign(std::istreambuf_iterator<char>(e), {});
        return status;
    };
    std::string out, err;
    REQUIRE_MESSAGE(run("info " + surface, out, err) == 0, err);
    // Zooms 7..12 (256-sample tiles): see the first test case for the levels.
    CHECK(out.find("      12  ") != std::string::npos);
    // A lon/lat DEM's finest zoom is meshed on its own pixels; zooms whose lattice step spans
    // 8 pixels or more read the summary, those between read the overviews (read_level above).
    CHECK(out.find("guarantee:   tiles of the DEM's own zoom are meshed on its pixel centres") !=
          std::string::npos);
    CHECK(out.find("full resolution (the DEM's pixels)\n") != std::string::npos);
    CHECK(out.find("the summary's planes") != std::string::npos);
    CHECK(out.find("overview") != std::string::npos);
    CHECK(err.find("gdaladdo") == std::string::npos);

    REQUIRE_MESSAGE(run("info " + dir.file("large.tif"), out, err) == 0, err);
    CHECK(out.find("full resolution (the DEM's pixels)\n") != std::string::npos);
    // Once, though `info` opens the DEM twice (for the plan and for the reads column).
    const auto hint = err.find("gdaladdo -r average");
    CHECK(hint != std::string::npos);
    CHECK(err.find("gdaladdo -r average", hint + 1) == std::string::npos);
    CHECK(err.find(" info ") != std::string::npos); // logged at info level
}
