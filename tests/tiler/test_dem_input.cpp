// Bad DEMs get one clear error line with the documented exit code, or work: +-Inf samples,
// files GDAL cannot read (truncated, declared far larger than they are, a VRT whose source is
// gone, no read permission), rasters one sample thick, voids not declared as nodata (and the
// --nodata fix), a NUL in a path. Real files in a temp dir, the real binary (TB_BINARY).
#include "core/error.hpp"
#include "tests/tiler/qm_reader.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/gzip.hpp"
#include "tiler/sources/gdal_source.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <sys/wait.h>

using tb_test::Fixture;
using tb_test::ScratchDir;
namespace fs = std::filesystem;

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

Run run(const ScratchDir& dir, const std::string& arguments, const std::string& prefix = "") {
    const std::string out = dir.file("stdout.txt"), err = dir.file("stderr.txt");
    const std::string command =
        prefix + std::string(TB_BINARY) + " " + arguments + " >" + out + " 2>" + err;
    const int status = std::system(command.c_str());
    Run r;
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = slurp(out);
    r.err = slurp(err);
    return r;
}

// Smooth hills over 0.5 x 0.5 degrees at 57N 11E, `n` x `n` samples.
Fixture hills(int n, GDALDataType type = GDT_Float32) {
    Fixture f;
    f.width = f.height = n;
    f.type = type;
    f.epsg = 4326;
    f.geotransform = std::array<double, 6>{11, 0.5 / n, 0, 57.5, 0, -0.5 / n};
    for (int y = 0; y < n; ++y) {
        for (int x = 0; x < n; ++x) {
            f.values.push_back(std::round(300 + 200 * std::sin(x * 0.1) * std::cos(y * 0.13)));
        }
    }
    return f;
}

// Cell `index` (west to east) of a row of 40 x 40 cells of one 3" grid, every sample `value`.
Fixture mosaic_cell(int index, GDALDataType type, double value) {
    Fixture f;
    f.width = f.height = 40;
    f.type = type;
    f.epsg = 4326;
    f.geotransform =
        std::array<double, 6>{7.6 + index * 40.0 / 1200, 1.0 / 1200, 0, 46.4, 0, -1.0 / 1200};
    f.values.assign(1600, value);
    return f;
}

// Every number in a JSON document is finite (nlohmann parses only valid JSON, which has no
// inf or nan).
void check_json_numbers(const nlohmann::json& j) {
    if (j.is_number()) {
        CHECK(std::isfinite(j.get<double>()));
    }
    for (const auto& child : j) {
        if (j.is_structured()) {
            check_json_numbers(child);
        }
    }
}

const char* kBuild = " --size 32 --threads 1 --layer terrain --formats glb";

} // namespace

TEST_CASE("to_height: NaN and +-Inf are nodata, like the nodata value; the rest is scaled") {
    using tb::tiler::to_height;
    const std::optional<double> none;
    CHECK(std::isnan(to_height(INFINITY, none, false, 1, 0)));
    CHECK(std::isnan(to_height(-INFINITY, none, true, 1, 0)));
    CHECK(std::isnan(to_height(NAN, none, false, 1, 0)));
    CHECK(std::isnan(to_height(-32767, -32767.0, false, 1, 0)));
    // A Float32 band's nodata written as a double that is not a float.
    CHECK(std::isnan(to_height(static_cast<float>(-3.4e38), -3.4e38, true, 1, 0)));
    CHECK(tb::tiler::sample_height(static_cast<float>(-3.4e38), -3.4e38, false, 1, 0) < -3e38);
    CHECK(to_height(100, -32767.0, false, 0.5, 10) == 60);
    // Outside the plausible range of Earth heights (after scale and offset): nodata.
    CHECK(to_height(9000, none, false, 1, 0) == 9000);
    CHECK(std::isnan(to_height(9000.5, none, false, 1, 0)));
    CHECK(std::isnan(to_height(-12001, none, false, 1, 0)));
    CHECK(std::isnan(to_height(3e38, none, true, 1, 0)));
    CHECK(to_height(-32000, none, false, 0.1, 0) == -3200);
    // Another range (--valid-range): 9,500 m kept, 100 m refused.
    const tb::tiler::ValidRange mars{-9000, 22000};
    CHECK(to_height(9500, none, false, 1, 0, mars) == 9500);
    CHECK(std::isnan(to_height(-9500, none, false, 1, 0, mars)));
    const auto r = tb::tiler::parse_valid_range("-500,12000.5", "--valid-range");
    CHECK(r.low == -500);
    CHECK(r.high == 12000.5);
    CHECK_FALSE(r.is_default());
    for (const char* bad : {"", "5", "1,", ",2", "3,3", "4,1", "a,b", "1,2,3", "nan,5"}) {
        CAPTURE(bad);
        CHECK_THROWS_WITH_AS(tb::tiler::parse_valid_range(bad, "--valid-range"),
                             doctest::Contains("expected MIN,MAX in metres"),
                             tb::InputError);
    }
}

