// Encoding tiles as glb / drc: the eps promise after decoding, exact lattice decoding, crack-
// free borders between neighbouring tiles, glTF structure and the .drc metadata schema.
#include "tests/tiler/linf_oracle.hpp"

#include "core/error.hpp"
#include "core/triangulate.hpp"
#include "tiler/formats/draco_decode.hpp"
#include "tiler/formats/encode.hpp"
#include "tiler/geodesy.hpp"
#include "tiler/layer.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <tuple>

using namespace tb;
using namespace tb::tiler;

namespace {

using Terrain = std::function<float(std::int64_t global_column, std::int64_t global_row)>;

// A geodetic tile raster filled from a terrain given in global sample indices (columns from
// the west of the world, rows from the north), so neighbouring tiles share border samples.
TileRaster make_raster(const TileId& id, int n, const Terrain& terrain) {
    TileRaster r;
    r.id = id;
    r.scheme = Scheme::Geodetic;
    r.bounds = tile_bounds(Scheme::Geodetic, id);
    r.size = n;
    r.grid.width = r.grid.height = n + 1;
    const std::int64_t rows_from_north = (tiles_down(Scheme::Geodetic, id.z) - 1 - id.y) * n;
    for (int j = 0; j <= n; ++j) {
        for (int i = 0; i <= n; ++i) {
            r.grid.heights.push_back(terrain(id.x * n + i, rows_from_north + j));
        }
    }
    return r;
}

// Smooth hills plus a ridge plus seeded hash noise (metres above the ellipsoid).
Terrain hills(std::uint32_t seed, double relief) {
    return [seed, relief](std::int64_t c, std::int64_t r) {
        std::uint64_t h = seed * 0x9E3779B97F4A7C15ull ^
                          (std::uint64_t(c) * 0xBF58476D1CE4E5B9ull) ^
                          (std::uint64_t(r) * 0x94D049BB133111EBull);
        h ^= h >> 31;
        h *= 0xD6E8FEB86659FD93ull;
        h ^= h >> 32;
        const double noise = double(h % 1000) / 1000.0 - 0.5;
        const double x = double(c % 100000), y = double(r % 100000);
        const double v =
            300 +
            relief * (std::sin(x * 0.05) * std::cos(y * 0.037) + 0.5 * std::sin((x + y) * 0.11) +
                      std::max(0.0, 1 - std::abs(x - y - 40) / 30.0)) +
            0.02 * relief * noise;
        return static_cast<float>(v);
    };
}

// Every sample a vertex, two triangles per cell, CCW in (column, row) as core produces.
core::Mesh full_grid_mesh(const TileRaster& r) {
    core::Mesh m;
    const int w = r.grid.width;
    for (int j = 0; j < r.grid.height; ++j) {
        for (int i = 0; i < w; ++i) {
            m.points.push_back({i, j});
            m.z.push_back(r.grid.at(i, j));
        }
    }
    for (int j = 0; j + 1 < r.grid.height; ++j) {
        for (int i = 0; i + 1 < w; ++i) {
            const core::Index a = j * w + i, b = a + 1, c = a + w + 1, d = a + w;
            for (core::Index v : {a, b, c, a, c, d}) {
                m.triangles.push_back(v);
            }
        }
    }
    return m;
}

// Decoded positions -> ECEF, for either format.
std::vector<Ecef> decoded_ecef(const DecodedTile& d, Format format) {
    std::vector<Ecef> out;
    if (format == Format::Glb) {
        // glTF y-up (X, Y, Z) = ECEF (x, z, -y): world = translation + local, in double.
        for (const auto& p : d.positions) {
            const double wx = d.translation[0] + p[0];
            const double wy = d.translation[1] + p[1];
            const double wz = d.translation[2] + p[2];
            out.push_back({wx, -wz, wy});
        }
        return out;
    }
    const EnuFrame frame = enu_frame({d.metadata.doubles.at("origin_lon_deg"),
                                      d.metadata.doubles.at("origin_lat_deg"),
                                      d.metadata.doubles.at("origin_h_m")});
    for (const auto& p : d.positions) {
        out.push_back(enu_to_ecef(frame, p));
    }
    return out;
}

// Native scheme coordinates of a lon/lat: degrees for geodetic, EPSG:3857 metres for mercator.
std::pair<double, double> native(Scheme scheme, double lon, double lat) {
    if (scheme == Scheme::Geodetic) {
        return {lon, lat};
    }
    constexpr double kR = 6378137.0, kRad = 3.14159265358979323846 / 180;
    return {kR * lon * kRad, kR * std::log(std::tan(3.14159265358979323846 / 4 + lat * kRad / 2))};
}

// ECEF -> (column, row, h) by TileRaster's documented sample layout, computed here on purpose
// (not with the tiler's lonlat_to_grid) so the test checks the encoder's placement.
std::vector<test::OracleVertex> to_grid(const std::vector<Ecef>& ecef, const TileRaster& r) {
    const auto [x_west, y_north] = native(r.scheme, r.bounds.west, r.bounds.north);
    const auto [x_east, y_south] = native(r.scheme, r.bounds.east, r.bounds.south);
    std::vector<test::OracleVertex> out;
    for (const Ecef& p : ecef) {
        const Geodetic g = to_geodetic(p);
        const auto [x, y] = native(r.scheme, g.lon, g.lat);
        if (r.frame.dx > 0) { // a raster of source pixels: its frame places them
            const double fx = r.frame.lonlat ? g.lon : x, fy = r.frame.lonlat ? g.lat : y;
            out.push_back({(fx - r.frame.x0) / r.frame.dx, (r.frame.y0 - fy) / r.frame.dy, g.h});
            continue;
        }
        out.push_back({(x - x_west) / (x_east - x_west) * r.size,
                       (y_north - y) / (y_north - y_south) * r.size,
                       g.h});
    }
    return out;
}

// How far (grid units) snapping may pull a vertex horizontally: s*sqrt(3)/2 over the
// smallest sample spacing of the tile. Border samples may fall outside the decoded footprint by
// that much; the oracle then evaluates them on the nearest triangle.
double snap_reach(const TileRaster& r, const ErrorBudget& b) {
    const double rad = 3.14159265358979323846 / 180 * 6.3e6 / r.size;
    const double max_lat = std::max(std::abs(r.bounds.south), std::abs(r.bounds.north));
    const double cos_lat = std::cos(max_lat * 3.14159265358979323846 / 180);
    double cell = std::min((r.bounds.north - r.bounds.south) * rad,
                           (r.bounds.east - r.bounds.west) * rad * cos_lat);
    if (r.frame.dx > 0 && r.frame.lonlat) {
        const double deg = 3.14159265358979323846 / 180 * 6.3e6;
        cell = std::min(r.frame.dy * deg, r.frame.dx * deg * cos_lat);
    } else if (r.frame.dx > 0) {
        cell = std::min(r.frame.dx, r.frame.dy) * cos_lat;
    }
    return b.quant_step * std::sqrt(3.0) / 2 * 1.01 / cell;
}

test::OracleResult
decoded_error(const std::string& bytes, Format format, const TileRaster& r, const ErrorBudget& b) {
    const DecodedTile d = format == Format::Glb ? decode_glb(bytes) : decode_drc(bytes);
    return test::linf_error(
        to_grid(decoded_ecef(d, format), r), d.indices, r.grid, snap_reach(r, b));
}

void require_within_eps(const TileRaster& r, const core::Mesh& mesh, const ErrorBudget& b) {
    for (Format f : {Format::Glb, Format::Drc}) {
        CAPTURE(f == Format::Glb ? "glb" : "drc");
        const test::OracleResult res = decoded_error(encode_tile(r, mesh, f, b), f, r, b);
        CAPTURE(res.worst_column);
        CAPTURE(res.worst_row);
        CHECK(res.uncovered == 0);
        CHECK(res.checked > 0);
        CHECK(res.max_error <= b.eps);
    }
}

} // namespace

