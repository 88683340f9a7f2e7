// The multi-resolution summary and the cell check, against brute force: every pixel of every
// block lies within its block's plane and range, and the cell check bounds every pixel under a
// drawn surface.
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/mesh/cell_check.hpp"
#include "tiler/sources/geoid.hpp"
#include "tiler/summary/dem_summary.hpp"
#include "tiler/summary/summary_file.hpp"
#include "tiler/summary/summary_tile.hpp"

#include <doctest/doctest.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>

using namespace tb::tiler;

namespace {

// A drawn surface over [0, n] x [0, n]: a grid of cells each cut by a random diagonal, random
// heights, some vertices moved off the lattice (as quantization moves them).
struct Surface {
    std::vector<std::array<double, 3>> vertices;
    std::vector<std::uint32_t> triangles;
};

Surface random_surface(int n, std::mt19937& rng) {
    std::uniform_real_distribution<double> h(-50, 50), jiggle(-0.3, 0.3);
    Surface s;
    for (int j = 0; j <= n; ++j) {
        for (int i = 0; i <= n; ++i) {
            const bool inner = i > 0 && j > 0 && i < n && j < n;
            s.vertices.push_back(
                {i + (inner ? jiggle(rng) : 0.0), j + (inner ? jiggle(rng) : 0.0), h(rng)});
        }
    }
    const auto at = [n](int i, int j) { return static_cast<std::uint32_t>(j * (n + 1) + i); };
    for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
            if (rng() % 2) {
                s.triangles.insert(s.triangles.end(), {at(i, j), at(i + 1, j), at(i + 1, j + 1)});
                s.triangles.insert(s.triangles.end(), {at(i, j), at(i + 1, j + 1), at(i, j + 1)});
            } else {
                s.triangles.insert(s.triangles.end(), {at(i, j), at(i + 1, j), at(i, j + 1)});
                s.triangles.insert(s.triangles.end(),
                                   {at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)});
            }
        }
    }
    return s;
}

// The drawn height at (x, y): the first triangle holding it (barycentric, with a hair).
bool drawn_at(const Surface& s, double x, double y, double& out) {
    for (std::size_t t = 0; t < s.triangles.size(); t += 3) {
        const auto& a = s.vertices[s.triangles[t]];
        const auto& b = s.vertices[s.triangles[t + 1]];
        const auto& c = s.vertices[s.triangles[t + 2]];
        const double det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
        const double la = ((b[0] - x) * (c[1] - y) - (c[0] - x) * (b[1] - y)) / det;
        const double lb = ((c[0] - x) * (a[1] - y) - (a[0] - x) * (c[1] - y)) / det;
        const double lc = 1 - la - lb;
        if (la >= -1e-12 && lb >= -1e-12 && lc >= -1e-12) {
            out = la * a[2] + lb * b[2] + lc * c[2];
            return true;
        }
    }
    return false;
}

} // namespace

TEST_CASE("the cell check bounds every pixel of every cell under a drawn surface (seeds 1-20)") {
    for (unsigned seed = 1; seed <= 20; ++seed) {
        CAPTURE(seed);
        std::mt19937 rng(seed);
        const int n = 6;
        const Surface s = random_surface(n, rng);
        // Pixels on a fine grid, grouped in blocks of 5 x 5 pixels with a random plane each.
        std::uniform_real_distribution<double> slope(-20, 20), rough(-3, 3);
        const double step = 0.13;
        const int px = static_cast<int>(n / step);
        std::vector<CheckCell> cells;
        double brute = 0;
        for (int by = 0; by * 5 < px; ++by) {
            for (int bx = 0; bx * 5 < px; ++bx) {
                CheckCell c;
                c.x0 = bx * 5 * step, c.y0 = by * 5 * step;
                c.x1 = std::min(bx * 5 + 4, px - 1) * step,
                c.y1 = std::min(by * 5 + 4, px - 1) * step;
                c.height = slope(rng), c.per_column = slope(rng), c.per_row = slope(rng);
                std::vector<std::array<double, 3>> pixels;
                for (int j = by * 5; j <= std::min(by * 5 + 4, px - 1); ++j) {
                    for (int i = bx * 5; i <= std::min(bx * 5 + 4, px - 1); ++i) {
                        const double x = i * step, y = j * step;
                        const double h = c.reference(x, y) + rough(rng);
                        c.half = std::max(c.half, std::abs(h - c.reference(x, y)));
                        pixels.push_back({x, y, h});
                    }
                }
                cells.push_back(c);
                for (const auto& p : pixels) {
                    double d = 0;
                    REQUIRE(drawn_at(s, p[0], p[1], d));
                    brute = std::max(brute, std::abs(d - p[2]));
                }
            }
        }
        const CellsVerdict v = cells_error(GridSurface{s.vertices, s.triangles}, cells);
        CHECK(v.outside == 0);
        CHECK(brute <= v.error);
    }
}