TEST_CASE("outliers (+-3.4e38, a 3e38 spike) are nodata: one warning names them, the build "
          "succeeds, and every published header and bound is finite") {
    ScratchDir dir;
    Fixture f = hills(129);
    f.type = GDT_Float32;
    f.values[5 * 129 + 7] = 3.4e38;
    f.values[40 * 129 + 90] = -3.4e38;
    f.values[100 * 129 + 20] = 3e38;
    const std::string dem = tb_test::write_fixture(dir.file("spikes.tif"), f);
    const tb::tiler::DemInfo info = tb::tiler::inspect_dem(dem);
    CHECK(info.outliers == 3);
    CHECK(info.outlier_column == 7);
    CHECK(info.outlier_row == 5);
    CHECK(info.min_height == 100);
    CHECK(info.max_height == 500);
    const Run i = run(dir, "info " + dem);
    REQUIRE_MESSAGE(i.code == 0, i.err);
    CHECK(i.out.find("outliers:    3 sample(s) outside -12000 .. 9000 m") != std::string::npos);
    const Run b = run(dir,
                      "build " + dem + " -o " + dir.file("out") + " --formats glb,terrain" +
                          " --threads 1 --layer terrain --json");
    REQUIRE_MESSAGE(b.code == 0, b.err);
    CHECK(b.err.find("3 sample(s) outside the plausible range of heights (-12000 .. 9000 m") !=
          std::string::npos);
    CHECK(b.err.find("pixel (7, 5)") != std::string::npos);
    check_json_numbers(nlohmann::json::parse(b.out));
    check_json_numbers(nlohmann::json::parse(slurp(dir.file("out/terrain/tileset.json"))));
    std::size_t headers = 0;
    for (const auto& e : fs::recursive_directory_iterator(dir.file("out/terrain"))) {
        if (e.path().extension() != ".terrain") {
            continue;
        }
        CAPTURE(e.path().string());
        const auto tile = tb::tiler::gzip_decompress(slurp(e.path().string()), 1 << 30);
        REQUIRE(tile); // stored gzip-compressed
        const auto t = tb_qm::read(*tile);
        CHECK(std::isfinite(t.min_height));
        CHECK(std::isfinite(t.max_height));
        CHECK(t.max_height < 600); // the hills and the geoid, not 3.4e38
        CHECK(std::isfinite(t.sphere[3]));
        ++headers;
    }
    CHECK(headers > 0);
    // A wider range keeps the 3e38 spike out still, and records itself in the manifest.
    const Run wide =
        run(dir,
            "build " + dem + " -o " + dir.file("wide") +
                " --formats glb --threads 1 --layer terrain --valid-range -12000,12000");
    REQUIRE_MESSAGE(wide.code == 0, wide.err);
    CHECK(wide.err.find("(-12000 .. 12000 m; --valid-range") != std::string::npos);
    CHECK(slurp(dir.file("wide/terrain/build-manifest.json"))
              .find("\"valid_range\": [-12000, 12000]") != std::string::npos);
    CHECK(slurp(dir.file("out/terrain/build-manifest.json")).find("valid_range") ==
          std::string::npos);
    const Run narrow = run(dir, "info " + dem + " --valid-range 0,300");
    REQUIRE_MESSAGE(narrow.code == 0, narrow.err);
    CHECK(narrow.out.find("outliers:    ") != std::string::npos);
    CHECK(narrow.out.find("sample(s) outside 0 .. 300 m") != std::string::npos);
    CHECK(run(dir, "info " + dem + " --valid-range 5,1").code == 2);
}

