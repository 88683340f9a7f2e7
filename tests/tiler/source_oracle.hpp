#pragma once
// An independent judge of the promise against the user's own DEM, sharing no code with tiler/:
// the source is read with GDAL (every valid pixel centre, reprojected to WGS84 lon/lat with OGR
// where the CRS is another), EGM96 undulations are read with GDAL from PROJ's grid and
// interpolated here, a .glb tile is decoded with Draco's own decoder, and the surface a client
// draws (straight triangles between the decoded ECEF vertices) is intersected with the
// ellipsoid normal through each pixel centre.
#include <doctest/doctest.h>
#include <draco/compression/decode.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace tb_oracle {

constexpr double kPi = 3.14159265358979323846;
constexpr double kA = 6378137.0;
constexpr double kF = 1 / 298.257223563;
constexpr double kE2 = kF * (2 - kF);

using V3 = std::array<double, 3>;

inline V3 ecef(double lon_deg, double lat_deg, double h) {
    const double lon = lon_deg * kPi / 180, lat = lat_deg * kPi / 180;
    const double n = kA / std::sqrt(1 - kE2 * std::sin(lat) * std::sin(lat));
    return {(n + h) * std::cos(lat) * std::cos(lon),
            (n + h) * std::cos(lat) * std::sin(lon),
            (n * (1 - kE2) + h) * std::sin(lat)};
}

// lon, lat (degrees), h by fixed-point iteration on the latitude (converges to far below a
// millimetre in a few steps away from the poles).
inline V3 geodetic(const V3& p) {
    const double lon = std::atan2(p[1], p[0]);
    const double r = std::hypot(p[0], p[1]);
    double lat = std::atan2(p[2], r * (1 - kE2));
    double h = 0;
    for (int k = 0; k < 8; ++k) {
        const double n = kA / std::sqrt(1 - kE2 * std::sin(lat) * std::sin(lat));
        h = r / std::cos(lat) - n;
        lat = std::atan2(p[2], r * (1 - kE2 * n / (n + h)));
    }
    return {lon * 180 / kPi, lat * 180 / kPi, h};
}

// EGM96 from PROJ's 15' grid, read with GDAL, bilinear between its pixel centres.
class Geoid {
public:
    Geoid() {
        GDALAllRegister();
        GDALDatasetUniquePtr ds(GDALDataset::Open("/usr/share/proj/egm96_15.gtx", GDAL_OF_RASTER));
        REQUIRE_MESSAGE(ds != nullptr, "EGM96 grid /usr/share/proj/egm96_15.gtx (proj-data)");
        width_ = ds->GetRasterXSize(), height_ = ds->GetRasterYSize();
        REQUIRE(ds->GetGeoTransform(gt_.data()) == CE_None);
        values_.resize(static_cast<std::size_t>(width_) * height_);
        REQUIRE(ds->GetRasterBand(1)->RasterIO(GF_Read,
                                               0,
                                               0,
                                               width_,
                                               height_,
                                               values_.data(),
                                               width_,
                                               height_,
                                               GDT_Float64,
                                               0,
                                               0,
                                               nullptr) == CE_None);
    }
    double at(double lon, double lat) const {
        double u = (lon - gt_[0]) / gt_[1] - 0.5;
        double v = (lat - gt_[3]) / gt_[5] - 0.5;
        u = std::fmod(std::fmod(u, width_) + width_, width_);
        v = std::clamp(v, 0.0, height_ - 1.0);
        const int c0 = static_cast<int>(u), c1 = (c0 + 1) % width_;
        const int r0 = std::min(static_cast<int>(v), height_ - 2), r1 = r0 + 1;
        const double fu = u - c0, fv = v - r0;
        const auto g = [&](int c, int r) {
            return values_[static_cast<std::size_t>(r) * width_ + c];
        };
        return (g(c0, r0) * (1 - fu) + g(c1, r0) * fu) * (1 - fv) +
               (g(c0, r1) * (1 - fu) + g(c1, r1) * fu) * fv;
    }

private:
    int width_ = 0, height_ = 0;
    std::array<double, 6> gt_{};
    std::vector<double> values_;
};

struct Pixel {
    double lon = 0, lat = 0;
    double h = 0; // ellipsoidal: the DEM's height plus the EGM96 undulation
};