TEST_CASE("the cell check of single pixels is the brute-force error, exactly") {
    std::mt19937 rng(5);
    const Surface s = random_surface(5, rng);
    std::uniform_real_distribution<double> where(0, 5), h(-60, 60);
    std::vector<CheckCell> cells;
    double brute = 0;
    for (int k = 0; k < 400; ++k) {
        CheckCell c;
        c.x0 = c.x1 = where(rng);
        c.y0 = c.y1 = where(rng);
        c.height = h(rng);
        double d = 0;
        REQUIRE(drawn_at(s, c.x0, c.y0, d));
        brute = std::max(brute, std::abs(d - c.height));
        cells.push_back(c);
    }
    const CellsVerdict v = cells_error(GridSurface{s.vertices, s.triangles}, cells);
    CHECK(v.error == doctest::Approx(brute).epsilon(1e-9));
    // A cell beyond the surface is met by no triangle.
    CheckCell far;
    far.x0 = far.x1 = 40, far.y0 = far.y1 = 40;
    cells.push_back(far);
    CHECK(cells_error(GridSurface{s.vertices, s.triangles}, cells).outside == 1);
}

TEST_CASE("every valid pixel of a DEM lies within its summary block's plane and range, at every "
          "level") {
    tb_test::ScratchDir dir;
    tb_test::Fixture f;
    f.width = 301, f.height = 203; // not a multiple of any block
    f.values.resize(static_cast<std::size_t>(f.width) * f.height);
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> noise(0, 9);
    for (int j = 0; j < f.height; ++j) {
        for (int i = 0; i < f.width; ++i) {
            double h =
                800 + 3 * i - 2 * j + 300 * std::sin(i / 17.0) * std::cos(j / 11.0) + noise(rng);
            if (std::hypot(i - 120, j - 90) < 30 || (i > 250 && j < 20)) {
                h = -32768;
            }
            f.values[static_cast<std::size_t>(j) * f.width + i] = h;
        }
    }
    f.type = GDT_Int16;
    f.nodata = -32768;
    f.geotransform = std::array<double, 6>{7.6, 1.0 / 1200, 0, 46.4, 0, -1.0 / 1200};
    f.epsg = 4326;
    const std::string path = tb_test::write_fixture(dir.file("dem.tif"), f);
    const auto source = DemSource::open({path});
    const auto grid = source->pixel_grid(Scheme::Geodetic);
    REQUIRE(grid);
    for (const VerticalDatum datum : {VerticalDatum::Egm96, VerticalDatum::Ellipsoid}) {
        CAPTURE(to_string(datum));
        const DemSummary s =
            DemSummary::build(*source, PixelPlace(*source, Scheme::Geodetic), datum);
        CHECK(s.coarsest_level() == 9); // one block holds all 301 columns
        const std::vector<double> px = source->read_pixels(0, 0, f.width, f.height);
        for (int level = s.finest_level(); level <= s.coarsest_level(); ++level) {
            CAPTURE(level);
            double widest = 0;
            std::size_t checked = 0;
            for (std::int64_t j = 0; j < f.height; ++j) {
                for (std::int64_t i = 0; i < f.width; ++i) {
                    double h = px[static_cast<std::size_t>(j * f.width + i)];
                    if (std::isnan(h)) {
                        continue;
                    }
                    if (datum == VerticalDatum::Egm96) {
                        h += egm96_undulation(grid->x(i), grid->y(j));
                    }
                    const SummaryBlock* b = s.block(level, i >> level, j >> level);
                    REQUIRE(b != nullptr);
                    REQUIRE_FALSE(b->empty());
                    const double r =
                        h -
                        DemSummary::plane(*b, level, i >> level, j >> level, double(i), double(j));
                    CHECK(r >= b->low);
                    CHECK(r <= b->high);
                    widest = std::max(widest, static_cast<double>(b->high) - b->low);
                    ++checked;
                }
            }
            CHECK(checked > 50000);
            // The planes follow the slope: the ranges stay near the relief left over, far
            // below the DEM's own relief (about 1,900 m).
            if (level == s.finest_level()) {
                CHECK(widest < 150);
            }
        }
        // A block of voids only is empty.
        CHECK(s.block(3, 32, 1)->empty());
    }
}