TEST_CASE("+-Inf samples are nodata: info shows a finite range and build writes valid JSON") {
    ScratchDir dir;
    Fixture f = hills(129);
    f.values[5 * 129 + 5] = INFINITY;
    f.values[6 * 129 + 90] = -INFINITY;
    const std::string dem = tb_test::write_fixture(dir.file("edges.tif"), f);
    const tb::tiler::DemInfo info = tb::tiler::inspect_dem(dem);
    CHECK(info.has_data);
    CHECK(info.min_height == 100);
    CHECK(info.max_height == 500);

    const Run i = run(dir, "info " + dem);
    REQUIRE_MESSAGE(i.code == 0, i.err);
    CHECK(i.out.find("inf") == std::string::npos);
    const Run b = run(dir, "build " + dem + " -o " + dir.file("out") + kBuild + " --json");
    REQUIRE_MESSAGE(b.code == 0, b.err);
    check_json_numbers(nlohmann::json::parse(b.out));
    for (const char* doc : {"tileset.json", "build-manifest.json"}) {
        CAPTURE(doc);
        const std::string text = slurp(dir.file(std::string("out/terrain/") + doc));
        REQUIRE_FALSE(text.empty());
        check_json_numbers(nlohmann::json::parse(text));
    }
}

TEST_CASE("a truncated GeoTIFF is a read error (exit 3) naming GDAL's message") {
    ScratchDir dir;
    const std::string whole = tb_test::write_fixture(dir.file("whole.tif"), hills(129));
    const std::string bytes = slurp(whole);
    // The header and the strip offsets are at the front, the pixels behind them.
    std::ofstream(dir.file("cut.tif"), std::ios::binary) << bytes.substr(0, bytes.size() / 2);
    const std::string dem = dir.file("cut.tif");
    try {
        tb::tiler::inspect_dem(dem);
        FAIL("expected an IoError");
    } catch (const tb::IoError& e) {
        const std::string what = e.what();
        CHECK(what.find(dem + ": read failed (") != std::string::npos);
    }
    for (const std::string& command : {"info " + dem,
                                       "build " + dem + " -o " + dir.file("out") + kBuild,
                                       "tile " + dem + " 8 270 73 -o " + dir.file("t.glb")}) {
        CAPTURE(command);
        const Run r = run(dir, command);
        CHECK(r.code == 3);
        CHECK(r.err.find(dem + ": read failed (") != std::string::npos);
        CHECK(r.err.find("nodata") == std::string::npos);
    }
}

TEST_CASE("a TIFF declaring 10^6 x 10^6 pixels in 288 bytes is a read error (exit 3)") {
    ScratchDir dir;
    // Little-endian classic TIFF: one IFD, one strip of 4 * 10^12 bytes that is not there.
    std::string t = std::string("II*\0", 4);
    const auto u16 = [&](unsigned v) {
        t += static_cast<char>(v & 0xff);
        t += static_cast<char>(v >> 8);
    };
    const auto u32 = [&](std::uint32_t v) {
        for (int k = 0; k < 4; ++k) {
            t += static_cast<char>((v >> (8 * k)) & 0xff);
        }
    };
    u32(8);
    const std::uint32_t kSide = 1000000;
    const std::vector<std::array<std::uint32_t, 3>> entries = {{256, 4, kSide},
                                                               {257, 4, kSide},
                                                               {258, 3, 32},
                                                               {259, 3, 1},
                                                               {262, 3, 1},
                                                               {273, 4, 8},
                                                               {277, 3, 1},
                                                               {278, 4, kSide},
                                                               {279, 4, 0xfffffff0u},
                                                               {339, 3, 3}};
    u16(static_cast<unsigned>(entries.size()));
    for (const auto& [tag, type, value] : entries) {
        u16(tag), u16(type), u32(1);
        if (type == 3) {
            u16(value), u16(0);
        } else {
            u32(value);
        }
    }
    u32(0);
    t.resize(288, '\0');
    const std::string dem = dir.file("huge.tif");
    std::ofstream(dem, std::ios::binary) << t;
    REQUIRE(fs::file_size(dem) == 288);
    const Run r = run(dir, "info " + dem);
    CHECK(r.code == 3);
    CHECK(r.err.find(dem + ": read failed (") != std::string::npos);
    const Run b = run(dir, "build " + dem + " -o " + dir.file("out") + kBuild);
    CHECK(b.code == 3);
}

