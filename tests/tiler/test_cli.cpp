// The tile, mesh and info commands, run as processes (TB_BINARY): exit codes, messages, and
// outputs read back independently (GDAL for .tif, a brute-force L-inf pass for .obj).
#include "tests/tiler/test_raster_util.hpp"

#include <doctest/doctest.h>

#include <fstream>
#include <random>
#include <sstream>
#include <sys/wait.h>

using tb_test::Fixture;
using tb_test::ScratchDir;

namespace {

struct Run {
    int code = -1;
    std::string out, err;
};

std::string slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

// Runs `terrabound ARGUMENTS` in the current directory, or in `cwd` when given.
Run run(const ScratchDir& dir, const std::string& arguments, const std::string& cwd = "") {
    const std::string out = dir.file("stdout.txt"), err = dir.file("stderr.txt");
    const std::string command = (cwd.empty() ? "" : "cd '" + cwd + "' && ") +
                                std::string(TB_BINARY) + " " + arguments + " >" + out + " 2>" + err;
    const int status = std::system(command.c_str());
    Run r;
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = slurp(out);
    r.err = slurp(err);
    return r;
}

struct Obj {
    std::vector<std::array<double, 3>> vertices;
    std::vector<std::array<int, 3>> triangles;
};

Obj read_obj(const std::string& path) {
    Obj obj;
    std::ifstream in(path);
    std::string kind;
    while (in >> kind) {
        if (kind == "v") {
            std::array<double, 3> v{};
            in >> v[0] >> v[1] >> v[2];
            obj.vertices.push_back(v);
        } else if (kind == "f") {
            std::array<int, 3> t{};
            in >> t[0] >> t[1] >> t[2];
            obj.triangles.push_back({t[0] - 1, t[1] - 1, t[2] - 1});
        }
    }
    return obj;
}

// A rough seeded terrain with a nodata hole, written as an Int16 GeoTIFF without a CRS.
std::string rough_fixture(const ScratchDir& dir,
                          std::vector<float>& heights,
                          std::vector<std::uint8_t>& valid) {
    std::mt19937 rng(42);
    const int w = 97, h = 83;
    Fixture f;
    f.width = w, f.height = h;
    f.type = GDT_Int16;
    f.nodata = -32768;
    heights.assign(w * h, 0);
    valid.assign(w * h, 1);
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
            const double v = 300 + 80 * std::sin(x * 0.11) * std::cos(y * 0.07) + (rng() % 9);
            const bool hole = (x - 40) * (x - 40) + (y - 30) * (y - 30) < 60;
            f.values.push_back(hole ? -32768.0 : std::round(v));
            heights[y * w + x] = hole ? 0.0f : static_cast<float>(std::round(v));
            valid[y * w + x] = hole ? 0 : 1;
        }
    }
    return tb_test::write_fixture(dir.file("rough.tif"), f);
}

} // namespace

TEST_CASE("mesh writes an OBJ whose every valid sample is within eps, by an independent check") {
    ScratchDir dir;
    std::vector<float> heights;
    std::vector<std::uint8_t> valid;
    const std::string input = rough_fixture(dir, heights, valid);
    for (double eps : {0.5, 4.0, 30.0}) {
        const std::string out = dir.file("rough.obj");
        const Run r =
            run(dir, "mesh " + input + " --eps " + std::to_string(eps) + " -o " + out + " --stats");
        REQUIRE_MESSAGE(r.code == 0, r.err);
        CHECK(r.out.find("\"width\":97,\"height\":83") != std::string::npos);
        CHECK(r.out.find("\"max_error\":") != std::string::npos);
        const Obj obj = read_obj(out);
        REQUIRE(obj.triangles.size() >= 2);
        const double worst =
            tb_test::brute_force_max_error(obj.vertices, obj.triangles, 97, 83, heights, valid);
        CHECK(worst <= eps + 1e-9); // exact in core; 1e-9 absorbs double barycentric rounding
    }
    // JSON output in the linf_check format.
    const Run j = run(dir, "mesh " + input + " --eps 2 -o " + dir.file("m.json"));
    REQUIRE(j.code == 0);
    const std::string json = slurp(dir.file("m.json"));
    CHECK(json.rfind("{\"vertices\":[", 0) == 0);
    CHECK(json.find("],\"triangles\":[") != std::string::npos);
}

