// quantized-mesh-1.0 tiles judged by an independent reader (qm_reader.hpp): the bytes of
// synthetic meshes (32-bit indices, edge lists, header, extensions), and the tiles of a real DEM
// against GDAL's reading of it plus PROJ's EGM96 (source_oracle.hpp).
#include "core/error.hpp"
#include "mountains.hpp"
#include "qm_judge.hpp"
#include "qm_reader.hpp"
#include "source_oracle.hpp"
#include "tiler/formats/quantized_mesh.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <random>
#include <set>

namespace {

using namespace tb;
using tb::tiler::LonLatBox;
using tb::tiler::TileId;
using tb::tiler::TileMesh;

// A regular (n+1) x (n+1) mesh over `b`, rolling heights, two CCW triangles per cell.
TileMesh grid_mesh(const LonLatBox& b, int n) {
    TileMesh m;
    for (int j = 0; j <= n; ++j) {
        const double y = j == n ? b.north : b.south + (b.north - b.south) * j / n;
        for (int i = 0; i <= n; ++i) {
            const double x = i == n ? b.east : b.west + (b.east - b.west) * i / n;
            m.add(x,
                  y,
                  static_cast<float>(200 + 150 * std::sin(i * 0.07) * std::cos(j * 0.05)),
                  i == 0 || j == 0 || i == n || j == n);
        }
    }
    for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
            const core::Index a = static_cast<core::Index>(j * (n + 1) + i), up = n + 1;
            m.triangles.insert(m.triangles.end(), {a, a + 1, a + 1 + up, a, a + 1 + up, a + up});
        }
    }
    return m;
}

// A triangle with its smallest index first (orientation kept).
std::array<std::uint32_t, 3> canonical(std::uint32_t a, std::uint32_t b, std::uint32_t c) {
    if (b < a && b < c) {
        return {b, c, a};
    }
    if (c < a && c < b) {
        return {c, a, b};
    }
    return {a, b, c};
}

// The header's horizon occlusion point hides every vertex and is the tightest that does.
void check_horizon(const tb_qm::Tile& t, const std::vector<tb_oracle::V3>& ecef) {
    CHECK(tb_mountains::check_horizon(t.horizon, ecef) < 1e-6);
}