TEST_CASE("a VRT whose source file is gone is a read error (exit 3) naming the missing file") {
    ScratchDir dir;
    tb_test::write_fixture(dir.file("part.tif"), hills(65));
    std::ofstream(dir.file("mosaic.vrt"))
        << "<VRTDataset rasterXSize=\"65\" rasterYSize=\"65\"><SRS>EPSG:4326</SRS>"
           "<GeoTransform>11, 0.0076923, 0, 57.5, 0, -0.0076923</GeoTransform>"
           "<VRTRasterBand dataType=\"Float32\" band=\"1\"><SimpleSource>"
           "<SourceFilename relativeToVRT=\"1\">part.tif</SourceFilename>"
           "<SourceBand>1</SourceBand></SimpleSource></VRTRasterBand></VRTDataset>";
    const std::string vrt = dir.file("mosaic.vrt");
    REQUIRE(run(dir, "info " + vrt).code == 0);
    fs::remove(dir.file("part.tif"));
    const Run r = run(dir, "info " + vrt);
    CHECK(r.code == 3);
    CHECK(r.err.find(vrt + ": read failed (") != std::string::npos);
    CHECK(r.err.find("part.tif") != std::string::npos);
}

TEST_CASE("a DEM without read permission is a read error (exit 3), not a crash") {
    ScratchDir dir;
    // The SRTMHGT driver knows a file by its name; an unreadable .hgt used to crash GDAL.
    Fixture f = hills(121, GDT_Int16);
    const std::string dem = tb_test::write_fixture(dir.file("dem.tif"), f);
    const std::string hgt = dir.file("N57E011.hgt");
    fs::copy_file(dem, hgt);
    fs::permissions(hgt, fs::perms::none);
    fs::permissions(dir.path, fs::perms::all);
    std::string prefix;
    if (::geteuid() == 0) {
        // Root reads anything; run the binary as 'nobody' when setpriv is there.
        if (std::system("command -v setpriv >/dev/null 2>&1") != 0) {
            MESSAGE("skipped: running as root without setpriv, so chmod 000 does not deny reads");
            return;
        }
        prefix = "setpriv --reuid=65534 --regid=65534 --clear-groups ";
    }
    for (const std::string& command :
         {"info " + hgt, "build " + hgt + " -o " + dir.file("out") + kBuild}) {
        CAPTURE(command);
        const Run r = run(dir, command, prefix);
        CHECK(r.code == 3);
        CHECK(r.err.find(hgt + ": cannot be read (Permission denied)") != std::string::npos);
    }
}

TEST_CASE("rasters one sample thick are tiled: 1 x 1, 100000 x 1 and 1 x 300") {
    ScratchDir dir;
    struct Thin {
        int width, height;
    };
    for (const Thin s : {Thin{1, 1}, Thin{100000, 1}, Thin{1, 300}}) {
        CAPTURE(s.width);
        CAPTURE(s.height);
        Fixture f;
        f.width = s.width, f.height = s.height;
        f.epsg = 4326;
        f.geotransform = std::array<double, 6>{11, 0.001, 0, 57.5, 0, -0.001};
        for (int k = 0; k < s.width * s.height; ++k) {
            f.values.push_back(100 + k % 50);
        }
        const std::string dem = tb_test::write_fixture(dir.file("thin.tif"), f);
        const Run i = run(dir, "info " + dem);
        REQUIRE_MESSAGE(i.code == 0, i.err);
        CHECK(i.out.find("pyramid:") != std::string::npos);
        fs::remove_all(dir.file("out"));
        const Run b = run(dir, "build " + dem + " -o " + dir.file("out") + kBuild + " --json");
        REQUIRE_MESSAGE(b.code == 0, b.err);
        const auto summary = nlohmann::json::parse(b.out);
        CHECK(summary["written"].get<int>() > 0);
        CHECK(summary["failed"].get<int>() == 0);
        check_json_numbers(nlohmann::json::parse(slurp(dir.file("out/terrain/tileset.json"))));
    }
}