TEST_CASE("mesh refuses a bad eps, a missing file and an unknown output type") {
    ScratchDir dir;
    std::vector<float> heights;
    std::vector<std::uint8_t> valid;
    const std::string input = rough_fixture(dir, heights, valid);
    Run r = run(dir, "mesh " + input + " --eps 0 -o " + dir.file("x.obj"));
    CHECK(r.code == 2);
    CHECK(r.err.find("--eps") != std::string::npos);
    r = run(dir, "mesh " + input + " --eps nan -o " + dir.file("x.obj"));
    CHECK(r.code == 2);
    r = run(dir, "mesh " + dir.file("nope.tif") + " --eps 1 -o " + dir.file("x.obj"));
    CHECK(r.code == 2);
    CHECK(r.err.find("no such file") != std::string::npos);
    r = run(dir, "mesh " + input + " --eps 1 -o " + dir.file("x.stl"));
    CHECK(r.code == 2);
    CHECK(r.err.find(".obj or .json") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir.file("x.obj")));
}

TEST_CASE("tile writes the tile raster as a georeferenced GeoTIFF and the mesh as OBJ") {
    const auto path = tb_test::shared_dem("N44W072.hgt");
    if (!path) {
        return;
    }
    ScratchDir dir;
    const std::string tif = dir.file("t.tif");
    Run r = run(dir, "tile " + *path + " 10 617 765 -o " + tif);
    REQUIRE_MESSAGE(r.code == 0, r.err);
    GDALAllRegister();
    GDALDatasetUniquePtr ds(GDALDataset::Open(tif.c_str(), GDAL_OF_RASTER));
    REQUIRE(ds != nullptr);
    // The tile is meshed on the DEM's own pixels: its raster is the block of 3" pixels whose
    // centres lie in the tile (a z10 tile is 0.17578 degrees, 210 or 211 pixels across).
    const int w = ds->GetRasterXSize(), h = ds->GetRasterYSize();
    CHECK(w >= 210);
    CHECK(w <= 211);
    CHECK(h >= 210);
    CHECK(h <= 211);
    double gt[6];
    REQUIRE(ds->GetGeoTransform(gt) == CE_None);
    const double pixel = 1.0 / 1200;
    CHECK(gt[1] == doctest::Approx(pixel));
    const double west = -180 + 617 * 180.0 / 1024;
    const double first_centre = gt[0] + pixel / 2;
    CHECK(first_centre >= west);
    CHECK(first_centre < west + pixel);
    // ... on the DEM's grid (N44W072's pixel centres sit on whole multiples of 3" from -72).
    const double k = (first_centre + 72) / pixel;
    CHECK(std::abs(k - std::round(k)) < 1e-6);
    std::vector<float> heights(static_cast<std::size_t>(w) * h);
    REQUIRE(ds->GetRasterBand(1)->RasterIO(
                GF_Read, 0, 0, w, h, heights.data(), w, h, GDT_Float32, 0, 0, nullptr) == CE_None);
    ds.reset();

    const std::string obj_path = dir.file("t.obj");
    r = run(dir, "tile " + *path + " 10 617 765 --eps 3 -o " + obj_path);
    REQUIRE_MESSAGE(r.code == 0, r.err);
    const Obj obj = read_obj(obj_path);
    const double worst = tb_test::brute_force_max_error(
        obj.vertices, obj.triangles, w, h, heights, {}, std::pow(180.0 / 1024 / pixel, 2));
    CHECK(worst <= 3.0 + 1e-9);

    r = run(dir, "tile " + *path + " 10 617 765 -o " + dir.file("t.glb"));
    REQUIRE_MESSAGE(r.code == 0, r.err);
    CHECK(slurp(dir.file("t.glb")).rfind("glTF", 0) == 0);
}