// Every valid pixel centre of band 1 of `path`, with ellipsoidal heights.
inline std::vector<Pixel> read_pixels(const std::string& path, const Geoid& geoid) {
    GDALAllRegister();
    GDALDatasetUniquePtr ds(GDALDataset::Open(path.c_str(), GDAL_OF_RASTER));
    REQUIRE(ds != nullptr);
    const int w = ds->GetRasterXSize(), h = ds->GetRasterYSize();
    std::array<double, 6> gt{};
    REQUIRE(ds->GetGeoTransform(gt.data()) == CE_None);
    GDALRasterBand* band = ds->GetRasterBand(1);
    int has_nodata = 0;
    const double nodata = band->GetNoDataValue(&has_nodata);
    const bool is_float = band->GetRasterDataType() == GDT_Float32;
    std::vector<double> raw(static_cast<std::size_t>(w) * h);
    REQUIRE(band->RasterIO(GF_Read, 0, 0, w, h, raw.data(), w, h, GDT_Float64, 0, 0, nullptr) ==
            CE_None);
    OGRSpatialReference src = *ds->GetSpatialRef(), wgs84;
    src.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    wgs84.importFromEPSG(4326);
    wgs84.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    std::unique_ptr<OGRCoordinateTransformation> ct;
    if (!src.IsGeographic()) {
        ct.reset(OGRCreateCoordinateTransformation(&src, &wgs84));
        REQUIRE(ct != nullptr);
    }
    std::vector<Pixel> out;
    for (int j = 0; j < h; ++j) {
        for (int i = 0; i < w; ++i) {
            const double v = raw[static_cast<std::size_t>(j) * w + i];
            if (!std::isfinite(v) ||
                (has_nodata && (v == nodata || (is_float && float(v) == float(nodata))))) {
                continue;
            }
            double x = gt[0] + (i + 0.5) * gt[1] + (j + 0.5) * gt[2];
            double y = gt[3] + (i + 0.5) * gt[4] + (j + 0.5) * gt[5];
            if (ct) {
                REQUIRE(ct->Transform(1, &x, &y));
            }
            out.push_back({x, y, v + geoid.at(x, y)});
        }
    }
    return out;
}

struct Drawn {
    std::vector<V3> ecef; // decoded vertices, metres
    std::vector<std::uint32_t> indices;
};

// A .glb tile as a client decodes it: the JSON chunk's root translation and the Draco buffer
// (glTF y-up: ECEF (x, y, z) = (X, -Z, Y)). An empty tile (no BIN chunk) draws nothing.
inline Drawn decode_glb(const std::string& bytes) {
    const auto u32 = [&](std::size_t at) {
        std::uint32_t v = 0;
        std::memcpy(&v, bytes.data() + at, 4);
        return v;
    };
    REQUIRE(bytes.size() >= 20);
    REQUIRE(u32(0) == 0x46546C67);
    const std::uint32_t json_len = u32(12);
    const std::string json = bytes.substr(20, json_len);
    Drawn out;
    if (20 + json_len == bytes.size()) {
        CHECK(json.find("\"meshes\"") == std::string::npos);
        return out;
    }
    const std::size_t bin = 20 + json_len + 8;
    const auto number_after = [&](const std::string& key, std::size_t from) {
        const std::size_t at = json.find("\"" + key + "\":", from);
        REQUIRE(at != std::string::npos);
        return std::stod(json.substr(at + key.size() + 3));
    };
    const std::size_t views = json.find("\"bufferViews\":[");
    REQUIRE(views != std::string::npos);
    const auto offset = static_cast<std::size_t>(number_after("byteOffset", views));
    const auto length = static_cast<std::size_t>(number_after("byteLength", views));
    V3 t{0, 0, 0};
    const std::size_t tr = json.find("\"translation\":[");
    if (tr != std::string::npos) {
        std::size_t at = tr + 15;
        for (double& c : t) {
            std::size_t used = 0;
            c = std::stod(json.substr(at), &used);
            at += used + 1;
        }
    }
    draco::DecoderBuffer buffer;
    buffer.Init(bytes.data() + bin + offset, length);
    draco::Decoder decoder;
    auto mesh = decoder.DecodeMeshFromBuffer(&buffer);
    REQUIRE(mesh.ok());
    const draco::Mesh& m = *mesh.value();
    const draco::PointAttribute* pos = m.GetNamedAttribute(draco::GeometryAttribute::POSITION);
    REQUIRE(pos != nullptr);
    for (draco::PointIndex::ValueType p = 0; p < m.num_points(); ++p) {
        float v[3];
        pos->GetMappedValue(draco::PointIndex(p), v);
        const double X = t[0] + v[0], Y = t[1] + v[1], Z = t[2] + v[2];
        out.ecef.push_back({X, -Z, Y});
    }
    for (draco::FaceIndex::ValueType f = 0; f < m.num_faces(); ++f) {
        for (int k = 0; k < 3; ++k) {
            out.indices.push_back(m.face(draco::FaceIndex(f))[k].value());
        }
    }
    return out;
}

struct Verdict {
    double worst = 0; // largest |drawn - pixel| over the pixels judged, metres
    double worst_lon = 0, worst_lat = 0;
    std::int64_t judged = 0;  // pixels under a drawn triangle
    std::int64_t undrawn = 0; // pixels inside the box that no triangle holds
};