TEST_CASE("voids not declared as nodata are named with the fix, and --nodata fixes them") {
    ScratchDir dir;
    Fixture f = hills(129, GDT_Int16);
    for (int y = 40; y < 60; ++y) {
        for (int x = 30; x < 70; ++x) {
            f.values[static_cast<std::size_t>(y) * 129 + x] = -32767; // 4.8% of the samples
        }
    }
    const std::string dem = tb_test::write_fixture(dir.file("voids.tif"), f);
    const tb::tiler::DemInfo info = tb::tiler::inspect_dem(dem);
    REQUIRE(info.likely_nodata);
    CHECK(*info.likely_nodata == -32767);
    CHECK(info.likely_nodata_share == doctest::Approx(800.0 / (129 * 129)));

    const Run b = run(dir, "build " + dem + " -o " + dir.file("out") + kBuild);
    CHECK(b.code == 2);
    CHECK(b.err.find(dem + ": 4.81% of band 1's samples are -32767") != std::string::npos);
    CHECK(b.err.find("pass --nodata -32767") != std::string::npos);
    CHECK(std::count(b.err.begin(), b.err.end(), '\n') == 1);
    const Run i = run(dir, "info " + dem);
    REQUIRE(i.code == 0);
    CHECK(i.out.find("--nodata -32767") != std::string::npos);

    const Run fixed =
        run(dir, "build " + dem + " -o " + dir.file("out") + kBuild + " --nodata -32767 --json");
    REQUIRE_MESSAGE(fixed.code == 0, fixed.err);
    const auto summary = nlohmann::json::parse(fixed.out);
    CHECK(summary["failed"].get<int>() == 0);
    CHECK(summary["written"].get<int>() > 0);
    const Run fixed_info = run(dir, "info " + dem + " --nodata -32767");
    REQUIRE(fixed_info.code == 0);
    CHECK(fixed_info.out.find("nodata:      -32767") != std::string::npos);
    CHECK(fixed_info.out.find("heights:     100 .. 500") != std::string::npos);
    const Run tile = run(
        dir, "tile " + dem + " 9 543 418 -o " + dir.file("t.glb") + " --size 32 --nodata -32767");
    CHECK_MESSAGE(tile.code == 0, tile.err);
    CHECK(run(dir, "build " + dem + " -o " + dir.file("o2") + kBuild + " --nodata x").code == 2);
}

TEST_CASE("undeclared voids in a mosaic are found in its files' statistics merged") {
    ScratchDir dir;
    // Two cells side by side: 800 samples of -32767 in the west one, 200 in the east one. The
    // mosaic's share is what both hold together: 1,000 of 2 x 129^2, 3 %.
    Fixture west = hills(129, GDT_Int16);
    Fixture east = hills(129, GDT_Int16);
    (*east.geotransform)[0] += 0.5;
    for (int y = 40; y < 60; ++y) {
        for (int x = 30; x < 70; ++x) {
            west.values[static_cast<std::size_t>(y) * 129 + x] = -32767;
            if (x < 40) {
                east.values[static_cast<std::size_t>(y) * 129 + x] = -32767;
            }
        }
    }
    const std::vector<std::string> paths{tb_test::write_fixture(dir.file("w.tif"), west),
                                         tb_test::write_fixture(dir.file("e.tif"), east)};
    std::string message;
    try {
        tb::tiler::DemSource::open(paths);
    } catch (const tb::InputError& e) {
        message = e.what();
    }
    CHECK(message.find("3% of band 1's samples are -32767") != std::string::npos);
    CHECK(message.find("(100 .. 500 m)") != std::string::npos);
    CHECK(tb::tiler::DemSource::open(paths, -32767.0)->info().min_height == 100);
}

TEST_CASE("of several bad files, the error names the first given, however they are read") {
    ScratchDir dir;
    // Files are opened on several threads; the error must not depend on which finishes first.
    std::vector<std::string> paths;
    for (int k = 0; k < 40; ++k) {
        Fixture f = hills(33, GDT_Int16);
        (*f.geotransform)[0] += 0.5 * k;
        paths.push_back(tb_test::write_fixture(dir.file("c" + std::to_string(k) + ".tif"), f));
    }
    std::ofstream(dir.file("text.tif")) << "not a raster\n";
    paths[17] = dir.file("gone.tif");
    paths[23] = dir.file("text.tif");
    for (int round = 0; round < 5; ++round) {
        std::string message;
        try {
            tb::tiler::DemSource::open(paths);
        } catch (const tb::InputError& e) {
            message = e.what();
        }
        CHECK(message == paths[17] + ": no such file; check the path");
    }
}