namespace {

// A small lon/lat DEM with relief, written as a GeoTIFF.
std::string rough_dem(const tb_test::ScratchDir& dir, const std::string& name, double lift) {
    tb_test::Fixture f;
    f.width = 173, f.height = 131;
    f.values.resize(static_cast<std::size_t>(f.width) * f.height);
    for (int j = 0; j < f.height; ++j) {
        for (int i = 0; i < f.width; ++i) {
            f.values[static_cast<std::size_t>(j) * f.width + i] =
                lift + 500 + 200 * std::sin(i / 9.0) * std::cos(j / 13.0) + (i * 7 + j * 3) % 5;
        }
    }
    f.type = GDT_Float32;
    f.geotransform = std::array<double, 6>{7.6, 1.0 / 1200, 0, 46.4, 0, -1.0 / 1200};
    f.epsg = 4326;
    return tb_test::write_fixture(dir.file(name), f);
}

bool same_blocks(const DemSummary& a, const DemSummary& b) {
    if (a.width() != b.width() || a.height() != b.height() ||
        a.levels().size() != b.levels().size()) {
        return false;
    }
    for (std::size_t k = 0; k < a.levels().size(); ++k) {
        const auto& x = a.levels()[k];
        const auto& y = b.levels()[k];
        if (x.size() != y.size() ||
            !std::equal(x.begin(), x.end(), y.begin(), [](const auto& p, const auto& q) {
                return std::memcmp(&p, &q, sizeof(SummaryBlock)) == 0;
            })) {
            return false;
        }
    }
    return true;
}

// A rough DEM's summary and its key, as save_summary and load_summary take them.
struct MadeSummary {
    std::string dem;
    DemSummary summary;
    std::string key;
    explicit MadeSummary(const tb_test::ScratchDir& dir) : dem(rough_dem(dir, "rough.tif", 0)) {
        const auto source = DemSource::open({dem});
        const auto grid = source->pixel_grid(Scheme::Geodetic);
        REQUIRE(grid);
        summary = DemSummary::build(
            *source, PixelPlace(*source, Scheme::Geodetic), VerticalDatum::Ellipsoid);
        const auto made_key = summary_key(
            {dem}, std::nullopt, VerticalDatum::Ellipsoid, PixelPlace(*source, Scheme::Geodetic));
        REQUIRE(made_key);
        key = *made_key;
    }
};

} // namespace