TEST_CASE("error_budget picks the largest power-of-two step whose error stays within eps/8") {
    for (double eps : {0.003, 0.1, 0.5, 1.0, 3.0, 20.0, 77067.0}) {
        CAPTURE(eps);
        const ErrorBudget b = error_budget(eps);
        int exponent = 0;
        CHECK(std::frexp(b.quant_step, &exponent) == 0.5); // a power of two
        CHECK(b.quant_error <= eps / 8);
        CHECK(b.quant_error * 2 > eps / 8); // twice the step would not fit
        CHECK(b.quant_error >= b.quant_step * std::sqrt(3.0) / 2 * (1 + kQuantMaxSlope) * 0.999);
        CHECK(b.sag == eps * kSagShare);
        CHECK(b.mesh_eps == eps - b.quant_error - b.sag);
        CHECK(b.drawn_bound == eps);
        CHECK(b.max_edge_m == doctest::Approx(std::sqrt(6 * kSagRadius * b.sag / kSagMargin)));
    }
    CHECK_THROWS_AS(error_budget(0.0), InputError);
    CHECK_THROWS_AS(error_budget(-1.0), InputError);
    CHECK_THROWS_AS(error_budget(NAN), InputError);
}

TEST_CASE(
    "glb and drc round trips keep the counts and decode every vertex onto its lattice point") {
    const TileRaster r = make_raster({12, 1234, 3000}, 32, hills(7, 200));
    const core::Mesh mesh = full_grid_mesh(r);
    const ErrorBudget b = error_budget(0.7);
    for (Format f : {Format::Glb, Format::Drc}) {
        CAPTURE(f == Format::Glb ? "glb" : "drc");
        const std::string bytes = encode_tile(r, mesh, f, b);
        CHECK(bytes == encode_tile(r, mesh, f, b)); // deterministic, bit for bit
        const DecodedTile d = f == Format::Glb ? decode_glb(bytes) : decode_drc(bytes);
        REQUIRE(d.positions.size() == mesh.points.size());
        REQUIRE(d.indices.size() == mesh.triangles.size());
        for (const auto& p : d.positions) {
            for (double c : p) {
                CHECK(c / b.quant_step == std::round(c / b.quant_step));
            }
        }
        for (double t : d.translation) {
            CHECK(t / b.quant_step == std::round(t / b.quant_step));
        }
        // Every decoded vertex is its grid vertex moved by at most s*sqrt(3)/2.
        const auto grid = to_grid(decoded_ecef(d, f), r);
        std::set<std::pair<int, int>> seen;
        for (std::size_t v = 0; v < grid.size(); ++v) {
            const int i = static_cast<int>(std::lround(grid[v].column));
            const int j = static_cast<int>(std::lround(grid[v].row));
            REQUIRE(i >= 0);
            REQUIRE(j >= 0);
            REQUIRE(i <= r.size);
            REQUIRE(j <= r.size);
            seen.insert({i, j});
            const Ecef exact =
                to_ecef({r.bounds.west + (r.bounds.east - r.bounds.west) * i / r.size,
                         r.bounds.north - (r.bounds.north - r.bounds.south) * j / r.size,
                         double(r.grid.at(i, j))});
            const Ecef got = decoded_ecef(d, f)[v];
            CHECK(std::hypot(got.x - exact.x, got.y - exact.y, got.z - exact.z) <=
                  b.quant_step * std::sqrt(3.0) / 2 + 1e-6);
        }
        CHECK(seen.size() == mesh.points.size()); // a bijection onto the grid vertices
    }
}