TEST_CASE("a sample equal to a mosaic's nodata is a void in it, whatever its file declares") {
    ScratchDir dir;
    Fixture a = mosaic_cell(0, GDT_Int16, 100);
    a.nodata = -9999; // the mosaic's nodata: the first file's
    Fixture b = mosaic_cell(1, GDT_Int16, 200);
    b.nodata = -32768;
    for (int k = 0; k < 400; ++k) {
        b.values[k] = -9999; // a quarter of b: voids in the mosaic, not heights
    }
    Fixture c = mosaic_cell(1, GDT_Int16, 2000);
    c.scale = 0.1; // another scale: the mosaic holds c's heights, so -32768 raw is -3276.8 m
    for (int k = 0; k < 5; ++k) {
        c.values[k] = -32768;
    }
    const std::string pa = tb_test::write_fixture(dir.file("a.tif"), a);
    const std::string pb = tb_test::write_fixture(dir.file("b.tif"), b);
    const std::string pc = tb_test::write_fixture(dir.file("c.tif"), c);

    const auto ab = tb::tiler::DemSource::open({pa, pb}); // no undeclared voids to refuse
    CHECK(ab->info().min_height == 100);
    CHECK(ab->info().max_height == 200);
    CHECK(ab->info().nodata == -9999);
    const double step = 180.0 / std::exp2(12) / 256;
    const auto column = static_cast<std::int64_t>(std::llround((7.6 + 60.5 / 1200 + 180) / step));
    const auto row = [&](double pixel_row) {
        return static_cast<std::int64_t>(std::llround((90 - (46.4 - pixel_row / 1200)) / step));
    };
    CHECK(ab->sample(tb::tiler::Scheme::Geodetic, 12, 256, column, row(2.5), 1, 1).valid[0] == 0);
    CHECK(ab->sample(tb::tiler::Scheme::Geodetic, 12, 256, column, row(30.5), 1, 1).valid[0] == 1);

    const auto ac = tb::tiler::DemSource::open({pa, pc});
    CHECK(ac->info().min_height == doctest::Approx(-3276.8));
    CHECK(ac->info().max_height == doctest::Approx(200));
}

TEST_CASE("a sea at 0 m beside land, or a plateau, is not taken for undeclared voids") {
    ScratchDir dir;
    Fixture f = hills(129);
    for (std::size_t k = 0; k < f.values.size() / 3; ++k) {
        f.values[k] = 0; // a third at sea level, land from 100 m
    }
    CHECK_FALSE(
        tb::tiler::inspect_dem(tb_test::write_fixture(dir.file("sea.tif"), f)).likely_nodata);
    for (std::size_t k = 0; k < f.values.size() / 3; ++k) {
        f.values[k] = 2500; // a flat plateau 2000 m above hills of 100 .. 500 m
    }
    CHECK_FALSE(
        tb::tiler::inspect_dem(tb_test::write_fixture(dir.file("plateau.tif"), f)).likely_nodata);
}

TEST_CASE("a NUL byte in a DEM path is refused, not cut off") {
    ScratchDir dir;
    const std::string dem = tb_test::write_fixture(dir.file("a.tif"), hills(33));
    const std::string with_nul = dem + std::string("\0.bak", 5);
    try {
        tb::tiler::inspect_dem(with_nul);
        FAIL("expected an InputError");
    } catch (const tb::InputError& e) {
        CHECK(std::string(e.what()).find("NUL") != std::string::npos);
        CHECK(std::string(e.what()).find(dem + "\\x00.bak") != std::string::npos);
    }
}