TEST_CASE("tile reports ids outside the scheme or the data with exit code 2") {
    const auto path = tb_test::shared_dem("N44W072.hgt");
    if (!path) {
        return;
    }
    ScratchDir dir;
    Run r = run(dir, "tile " + *path + " 25 0 0 -o " + dir.file("a.tif"));
    CHECK(r.code == 2);
    CHECK(r.err.find("outside 0..24") != std::string::npos);
    r = run(dir, "tile " + *path + " 10 5000 0 -o " + dir.file("a.tif"));
    CHECK(r.code == 2);
    CHECK(r.err.find("outside the geodetic scheme") != std::string::npos);
    r = run(dir, "tile " + *path + " 10 0 0 -o " + dir.file("a.tif"));
    CHECK(r.code == 2);
    CHECK(r.err.find("has no data there") != std::string::npos);
    r = run(dir, "tile " + *path + " 10 617 765 --scheme utm -o " + dir.file("a.tif"));
    CHECK(r.code == 2);
    CHECK_FALSE(std::filesystem::exists(dir.file("a.tif")));
}

TEST_CASE("info adds the pyramid plan, and says why a raster without a CRS has none") {
    ScratchDir dir;
    std::vector<float> heights;
    std::vector<std::uint8_t> valid;
    const std::string plain = rough_fixture(dir, heights, valid);
    Run r = run(dir, "info " + plain);
    REQUIRE_MESSAGE(r.code == 0, r.err);
    CHECK(r.out.find("pyramid:     none (") != std::string::npos);
    CHECK(r.out.find("no georeferencing") != std::string::npos);
    if (const auto path = tb_test::shared_dem("N44W072.hgt")) {
        r = run(dir, "info " + *path);
        REQUIRE_MESSAGE(r.code == 0, r.err);
        CHECK(r.out.find("zooms 7..10") != std::string::npos);
        CHECK(r.out.find("egm96") != std::string::npos);
        r = run(dir, "info --scheme mercator " + *path);
        REQUIRE(r.code == 0);
        CHECK(r.out.find("mercator") != std::string::npos);
    }
}

TEST_CASE("a collection given as a directory or a list file: info ranks its DEMs, build makes "
          "one layer of them, and a bad --priority is named") {
    ScratchDir dir;
    // A 3" geographic DEM and a 10 m UTM block inside it, in a directory with a sidecar.
    const std::string dems = dir.file("dems");
    std::filesystem::create_directories(dems + "/survey");
    Fixture coarse;
    coarse.width = 61, coarse.height = 61;
    coarse.type = GDT_Int16;
    coarse.epsg = 4326;
    coarse.geotransform = std::array<double, 6>{7.6, 1.0 / 1200, 0, 46.4, 0, -1.0 / 1200};
    for (int k = 0; k < coarse.width * coarse.height; ++k) {
        coarse.values.push_back(800 + (k % 61) + (k / 61));
    }
    tb_test::write_fixture(dems + "/srtm.tif", coarse);
    Fixture fine;
    fine.width = 60, fine.height = 60;
    fine.type = GDT_Float32;
    fine.epsg = 32632;
    fine.geotransform = std::array<double, 6>{394300, 10, 0, 5136000, 0, -10}; // near 7.62E 46.37N
    for (int k = 0; k < fine.width * fine.height; ++k) {
        fine.values.push_back(850 + 0.1 * (k % 60));
    }
    tb_test::write_fixture(dems + "/survey/block.tif", fine);
    std::ofstream(dems + "/srtm.tif.aux.xml") << "<PAMDataset/>";

    Run r = run(dir, "info " + dems);
    REQUIRE_MESSAGE(r.code == 0, r.err);
    CHECK(r.out.find("collection of 2 files in 2 DEM groups, ranked finest") != std::string::npos);
    const auto first = r.out.find("  1. " + dems + "/survey/block.tif: 10 m pixels, EPSG:32632");
    const auto second = r.out.find("  2. " + dems + "/srtm.tif");
    CHECK(first != std::string::npos);
    CHECK(second != std::string::npos);
    CHECK(first < second);

    // A list file in the listed order: the coarse DEM first, and it wins.
    std::ofstream(dir.file("dems.txt")) << "# the order is the priority\ndems/srtm.tif\n"
                                        << "dems/survey\n";
    r = run(dir, "info --priority listed " + dir.file("dems.txt"));
    REQUIRE_MESSAGE(r.code == 0, r.err);
    CHECK(r.out.find("ranked listed") != std::string::npos);
    CHECK(r.out.find("  1. " + dems + "/srtm.tif") != std::string::npos);

    r = run(dir, "build " + dems + " -o " + dir.file("out") + " --formats glb");
    REQUIRE_MESSAGE(r.code == 0, r.err);
    CHECK(std::filesystem::exists(dir.file("out/dems/tileset.json")));

    r = run(dir, "build " + dems + " -o " + dir.file("out2") + " --priority first");
    CHECK(r.code == 2);
    CHECK(r.err.find("build: --priority: 'first' is not a priority") != std::string::npos);
    r = run(dir, "info " + dir.file("nothing") + "/*.tif");
    CHECK(r.code == 2);
    CHECK(r.err.find("matches no file") != std::string::npos);
}

