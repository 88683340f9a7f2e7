// The eps promise for what clients draw: straight triangles between the decoded ECEF vertices.
// For every valid sample the drawn height is measured along the ellipsoid normal through the
// sample (the intersection of that line with the plane of the ECEF triangle over the sample),
// so chord sag and the lon/lat -> ECEF distortion are both in the measurement.
#include "core/triangulate.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/formats/draco_decode.hpp"
#include "tiler/formats/encode.hpp"
#include "tiler/geodesy.hpp"
#include "tiler/layer.hpp"
#include "tiler/sources/tile_raster.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

using namespace tb::tiler;

namespace {

constexpr double kPi = 3.14159265358979323846;

struct Drawn {
    double worst = 0;         // largest |drawn - sample| over the valid samples, metres
    double longest_edge = 0;  // in tile samples
    std::int64_t samples = 0; // valid samples measured
    std::int64_t triangles = 0;
};

using V3 = std::array<double, 3>;
V3 sub(const V3& a, const V3& b) {
    return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
double dot(const V3& a, const V3& b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
V3 cross(const V3& a, const V3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// Measures a .glb tile of `raster` against every valid sample of its grid. Vertices sit at
// samples (moved by the lattice snap, far below a sample) or, on a pixel tile's border line,
// between them, so the triangle over a sample is found with barycentric coordinates.
Drawn measure_glb(const std::string& bytes, const TileRaster& raster) {
    const DecodedTile d = decode_glb(bytes);
    // glTF y-up (X, Y, Z) = ECEF (x, z, -y), relative to the root translation.
    std::vector<V3> ecef;
    std::vector<std::array<double, 2>> grid;
    for (const auto& p : d.positions) {
        const double wx = d.translation[0] + p[0];
        const double wy = d.translation[1] + p[1];
        const double wz = d.translation[2] + p[2];
        const V3 e{wx, -wz, wy};
        ecef.push_back(e);
        const Geodetic g = to_geodetic({e[0], e[1], e[2]});
        double column = 0, row = 0;
        lonlat_to_grid(raster, {g.lon, g.lat}, column, row);
        // A vertex at a sample, moved by the snap far below a sample, is put back on it (so
        // samples on the block's edge stay inside); border-line vertices keep their place.
        const auto settle = [](double u) {
            return std::abs(u - std::round(u)) < 0.01 ? std::round(u) : u;
        };
        grid.push_back({settle(column), settle(row)});
    }
    const int w = raster.grid.width, h = raster.grid.height;
    // The triangle over each sample (shared edges: either triangle; the drawn surface is
    // continuous there).
    std::vector<std::int64_t> owner(static_cast<std::size_t>(w) * h, -1);
    Drawn out;
    out.triangles = static_cast<std::int64_t>(d.indices.size() / 3);
    for (std::size_t t = 0; t + 2 < d.indices.size(); t += 3) {
        const auto& a = grid[d.indices[t]];
        const auto& b = grid[d.indices[t + 1]];
        const auto& c = grid[d.indices[t + 2]];
        for (const auto& [p, q] : {std::pair{a, b}, std::pair{b, c}, std::pair{c, a}}) {
            out.longest_edge = std::max(out.longest_edge, std::hypot(q[0] - p[0], q[1] - p[1]));
        }
        const double det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
        REQUIRE(det != 0);
        const int x0 = std::max(0, static_cast<int>(std::floor(std::min({a[0], b[0], c[0]}))));
        const int x1 = std::min(w - 1, static_cast<int>(std::ceil(std::max({a[0], b[0], c[0]}))));
        const int y0 = std::max(0, static_cast<int>(std::floor(std::min({a[1], b[1], c[1]}))));
        const int y1 = std::min(h - 1, static_cast<int>(std::ceil(std::max({a[1], b[1], c[1]}))));
        for (int y = y0; y <= y1; ++y) {
            for (int x = x0; x <= x1; ++x) {
                const double la = ((b[0] - x) * (c[1] - y) - (c[0] - x) * (b[1] - y)) / det;
                const double lb = ((c[0] - x) * (a[1] - y) - (a[0] - x) * (c[1] - y)) / det;
                if (std::min({la, lb, 1 - la - lb}) >= -1e-6) {
                    owner[static_cast<std::size_t>(y * w + x)] = static_cast<std::int64_t>(t);
                }
            }
        }
    }
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
            if (!raster.grid.is_valid(x, y)) {
                continue;
            }
            const std::int64_t t = owner[static_cast<std::size_t>(y) * w + x];
            REQUIRE(t >= 0);
            const V3& A = ecef[d.indices[static_cast<std::size_t>(t)]];
            const V3& B = ecef[d.indices[static_cast<std::size_t>(t) + 1]];
            const V3& C = ecef[d.indices[static_cast<std::size_t>(t) + 2]];
            const LonLat ll = grid_to_lonlat(raster, x, y);
            const Ecef base = to_ecef({ll.lon, ll.lat, 0.0});
            const double lon = ll.lon * kPi / 180, lat = ll.lat * kPi / 180;
            // The ellipsoid normal: the line base + s * n is exactly the points of this lon/lat.
            const V3 n{std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat)};
            const V3 normal = cross(sub(B, A), sub(C, A));
            const double s = dot(sub(A, {base.x, base.y, base.z}), normal) / dot(n, normal);
            const double err = std::abs(s - static_cast<double>(raster.grid.at(x, y)));
            out.worst = std::max(out.worst, err);
            ++out.samples;
        }
    }
    return out;
}

// A 1 x 1 degree GeoTIFF at a constant ellipsoidal height (flat ground for the sag).
std::shared_ptr<const Layer> flat_layer(const tb_test::ScratchDir& dir, double lat0, int max_zoom) {
    tb_test::Fixture f;
    f.width = f.height = 361;
    f.values.assign(static_cast<std::size_t>(f.width) * f.height, 0.0);
    f.geotransform = std::array<double, 6>{10.0, 1.0 / 360, 0, lat0 + 1, 0, -1.0 / 360};
    f.epsg = 4326;
    LayerOptions options;
    options.sources = {tb_test::write_fixture(dir.file("flat.tif"), f)};
    options.datum = VerticalDatum::Ellipsoid;
    options.max_zoom = max_zoom;
    return Layer::open(options);
}

// The tile of zoom z at the layer's data centre.
TileId centre_tile(const Layer& layer, int z) {
    const LonLatBox b = layer.data_bounds();
    const double lon = (b.west + b.east) / 2, lat = (b.south + b.north) / 2;
    const TileRange r =
        tiles_covering(layer.options().scheme, {lon, lat, lon + 1e-9, lat + 1e-9}, z);
    REQUIRE(!r.empty());
    return {z, r.x0, r.y0};
}

// What the layer draws at eps(z), checked against eps on every sample.
Drawn check_layer_tile(const Layer& layer, const TileId& id) {
    const double eps = layer.eps_for_zoom(id.z);
    const MeshedTile meshed = layer.mesh_tile_at(layer.tile(id), eps);
    const TileRaster& raster = meshed.raster;
    const Drawn got = measure_glb(layer.make_tile(layer.tile(id), Format::Glb), raster);
    const ErrorBudget& b = meshed.budget;
    MESSAGE("tile " << id.z << "/" << id.x << "/" << id.y << ": eps " << eps << " m, worst drawn "
                    << got.worst << " m over " << got.samples << " samples, " << got.triangles
                    << " triangles, longest edge " << got.longest_edge << " <= " << b.max_edge);
    CHECK(got.samples > 0);
    CHECK(got.worst <= eps);
    CHECK(got.longest_edge <= b.max_edge + 1e-3); // the lattice snap moves vertices a hair
    return got;
}

} // namespace