TEST_CASE("a 301 x 301 vertex mesh encodes with 32-bit indices that decode to its own "
          "triangles, edge lists and header") {
    const LonLatBox b{10, 50, 10.5, 50.5};
    const int n = 300;
    const TileMesh m = grid_mesh(b, n);
    const tiler::QuantizedMesh q = tiler::quantize_mesh(m, b);
    const std::string bytes = tiler::encode_quantized_mesh(q, {});
    const tb_qm::Tile t = tb_qm::read(bytes);
    REQUIRE(t.vertex_count == (n + 1) * (n + 1));
    CHECK(t.wide);
    CHECK(t.index_start % 4 == 0);
    CHECK(t.extensions.empty());

    // Decoded vertex k is the mesh vertex at its (u, v): every grid position is distinct.
    std::map<std::pair<int, int>, std::uint32_t> at;
    for (std::uint32_t i = 0; i < m.vertex_count(); ++i) {
        const int u = static_cast<int>(std::lround((m.x[i] - b.west) / (b.east - b.west) * 32767));
        const int v =
            static_cast<int>(std::lround((m.y[i] - b.south) / (b.north - b.south) * 32767));
        REQUIRE(at.emplace(std::pair(u, v), i).second);
    }
    std::vector<std::uint32_t> original(t.vertex_count);
    for (std::uint32_t k = 0; k < t.vertex_count; ++k) {
        const auto it = at.find({t.u[k], t.v[k]});
        REQUIRE(it != at.end());
        original[k] = it->second;
    }
    // The header's height range is the decoded heights' own.
    CHECK(*std::min_element(t.h.begin(), t.h.end()) == 0);
    CHECK(*std::max_element(t.h.begin(), t.h.end()) == 32767);
    // Border vertices keep their heights (within half a height step); the drawn surface passes
    // through every interior vertex's own place and height (within a step: the encoder re-heights
    // vertices that quantization moved).
    const double step = (static_cast<double>(t.max_height) - t.min_height) / 32767;
    std::vector<std::vector<std::uint32_t>> fans(t.vertex_count);
    for (std::uint32_t e = 0; e < t.triangles.size(); ++e) {
        fans[t.triangles[e]].push_back(e / 3);
    }
    double worst_border = 0, worst_inside = 0;
    for (std::uint32_t k = 0; k < t.vertex_count; ++k) {
        const std::uint32_t i = original[k];
        if (t.u[k] == 0 || t.u[k] == 32767 || t.v[k] == 0 || t.v[k] == 32767) {
            worst_border = std::max(worst_border, std::abs(t.height(k) - m.z[i]) / step);
            continue;
        }
        const double pu = (m.x[i] - b.west) / (b.east - b.west) * 32767;
        const double pv = (m.y[i] - b.south) / (b.north - b.south) * 32767;
        bool found = false;
        for (std::uint32_t tri : fans[k]) {
            const std::uint32_t a = t.triangles[3 * tri], c1 = t.triangles[3 * tri + 1],
                                c2 = t.triangles[3 * tri + 2];
            const double det =
                (t.v[c1] - t.v[c2]) * (t.u[a] - t.u[c2]) + (t.u[c2] - t.u[c1]) * (t.v[a] - t.v[c2]);
            const double l1 =
                ((t.v[c1] - t.v[c2]) * (pu - t.u[c2]) + (t.u[c2] - t.u[c1]) * (pv - t.v[c2])) / det;
            const double l2 =
                ((t.v[c2] - t.v[a]) * (pu - t.u[c2]) + (t.u[a] - t.u[c2]) * (pv - t.v[c2])) / det;
            if (l1 < -1e-12 || l2 < -1e-12 || 1 - l1 - l2 < -1e-12) {
                continue;
            }
            const double h = l1 * t.height(a) + l2 * t.height(c1) + (1 - l1 - l2) * t.height(c2);
            worst_inside = std::max(worst_inside, std::abs(h - m.z[i]) / step);
            found = true;
            break;
        }
        CHECK(found);
    }
    MESSAGE("border heights within " << worst_border << " steps, interior surface within "
                                     << worst_inside << " steps of the mesh's");
    CHECK(worst_border <= 0.5 + 1e-6);
    CHECK(worst_inside <= 1.0);
    std::multiset<std::array<std::uint32_t, 3>> want, got;
    for (std::size_t e = 0; e < m.triangles.size(); e += 3) {
        want.insert(canonical(m.triangles[e], m.triangles[e + 1], m.triangles[e + 2]));
    }
    for (std::size_t e = 0; e < t.triangles.size(); e += 3) {
        got.insert(canonical(
            original[t.triangles[e]], original[t.triangles[e + 1]], original[t.triangles[e + 2]]));
    }
    CHECK(got == want);

    // Edge lists: exactly the vertices on each border line.
    const int sides[4][2] = {{0, -1}, {-1, 0}, {32767, -1}, {-1, 32767}}; // u or v fixed
    for (int s = 0; s < 4; ++s) {
        std::set<std::uint32_t> expected;
        for (std::uint32_t k = 0; k < t.vertex_count; ++k) {
            if ((sides[s][0] >= 0 && t.u[k] == sides[s][0]) ||
                (sides[s][1] >= 0 && t.v[k] == sides[s][1])) {
                expected.insert(k);
            }
        }
        const auto& list = t.edges[static_cast<std::size_t>(s)];
        CHECK(list.size() == static_cast<std::size_t>(n + 1));
        CHECK(std::set<std::uint32_t>(list.begin(), list.end()) == expected);
    }

    // The bounding sphere holds every decoded vertex, and the horizon point hides them.
    std::vector<tb_oracle::V3> ecef;
    for (std::uint32_t k = 0; k < t.vertex_count; ++k) {
        ecef.push_back(
            tb_oracle::ecef(t.lon(k, b.west, b.east), t.lat(k, b.south, b.north), t.height(k)));
        const auto& e = ecef.back();
        const double d = std::hypot(e[0] - t.sphere[0], e[1] - t.sphere[1], e[2] - t.sphere[2]);
        CHECK(d <= t.sphere[3] * (1 + 1e-12));
    }
    check_horizon(t, ecef);
}