TEST_CASE("decoded triangles are counter-clockwise seen from above, in ECEF") {
    const TileRaster r = make_raster({9, 300, 400}, 16, hills(3, 50));
    const core::Mesh mesh = full_grid_mesh(r);
    const ErrorBudget b = error_budget(2.0);
    for (Format f : {Format::Glb, Format::Drc}) {
        CAPTURE(f == Format::Glb ? "glb" : "drc");
        const std::string bytes = encode_tile(r, mesh, f, b);
        const DecodedTile d = f == Format::Glb ? decode_glb(bytes) : decode_drc(bytes);
        const std::vector<Ecef> p = decoded_ecef(d, f);
        std::size_t up = 0;
        for (std::size_t t = 0; t < d.indices.size(); t += 3) {
            const Ecef& a = p[d.indices[t]];
            const Ecef& bb = p[d.indices[t + 1]];
            const Ecef& c = p[d.indices[t + 2]];
            const double ux = bb.x - a.x, uy = bb.y - a.y, uz = bb.z - a.z;
            const double vx = c.x - a.x, vy = c.y - a.y, vz = c.z - a.z;
            const double nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
            up += (nx * a.x + ny * a.y + nz * a.z > 0) ? 1 : 0; // outward, away from the centre
        }
        CHECK(up == d.indices.size() / 3);
    }
}