TEST_CASE("flat ground: what clients draw stays within eps of every sample at every zoom") {
    tb_test::ScratchDir dir;
    for (double lat0 : {0.0, 60.0}) {
        INFO("latitude ", lat0);
        const auto layer = flat_layer(dir, lat0, 10);
        for (int z = layer->min_zoom(); z <= layer->max_zoom(); ++z) {
            INFO("zoom ", z);
            const Drawn got = check_layer_tile(*layer, centre_tile(*layer, z));
            // Flat ground is now many triangles: the edge bound, not the terrain, sets them.
            CHECK(got.triangles > 2);
        }
    }
}

TEST_CASE("flat ground without the sag budget (the old pipeline) draws below eps: the check "
          "can fail") {
    tb_test::ScratchDir dir;
    const auto layer = flat_layer(dir, 0.0, 10);
    const TileId id = centre_tile(*layer, 10);
    const double eps = layer->eps_for_zoom(10);
    const TileRaster raster = layer->make_raster(layer->tile(id));
    ErrorBudget old = error_budget(eps);
    old.sag = 0;
    old.mesh_eps = eps - old.quant_error;
    const tb::core::Mesh mesh =
        tb::core::triangulate(raster.grid, tb::core::TriangulateOptions{old.mesh_eps, true});
    CHECK(mesh.triangle_count() == 2);
    const Drawn got = measure_glb(encode_tile(raster, mesh, Format::Glb, old), raster);
    MESSAGE("old pipeline, tile 10/" << id.x << "/" << id.y << ": eps " << eps << " m, worst drawn "
                                     << got.worst << " m");
    CHECK(got.worst > eps);
}

TEST_CASE("real flat and coastal SRTM tiles keep eps for what clients draw, with bounded edges") {
    for (const char* name : {"N40W074.hgt", "N19W155.hgt.zip"}) {
        const auto path = tb_test::shared_dem(name);
        if (!path) {
            continue;
        }
        INFO(name);
        LayerOptions options;
        options.sources = {std::string(name).ends_with(".zip")
                               ? "/vsizip/" + *path + "/" +
                                     std::string(name).substr(0, std::string(name).size() - 4)
                               : *path};
        const auto layer = Layer::open(options);
        for (int z = layer->min_zoom(); z <= layer->max_zoom(); ++z) {
            INFO("zoom ", z);
            check_layer_tile(*layer, centre_tile(*layer, z));
        }
    }
}

TEST_CASE("tile_error_budget is constant per zoom and its edge keeps the sag within its share") {
    for (Scheme scheme : {Scheme::Geodetic, Scheme::Mercator}) {
        for (int z = 5; z <= 14; ++z) {
            const double eps = 0.5 * std::ldexp(1.0, 14 - z);
            const ErrorBudget b = tile_error_budget(eps, scheme, z, 256);
            INFO("scheme ", to_string(scheme), " z ", z);
            CHECK(b.max_edge >= tb::core::kMinMaxEdge);
            CHECK(b.mesh_eps + b.quant_error + b.sag == doctest::Approx(eps));
            CHECK(b.mesh_eps >= eps / 8);
            // The sag of the longest allowed edge, margin included, is within the share.
            CHECK(kSagMargin * b.max_edge_m * b.max_edge_m / (6 * kSagRadius) <=
                  b.sag * (1 + 1e-12));
            CHECK(b.max_edge * sample_spacing_m(scheme, z, 256) == doctest::Approx(b.max_edge_m));
        }
    }
    // A parallel's step is never longer than the meridian step used for geodetic tiles.
    const double step = sample_spacing_m(Scheme::Geodetic, 10, 256);
    CHECK(step == doctest::Approx(kPi / 180 * 6399593.6258 * (180.0 / 1024) / 256));
}
