// 3D Tiles terrain (Cesium3DTilesTerrainProvider) judged by an independent reader
// (terrain3d_reader.hpp: meshoptimizer's decoder, CesiumJS's placement of positions) and the
// source oracle (GDAL's reading of the DEM plus PROJ's EGM96, the drawn ECEF triangles
// intersected with the ellipsoid normal through every pixel centre).
#include "core/error.hpp"
#include "mountains.hpp"
#include "source_oracle.hpp"
#include "terrain3d_reader.hpp"
#include "tiler/formats/terrain_tiles.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"

#include <doctest/doctest.h>

#include <filesystem>
#include <map>
#include <memory>

namespace {

using namespace tb;
using tb::tiler::TileId;
using tb_terrain3d::json;

using tb_mountains::kMountains;
using tb_mountains::mountains;
using tb_mountains::Mountains;

std::string document(const tiler::Layer& layer, const std::string& path) {
    std::string out;
    REQUIRE_MESSAGE(layer.document(path, out), "no document " << path);
    return out;
}

// White Mountains (steep, no voids) and Swiss Alps (steeper, 7 % voids in the steepest parts).
TEST_CASE("3D Tiles terrain of a mountain DEM: every pixel under the finest and coarsest "
          "meshed tiles is within the glb's published error, the zoom's eps where it meshes the "
          "pixels") {
    std::size_t sixteen_bit_tiles = 0;
    tb_mountains::for_each_mountain([&](const std::string& name, const Mountains& mountain) {
        const Mountains* m = &mountain;
        const tiler::Layer& layer = *m->layer;
        for (int z : {layer.min_zoom(), layer.max_zoom()}) {
            const tiler::TileRange r = layer.tiles_at(z);
            std::vector<std::uint8_t> drawn(m->pixels.size(), 0);
            double worst = 0;
            std::int64_t judged = 0;
            std::size_t sixteen_bit = 0, tiles = 0;
            for (std::int64_t y = r.y0; y <= r.y1; ++y) {
                for (std::int64_t x = r.x0; x <= r.x1; ++x) {
                    const TileId id{z, x, y};
                    CAPTURE(id.x);
                    CAPTURE(id.y);
                    const tb_terrain3d::Glb g = tb_terrain3d::read_glb(
                        layer.make_tile(layer.tile(id), tiler::Format::Terrain3d));
                    if (layer.zoom_source(z) == tiler::ZoomSource::Pixels) {
                        CHECK(g.published <= layer.terrain_eps_for_zoom(z) * (1 + 1e-9));
                    }
                    CHECK(g.published >= layer.terrain_eps_for_zoom(z) * (1 - 1e-9));
                    const tiler::LonLatBox b = tiler::tile_bounds(tiler::Scheme::Geodetic, id);
                    // A pixel beside a tile side may lie a hair outside the drawn triangles: 16-bit
                    // positions move edge vertices by up to half a step across the side (CesiumJS
                    // hides such slits with skirts). It is judged against the nearest triangle.
                    const double reach = (b.north - b.south) * 111320.0 / 65535;
                    const tb_oracle::Drawn as_drawn{g.drawn.ecef, g.drawn.indices};
                    const tb_oracle::Verdict v = tb_oracle::judge(
                        as_drawn, m->pixels, b.west, b.south, b.east, b.north, drawn, reach);
                    CHECK(v.worst <= g.published + 1e-3);
                    worst = std::max(worst, v.worst / g.published);
                    judged += v.judged;
                    ++tiles;
                    const json& pos = g.doc["accessors"][0];
                    sixteen_bit += pos["componentType"] == 5123 ? 1 : 0;
                    // Smooth normals, one per vertex, pointing up out of the ground.
                    REQUIRE(g.normals.size() == g.drawn.ecef.size());
                    for (std::size_t k = 0; k < g.normals.size(); ++k) {
                        const tb_oracle::V3 geo = tb_oracle::geodetic(g.drawn.ecef[k]);
                        const tb_oracle::V3 up = tb_oracle::ecef(geo[0], geo[1], 1);
                        const tb_oracle::V3 base = tb_oracle::ecef(geo[0], geo[1], 0);
                        const double d = g.normals[k][0] * (up[0] - base[0]) +
                                         g.normals[k][1] * (up[1] - base[1]) +
                                         g.normals[k][2] * (up[2] - base[2]);
                        CHECK(d > 0); // up out of the ground (Alpine cliffs reach 80 degrees)
                    }
                    // The edge lists hold exactly the vertices on the tile's sides (a 16-bit
                    // position moves a vertex by up to half a step of its box, about 1/65535 of the
                    // tile across).
                    const double tol = (b.east - b.west) / 65535 + 1e-9;
                    for (std::size_t s = 0; s < 4; ++s) {
                        REQUIRE(g.edges[s].size() >= 2);
                        for (std::uint32_t k : g.edges[s]) {
                            const tb_oracle::V3 geo = tb_oracle::geodetic(g.drawn.ecef[k]);
                            const double want = s == 0   ? b.west
                                                : s == 1 ? b.south
                                                : s == 2 ? b.east
                                                         : b.north;
                            CHECK(std::abs((s % 2 == 0 ? geo[0] : geo[1]) - want) < tol);
                        }
                    }
                }
            }
            std::size_t undrawn = 0;
            for (std::size_t k = 0; k < m->pixels.size(); ++k) {
                undrawn += drawn[k] ? 0 : 1;
            }
            MESSAGE(name << " zoom " << z << ": " << tiles << " tiles (" << sixteen_bit
                         << " with 16-bit positions), " << judged << " pixels judged, worst "
                         << worst << " of the published error, " << undrawn << " undrawn");
            CHECK(judged >= static_cast<std::int64_t>(m->pixels.size()));
            CHECK(undrawn == 0);
            sixteen_bit_tiles += sixteen_bit;
        }
    });
}

TEST_CASE("3D Tiles terrain subtrees list exactly the available tiles, with metadata that holds "
          "each tile's vertices") {
    const Mountains* m = mountains();
    if (!m) {
        MESSAGE("skipped: " << std::string(kMountains) << " is absent");
        return;
    }
    const tiler::Layer& layer = *m->layer;
    const json tileset = json::parse(document(layer, "terrain/tileset.json"));
    REQUIRE(tileset["root"]["children"].size() == 2);
    const json& implicit = tileset["root"]["children"][0]["implicitTiling"];
    const int levels = implicit["subtreeLevels"];
    REQUIRE(implicit["availableLevels"] == layer.max_zoom() + 1);
    const tiler::LonLatBox data = layer.data_bounds();
    // The tiles of zoom z over the data (both roots at zoom 0).
    const auto expected = [&](int z, std::int64_t gx, std::int64_t gy) {
        if (z == 0) {
            return true;
        }
        const tiler::LonLatBox b = tiler::tile_bounds(tiler::Scheme::Geodetic, TileId{z, gx, gy});
        return b.west < data.east && b.east > data.west && b.south < data.north &&
               b.north > data.south;
    };
    std::size_t subtrees = 0, tiles = 0, checked = 0;
    for (int root = 0; root < 2; ++root) {
        // Breadth first from the root subtree, through the child subtrees each one lists.
        std::vector<std::array<std::int64_t, 3>> todo{{0, 0, 0}};
        while (!todo.empty()) {
            const auto [level, sx, sy] = todo.back();
            todo.pop_back();
            const std::string path = "terrain/" + std::to_string(root) + "/" +
                                     std::to_string(level) + "/" + std::to_string(sx) + "/" +
                                     std::to_string(sy) + ".subtree";
            CAPTURE(path);
            const tb_terrain3d::Subtree s = tb_terrain3d::read_subtree(document(layer, path));
            ++subtrees;
            const json& avail = s.doc["tileAvailability"];
            CHECK(s.doc["contentAvailability"][0] == avail);
            std::vector<TileId> listed;
            std::size_t offset = 0;
            for (int l = 0; l < levels && level + l <= layer.max_zoom(); ++l) {
                const std::int64_t side = std::int64_t{1} << l;
                std::vector<std::pair<std::uint64_t, TileId>> in_order;
                for (std::int64_t j = 0; j < side; ++j) {
                    for (std::int64_t i = 0; i < side; ++i) {
                        const int z = static_cast<int>(level) + l;
                        const std::int64_t gx = (std::int64_t{root} << z) + sx * side + i;
                        const std::int64_t gy = sy * side + j;
                        const std::uint64_t index = tb_terrain3d::morton(i, j);
                        const bool on = s.available(avail, offset + index);
                        CHECK(on == expected(z, gx, gy));
                        if (on) {
                            in_order.emplace_back(index, TileId{z, gx, gy});
                        }
                    }
                }
                std::sort(in_order.begin(), in_order.end(), [](const auto& a, const auto& b) {
                    return a.first < b.first;
                });
                for (const auto& e : in_order) {
                    listed.push_back(e.second);
                }
                offset += static_cast<std::size_t>(side * side);
            }
            CHECK(avail.value("availableCount", 0) == listed.size());
            tiles += listed.size();
            if (!listed.empty()) {
                const std::vector<double> lo = s.column("minimumHeight", 1),
                                          hi = s.column("maximumHeight", 1),
                                          sphere = s.column("boundingSphere", 4),
                                          horizon = s.column("horizonOcclusionPoint", 3);
                REQUIRE(lo.size() == listed.size());
                // The root tile, and every tile of the finest and coarsest meshed zooms.
                for (std::size_t k = 0; k < listed.size(); ++k) {
                    const TileId id = listed[k];
                    if (id.z != 0 && id.z != layer.min_zoom() && id.z != layer.max_zoom()) {
                        continue;
                    }
                    CAPTURE(id.z);
                    CAPTURE(id.x);
                    CAPTURE(id.y);
                    const tb_terrain3d::Glb g = tb_terrain3d::read_glb(
                        layer.make_tile(layer.tile(id), tiler::Format::Terrain3d));
                    for (const tb_oracle::V3& e : g.drawn.ecef) {
                        const double h = tb_oracle::geodetic(e)[2];
                        CHECK(h >= lo[k] - 0.01);
                        CHECK(h <= hi[k] + 0.01);
                        const double dx = e[0] - sphere[4 * k], dy = e[1] - sphere[4 * k + 1],
                                     dz = e[2] - sphere[4 * k + 2];
                        CHECK(std::sqrt(dx * dx + dy * dy + dz * dz) <= sphere[4 * k + 3]);
                    }
                    if (id.z > 0) {
                        tb_mountains::check_horizon(
                            {horizon[3 * k], horizon[3 * k + 1], horizon[3 * k + 2]}, g.drawn.ecef);
                    }
                    ++checked;
                }
            }
            // Child subtrees: listed exactly when their root tile is available.
            if (level + levels <= layer.max_zoom()) {
                const std::int64_t side = std::int64_t{1} << levels;
                for (std::int64_t j = 0; j < side; ++j) {
                    for (std::int64_t i = 0; i < side; ++i) {
                        const int z = static_cast<int>(level) + levels;
                        const bool on = s.available(s.doc["childSubtreeAvailability"],
                                                    tb_terrain3d::morton(i, j));
                        CHECK(on == expected(z,
                                             (std::int64_t{root} << z) + sx * side + i,
                                             sy * side + j));
                        if (on) {
                            todo.push_back({z, sx * side + i, sy * side + j});
                        }
                    }
                }
            } else {
                CHECK(s.doc["childSubtreeAvailability"]["constant"] == 0);
            }
        }
    }
    MESSAGE(subtrees << " subtrees list " << tiles << " tiles; " << checked
                     << " glb checked against their metadata");
    CHECK(checked > 10);
}

TEST_CASE("3D Tiles terrain: unknown subtrees and tiles outside the scheme or beyond max zoom "
          "are refused") {
    const Mountains* m = mountains();
    if (!m) {
        MESSAGE("skipped: " << std::string(kMountains) << " is absent");
        return;
    }
    const tiler::Layer& layer = *m->layer;
    std::string out;
    for (const char* bad : {"terrain/2/0/0/0.subtree",
                            "terrain/0/1/0/0.subtree",
                            "terrain/0/0/1/0.subtree",
                            "terrain/0/0/0/0.glb",
                            "terrain/0/-4/0/0.subtree",
                            "terrain/0/4/0/0/0.subtree",
                            "terrain/0/400/0/0.subtree",
                            "terrain/x.json"}) {
        CAPTURE(bad);
        CHECK_FALSE(layer.document(bad, out));
    }
    // A subtree past the finest level is no document either.
    const int past =
        (layer.max_zoom() / tiler::kTerrainSubtreeLevels + 1) * tiler::kTerrainSubtreeLevels;
    CHECK_FALSE(layer.document("terrain/0/" + std::to_string(past) + "/0/0.subtree", out));
    CHECK_THROWS_AS(
        layer.make_tile(layer.tile(TileId{layer.max_zoom() + 1, 0, 0}), tiler::Format::Terrain3d),
        NotFound);
    CHECK_THROWS_AS(layer.make_tile(layer.tile(TileId{0, 2, 0}), tiler::Format::Terrain3d),
                    InputError);
    CHECK_THROWS_AS(layer.make_tile(layer.tile(TileId{2, 0, 0}), tiler::Format::Terrain3d, {0}),
                    InputError);
    // Filler at zoom 0: flat on the geoid, no vertex outside its metadata's height range.
    const tb_terrain3d::Glb g = tb_terrain3d::read_glb(
        layer.make_tile(layer.tile(TileId{0, 1, 0}), tiler::Format::Terrain3d));
    CHECK(g.doc["asset"]["extras"]["filler"] == true);
    for (const tb_oracle::V3& e : g.drawn.ecef) {
        const double h = tb_oracle::geodetic(e)[2];
        CHECK(h > tiler::kGeoidLowest - 1);
        CHECK(h < tiler::kGeoidHighest + 1);
    }
}

} // namespace
