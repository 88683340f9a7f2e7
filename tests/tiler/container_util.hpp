#pragma once
// Helpers of the container tests (MBTiles, PMTiles): a temporary directory, a small DEM, the
// terrabound binary run to completion, and the DEM tiles a layer makes.
#include "tiler/dem_tiles.hpp"

#include <doctest/doctest.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <cmath>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <map>
#include <spawn.h>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

extern char** environ;

namespace container_test {

namespace fs = std::filesystem;

struct TempDir {
    fs::path path;
    TempDir() {
        std::string tmpl = (fs::temp_directory_path() / "tb-container-XXXXXX").string();
        REQUIRE(::mkdtemp(tmpl.data()) != nullptr);
        path = tmpl;
    }
    ~TempDir() {
        std::error_code ec;
        fs::remove_all(path, ec);
    }
    std::string operator/(const std::string& name) const { return (path / name).string(); }
};

inline std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

// 65 x 65 Float32 samples over 0.5 x 0.5 degrees near the Alps: a hill on a slope.
inline std::string write_dem(const std::string& path) {
    GDALAllRegister();
    GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("GTiff");
    REQUIRE(driver != nullptr);
    constexpr int n = 65;
    GDALDatasetUniquePtr ds(driver->Create(path.c_str(), n, n, 1, GDT_Float32, nullptr));
    REQUIRE(ds != nullptr);
    double gt[6] = {7.25, 0.5 / (n - 1), 0, 46.75, 0, -0.5 / (n - 1)};
    ds->SetGeoTransform(gt);
    OGRSpatialReference srs;
    srs.importFromEPSG(4326);
    ds->SetSpatialRef(&srs);
    std::vector<float> v(static_cast<std::size_t>(n) * n);
    for (int r = 0; r < n; ++r) {
        for (int c = 0; c < n; ++c) {
            const double x = c / double(n - 1), y = r / double(n - 1);
            v[static_cast<std::size_t>(r) * n + c] = static_cast<float>(
                900 + 300 * x +
                700 * std::exp(-((x - 0.4) * (x - 0.4) + (y - 0.5) * (y - 0.5)) * 12));
        }
    }
    REQUIRE(ds->GetRasterBand(1)->RasterIO(
                GF_Write, 0, 0, n, n, v.data(), n, n, GDT_Float32, 0, 0) == CE_None);
    return path;
}

struct Run {
    int code = -1;
    std::string out, err;
};

// Runs TB_BINARY with `args` to completion; stdout and stderr go through files in `dir`.
inline Run run(const std::vector<std::string>& args, const TempDir& dir) {
    std::vector<std::string> words{TB_BINARY};
    words.insert(words.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& w : words) {
        argv.push_back(w.data());
    }
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    const std::string out = dir / "stdout.txt", err = dir / "stderr.txt";
    posix_spawn_file_actions_addopen(&fa, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&fa, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    pid_t pid = -1;
    const int rc = posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    REQUIRE(rc == 0);
    int status = 0;
    REQUIRE(::waitpid(pid, &status, 0) == pid);
    Run r;
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    r.out = slurp(out);
    r.err = slurp(err);
    return r;
}

// `terrabound build DEM -o OUT --formats FORMAT --dem-size 256 EXTRA...`
inline std::vector<std::string> build_args(const std::string& dem,
                                           const std::string& out,
                                           const std::string& format,
                                           std::vector<std::string> extra = {}) {
    std::vector<std::string> a{"build", dem, "-o", out, "--formats", format, "--dem-size", "256"};
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
}

// Every DEM tile the layer of `dem` (256-pixel DEM tiles) makes in `format`, by XYZ id.
inline std::map<tb::tiler::TileId, std::string> expected_dem_tiles(const std::string& dem,
                                                                   tb::tiler::Format format) {
    using namespace tb::tiler;
    LayerOptions o;
    o.sources = {dem};
    o.dem_tile_size = 256;
    const auto layer = Layer::open(o);
    const DemTilePlan plan = dem_tile_plan(*layer);
    std::map<TileId, std::string> tiles;
    for (int z = plan.min_zoom; z <= plan.max_zoom; ++z) {
        const TileRange r = dem_tiles_at(*layer, z);
        for (std::int64_t y = r.y0; y <= r.y1; ++y) {
            for (std::int64_t x = r.x0; x <= r.x1; ++x) {
                tiles[TileId{z, x, y}] = make_dem_tile(
                    *layer, ValidTile::parse(Scheme::Mercator, TileId{z, x, y}), format);
            }
        }
    }
    return tiles;
}

} // namespace container_test