TEST_CASE("each subset of extensions is the full tile's own bytes, in id order") {
    const LonLatBox b{-72, 44, -71.5, 44.5};
    const TileMesh m = grid_mesh(b, 20);
    const tiler::QuantizedMesh q = tiler::quantize_mesh(m, b);
    tiler::QuantizedMeshExtras extras;
    for (std::size_t v = 0; v < m.vertex_count(); ++v) {
        extras.normals.push_back({0.6, 0.0, 0.8});
    }
    extras.water_mask.assign(256 * 256, 0);
    extras.water_mask[5] = 255;
    extras.metadata = "{\"available\":[]}";
    const std::string full = tiler::encode_quantized_mesh(q, extras);
    const tb_qm::Tile t = tb_qm::read(full);
    CHECK_FALSE(t.wide);
    REQUIRE(t.extensions.size() == 3);
    CHECK(t.extensions[0].id == 1);
    CHECK(t.extensions[0].data.size() == 2 * t.vertex_count);
    CHECK(t.extensions[1].id == 2);
    CHECK(t.extensions[1].data.size() == 65536);
    CHECK(t.extensions[2].id == 4);
    REQUIRE(t.extensions[2].data.size() == 4 + extras.metadata.size());
    std::uint32_t json_length = 0;
    std::memcpy(&json_length, t.extensions[2].data.data(), 4);
    CHECK(json_length == extras.metadata.size());
    CHECK(t.extensions[2].data.substr(4) == extras.metadata);
    const std::size_t base =
        full.size() - (5 + 2 * t.vertex_count) - (5 + 65536) - (5 + 4 + extras.metadata.size());
    for (unsigned mask = 0; mask < 8; ++mask) {
        CAPTURE(mask);
        const std::string part = tiler::select_extensions(full, mask);
        CHECK(part.compare(0, base, full, 0, base) == 0);
        const tb_qm::Tile p = tb_qm::read(part);
        std::vector<int> ids;
        for (const auto& e : p.extensions) {
            ids.push_back(e.id);
            CHECK(e.data == t.extension(e.id)->data);
        }
        std::vector<int> expected;
        for (int id : {1, 2, 4}) {
            if (mask & static_cast<unsigned>(id)) {
                expected.push_back(id);
            }
        }
        CHECK(ids == expected);
    }
    CHECK_THROWS_AS(tiler::select_extensions(full.substr(0, 100), 7), InputError);
}

TEST_CASE("terrain extension lists parse by their layer.json names, and layer.json lists "
          "exactly the kept ones") {
    using tiler::kMetadata, tiler::kOctVertexNormals, tiler::kWaterMask;
    CHECK(tiler::parse_terrain_extensions("all") == tiler::kAllQuantizedMeshExtensions);
    CHECK(tiler::parse_terrain_extensions("none") == 0u);
    CHECK(tiler::parse_terrain_extensions("metadata") == kMetadata);
    CHECK(tiler::parse_terrain_extensions("watermask,octvertexnormals") ==
          (kWaterMask | kOctVertexNormals));
    for (const char* bad : {"", "metadata,", "normals", "Metadata", "all,metadata"}) {
        CAPTURE(bad);
        CHECK_THROWS_WITH_AS(tiler::parse_terrain_extensions(bad),
                             doctest::Contains("name octvertexnormals, watermask or metadata"),
                             InputError);
    }
    CHECK(tiler::terrain_extensions_json(0) == "[]");
    CHECK(tiler::terrain_extensions_json(kWaterMask | kMetadata) == R"(["watermask","metadata"])");

    tiler::TerrainSpec spec{
        "dem", 2, 4, LonLatBox{7, 46, 7.5, 46.5}, [](int z) { return 1.0 * z; }, {}};
    const std::string full = tiler::terrain_layer_json(spec);
    CHECK(full.find(R"("extensions":["octvertexnormals","watermask","metadata"],)"
                    R"("metadataAvailability":10,)") != std::string::npos);
    CHECK(tiler::layer_json_with_extensions(full, tiler::kAllQuantizedMeshExtensions) == full);
    const std::string meta = tiler::layer_json_with_extensions(full, kMetadata);
    CHECK(meta.find(R"("extensions":["metadata"],"metadataAvailability":10,)") !=
          std::string::npos);
    const std::string bare = tiler::layer_json_with_extensions(full, kOctVertexNormals);
    CHECK(bare.find(R"("extensions":["octvertexnormals"],"available":[)") != std::string::npos);
    CHECK(bare.find("metadataAvailability") == std::string::npos);
    // Apart from the list, the documents are the same.
    CHECK(bare.size() +
              std::string(R"(,"watermask","metadata","metadataAvailability":10)").size() ==
          full.size());
    CHECK_THROWS_AS(tiler::layer_json_with_extensions("{}", kMetadata), InputError);
}