TEST_CASE("a mosaic of files of mixed types, scales and nodata reads each as it is, and its "
          "range and outliers come from the files' own scans") {
    ScratchDir dir;
    // Three 40 x 40 cells of one 3" grid, west to east: Int16 declaring -32768 as nodata, Float32
    // declaring none (its -32768 samples are voids through the mosaic's nodata, which the first
    // file gives), and Int16 heights stored as raw * 0.5 + 10, one raw 20000 (10,010 m) among them.
    Fixture a = mosaic_cell(0, GDT_Int16, 100);
    a.nodata = -32768;
    a.values[3 * 40 + 3] = 150;
    a.values[4 * 40 + 3] = -32768;
    Fixture b = mosaic_cell(1, GDT_Float32, 200);
    b.values[10 * 40 + 10] = 40;
    for (int k = 0; k < 40; ++k) {
        b.values[20 * 40 + k] = -32768;
    }
    Fixture c = mosaic_cell(2, GDT_Int16, 400);
    c.scale = 0.5, c.offset = 10;
    c.values[7 * 40 + 5] = 20000;
    const std::vector<std::string> paths{tb_test::write_fixture(dir.file("a.tif"), a),
                                         tb_test::write_fixture(dir.file("b.tif"), b),
                                         tb_test::write_fixture(dir.file("c.tif"), c)};
    const auto mosaic = tb::tiler::DemSource::open(paths);
    REQUIRE(mosaic->parts().size() == 1); // one grid: one mosaic
    const tb::tiler::DemInfo& info = mosaic->info();
    CHECK(info.width == 120);
    CHECK(info.height == 40);
    CHECK(info.data_type == "Float64"); // the scales differ: the mosaic applies them
    CHECK(info.range_exact);
    CHECK(info.has_data);
    CHECK(info.min_height == 40);
    CHECK(info.max_height == 210);
    CHECK(info.outliers == 1);
    CHECK(info.outlier_column == 80 + 5); // a pixel of the mosaic
    CHECK(info.outlier_row == 7);
    CHECK(info.outlier_height == 10010);
    // Each cell's heights as the mosaic reads them, away from the odd pixels.
    const double step = 180.0 / std::exp2(12) / 256;
    const auto row = static_cast<std::int64_t>(std::llround((90 - (46.4 - 30.5 / 1200)) / step));
    const double expected[] = {100, 200, 210};
    for (int k = 0; k < 3; ++k) {
        const double lon = 7.6 + (k * 40 + 30.5) / 1200;
        const auto column = static_cast<std::int64_t>(std::llround((lon + 180) / step));
        const auto block = mosaic->sample(tb::tiler::Scheme::Geodetic, 12, 256, column, row, 1, 1);
        CHECK(block.valid[0] == 1);
        CHECK(block.heights[0] == expected[k]);
    }
}

TEST_CASE("inspect_metadata says what inspect_dem says of a file, without its heights") {
    ScratchDir dir;
    Fixture f;
    f.width = 30, f.height = 20;
    f.type = GDT_Int16;
    f.epsg = 32632;
    f.nodata = -9999;
    f.geotransform = std::array<double, 6>{400000, 10, 0, 5100000, 0, -10};
    f.values.assign(600, 350);
    const std::string path = tb_test::write_fixture(dir.file("m.tif"), f);
    const tb::tiler::DemInfo full = tb::tiler::inspect_dem(path);
    const tb::tiler::DemInfo meta = tb::tiler::inspect_metadata(path);
    CHECK(full.has_data);
    CHECK(full.max_height == 350);
    CHECK_FALSE(meta.has_data);
    CHECK(meta.width == full.width);
    CHECK(meta.height == full.height);
    CHECK(meta.data_type == full.data_type);
    CHECK(meta.crs_id == full.crs_id);
    CHECK(meta.nodata == full.nodata);
    CHECK(meta.geotransform == full.geotransform);
    CHECK(meta.lonlat_bounds == full.lonlat_bounds);
    CHECK(meta.resolution_m == full.resolution_m);
}

TEST_CASE("files of one mosaic that overlap and differ by more than eps there get a warning "
          "naming both and which wins; files that agree, or only touch, get none") {
    ScratchDir dir;
    // a: hills on a 129 x 129 grid; b: the same grid's pixels from column 96 on, overlapping
    // a's last 33 columns; c: the columns after a's, touching it.
    const Fixture a = hills(129);
    const auto part = [&](int from, double add) {
        Fixture f = a;
        f.width = 129 - from + 64;
        f.values.clear();
        for (int y = 0; y < 129; ++y) {
            for (int x = from; x < from + f.width; ++x) {
                f.values.push_back(x < 129 ? a.values[y * 129 + x] + add : 500.0);
            }
        }
        (*f.geotransform)[0] = (*a.geotransform)[0] + from * (*a.geotransform)[1];
        return f;
    };
    const std::string pa = tb_test::write_fixture(dir.file("a.tif"), a);
    const std::string agree = tb_test::write_fixture(dir.file("agree.tif"), part(96, 0));
    const std::string differ = tb_test::write_fixture(dir.file("differ.tif"), part(96, 40));
    const std::string touch = tb_test::write_fixture(dir.file("touch.tif"), part(129, 40));
    const Run same = run(dir, "info " + pa + " " + agree + " " + touch);
    REQUIRE_MESSAGE(same.code == 0, same.err);
    CHECK(same.err.find("overlap") == std::string::npos);
    const Run other = run(dir, "info " + differ + " " + pa);
    REQUIRE_MESSAGE(other.code == 0, other.err);
    CHECK(other.err.find("Z warn ") != std::string::npos);
    CHECK(other.err.find(differ + " and " + pa +
                         " overlap (4257 pixels valid in both) and "
                         "differ there by up to 40 m") != std::string::npos);
    CHECK(other.err.find(differ + " wins where both have data, being given first") !=
          std::string::npos);
}