TEST_CASE("a summary saved to disk reads back block for block, and a damaged, cut or foreign "
          "file is refused") {
    tb_test::ScratchDir dir;
    const std::string dem = rough_dem(dir, "rough.tif", 0);
    const auto source = DemSource::open({dem});
    const auto grid = source->pixel_grid(Scheme::Geodetic);
    REQUIRE(grid);
    const DemSummary made =
        DemSummary::build(*source, PixelPlace(*source, Scheme::Geodetic), VerticalDatum::Ellipsoid);
    const auto key = summary_key(
        {dem}, std::nullopt, VerticalDatum::Ellipsoid, PixelPlace(*source, Scheme::Geodetic));
    REQUIRE(key);
    const auto path = summary_path(dir.file("cache"), dem, *key);
    CHECK(path.filename().string().rfind("rough-", 0) == 0);
    CHECK_FALSE(load_summary(path, *key)); // nothing there yet
    save_summary(path, *key, made);
    const auto read = load_summary(path, *key);
    REQUIRE(read);
    CHECK(same_blocks(made, *read));
    // Another key (another datum) does not read this file.
    const auto other = summary_key(
        {dem}, std::nullopt, VerticalDatum::Egm96, PixelPlace(*source, Scheme::Geodetic));
    REQUIRE(other);
    CHECK(*other != *key);
    CHECK(summary_path(dir.file("cache"), dem, *other) != path);
    CHECK_FALSE(load_summary(path, *other));
    // One flipped bit, then a cut file: refused, never read as a summary.
    std::string bytes;
    {
        std::ifstream in(path, std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    const auto write = [&path](const std::string& b) {
        std::ofstream(path, std::ios::binary | std::ios::trunc) << b;
    };
    std::string flipped = bytes;
    flipped[flipped.size() / 2] ^= 0x10;
    write(flipped);
    CHECK_FALSE(load_summary(path, *key));
    write(bytes.substr(0, bytes.size() - 100));
    CHECK_FALSE(load_summary(path, *key));
    write(bytes);
    CHECK(load_summary(path, *key));
}

TEST_CASE("saving a summary removes the temporary files a killed process left an hour ago or "
          "more, and no other file") {
    namespace fs = std::filesystem;
    tb_test::ScratchDir dir;
    const MadeSummary m(dir);
    const fs::path cache = dir.file("cache");
    fs::create_directories(cache);
    const auto touch = [&](const std::string& name, std::chrono::minutes age) {
        std::ofstream(cache / name) << "half";
        fs::last_write_time(cache / name, fs::file_time_type::clock::now() - age);
    };
    touch("old-0123456789abcdef.tbsum.tmp-4242-1", std::chrono::minutes(61));
    touch("new-0123456789abcdef.tbsum.tmp-4243-1", std::chrono::minutes(5));
    touch("notes.tmp-1", std::chrono::minutes(600));
    save_summary(summary_path(cache, m.dem, m.key), m.key, m.summary);
    CHECK_FALSE(fs::exists(cache / "old-0123456789abcdef.tbsum.tmp-4242-1"));
    CHECK(fs::exists(cache / "new-0123456789abcdef.tbsum.tmp-4243-1"));
    CHECK(fs::exists(cache / "notes.tmp-1"));
    CHECK(load_summary(summary_path(cache, m.dem, m.key), m.key));
}

TEST_CASE("a layer keeps its summary in summary_dir, reads it back, and makes a new one when the "
          "source changes") {
    tb_test::ScratchDir dir;
    const std::string dem = rough_dem(dir, "valley.tif", 0);
    const std::string cache = dir.file("summaries");
    const auto open = [&] {
        LayerOptions o;
        o.sources = {dem};
        o.summary_dir = cache;
        o.min_zoom = 0;
        return Layer::open(o);
    };
    const auto files = [&] {
        std::vector<std::filesystem::path> out;
        if (std::filesystem::exists(cache)) {
            for (const auto& e : std::filesystem::directory_iterator(cache)) {
                out.push_back(e.path());
            }
        }
        return out;
    };
    auto first = open();
    const TileRange r = first->tiles_at(4); // lattice steps of 13 pixels: read off the summary
    REQUIRE(r.count() == 1);
    const TileId id{4, r.x0, r.y0};
    const auto make = [&id](const Layer& layer) {
        return layer.make_tile(layer.tile(id), Format::Glb, {});
    };
    const std::string tile = make(*first);
    first.reset(); // its dataset closed, as a later run would find it
    REQUIRE(files().size() == 1);
    const auto kept = files().front();
    CHECK(kept.extension() == ".tbsum");
    const auto written = std::filesystem::last_write_time(kept);
    // A second layer reads the file (it is not written again) and makes the same tile.
    CHECK(make(*open()) == tile);
    CHECK(std::filesystem::last_write_time(kept) == written);
    // The source changes: a new summary under a new name, and its tile follows the new heights.
    std::filesystem::remove(dem);
    rough_dem(dir, "valley.tif", 300);
    CHECK(make(*open()) != tile);
    CHECK(files().size() == 2);
    // "off" keeps nothing.
    LayerOptions off;
    off.sources = {dem};
    off.summary_dir = "off";
    off.min_zoom = 0;
    std::filesystem::remove_all(cache);
    make(*Layer::open(off));
    CHECK(files().empty());
}

TEST_CASE("a sparse GeoTIFF's unwritten blocks are voids in the summary, not read, and the "
          "written ones are summarised as a dense file's") {
    tb_test::ScratchDir dir;
    GDALAllRegister();
    const int n = 4096;
    const std::string path = dir.file("sparse.tif");
    {
        char** create = nullptr;
        create = CSLSetNameValue(create, "SPARSE_OK", "TRUE");
        create = CSLSetNameValue(create, "TILED", "YES");
        GDALDatasetUniquePtr ds(GetGDALDriverManager()->GetDriverByName("GTiff")->Create(
            path.c_str(), n, n, 1, GDT_Int16, create));
        CSLDestroy(create);
        REQUIRE(ds);
        const std::array<double, 6> g{7.0, 1.0 / 1200, 0, 47.0, 0, -1.0 / 1200};
        ds->SetGeoTransform(const_cast<double*>(g.data()));
        OGRSpatialReference srs;
        srs.importFromEPSG(4326);
        ds->SetSpatialRef(&srs);
        ds->GetRasterBand(1)->SetNoDataValue(-32768);
        // One written window of 300 x 200 pixels at (1000, 2000); everything else unwritten.
        std::vector<std::int16_t> hill(300 * 200);
        for (int j = 0; j < 200; ++j) {
            for (int i = 0; i < 300; ++i) {
                hill[static_cast<std::size_t>(j) * 300 + i] = static_cast<std::int16_t>(
                    400 + 100 * std::sin(i / 20.0) + 50 * std::cos(j / 15.0));
            }
        }
        REQUIRE(
            ds->GetRasterBand(1)->RasterIO(
                GF_Write, 1000, 2000, 300, 200, hill.data(), 300, 200, GDT_Int16, 0, 0, nullptr) ==
            CE_None);
    }
    const auto source = DemSource::open({path});
    CHECK(source->window_empty(0, 0, 512, 512));
    CHECK_FALSE(source->window_empty(1024, 2048, 256, 256));
    const auto grid = source->pixel_grid(Scheme::Geodetic);
    REQUIRE(grid);
    const DemSummary s =
        DemSummary::build(*source, PixelPlace(*source, Scheme::Geodetic), VerticalDatum::Ellipsoid);
    const std::vector<double> px = source->read_pixels(0, 0, n, n);
    std::size_t checked = 0, empty = 0;
    const int k = s.finest_level();
    for (std::int64_t by = 0; by < s.blocks_down(k); ++by) {
        for (std::int64_t bx = 0; bx < s.blocks_across(k); ++bx) {
            const SummaryBlock* b = s.block(k, bx, by);
            bool any = false;
            for (std::int64_t j = by << k; j <= s.last_row(k, by); ++j) {
                for (std::int64_t i = bx << k; i <= s.last_column(k, bx); ++i) {
                    const double h = px[static_cast<std::size_t>(j * n + i)];
                    if (std::isnan(h)) {
                        continue;
                    }
                    any = true;
                    const double r = h - DemSummary::plane(*b, k, bx, by, double(i), double(j));
                    CHECK(r >= b->low);
                    CHECK(r <= b->high);
                    ++checked;
                }
            }
            CHECK(b->empty() == !any);
            empty += b->empty() ? 1 : 0;
        }
    }
    CHECK(checked == 300 * 200);
    CHECK(empty > 250000);
    // 4096^2 pixels keep the finest level; a 100000^2 raster starts at 64-pixel blocks.
    CHECK(k == kFinestLevel);
    CHECK(summary_finest_level(100000, 100000) == 6);
    CHECK(summary_finest_level(14404, 14404) == kFinestLevel);
}

namespace {

// Every valid pixel of `source` inside the tile of `raster` lies in one of `cells` (box and
// half-range): returns how many were checked. The pixel centres are moved to lon/lat with OGR
// here, not through the tiler.
std::size_t check_pixels_in_cells(const std::string& path,
                                  const std::vector<double>& px,
                                  int width,
                                  const TileRaster& raster,
                                  const std::vector<CheckCell>& cells) {
    GDALDatasetUniquePtr ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER));
    REQUIRE(ds != nullptr);
    double gt[6];
    REQUIRE(ds->GetGeoTransform(gt) == CE_None);
    OGRSpatialReference wgs84, src = *ds->GetSpatialRef();
    wgs84.importFromEPSG(4326);
    wgs84.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    src.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    std::unique_ptr<OGRCoordinateTransformation> ct(
        OGRCreateCoordinateTransformation(&src, &wgs84));
    REQUIRE(ct != nullptr);
    // Cells bucketed by their boxes, 16 x 16 buckets over the tile's grid.
    constexpr int kBuckets = 16;
    const double side = static_cast<double>(raster.size) / kBuckets;
    std::vector<std::vector<std::size_t>> buckets(kBuckets * kBuckets);
    for (std::size_t k = 0; k < cells.size(); ++k) {
        const CheckCell& c = cells[k];
        for (int by = std::max(0, int(c.y0 / side)); by <= std::min(kBuckets - 1, int(c.y1 / side));
             ++by) {
            for (int bx = std::max(0, int(c.x0 / side));
                 bx <= std::min(kBuckets - 1, int(c.x1 / side));
                 ++bx) {
                buckets[static_cast<std::size_t>(by * kBuckets + bx)].push_back(k);
            }
        }
    }
    std::size_t checked = 0;
    for (std::size_t n = 0; n < px.size(); ++n) {
        if (std::isnan(px[n])) {
            continue;
        }
        const double i = static_cast<double>(n % static_cast<std::size_t>(width)) + 0.5;
        const double j = static_cast<double>(n / static_cast<std::size_t>(width)) + 0.5;
        double x = gt[0] + i * gt[1] + j * gt[2], y = gt[3] + i * gt[4] + j * gt[5];
        REQUIRE(ct->Transform(1, &x, &y));
        const LonLatBox& b = raster.bounds;
        if (x < b.west || x > b.east || y < b.south || y > b.north) {
            continue;
        }
        double col = 0, row = 0;
        lonlat_to_grid(raster, {x, y}, col, row);
        const int bx = std::clamp(int(col / side), 0, kBuckets - 1);
        const int by = std::clamp(int(row / side), 0, kBuckets - 1);
        bool held = false;
        for (const std::size_t k : buckets[static_cast<std::size_t>(by * kBuckets + bx)]) {
            const CheckCell& c = cells[k];
            held =
                held || (col >= c.x0 - 1e-9 && col <= c.x1 + 1e-9 && row >= c.y0 - 1e-9 &&
                         row <= c.y1 + 1e-9 && std::abs(c.reference(col, row) - px[n]) <= c.half);
        }
        CHECK(held);
        ++checked;
    }
    return checked;
}

} // namespace