TEST_CASE("oct-encoded normals decode with CesiumJS's formula within a degree (seed 7)") {
    std::mt19937 rng(7);
    std::normal_distribution<double> g;
    double worst = 0;
    for (int k = 0; k < 20000; ++k) {
        std::array<double, 3> n{g(rng), g(rng), g(rng)};
        const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (double& c : n) {
            c /= len;
        }
        const auto e = tiler::oct_encode(n);
        const auto d = tb_qm::oct_decode(e[0], e[1]);
        const double dot = std::clamp(n[0] * d[0] + n[1] * d[1] + n[2] * d[2], -1.0, 1.0);
        worst = std::max(worst, std::acos(dot) * 180 / tb_oracle::kPi);
    }
    MESSAGE("worst oct round trip: " << worst << " degrees");
    CHECK(worst < 1.0);
}

// ---- a real DEM ----

using tb_mountains::kMountains;

using tb_mountains::mountains;
using tb_mountains::Mountains;

// White Mountains (steep, no voids) and Swiss Alps (steeper, 7 % voids in the steepest parts).
TEST_CASE("every pixel of a mountain DEM under its finest and coarsest terrain tiles is "
          "within the tile's published error, the zoom's eps where it meshes the pixels") {
    tb_mountains::for_each_mountain([&](const std::string& name, const Mountains& mountain) {
        const Mountains* m = &mountain;
        const tiler::Layer& layer = *m->layer;
        for (int z : {layer.min_zoom(), layer.max_zoom()}) {
            const tiler::TileRange r = layer.tiles_at(z);
            double worst = 0;
            std::size_t judged = 0;
            for (std::int64_t y = r.y0; y <= r.y1; ++y) {
                for (std::int64_t x = r.x0; x <= r.x1; ++x) {
                    const TileId id{z, x, y};
                    CAPTURE(id.x);
                    CAPTURE(id.y);
                    const tb_qm::Tile t =
                        tb_qm::read(layer.make_tile(layer.tile(id), tiler::Format::Terrain));
                    const double published = published_error(t);
                    if (layer.zoom_source(z) == tiler::ZoomSource::Pixels) {
                        CHECK(published <= layer.terrain_eps_for_zoom(z) * (1 + 1e-9));
                    }
                    CHECK(published >= layer.terrain_eps_for_zoom(z) * (1 - 1e-9));
                    const auto [e, count] =
                        worst_pixel(t, tiler::tile_bounds(tiler::Scheme::Geodetic, id), m->pixels);
                    // The oracle's geoid (PROJ's grid, bilinear here) and the tiler's agree to
                    // well under a millimetre; the float32 heights of the mesh round to 0.1 mm.
                    CHECK(e <= published + 1e-3);
                    worst = std::max(worst, e / published);
                    judged += count;
                }
            }
            MESSAGE(name << " zoom " << z << ": " << judged << " pixels, worst error " << worst
                         << " of the published error, "
                         << std::string(tiler::to_string(layer.zoom_source(z))) << " zoom eps "
                         << layer.terrain_eps_for_zoom(z) << " m");
            CHECK(judged > 0);
        }
    });
}