namespace {

// A 40 x 40 Int16 DEM of 3" pixels at (west, 46.0), heights 1000 + column + row in its own
// unit: `unit` as band 1's unit type when given, `crs` as its CRS.
std::string feet_dem(const std::string& path, double west, const char* unit, const char* crs) {
    Fixture f;
    f.width = f.height = 40;
    f.type = GDT_Int16;
    for (int j = 0; j < f.height; ++j) {
        for (int i = 0; i < f.width; ++i) {
            f.values.push_back(1000 + i + j);
        }
    }
    f.geotransform = std::array<double, 6>{west, 1.0 / 1200, 0, 46.0, 0, -1.0 / 1200};
    f.epsg = 4326;
    tb_test::write_fixture(path, f);
    GDALDatasetUniquePtr ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER | GDAL_OF_UPDATE));
    REQUIRE(ds != nullptr);
    if (unit != nullptr) {
        REQUIRE(ds->GetRasterBand(1)->SetUnitType(unit) == CE_None);
    }
    if (crs != nullptr) {
        OGRSpatialReference srs;
        REQUIRE(srs.SetFromUserInput(crs) == OGRERR_NONE);
        REQUIRE(ds->SetSpatialRef(&srs) == CE_None);
    }
    return path;
}

} // namespace

TEST_CASE("heights in feet are read as metres: by band 1's unit or the vertical CRS's, in one "
          "file, a mosaic of such files and a collection beside a DEM in metres") {
    ScratchDir dir;
    const double ft = 0.3048, us_ft = 1200.0 / 3937;
    const std::string a = feet_dem(dir.file("a.tif"), 7.0, "ft", nullptr);
    using tb::tiler::DemSource;
    const auto one = DemSource::open({a});
    CHECK(one->info().height_unit == "ft");
    CHECK(one->info().min_height == doctest::Approx(1000 * ft));
    CHECK(one->info().max_height == doctest::Approx(1078 * ft));
    CHECK(one->read_pixels(3, 5, 1, 1)[0] == doctest::Approx(1008 * ft));
    // NAVD88 height in US survey feet as the CRS's vertical part, no unit on the band.
    const std::string v = feet_dem(dir.file("v.tif"), 7.0, nullptr, "EPSG:4326+6360");
    const auto vertical = DemSource::open({v});
    CHECK(vertical->info().metres_per_unit == doctest::Approx(us_ft));
    CHECK(vertical->read_pixels(3, 5, 1, 1)[0] == doctest::Approx(1008 * us_ft));
    // Two files of one grid side by side: one mosaic, read in metres once, not twice.
    const std::string b = feet_dem(dir.file("b.tif"), 7.0 + 40.0 / 1200, "ft", nullptr);
    const auto mosaic = DemSource::open({a, b});
    REQUIRE(mosaic->members().empty());
    CHECK(mosaic->info().width == 80);
    CHECK(mosaic->info().max_height == doctest::Approx(1078 * ft));
    CHECK(mosaic->read_pixels(43, 5, 1, 1)[0] == doctest::Approx(1008 * ft));
    // A metre DEM of another grid over the same place: the collection's heights agree.
    Fixture m;
    m.width = m.height = 20;
    m.type = GDT_Float32;
    for (int j = 0; j < m.height; ++j) {
        for (int i = 0; i < m.width; ++i) {
            m.values.push_back((1000 + 2 * i + 0.5 + 2 * j + 0.5) * ft);
        }
    }
    m.geotransform = std::array<double, 6>{7.0, 1.0 / 600, 0, 46.0, 0, -1.0 / 600};
    m.epsg = 4326;
    const std::string metres = tb_test::write_fixture(dir.file("m.tif"), m);
    const auto both = DemSource::open({metres, a});
    REQUIRE(both->members().size() == 2);
    CHECK(both->info().min_height > 300);
    CHECK(both->info().max_height < 1080 * ft);
}