TEST_CASE(
    "glb is glTF 2.0 with Draco required, aligned chunks and accessor bounds of the decoded data") {
    const TileRaster r = make_raster({10, 600, 700}, 24, hills(11, 120));
    const core::Mesh mesh = full_grid_mesh(r);
    const std::string bytes = encode_tile(r, mesh, Format::Glb, error_budget(1.0));
    REQUIRE(bytes.size() % 4 == 0);
    const DecodedTile d = decode_glb(bytes);
    CHECK(d.json.size() % 4 == 0);
    const auto j = nlohmann::json::parse(d.json);
    CHECK(j["asset"]["version"] == "2.0");
    CHECK(j["asset"]["generator"] == "Terrabound");
    CHECK(j["extensionsUsed"] == nlohmann::json::array({"KHR_draco_mesh_compression"}));
    CHECK(j["extensionsRequired"] == nlohmann::json::array({"KHR_draco_mesh_compression"}));
    REQUIRE(j["meshes"].size() == 1);
    const auto& prim = j["meshes"][0]["primitives"][0];
    CHECK(prim["mode"] == 4);
    const auto& accessor = j["accessors"][prim["attributes"]["POSITION"].get<int>()];
    CHECK(!accessor.contains("bufferView"));
    CHECK(accessor["componentType"] == 5126);
    CHECK(accessor["type"] == "VEC3");
    CHECK(accessor["count"] == mesh.points.size());
    const auto& indices = j["accessors"][prim["indices"].get<int>()];
    CHECK(!indices.contains("bufferView"));
    CHECK(indices["count"] == mesh.triangles.size());
    CHECK(indices["type"] == "SCALAR");
    for (int k = 0; k < 3; ++k) {
        double lo = 1e300, hi = -1e300;
        for (const auto& p : d.positions) {
            lo = std::min(lo, p[k]);
            hi = std::max(hi, p[k]);
        }
        CHECK(accessor["min"][k].get<double>() == lo);
        CHECK(accessor["max"][k].get<double>() == hi);
    }
    const auto& ext = prim["extensions"]["KHR_draco_mesh_compression"];
    const auto& view = j["bufferViews"][ext["bufferView"].get<int>()];
    CHECK(view["buffer"] == 0);
    const std::size_t bin_len = bytes.size() - 20 - d.json.size() - 8;
    CHECK(j["buffers"][0]["byteLength"].get<std::size_t>() <= bin_len);
    CHECK(j["buffers"][0]["byteLength"].get<std::size_t>() + 3 >= bin_len);
    CHECK(view["byteOffset"].get<std::size_t>() + view["byteLength"].get<std::size_t>() <=
          j["buffers"][0]["byteLength"].get<std::size_t>());
    // The node translation is the tile centre, in y-up axes: (Cx, Cz, -Cy).
    const auto& t = j["nodes"][0]["translation"];
    const Ecef centre =
        to_ecef({(r.bounds.west + r.bounds.east) / 2, (r.bounds.south + r.bounds.north) / 2, 0.0});
    CHECK(std::abs(t[0].get<double>() - centre.x) < 1000);
    CHECK(std::abs(t[1].get<double>() - centre.z) < 1000);
    CHECK(std::abs(t[2].get<double>() + centre.y) < 1000);
    CHECK(t[0].get<double>() == d.translation[0]);
}

TEST_CASE("drc carries the terrabound-tile-1 metadata schema") {
    const TileId id{11, 1500, 1400};
    const TileRaster r = make_raster(id, 16, hills(5, 80));
    const ErrorBudget b = error_budget(1.5);
    const DecodedTile d = decode_drc(encode_tile(r, full_grid_mesh(r), Format::Drc, b));
    const DrcMetadata& m = d.metadata;
    CHECK(m.strings.at("schema") == "terrabound-tile-1");
    CHECK(m.strings.at("crs") == "EPSG:4979");
    CHECK(m.strings.at("frame") == "ENU");
    CHECK(m.strings.at("up_axis") == "Z");
    CHECK(m.strings.at("scheme") == "geodetic");
    CHECK(m.doubles.size() == kDrcDoubleKeys.size());
    CHECK(m.doubles.at("west_deg") == r.bounds.west);
    CHECK(m.doubles.at("north_deg") == r.bounds.north);
    CHECK(m.doubles.at("eps_m") == 1.5);
    CHECK(m.doubles.at("quant_step_m") == b.quant_step);
    CHECK(m.doubles.at("quant_error_m") == b.quant_error);
    const double oh = m.doubles.at("origin_h_m");
    CHECK(oh / b.quant_step == std::round(oh / b.quant_step));
    CHECK(m.doubles.at("min_h_m") <= m.doubles.at("max_h_m"));
    CHECK(m.ints.at("level") == 11);
    CHECK(m.ints.at("x") == 1500);
    CHECK(m.ints.at("y") == 1400);
}

TEST_CASE("triangulated tiles stay within eps of every valid sample after glb and drc decoding "
          "(seeds 1-3)") {
    for (std::uint32_t seed : {1u, 2u, 3u}) {
        for (double eps : {0.25, 2.0, 30.0}) {
            CAPTURE(seed);
            CAPTURE(eps);
            TileRaster r = make_raster({13, 4000 + seed, 6000}, 64, hills(seed, 150.0 * seed));
            if (seed == 2) {
                // Nodata holes: those samples constrain nothing.
                r.grid.valid.assign(r.grid.heights.size(), 1);
                for (int j = 10; j < 30; ++j) {
                    for (int i = 20; i < 35; ++i) {
                        r.grid.valid[static_cast<std::size_t>(j) * r.grid.width + i] = 0;
                    }
                }
            }
            const ErrorBudget b = error_budget(eps);
            const core::Mesh mesh = core::triangulate(r.grid, {b.mesh_eps, true});
            require_within_eps(r, mesh, b);
        }
    }
}