TEST_CASE("info describes a collection of many files as a whole, and each file with --each") {
    ScratchDir dir;
    // Twelve 20 x 20 pieces of one 3" grid: one DEM group of twelve files.
    const std::string dems = dir.file("pieces");
    std::filesystem::create_directories(dems);
    for (int j = 0; j < 3; ++j) {
        for (int i = 0; i < 4; ++i) {
            Fixture piece;
            piece.width = 20, piece.height = 20;
            piece.type = GDT_Int16;
            piece.epsg = 4326;
            piece.geotransform = std::array<double, 6>{
                7.6 + i * 20.0 / 1200, 1.0 / 1200, 0, 46.4 - j * 20.0 / 1200, 0, -1.0 / 1200};
            for (int k = 0; k < 400; ++k) {
                piece.values.push_back(800 + i * 20 + k % 20 + j * 20 + k / 20);
            }
            tb_test::write_fixture(dems + "/p" + std::to_string(j) + std::to_string(i) + ".tif",
                                   piece);
        }
    }
    auto count = [](const std::string& text, const std::string& what) {
        int n = 0;
        for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) {
            ++n;
        }
        return n;
    };
    Run r = run(dir, "info " + dems);
    REQUIRE_MESSAGE(r.code == 0, r.err);
    CHECK(r.out.find("12 DEM files, the first " + dems + "/p00.tif (each described with --each)") !=
          std::string::npos);
    CHECK(r.out.find("collection of 12 files in 1 DEM group:") != std::string::npos);
    CHECK(r.out.find(": 12 files, ") != std::string::npos);
    CHECK(r.out.find("EPSG:4326, lon 7.6") != std::string::npos);
    CHECK(count(r.out, "  format:") == 0);
    CHECK(r.out.find("  pyramid:") != std::string::npos);

    r = run(dir, "info --each " + dems);
    REQUIRE_MESSAGE(r.code == 0, r.err);
    CHECK(count(r.out, "  format:      GTiff") == 12);
    CHECK(r.out.find("collection of 12 files in 1 DEM group:") != std::string::npos);

    // Named relative to the current directory: the mosaic reads the same files.
    r = run(dir, "info pieces", dir.file(""));
    REQUIRE_MESSAGE(r.code == 0, r.err);
    CHECK(r.out.find("collection of 12 files in 1 DEM group:") != std::string::npos);
    CHECK(r.out.find("  1. pieces/p00.tif, pieces/p01.tif, pieces/p02.tif and 9 more: 12 files") !=
          std::string::npos);
    CHECK(r.out.find("  pyramid:     geodetic") != std::string::npos);
}