// Judges the drawn tile against every pixel whose centre lies in the lon/lat box (closed).
// drawn[k] is set for every pixel k the tile draws (a pixel on a border line two tiles share
// may be drawn by either).
inline Verdict judge(const Drawn& d,
                     const std::vector<Pixel>& pixels,
                     double west,
                     double south,
                     double east,
                     double north,
                     std::vector<std::uint8_t>& drawn,
                     double reach_m) {
    std::vector<const Pixel*> inside;
    for (const Pixel& p : pixels) {
        if (p.lon >= west && p.lon <= east && p.lat >= south && p.lat <= north) {
            inside.push_back(&p);
        }
    }
    std::vector<V3> geo;
    for (const V3& e : d.ecef) {
        geo.push_back(geodetic(e));
    }
    // Buckets of 128 x 128 over the box.
    constexpr int kCells = 128;
    const double cw = (east - west) / kCells, ch = (north - south) / kCells;
    const auto cell = [&](double lon, double lat, int& i, int& j) {
        i = std::clamp(static_cast<int>(std::floor((lon - west) / cw)), 0, kCells - 1);
        j = std::clamp(static_cast<int>(std::floor((lat - south) / ch)), 0, kCells - 1);
    };
    std::vector<std::vector<std::uint32_t>> bucket(kCells * kCells);
    for (std::size_t k = 0; k < inside.size(); ++k) {
        int i = 0, j = 0;
        cell(inside[k]->lon, inside[k]->lat, i, j);
        bucket[static_cast<std::size_t>(j) * kCells + i].push_back(static_cast<std::uint32_t>(k));
    }
    std::vector<double> error(inside.size(), -1);
    // Two passes: points inside a triangle (barycentric slack 1e-9), then, for points no
    // triangle held, those within reach_m of one (the quantization snap moves a vertex on the
    // data's outer edge by up to that much, so a pixel on that edge may lie a hair outside).
    const double reach_deg =
        reach_m /
        (kPi / 180 * kA * std::cos(std::max(std::abs(south), std::abs(north)) * kPi / 180));
    for (int pass = 0; pass < 2; ++pass) {
        for (std::size_t t = 0; t + 2 < d.indices.size(); t += 3) {
            const V3 &a = geo[d.indices[t]], &b = geo[d.indices[t + 1]], &c = geo[d.indices[t + 2]];
            const double det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
            if (det == 0) {
                continue;
            }
            // Barycentric slack of a point reach_deg outside: reach over the smallest altitude.
            const double longest = std::max({std::hypot(b[0] - a[0], b[1] - a[1]),
                                             std::hypot(c[0] - b[0], c[1] - b[1]),
                                             std::hypot(a[0] - c[0], a[1] - c[1])});
            const double slack = pass == 0 ? 1e-9 : reach_deg * longest / std::abs(det);
            int i0 = 0, j0 = 0, i1 = 0, j1 = 0;
            cell(std::min({a[0], b[0], c[0]}), std::min({a[1], b[1], c[1]}), i0, j0);
            cell(std::max({a[0], b[0], c[0]}), std::max({a[1], b[1], c[1]}), i1, j1);
            const V3 &A = d.ecef[d.indices[t]], &B = d.ecef[d.indices[t + 1]],
                     &C = d.ecef[d.indices[t + 2]];
            const V3 ab{B[0] - A[0], B[1] - A[1], B[2] - A[2]};
            const V3 ac{C[0] - A[0], C[1] - A[1], C[2] - A[2]};
            const V3 n{ab[1] * ac[2] - ab[2] * ac[1],
                       ab[2] * ac[0] - ab[0] * ac[2],
                       ab[0] * ac[1] - ab[1] * ac[0]};
            for (int j = j0; j <= j1; ++j) {
                for (int i = i0; i <= i1; ++i) {
                    for (std::uint32_t k : bucket[static_cast<std::size_t>(j) * kCells + i]) {
                        if (pass == 1 && error[k] >= 0) {
                            continue;
                        }
                        const Pixel& p = *inside[k];
                        const double la =
                            ((b[0] - p.lon) * (c[1] - p.lat) - (c[0] - p.lon) * (b[1] - p.lat)) /
                            det;
                        const double lb =
                            ((c[0] - p.lon) * (a[1] - p.lat) - (a[0] - p.lon) * (c[1] - p.lat)) /
                            det;
                        if (std::min({la, lb, 1 - la - lb}) < -slack) {
                            continue;
                        }
                        // The drawn point above the pixel: where the ellipsoid normal through
                        // (lon, lat) meets the triangle's plane.
                        const V3 base = ecef(p.lon, p.lat, 0);
                        const double lon = p.lon * kPi / 180, lat = p.lat * kPi / 180;
                        const V3 u{std::cos(lat) * std::cos(lon),
                                   std::cos(lat) * std::sin(lon),
                                   std::sin(lat)};
                        const double s = ((A[0] - base[0]) * n[0] + (A[1] - base[1]) * n[1] +
                                          (A[2] - base[2]) * n[2]) /
                                         (u[0] * n[0] + u[1] * n[1] + u[2] * n[2]);
                        error[k] = std::max(error[k], std::abs(s - p.h));
                    }
                }
            }
        }
    }
    Verdict v;
    for (std::size_t k = 0; k < inside.size(); ++k) {
        if (error[k] < 0) {
            ++v.undrawn;
            continue;
        }
        drawn[static_cast<std::size_t>(inside[k] - pixels.data())] = 1;
        ++v.judged;
        if (error[k] > v.worst) {
            v.worst = error[k];
            v.worst_lon = inside[k]->lon, v.worst_lat = inside[k]->lat;
        }
    }
    return v;
}

} // namespace tb_oracle