TEST_CASE("neighbouring tiles decode their shared border vertices to bit-identical ECEF") {
    const Terrain terrain = hills(9, 400);
    const TileRaster west = make_raster({14, 9000, 11000}, 64, terrain);
    const TileRaster east = make_raster({14, 9001, 11000}, 64, terrain);
    const TileRaster south = make_raster({14, 9000, 10999}, 64, terrain);
    const ErrorBudget b = error_budget(0.5);
    // Edge vertices (column, row in `a`'s grid) -> decoded world position, for one tile.
    const auto border = [&](const TileRaster& r, bool want_column, int fixed) {
        const core::Mesh mesh = core::triangulate(r.grid, {b.mesh_eps, true});
        const DecodedTile d = decode_glb(encode_tile(r, mesh, Format::Glb, b));
        const std::vector<Ecef> world = decoded_ecef(d, Format::Glb);
        const auto grid = to_grid(world, r);
        std::map<long, std::tuple<double, double, double>> out;
        for (std::size_t v = 0; v < grid.size(); ++v) {
            const long c = std::lround(grid[v].column), rr = std::lround(grid[v].row);
            if (want_column ? c == fixed : rr == fixed) {
                out[want_column ? rr : c] = {world[v].x, world[v].y, world[v].z};
            }
        }
        return out;
    };
    const auto west_edge = border(west, true, 64);
    const auto east_edge = border(east, true, 0);
    CHECK(west_edge.size() >= 2);
    CHECK(west_edge == east_edge); // same rows, bit-identical doubles
    const auto west_bottom = border(west, false, 64);
    const auto south_top = border(south, false, 0);
    CHECK(west_bottom.size() >= 2);
    CHECK(west_bottom == south_top);
}

TEST_CASE("a tile too large for its lattice step is refused with a clear InputError") {
    const TileRaster r = make_raster({0, 0, 0}, 4, [](std::int64_t, std::int64_t) { return 0.0f; });
    CHECK_THROWS_AS(encode_tile(r, full_grid_mesh(r), Format::Glb, error_budget(0.5)), InputError);
    // A hemisphere tile is fine once eps is coarse enough for 24-bit positions.
    CHECK_NOTHROW(encode_tile(r, full_grid_mesh(r), Format::Glb, error_budget(100.0)));
}