// Every pair of neighbours of the finest zoom away from the DEM's edge (where the tiles reach
// past the data and are joined to their corners), of a DEM without voids and of one with voids
// crossing tile borders.
TEST_CASE("neighbouring terrain tiles share their border vertices, heights and normals") {
    tb_mountains::for_each_mountain([&](const std::string& name, const Mountains& mountain) {
        const Mountains* m = &mountain;
        const tiler::Layer& layer = *m->layer;
        const int z = layer.max_zoom();
        const tiler::TileRange r = layer.tiles_at(z);
        REQUIRE(r.x1 - r.x0 >= 3);
        REQUIRE(r.y1 - r.y0 >= 3);
        // Per tile and side (west, south, east, north): position along the side -> decoded
        // height, half its height step, oct normal.
        using Side = std::map<int, std::tuple<double, double, std::uint8_t, std::uint8_t>>;
        std::map<std::pair<std::int64_t, std::int64_t>, std::array<Side, 4>> sides;
        for (std::int64_t y = r.y0 + 1; y < r.y1; ++y) {
            for (std::int64_t x = r.x0 + 1; x < r.x1; ++x) {
                const tb_qm::Tile t = tb_qm::read(
                    layer.make_tile(layer.tile(TileId{z, x, y}), tiler::Format::Terrain));
                const tb_qm::Extension* normals = t.extension(1);
                REQUIRE(normals != nullptr);
                const double step = (static_cast<double>(t.max_height) - t.min_height) / 32767;
                auto& out = sides[{x, y}];
                for (int side = 0; side < 4; ++side) {
                    for (std::uint32_t k : t.edges[static_cast<std::size_t>(side)]) {
                        const int along = side == 0 || side == 2 ? t.v[k] : t.u[k];
                        out[static_cast<std::size_t>(side)][along] = {
                            t.height(k),
                            step / 2,
                            static_cast<std::uint8_t>(normals->data[2 * k]),
                            static_cast<std::uint8_t>(normals->data[2 * k + 1])};
                    }
                }
            }
        }
        std::size_t pairs = 0, shared = 0;
        for (const auto& [xy, a] : sides) {
            // East neighbour (A's east side, B's west), north neighbour (A's north, C's south).
            for (const auto& [dx, dy, side_a, side_b] :
                 {std::tuple{1, 0, 2, 0}, std::tuple{0, 1, 3, 1}}) {
                const auto it = sides.find({xy.first + dx, xy.second + dy});
                if (it == sides.end()) {
                    continue;
                }
                const Side& ea = a[static_cast<std::size_t>(side_a)];
                const Side& eb = it->second[static_cast<std::size_t>(side_b)];
                CAPTURE(xy.first);
                CAPTURE(xy.second);
                REQUIRE(ea.size() >= 2);
                CHECK(ea.size() == eb.size());
                for (const auto& [along, va] : ea) {
                    const auto b = eb.find(along);
                    REQUIRE_MESSAGE(b != eb.end(),
                                    "vertex at " << along << " is missing in the neighbour");
                    const auto& vb = b->second;
                    CHECK(std::abs(std::get<0>(va) - std::get<0>(vb)) <=
                          std::get<1>(va) + std::get<1>(vb) + 1e-6);
                    CHECK(std::get<2>(va) == std::get<2>(vb));
                    CHECK(std::get<3>(va) == std::get<3>(vb));
                }
                ++pairs;
                shared += ea.size();
            }
        }
        MESSAGE(name << ": " << pairs << " neighbour pairs share " << shared << " border vertices");
        CHECK(pairs >= 4);
    });
}

TEST_CASE("terrain tiles: zoom 0 meshed from the data where it lies and sea-level filler "
          "elsewhere, nothing beyond max zoom, 400 outside the scheme") {
    const Mountains* m = mountains();
    if (!m) {
        MESSAGE("skipped: " << std::string(kMountains) << " is absent");
        return;
    }
    const tiler::Layer& layer = *m->layer;
    for (const TileId id : {TileId{0, 0, 0}, TileId{0, 1, 0}}) {
        CAPTURE(id.x);
        const tb_qm::Tile t = tb_qm::read(layer.make_tile(layer.tile(id), tiler::Format::Terrain));
        const bool data = id.x == 0; // the west root holds the DEM (lon -72)
        // Filler lies on the geoid: EGM96 spans about -107..+86 m. (The data's zoom-0 samples
        // may lie within the root's bound of the geoid too.)
        CHECK(t.min_height > -110);
        if (!data) {
            CHECK(t.max_height < 90);
        }
        const tb_qm::Extension* water = t.extension(2);
        REQUIRE(water != nullptr);
        if (!data) {
            CHECK(water->data == std::string(1, '\xff'));
        }
        const std::string meta = metadata_of(t);
        CHECK((meta.find("\"filler\":true") != std::string::npos) == !data);
        // The west root's children list the data's tiles.
        CHECK((meta.find("startX") != std::string::npos) == data);
    }
    CHECK_THROWS_AS(
        layer.make_tile(layer.tile(TileId{layer.max_zoom() + 1, 0, 0}), tiler::Format::Terrain),
        NotFound);
    CHECK_THROWS_AS(layer.make_tile(layer.tile(TileId{0, 2, 0}), tiler::Format::Terrain),
                    InputError);
    CHECK_THROWS_AS(layer.make_tile(layer.tile(TileId{3, 0, 8}), tiler::Format::Terrain),
                    InputError);
}

} // namespace