namespace {

// A steep plane of `per_column` and `per_row` metres per pixel (its blocks have no range: the
// stray alone must hold it), with a void and a one-pixel ridge of 80 m along the diagonal.
tb_test::Fixture steep_plane(int n, double per_column, double per_row) {
    tb_test::Fixture f;
    f.width = f.height = n;
    f.type = GDT_Float32;
    f.nodata = -9999;
    for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
            const bool hole = std::hypot(i - n / 3, j - 2 * n / 3) < n / 12;
            f.values.push_back(hole ? -9999
                                    : 1000 + per_column * i - per_row * j + (i == j ? 80 : 0));
        }
    }
    return f;
}

// Checks every valid pixel of the fixture against the cells of each tile over it at each
// (zoom, level) of `scheme`: how many were checked, and the largest half-range of a cell.
std::pair<std::size_t, double>
judge_cells(const std::string& path, Scheme scheme, const std::vector<std::pair<int, int>>& zooms) {
    const auto source = DemSource::open({path});
    const PixelPlace place(*source, scheme);
    REQUIRE_FALSE(place.serves());
    const DemSummary s = DemSummary::build(*source, place, VerticalDatum::Ellipsoid);
    const int n = source->info().width;
    const std::vector<double> px = source->read_pixels(0, 0, n, source->info().height);
    std::size_t checked = 0;
    double most = 0;
    for (const auto& [z, level] : zooms) {
        CAPTURE(z);
        const TileRange r = tiles_covering(scheme, source->footprint(), z);
        for (std::int64_t y = r.y0; y <= r.y1; ++y) {
            for (std::int64_t x = r.x0; x <= r.x1; ++x) {
                TileRaster raster;
                raster.id = {z, x, y};
                raster.scheme = scheme;
                raster.bounds = tile_bounds(scheme, raster.id);
                raster.size = 256;
                raster.grid.width = raster.grid.height = 257;
                const auto cells = summary_cells(s, place, raster, level);
                for (const CheckCell& c : cells) {
                    most = std::max(most, c.half);
                }
                checked += check_pixels_in_cells(path, px, n, raster, cells);
            }
        }
    }
    return {checked, most};
}

} // namespace

