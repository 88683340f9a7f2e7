// Vertex normals and the default material of .glb and .drc tiles: one unit, upward normal per
// decoded vertex, agreeing with the decoded faces around it, identical (glb) or within the
// quantization (drc) where two neighbouring tiles share a border vertex.
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/formats/draco_decode.hpp"
#include "tiler/formats/encode.hpp"
#include "tiler/geodesy.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <memory>
#include <string>
#include <vector>

using namespace tb;
using namespace tb::tiler;
using Vec = std::array<double, 3>;

namespace {

constexpr double kPi = 3.14159265358979323846;

double dot(const Vec& a, const Vec& b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
Vec cross(const Vec& a, const Vec& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double angle_deg(const Vec& a, const Vec& b) {
    const Vec c = cross(a, b); // atan2 stays exact for tiny angles, where acos does not
    return std::atan2(std::sqrt(dot(c, c)), dot(a, b)) * 180 / kPi;
}

// A decoded tile in ECEF: positions (exact doubles) and normals, whatever the format.
struct EcefTile {
    std::vector<Vec> positions, normals;
    std::vector<std::uint32_t> indices;
    double quant_step = 0; // drc only
};

EcefTile to_ecef_tile(const std::string& bytes, Format format) {
    const DecodedTile d = format == Format::Glb ? decode_glb(bytes) : decode_drc(bytes);
    EcefTile out;
    out.indices = d.indices;
    if (format == Format::Glb) {
        // glTF y-up (X, Y, Z) is ECEF (X, -Z, Y); positions are relative to the translation.
        for (const auto& p : d.positions) {
            const Vec w{d.translation[0] + p[0], d.translation[1] + p[1], d.translation[2] + p[2]};
            out.positions.push_back({w[0], -w[2], w[1]});
        }
        for (const auto& n : d.normals) {
            out.normals.push_back({n[0], -n[2], n[1]});
        }
        return out;
    }
    const EnuFrame f = enu_frame({d.metadata.doubles.at("origin_lon_deg"),
                                  d.metadata.doubles.at("origin_lat_deg"),
                                  d.metadata.doubles.at("origin_h_m")});
    out.quant_step = d.metadata.doubles.at("quant_step_m");
    for (const auto& p : d.positions) {
        const Ecef e = enu_to_ecef(f, p);
        out.positions.push_back({e.x, e.y, e.z});
    }
    for (const auto& n : d.normals) {
        Vec e{};
        for (int a = 0; a < 3; ++a) {
            e[a] = f.axes[0][a] * n[0] + f.axes[1][a] * n[1] + f.axes[2][a] * n[2];
        }
        out.normals.push_back(e);
    }
    return out;
}

Vec ellipsoid_up(const Vec& p) {
    const Geodetic g = to_geodetic({p[0], p[1], p[2]});
    const double lon = g.lon * kPi / 180, lat = g.lat * kPi / 180;
    return {std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat)};
}

// A plane tilted by about 10 degrees (rising east and north) with gentle hills on it (slopes
// up to 0.1, curvature radii above 30 km), heights in metres at ground metres x east, y south.
double terrain(double x, double y) {
    return 800 + 0.15 * x - 0.1 * y + 300 * std::sin(x / 3000) * std::cos(y / 4000);
}

// A 600 x 600 DEM of `terrain`: lon/lat (EPSG:4326, 3" pixels at 46 N 7 E) or UTM 32N (90 m).
struct Dem {
    tb_test::ScratchDir dir;
    std::shared_ptr<const Layer> layer;
    Dem(int epsg, Scheme scheme) {
        tb_test::Fixture f;
        f.width = f.height = 600;
        f.epsg = epsg;
        double mx = 0, my = 0; // ground metres per pixel
        if (epsg == 4326) {
            const double d = 0.5 / 600;
            f.geotransform = std::array<double, 6>{7, d, 0, 46.5, 0, -d};
            my = d * kPi / 180 * 6367000;
            mx = my * std::cos(46.25 * kPi / 180);
        } else {
            f.geotransform = std::array<double, 6>{350000, 90, 0, 5150000, 0, -90};
            mx = my = 90;
        }
        for (int j = 0; j < f.height; ++j) {
            for (int i = 0; i < f.width; ++i) {
                f.values.push_back(terrain(i * mx, j * my));
            }
        }
        log::set_level(log::Level::Warn);
        LayerOptions o;
        o.sources = {tb_test::write_fixture(dir.file("plane.tif"), f)};
        o.scheme = scheme;
        o.tile_size = 64; // small tiles keep this Debug test fast
        o.datum = VerticalDatum::Ellipsoid;
        layer = Layer::open(o);
    }
    // A tile of the finest zoom well inside the DEM, and its east and south neighbours.
    TileId inner(std::int64_t dx = 0, std::int64_t dy = 0) const {
        const int z = layer->max_zoom();
        const TileRange r = layer->tiles_at(z);
        REQUIRE(r.x1 - r.x0 >= 3);
        REQUIRE(r.y1 - r.y0 >= 3);
        return {z, (r.x0 + r.x1) / 2 + dx, (r.y0 + r.y1) / 2 + dy};
    }
};

struct Case {
    int epsg;
    Scheme scheme;
    const char* name;
};
// Pixel layers in both schemes (geodetic grid, and mercator tiles of a lon/lat grid) and a
// lattice layer (a projected DEM resampled on the zoom's lattice).
const Case kCases[] = {{4326, Scheme::Geodetic, "lon/lat DEM, geodetic"},
                       {4326, Scheme::Mercator, "lon/lat DEM, mercator"},
                       {32632, Scheme::Geodetic, "UTM DEM, geodetic lattice"}};

} // namespace

TEST_CASE("glb and drc tiles carry one unit-length, upward normal per decoded vertex that agrees "
          "with the decoded faces around it") {
    for (const Case& c : kCases) {
        const std::string name = c.name;
        CAPTURE(name);
        const Dem dem(c.epsg, c.scheme);
        const TileId id = dem.inner();
        for (Format format : {Format::Glb, Format::Drc}) {
            const std::string fmt = format_name(format);
            CAPTURE(fmt);
            const EcefTile t =
                to_ecef_tile(dem.layer->make_tile(dem.layer->tile(id), format), format);
            REQUIRE(t.positions.size() >= 4);
            REQUIRE(t.normals.size() == t.positions.size());
            // Area-weighted face normals (the cross product is twice the area times the unit
            // normal) summed at each vertex.
            std::vector<Vec> faces(t.positions.size(), Vec{});
            for (std::size_t e = 0; e < t.indices.size(); e += 3) {
                const Vec& a = t.positions[t.indices[e]];
                const Vec& b = t.positions[t.indices[e + 1]];
                const Vec& p = t.positions[t.indices[e + 2]];
                const Vec n = cross({b[0] - a[0], b[1] - a[1], b[2] - a[2]},
                                    {p[0] - a[0], p[1] - a[1], p[2] - a[2]});
                for (std::size_t k = 0; k < 3; ++k) {
                    Vec& f = faces[t.indices[e + k]];
                    for (int i = 0; i < 3; ++i) {
                        f[i] += n[i];
                    }
                }
            }
            double worst_len = 0, min_up = 1, worst_angle = 0, mean_tilt = 0;
            for (std::size_t v = 0; v < t.positions.size(); ++v) {
                const Vec& n = t.normals[v];
                const Vec up = ellipsoid_up(t.positions[v]);
                worst_len = std::max(worst_len, std::abs(std::sqrt(dot(n, n)) - 1));
                min_up = std::min(min_up, dot(n, up));
                worst_angle = std::max(worst_angle, angle_deg(n, faces[v]));
                mean_tilt += angle_deg(n, up) / double(t.positions.size());
            }
            MESSAGE(name << " " << fmt << ": " << t.positions.size() << " vertices, worst |n|-1 "
                         << worst_len << ", worst angle to faces " << worst_angle
                         << " deg, mean tilt " << mean_tilt << " deg");
            CHECK(worst_len < 1e-3);
            CHECK(min_up > 0.2);
            CHECK(worst_angle < 3.0);
            // The plane tilts by 10 degrees: normals are not just the ellipsoid's up.
            CHECK(mean_tilt > 6.0);
            CHECK(mean_tilt < 16.0);
        }
    }
}

TEST_CASE("neighbouring tiles give a border vertex they share the same normal (glb bit for bit, "
          "drc within its quantization)") {
    for (const Case& c : kCases) {
        const std::string name = c.name;
        CAPTURE(name);
        const Dem dem(c.epsg, c.scheme);
        for (const auto& [dx, dy] : {std::pair{1, 0}, std::pair{0, 1}}) {
            CAPTURE(dx);
            for (Format format : {Format::Glb, Format::Drc}) {
                const std::string fmt = format_name(format);
                CAPTURE(fmt);
                const EcefTile a = to_ecef_tile(
                    dem.layer->make_tile(dem.layer->tile(dem.inner()), format), format);
                const EcefTile b = to_ecef_tile(
                    dem.layer->make_tile(dem.layer->tile(dem.inner(dx, dy)), format), format);
                REQUIRE(a.normals.size() == a.positions.size());
                REQUIRE(b.normals.size() == b.positions.size());
                std::size_t shared = 0;
                double worst = 0;
                if (format == Format::Glb) {
                    // Shared border vertices decode to bit-identical ECEF in glb.
                    std::map<Vec, Vec> at;
                    for (std::size_t v = 0; v < b.positions.size(); ++v) {
                        at[b.positions[v]] = b.normals[v];
                    }
                    for (std::size_t v = 0; v < a.positions.size(); ++v) {
                        const auto it = at.find(a.positions[v]);
                        if (it == at.end()) {
                            continue;
                        }
                        ++shared;
                        CHECK(it->second == a.normals[v]); // bit for bit
                        worst = std::max(worst, angle_deg(it->second, a.normals[v]));
                    }
                } else {
                    // drc tiles quantize in their own ENU frames: a shared vertex decodes up to
                    // s*sqrt(3) apart in the two tiles; pair each with the nearest there.
                    const double reach = 2 * a.quant_step;
                    for (std::size_t v = 0; v < a.positions.size(); ++v) {
                        double best = reach * reach;
                        std::size_t match = b.positions.size();
                        for (std::size_t w = 0; w < b.positions.size(); ++w) {
                            const Vec& p = a.positions[v];
                            const Vec& q = b.positions[w];
                            const Vec d{p[0] - q[0], p[1] - q[1], p[2] - q[2]};
                            if (dot(d, d) < best) {
                                best = dot(d, d);
                                match = w;
                            }
                        }
                        if (match < b.positions.size()) {
                            ++shared;
                            worst = std::max(worst, angle_deg(a.normals[v], b.normals[match]));
                        }
                    }
                }
                MESSAGE(name << " " << fmt << std::string(dx ? " east" : " south") << ": " << shared
                             << " shared vertices, worst angle " << worst << " deg");
                CHECK(shared >= 3);
                // drc: each tile rotates into its own ENU frame before the 10-bit octahedral
                // quantization, so the two decoded normals differ by up to a few steps.
                CHECK(worst <= (format == Format::Drc ? 0.5 : 0.0));
            }
        }
    }
}

TEST_CASE("a glb declares one matte material and a Draco NORMAL accessor its primitive uses") {
    const Dem dem(4326, Scheme::Geodetic);
    const std::string bytes = dem.layer->make_tile(dem.layer->tile(dem.inner()), Format::Glb);
    const DecodedTile d = decode_glb(bytes);
    const auto j = nlohmann::json::parse(d.json);
    REQUIRE(j["materials"].size() == 1);
    const auto& material = j["materials"][0];
    const auto& pbr = material["pbrMetallicRoughness"];
    CHECK(pbr["metallicFactor"] == 0);
    CHECK(pbr["roughnessFactor"] == 1);
    REQUIRE(pbr["baseColorFactor"].size() == 4);
    for (const auto& channel : pbr["baseColorFactor"]) {
        CHECK(channel.get<double>() > 0.2);
        CHECK(channel.get<double>() <= 1.0);
    }
    const auto& prim = j["meshes"][0]["primitives"][0];
    CHECK(prim["material"] == 0);
    const auto& normal = j["accessors"][prim["attributes"]["NORMAL"].get<int>()];
    CHECK(normal["componentType"] == 5126);
    CHECK(normal["type"] == "VEC3");
    CHECK(normal["count"] == d.positions.size());
    CHECK(!normal.contains("bufferView"));
    CHECK(prim["attributes"]["NORMAL"] != prim["attributes"]["POSITION"]);
    const auto& draco = prim["extensions"]["KHR_draco_mesh_compression"]["attributes"];
    REQUIRE(draco.contains("NORMAL"));
    CHECK(draco["NORMAL"] != draco["POSITION"]);
    CHECK(d.normals.size() == d.positions.size());
}