TEST_CASE("a real SRTM window (N44W072.hgt, Mt Washington) stays within eps after encoding") {
    const std::string path = std::string(TB_SHARED_DATA) + "/N44W072.hgt";
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        MESSAGE("skipped: " << std::string(path) << " is missing");
        return;
    }
    std::string raw((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    REQUIRE(raw.size() == 1201u * 1201u * 2u);
    // A 129x129 window around the summit (row 870, column 840 of the 1201x1201 grid); the
    // heights are EGM96 but serve as ellipsoidal here: this tests the encoder, not the datum.
    const int n = 128, row0 = 800, col0 = 780;
    const Terrain srtm = [&](std::int64_t c, std::int64_t rr) {
        const std::size_t k =
            (static_cast<std::size_t>(row0 + rr % (n + 1)) * 1201 + col0 + c % (n + 1)) * 2;
        return float(std::int16_t((std::uint8_t(raw[k]) << 8) | std::uint8_t(raw[k + 1])));
    };
    TileRaster r = make_raster({11, 1, 1}, n, [](std::int64_t, std::int64_t) { return 0.0f; });
    r.id = {11, 1, 1};
    // Place the window on the tile around the mountain (geodetic z=11 near -71.3, 44.27).
    r.id.x = static_cast<std::int64_t>(std::floor((-71.3 + 180) / (180.0 / 2048)));
    r.id.y = static_cast<std::int64_t>(std::floor((44.27 + 90) / (180.0 / 2048)));
    r.bounds = tile_bounds(Scheme::Geodetic, r.id);
    for (int j = 0; j <= n; ++j) {
        for (int i = 0; i <= n; ++i) {
            r.grid.heights[static_cast<std::size_t>(j) * (n + 1) + i] = srtm(i, j);
        }
    }
    for (double eps : {1.0, 8.0}) {
        CAPTURE(eps);
        const ErrorBudget b = error_budget(eps);
        const core::Mesh mesh = core::triangulate(r.grid, {b.mesh_eps, true});
        require_within_eps(r, mesh, b);
    }
}

TEST_CASE("a mesa with 1000 m cliffs keeps eps: steep interior triangles get a finer lattice") {
    // Slopes of ~50 break the kQuantMaxSlope assumption; the encoder must notice and refine.
    const Terrain mesa = [](std::int64_t c, std::int64_t r) {
        const std::int64_t i = c % 64, j = r % 64;
        return (i >= 20 && i < 41 && j >= 18 && j < 45) ? 1300.0f : 300.0f + 0.01f * float(i);
    };
    const TileRaster r = make_raster({14, 9000, 11000}, 64, mesa);
    REQUIRE(r.grid.at(25, 25) == 1300.0f);
    const ErrorBudget b = error_budget(1.0);
    const core::Mesh mesh = core::triangulate(r.grid, {b.mesh_eps, true});
    require_within_eps(r, mesh, b);
    const DecodedTile d = decode_drc(encode_tile(r, mesh, Format::Drc, b));
    CHECK(d.metadata.doubles.at("quant_step_m") < b.quant_step);
}

TEST_CASE("the snapped surface must leave room for the chord sag: a mesh off by more is refused") {
    // A flat tile with one bump sample, meshed as two triangles that miss the bump by d. The
    // encoder measures the snapped surface linearly in grid coordinates; the chord sag (up to
    // budget.sag) comes on top, so only d up to eps - sag can be published as eps.
    const ErrorBudget b = error_budget(1.0);
    REQUIRE(b.drawn_bound == 1.0);
    REQUIRE(b.sag == doctest::Approx(0.1));
    for (const float d : {0.85f, 0.95f}) {
        CAPTURE(d);
        const Terrain bump = [d](std::int64_t c, std::int64_t r) {
            return c % 16 == 8 && r % 16 == 8 ? 300.0f + d : 300.0f;
        };
        const TileRaster r = make_raster({14, 9000, 11000}, 16, bump);
        const core::Mesh mesh = core::triangulate(r.grid, {0.99, true});
        REQUIRE(mesh.triangle_count() == 2);
        if (d < 0.9f) {
            // Within eps - sag even after snapping (a flat tile moves by at most s*sqrt(3)/2).
            const DecodedTile t = decode_drc(encode_tile(r, mesh, Format::Drc, b));
            CHECK(t.indices.size() == 6);
        } else {
            // Within eps, but not with the sag on top: no bound of eps may be published.
            CHECK_THROWS_AS(encode_tile(r, mesh, Format::Drc, b), tb::Error);
            CHECK_THROWS_AS(encode_tile(r, mesh, Format::Glb, b), tb::Error);
        }
    }
}

TEST_CASE(
    "real DEM tiles made by the layer stay within eps after decoding (S33W071.tif, Aconcagua)") {
    const std::string path = std::string(TB_SHARED_DATA) + "/S33W071.tif";
    if (!std::ifstream(path)) {
        MESSAGE("skipped: " << std::string(path) << " is missing");
        return;
    }
    for (Scheme scheme : {Scheme::Geodetic, Scheme::Mercator}) {
        CAPTURE(to_string(scheme));
        LayerOptions options;
        options.sources = {path};
        options.tile_size = 128;
        options.scheme = scheme;
        const std::shared_ptr<const Layer> layer = Layer::open(options);
        const int z = layer->max_zoom();
        const TileRange range = tiles_covering(scheme, {-70.02, -32.66, -70.0, -32.64}, z);
        REQUIRE(!range.empty());
        const TileId id{z, range.x0, range.y0};
        // Checked against the source's own pixels, the samples the tile is meshed on.
        const TileRaster raster =
            layer->mesh_tile_at(layer->tile(id), layer->eps_for_zoom(z)).raster;
        CHECK(raster.frame.dx > 0); // both schemes: the DEM is lon/lat
        for (double eps : {layer->eps_for_zoom(z), 0.5}) {
            CAPTURE(eps);
            const ErrorBudget b = error_budget(eps);
            for (Format f : {Format::Glb, Format::Drc}) {
                CAPTURE(f == Format::Glb ? "glb" : "drc");
                const test::OracleResult res =
                    decoded_error(layer->make_tile_at(layer->tile(id), f, eps), f, raster, b);
                CHECK(res.uncovered == 0);
                CHECK(res.checked > 1000);
                CHECK(res.max_error <= eps);
            }
        }
        // The west neighbour (the summit tile touches the DEM's east edge) decodes the vertices
        // on the shared border line to the same ECEF doubles.
        const TileId west{id.z, id.x - 1, id.y};
        const double edge = tile_bounds(scheme, id).west;
        const double reach = 4 * error_budget(layer->eps_for_zoom(z)).quant_step / 6.3e6 * 180 /
                             3.14159265358979323846 / std::cos(33.0 / 180 * 3.14159265358979323846);
        const auto on_edge = [&](const TileId& t) {
            const DecodedTile d = decode_glb(layer->make_tile(layer->tile(t), Format::Glb));
            std::set<std::tuple<double, double, double>> out;
            for (const Ecef& p : decoded_ecef(d, Format::Glb)) {
                if (std::abs(to_geodetic(p).lon - edge) < reach) {
                    out.insert({p.x, p.y, p.z});
                }
            }
            return out;
        };
        const auto a = on_edge(west);
        CHECK(a.size() >= 2);
        CHECK(a == on_edge(id));
    }
}

TEST_CASE("the smallest tile (one cell, two triangles) round trips through glb and drc") {
    const TileRaster r = make_raster({15, 20000, 9000}, 1, hills(4, 10));
    const core::Mesh mesh = full_grid_mesh(r);
    REQUIRE(mesh.triangle_count() == 2);
    require_within_eps(r, mesh, error_budget(0.1));
    CHECK(decode_glb(encode_tile(r, mesh, Format::Glb, error_budget(0.1))).indices.size() == 6);
}

TEST_CASE("tiny tiles at fine eps still decode exactly onto the lattice") {
    // Regression: Draco 1.5 passes the explicit origin and range through 6-decimal text; a
    // 2-triangle tile at eps 0.1 decoded 2.5e-7 m off its 2^-9 m lattice.
    int encoded = 0;
    for (int z : {15, 20, 24}) {
        for (int n : {1, 4}) {
            for (double eps : {0.003, 0.01, 0.1}) {
                CAPTURE(z);
                CAPTURE(n);
                CAPTURE(eps);
                const std::int64_t x = (std::int64_t{2} << z) / 3, y = (std::int64_t{1} << z) / 5;
                const TileRaster r = make_raster({z, x, y}, n, hills(6, 0.05));
                const ErrorBudget b = error_budget(eps);
                const double tile_m = (r.bounds.north - r.bounds.south) * 111000.0;
                for (Format f : {Format::Glb, Format::Drc}) {
                    std::string bytes;
                    try {
                        bytes = encode_tile(r, full_grid_mesh(r), f, b);
                    } catch (const InputError&) {
                        // More lattice steps than Draco quantizes exactly: refused, not
                        // rounded; only plausible for a tile of millions of steps.
                        CHECK(tile_m / b.quant_step > std::exp2(22));
                        continue;
                    }
                    const DecodedTile d = f == Format::Glb ? decode_glb(bytes) : decode_drc(bytes);
                    for (const auto& p : d.positions) {
                        for (double c : p) {
                            CHECK(c / b.quant_step == std::round(c / b.quant_step));
                        }
                    }
                    ++encoded;
                }
            }
        }
    }
    CHECK(encoded >= 24);
}

TEST_CASE("encode_tile writes the same bytes on one thread and on two, with normals given or "
          "made on demand, and when the first lattice must be refined") {
    const Terrain mesa = [](std::int64_t c, std::int64_t r) {
        const std::int64_t i = c % 64, j = r % 64;
        return (i >= 20 && i < 41 && j >= 18 && j < 45) ? 1300.0f : 300.0f + 0.01f * float(i);
    };
    struct Case {
        const char* name;
        TileRaster raster;
        double eps;
    };
    // hills: the first lattice holds; the mesa's cliffs: it is refined (the early encoding of
    // the second thread is thrown away). Both have 64 rows or more, so the check splits its
    // rows between two threads where it runs alone.
    const Case cases[] = {{"hills", make_raster({12, 2000, 1500}, 128, hills(4, 100)), 1.0},
                          {"mesa", make_raster({14, 9000, 11000}, 64, mesa), 1.0}};
    for (const Case& c : cases) {
        CAPTURE(std::string(c.name));
        const ErrorBudget b = error_budget(c.eps);
        const TileMesh tm =
            to_tile_mesh(c.raster, core::triangulate(c.raster.grid, {b.mesh_eps, true}), false);
        std::vector<std::array<double, 3>> normals;
        for (std::size_t v = 0; v < tm.vertex_count(); ++v) {
            const double a = 0.001 * static_cast<double>(v % 97);
            const double len = std::sqrt(1 + 2 * a * a);
            normals.push_back({a / len, a / len, 1 / len});
        }
        int made = 0;
        const NormalsFn make = [&] {
            ++made;
            return normals;
        };
        // Check points (every sample, as the layer gives measured tiles): the .drc's eps_m then
        // waits for them, so it is encoded after the check even with two threads.
        std::vector<CheckPoint> points;
        for (int row = 0; row < c.raster.grid.height; row += 7) {
            for (int col = 0; col < c.raster.grid.width; col += 5) {
                points.push_back({double(col), double(row), c.raster.grid.at(col, row)});
            }
        }
        for (Format f : {Format::Glb, Format::Drc}) {
            CAPTURE(f == Format::Glb ? "glb" : "drc");
            const std::vector<CheckPoint> no_points;
            for (bool with_points : {true, false}) {
                const std::vector<CheckPoint>& p = with_points ? points : no_points;
                CAPTURE(p.size());
                EncodeReport one_report, two_report;
                const std::string one =
                    encode_tile(c.raster, tm, f, b, p, &one_report, &normals, 1);
                made = 0;
                const std::string two =
                    encode_tile(c.raster, tm, f, b, p, &two_report, nullptr, 2, make);
                CHECK(made == 1);
                CHECK(two == one);
                CHECK(two_report.published == one_report.published);
                CHECK(two_report.points_error == one_report.points_error);
                made = 0;
                CHECK(encode_tile(c.raster, tm, f, b, p, nullptr, nullptr, 1, make) == one);
                CHECK(made == 1);
                CHECK(encode_tile(c.raster, tm, f, b, p, nullptr, &normals, 2) == one);
            }
        }
        if (std::string(c.name) == "mesa") {
            const DecodedTile d =
                decode_drc(encode_tile(c.raster, tm, Format::Drc, b, {}, nullptr, nullptr, 2));
            CHECK(d.metadata.doubles.at("quant_step_m") < b.quant_step); // refined
        }
    }
}

TEST_CASE("normals handed to encode_tile decode at their own vertices, in each format's axes, "
          "and move no position (seed 4)") {
    const TileRaster r = make_raster({12, 2000, 1500}, 32, hills(4, 100));
    const core::Mesh mesh = full_grid_mesh(r);
    const TileMesh tm = to_tile_mesh(r, mesh, false);
    const ErrorBudget b = error_budget(1.0);
    // A unit ECEF vector that changes by tens of degrees from one sample to the next, so a
    // normal that reached another vertex would show.
    const auto field = [](double lon, double lat) {
        const double l = lon * 3.14159265358979323846 / 180, p = lat * 3.14159265358979323846 / 180;
        const std::array<double, 3> east{-std::sin(l), std::cos(l), 0};
        const std::array<double, 3> north{
            -std::sin(p) * std::cos(l), -std::sin(p) * std::sin(l), std::cos(p)};
        const std::array<double, 3> up{
            std::cos(p) * std::cos(l), std::cos(p) * std::sin(l), std::sin(p)};
        const double a = 0.6 * std::sin(lon * 500), c = 0.4 * std::cos(lat * 700);
        std::array<double, 3> n{};
        double len = 0;
        for (int k = 0; k < 3; ++k) {
            n[k] = up[k] + a * east[k] + c * north[k];
            len += n[k] * n[k];
        }
        for (double& v : n) {
            v /= std::sqrt(len);
        }
        return n;
    };
    std::vector<std::array<double, 3>> normals;
    for (std::size_t v = 0; v < tm.vertex_count(); ++v) {
        normals.push_back(field(tm.x[v], tm.y[v]));
    }
    for (Format f : {Format::Glb, Format::Drc}) {
        CAPTURE(f == Format::Glb ? "glb" : "drc");
        const std::string with = encode_tile(r, tm, f, b, {}, nullptr, &normals);
        const DecodedTile d = f == Format::Glb ? decode_glb(with) : decode_drc(with);
        const DecodedTile plain = f == Format::Glb ? decode_glb(encode_tile(r, tm, f, b))
                                                   : decode_drc(encode_tile(r, tm, f, b));
        CHECK(plain.normals.empty());
        // Normals move no position (Draco may visit the vertices in another order).
        auto sorted = [](std::vector<std::array<double, 3>> p) {
            std::sort(p.begin(), p.end());
            return p;
        };
        CHECK(sorted(d.positions) == sorted(plain.positions));
        CHECK(d.indices.size() == plain.indices.size());
        REQUIRE(d.normals.size() == d.positions.size());
        const std::vector<Ecef> world = decoded_ecef(d, f);
        double worst = 0;
        for (std::size_t v = 0; v < world.size(); ++v) {
            const Geodetic g = to_geodetic(world[v]);
            const std::array<double, 3> want = field(g.lon, g.lat);
            std::array<double, 3> got{};
            const auto& n = d.normals[v];
            if (f == Format::Glb) {
                got = {n[0], -n[2], n[1]}; // glTF y-up (X, Y, Z) is ECEF (X, -Z, Y)
            } else {
                const EnuFrame frame = enu_frame({d.metadata.doubles.at("origin_lon_deg"),
                                                  d.metadata.doubles.at("origin_lat_deg"),
                                                  d.metadata.doubles.at("origin_h_m")});
                for (int a = 0; a < 3; ++a) {
                    got[a] =
                        frame.axes[0][a] * n[0] + frame.axes[1][a] * n[1] + frame.axes[2][a] * n[2];
                }
            }
            const double c = got[0] * want[0] + got[1] * want[1] + got[2] * want[2];
            worst = std::max(worst, std::acos(std::min(1.0, c)) * 180 / 3.14159265358979323846);
        }
        MESSAGE("worst decoded normal vs given: " << worst << " deg at " << kNormalBits << " bits");
        CHECK(worst < 0.25);
    }
    // A tile of voids only stays an empty scene: no material, no accessor.
    const TileMesh none;
    const std::vector<std::array<double, 3>> no_normals;
    const DecodedTile empty =
        decode_glb(encode_tile(r, none, Format::Glb, b, {}, nullptr, &no_normals));
    CHECK(empty.json.find("materials") == std::string::npos);
    CHECK(empty.positions.empty());
}