TEST_CASE("a summary of a grid turned against the tiles: every valid pixel lies in a cell of its "
          "tile, within the cell's range of its reference, at coarse and fine levels (polar "
          "stereographic north and south, the pole inside; lon/lat on the equator under "
          "mercator tiles)") {
    tb_test::ScratchDir dir;
    // 1 km pixels north of Greenland (NSIDC sea ice polar stereographic north).
    tb_test::Fixture north = steep_plane(600, 5, 3);
    north.epsg = 3413;
    north.geotransform = std::array<double, 6>{0, 1000, 0, -1200000, 0, -1000};
    const auto [n1, h1] = judge_cells(tb_test::write_fixture(dir.file("north.tif"), north),
                                      Scheme::Geodetic,
                                      {{2, 7}, {3, 6}, {4, 4}});
    CHECK(n1 > 3 * 300000);
    MESSAGE("north: " << n1 << " pixels, largest half-range " << h1 << " m");
    // 10 km pixels around the South Pole (Antarctic polar stereographic): the pole lies inside.
    tb_test::Fixture south = steep_plane(400, 5, 3);
    south.epsg = 3031;
    south.geotransform = std::array<double, 6>{-2000000, 10000, 0, 2000000, 0, -10000};
    const std::string south_path = tb_test::write_fixture(dir.file("south.tif"), south);
    CHECK(DemSource::open({south_path})->footprint().south == -90);
    const auto [n2, h2] = judge_cells(south_path, Scheme::Geodetic, {{1, 6}, {2, 5}, {3, 4}});
    CHECK(n2 > 3 * 150000);
    MESSAGE("south: " << n2 << " pixels, largest half-range " << h2 << " m");
    // 3" lon/lat pixels under mercator tiles, a level-10 block centred on the equator, where
    // mercator's bend is a cubic the half-block grid does not see.
    tb_test::Fixture equator = steep_plane(2048, 3, 2);
    equator.epsg = 4326;
    equator.geotransform = std::array<double, 6>{10.0, 1.0 / 1200, 0, 512.0 / 1200, 0, -1.0 / 1200};
    const auto [n3, h3] = judge_cells(tb_test::write_fixture(dir.file("equator.tif"), equator),
                                      Scheme::Mercator,
                                      {{3, 10}, {6, 7}});
    CHECK(n3 > 2 * 4000000);
    MESSAGE("equator: " << n3 << " pixels, largest half-range " << h3 << " m");
}

