#pragma once
// Helpers shared by the raster, layer and CLI tests: temp dirs, GDAL fixtures, real-DEM paths,
// and an independent brute-force L-inf check of a grid mesh.
#include "core/mesh.hpp"

#include <doctest/doctest.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

namespace tb_test {

namespace fs = std::filesystem;

// The whole file at `p` (empty when it cannot be read).
inline std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

// Replaces the file at `p` with `bytes`, as damage behind a store's back would.
inline void spill(const fs::path& p, const std::string& bytes) {
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out << bytes;
}

// A fresh directory under the system temp dir, removed at scope exit.
struct ScratchDir {
    fs::path path;
    ScratchDir() {
        std::string tmpl = (fs::temp_directory_path() / "tb-raster-XXXXXX").string();
        REQUIRE(::mkdtemp(tmpl.data()) != nullptr);
        path = tmpl;
    }
    ~ScratchDir() {
        std::error_code ec;
        fs::remove_all(path, ec);
    }
    std::string file(const std::string& name) const { return (path / name).string(); }
};

// Path of a file of ../shared/data, or nullopt (with a MESSAGE naming it) when absent.
inline std::optional<std::string> shared_dem(const std::string& name) {
    const std::string path = std::string(TB_SHARED_DATA) + "/" + name;
    if (!fs::exists(path)) {
        MESSAGE("skipped: " << std::string(path) << " is missing");
        return std::nullopt;
    }
    return path;
}

struct Fixture {
    int width = 4, height = 4, bands = 1;
    GDALDataType type = GDT_Float32;
    std::vector<double> values; // band 1 (other bands get zeros)
    std::optional<std::array<double, 6>> geotransform;
    int epsg = 0; // 0: no CRS
    std::optional<double> nodata;
    std::optional<double> scale, offset;
    std::string driver = "GTiff";
};

// Writes a fixture raster with GDAL and returns its path.
inline std::string write_fixture(const std::string& path, const Fixture& f) {
    GDALAllRegister();
    GDALDriver* driver = GetGDALDriverManager()->GetDriverByName(f.driver.c_str());
    REQUIRE(driver != nullptr);
    GDALDatasetUniquePtr ds(
        driver->Create(path.c_str(), f.width, f.height, f.bands, f.type, nullptr));
    REQUIRE(ds != nullptr);
    if (f.geotransform) {
        std::array<double, 6> g = *f.geotransform;
        REQUIRE(ds->SetGeoTransform(g.data()) == CE_None);
    }
    if (f.epsg) {
        OGRSpatialReference srs;
        srs.importFromEPSG(f.epsg);
        REQUIRE(ds->SetSpatialRef(&srs) == CE_None);
    }
    GDALRasterBand* band = ds->GetRasterBand(1);
    if (f.nodata) {
        band->SetNoDataValue(*f.nodata);
    }
    if (f.scale) {
        band->SetScale(*f.scale);
    }
    if (f.offset) {
        band->SetOffset(*f.offset);
    }
    std::vector<double> values = f.values;
    values.resize(static_cast<std::size_t>(f.width) * f.height, 0.0);
    if (!GDALDataTypeIsComplex(f.type)) {
        REQUIRE(band->RasterIO(GF_Write,
                               0,
                               0,
                               f.width,
                               f.height,
                               values.data(),
                               f.width,
                               f.height,
                               GDT_Float64,
                               0,
                               0,
                               nullptr) == CE_None);
    }
    return path;
}

// Independent L-inf check: for every valid sample, the height of the mesh triangle containing
// it (barycentric, in double) against the sample; also checks that the triangles' areas add up
// to the grid's rectangle. Returns the largest |mesh - sample|.
inline double brute_force_max_error(const std::vector<std::array<double, 3>>& vertices,
                                    const std::vector<std::array<int, 3>>& triangles,
                                    int width,
                                    int height,
                                    const std::vector<float>& heights,
                                    const std::vector<std::uint8_t>& valid,
                                    double expected_area = -1) {
    std::vector<double> best(heights.size(), -1.0);
    double area = 0;
    for (const auto& t : triangles) {
        const auto& a = vertices[static_cast<std::size_t>(t[0])];
        const auto& b = vertices[static_cast<std::size_t>(t[1])];
        const auto& c = vertices[static_cast<std::size_t>(t[2])];
        const double d = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
        area += std::abs(d) / 2;
        if (d == 0) {
            continue;
        }
        const int x0 = static_cast<int>(std::floor(std::min({a[0], b[0], c[0]})));
        const int x1 = static_cast<int>(std::ceil(std::max({a[0], b[0], c[0]})));
        const int y0 = static_cast<int>(std::floor(std::min({a[1], b[1], c[1]})));
        const int y1 = static_cast<int>(std::ceil(std::max({a[1], b[1], c[1]})));
        for (int y = std::max(0, y0); y <= std::min(height - 1, y1); ++y) {
            for (int x = std::max(0, x0); x <= std::min(width - 1, x1); ++x) {
                const double l1 = ((b[0] - x) * (c[1] - y) - (c[0] - x) * (b[1] - y)) / d;
                const double l2 = ((c[0] - x) * (a[1] - y) - (a[0] - x) * (c[1] - y)) / d;
                const double l3 = 1 - l1 - l2;
                if (l1 < -1e-12 || l2 < -1e-12 || l3 < -1e-12) {
                    continue;
                }
                const std::size_t k = static_cast<std::size_t>(y) * width + x;
                const double z = l1 * a[2] + l2 * b[2] + l3 * c[2];
                const double err = std::abs(z - heights[k]);
                best[k] = std::max(best[k], err);
            }
        }
    }
    // The triangles tile the grid's rectangle, or the area given (a tile reaching past its
    // outermost samples to its border lines).
    CHECK(area == doctest::Approx(expected_area >= 0
                                      ? expected_area
                                      : static_cast<double>(width - 1) * (height - 1)));
    double worst = 0;
    for (std::size_t k = 0; k < heights.size(); ++k) {
        REQUIRE_MESSAGE(best[k] >= 0, "sample " << k << " is covered by no triangle");
        if (valid.empty() || valid[k]) {
            worst = std::max(worst, best[k]);
        }
    }
    return worst;
}

} // namespace tb_test
