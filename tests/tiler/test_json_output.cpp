// Every JSON document Terrabound writes is valid JSON, and the mesh text reads back exactly:
// json_number refuses what JSON cannot hold; mesh heights parsed as doubles are the floats the
// mesher used, bit for bit.
#include "core/error.hpp"
#include "core/triangulate.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/json_number.hpp"
#include "tiler/layer.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>
#include <sys/wait.h>

using tb_test::ScratchDir;

TEST_CASE("json_number writes the shortest decimal that reads back as the same double") {
    for (double v : {0.0,
                     -0.0,
                     1.0,
                     0.1,
                     -1234.5678,
                     1e21,
                     6378137.0,
                     std::numeric_limits<double>::max(),
                     std::numeric_limits<double>::denorm_min(),
                     static_cast<double>(0.1f)}) {
        CAPTURE(v);
        const std::string text = tb::tiler::json_number(v);
        CHECK(std::strtod(text.c_str(), nullptr) == v);
        CHECK(nlohmann::json::parse(text).get<double>() == v);
    }
    CHECK(tb::tiler::json_number(0.1) == "0.1");
}

TEST_CASE("json_number refuses infinity and NaN, naming what it was writing") {
    for (double v : {INFINITY, -INFINITY, NAN}) {
        CAPTURE(v);
        try {
            tb::tiler::json_number(v, "the tileset's min height");
            FAIL("expected an InputError");
        } catch (const tb::InputError& e) {
            CHECK(std::string(e.what()).find("the tileset's min height") != std::string::npos);
        }
    }
}

TEST_CASE("mesh text heights read back as doubles are exactly the mesher's floats") {
    // 0.1 m steps: no such height is a float, so 9 digits read back as a double miss it.
    tb::core::HeightGrid grid;
    grid.width = 41, grid.height = 37;
    for (int y = 0; y < grid.height; ++y) {
        for (int x = 0; x < grid.width; ++x) {
            const double h = 1000 + 37.3 * std::sin(x * 0.3) * std::cos(y * 0.21) + 0.1 * (x % 7);
            grid.heights.push_back(static_cast<float>(std::round(h * 10) / 10));
        }
    }
    tb::core::TriangulateOptions options;
    options.eps = 0.5;
    const tb::core::Mesh mesh = tb::core::triangulate(grid, options);
    REQUIRE(mesh.z.size() > 3);

    std::istringstream obj(tb::tiler::mesh_to_obj(mesh));
    std::string kind;
    std::size_t v = 0;
    while (obj >> kind) {
        if (kind == "v") {
            std::string x, y, z;
            obj >> x >> y >> z;
            REQUIRE(v < mesh.z.size());
            CHECK(std::strtod(z.c_str(), nullptr) == static_cast<double>(mesh.z[v]));
            ++v;
        } else {
            std::string rest;
            std::getline(obj, rest);
        }
    }
    CHECK(v == mesh.z.size());

    const auto json = nlohmann::json::parse(tb::tiler::mesh_to_json(mesh));
    const auto& vertices = json["vertices"];
    REQUIRE(vertices.size() == 3 * mesh.z.size());
    for (std::size_t k = 0; k < mesh.z.size(); ++k) {
        CHECK(vertices[3 * k + 2].get<double>() == static_cast<double>(mesh.z[k]));
    }
}

TEST_CASE("terrabound mesh of fuji_float32.tif at eps 6 is within eps when read as doubles") {
    const auto dem = tb_test::shared_dem("fuji_float32.tif");
    if (!dem) {
        return;
    }
    ScratchDir dir;
    const std::string out = dir.file("fuji.obj");
    const std::string command =
        std::string(TB_BINARY) + " mesh " + *dem + " --eps 6 -o " + out + " 2>/dev/null";
    const int status = std::system(command.c_str());
    REQUIRE(WIFEXITED(status));
    REQUIRE(WEXITSTATUS(status) == 0);
    std::vector<std::array<double, 3>> vertices;
    std::vector<std::array<int, 3>> triangles;
    std::ifstream in(out);
    std::string kind;
    while (in >> kind) {
        if (kind == "v") {
            std::array<double, 3> p{};
            in >> p[0] >> p[1] >> p[2];
            vertices.push_back(p);
        } else {
            std::array<int, 3> t{};
            in >> t[0] >> t[1] >> t[2];
            triangles.push_back({t[0] - 1, t[1] - 1, t[2] - 1});
        }
    }
    GDALAllRegister();
    GDALDatasetUniquePtr ds(GDALDataset::Open(dem->c_str(), GDAL_OF_RASTER));
    REQUIRE(ds);
    const int w = ds->GetRasterXSize(), h = ds->GetRasterYSize();
    std::vector<float> heights(static_cast<std::size_t>(w) * h);
    REQUIRE(ds->GetRasterBand(1)->RasterIO(
                GF_Read, 0, 0, w, h, heights.data(), w, h, GDT_Float32, 0, 0, nullptr) == CE_None);
    const double worst = tb_test::brute_force_max_error(vertices, triangles, w, h, heights, {});
    // The mesher's bound is exact on floats; the barycentric check in double adds at most
    // rounding of a few ulps of 4000 m.
    CHECK(worst <= 6 + 1e-9);
}