TEST_CASE("pixel rows moved to lon/lat by interpolation match each pixel moved through the CRS, "
          "across the antimeridian too") {
    tb_test::ScratchDir dir;
    // 30 m pixels of UTM 60S around 17 S, from 178.9 E across 180 to 179.6 W.
    tb_test::Fixture f = steep_plane(2000, 0.1, 0.1);
    f.epsg = 32760;
    f.geotransform = std::array<double, 6>{810000, 30, 0, 8120000, 0, -30};
    const auto source = DemSource::open({tb_test::write_fixture(dir.file("utm60.tif"), f)});
    const PixelPlace place(*source, Scheme::Geodetic);
    REQUIRE(place.fine_span() > 1);
    double worst = 0;
    bool crossed = false;
    for (const int j : {0, 999, 1999}) {
        std::vector<double> lon, lat;
        place.row_to_lonlat(0, 1, j, f.width, place.fine_span(), lon, lat);
        std::vector<double> x(static_cast<std::size_t>(f.width)), y(x.size(), j);
        for (std::size_t i = 0; i < x.size(); ++i) {
            x[i] = static_cast<double>(i);
        }
        place.to_lonlat(x, y);
        for (std::size_t i = 0; i < x.size(); ++i) {
            crossed = crossed || (i > 0 && x[i] < x[i - 1]);
            const double dlon = std::remainder(lon[i] - x[i], 360.0);
            worst = std::max({worst, std::abs(dlon), std::abs(lat[i] - y[i])});
            CHECK(lon[i] >= -180);
            CHECK(lon[i] <= 180);
        }
    }
    CHECK(crossed);
    CHECK(worst < 1e-9); // degrees: 0.1 mm
}
