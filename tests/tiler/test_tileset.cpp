// The layer's 3D Tiles 1.1 tileset: every document reachable from tileset.json, every content
// a tile the layer makes, errors decreasing, regions nested and holding the decoded content.
#include "core/triangulate.hpp"
#include "tiler/formats/draco_decode.hpp"
#include "tiler/formats/encode.hpp"
#include "tiler/geodesy.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <map>
#include <optional>
#include <set>
#include <string>

using namespace tb;
using namespace tb::tiler;
using nlohmann::json;

namespace {

TilesetSpec make_spec(Scheme scheme, int min_zoom, int max_zoom, LonLatBox data, double finest) {
    TilesetSpec spec;
    spec.layer = "test";
    spec.scheme = scheme;
    spec.min_zoom = min_zoom;
    spec.max_zoom = max_zoom;
    spec.data_bounds = data;
    spec.min_height = -20;
    spec.max_height = 1900;
    spec.eps_for_zoom = [max_zoom, finest](int z) { return finest * std::exp2(max_zoom - z); };
    spec.has_tile = [scheme, data](const ValidTile& tile) {
        const TileId& id = tile.id();
        const TileRange r = tiles_covering(scheme, data, id.z);
        return !r.empty() && id.x >= r.x0 && id.x <= r.x1 && id.y >= r.y0 && id.y <= r.y1;
    };
    return spec;
}

// Resolves a relative URI against the directory of the document at `base`.
std::string resolve(const std::string& base, const std::string& uri) {
    std::string dir = base.substr(0, base.find_last_of('/') + 1);
    std::string rest = uri;
    while (rest.rfind("../", 0) == 0) {
        REQUIRE(!dir.empty());
        dir.pop_back();
        dir = dir.substr(0, dir.find_last_of('/') + 1);
        rest = rest.substr(3);
    }
    return dir + rest;
}

struct Walk {
    std::map<TileId, json> tiles; // content tile -> its region
    std::set<std::string> documents;
    int reference_tiles = 0;
};

bool region_contains(const json& outer, const json& inner) {
    const auto& o = outer["region"];
    const auto& i = inner["region"];
    return o[0] <= i[0] && o[1] <= i[1] && o[2] >= i[2] && o[3] >= i[3] && o[4] <= i[4] &&
           o[5] >= i[5];
}

TileId parse_tile(const std::string& path, const std::string& ext) {
    TileId id;
    long long x = 0, y = 0;
    int z = 0;
    char tail[16] = {};
    REQUIRE(std::sscanf(path.c_str(), "%d/%lld/%lld.%15s", &z, &x, &y, tail) == 4);
    REQUIRE(std::string(tail) == ext);
    id = {z, x, y};
    return id;
}

void walk_tile(
    const TilesetSpec& spec, const std::string& doc, const json& tile, const json* parent, Walk& w);

void walk_document(const TilesetSpec& spec, const std::string& path, const json* parent, Walk& w) {
    std::string text;
    REQUIRE_MESSAGE(tileset_document(spec, path, text), path);
    REQUIRE(w.documents.insert(path).second);
    const json j = json::parse(text);
    CHECK(j["asset"]["version"] == "1.1");
    CHECK(j["root"]["refine"] == "REPLACE");
    CHECK(j["geometricError"].get<double>() >= j["root"]["geometricError"].get<double>());
    if (parent != nullptr) {
        // The external root is the referencing tile itself: same volume, same error.
        CHECK(j["root"]["boundingVolume"] == (*parent)["boundingVolume"]);
        CHECK(j["root"]["geometricError"] == (*parent)["geometricError"]);
    }
    walk_tile(spec, path, j["root"], nullptr, w);
}

void walk_tile(const TilesetSpec& spec,
               const std::string& doc,
               const json& tile,
               const json* parent,
               Walk& w) {
    const double ge = tile["geometricError"].get<double>();
    if (parent != nullptr) {
        CHECK(ge < (*parent)["geometricError"].get<double>());
        CHECK(region_contains((*parent)["boundingVolume"], tile["boundingVolume"]));
    }
    if (tile.contains("content")) {
        const std::string uri = resolve(doc, tile["content"]["uri"].get<std::string>());
        if (uri.size() > 5 && uri.substr(uri.size() - 5) == ".json") {
            CHECK(!tile.contains("children"));
            ++w.reference_tiles;
            walk_document(spec, uri, &tile, w);
            return;
        }
        const TileId id = parse_tile(uri, "glb");
        const std::optional<ValidTile> valid = ValidTile::of(spec.scheme, id);
        REQUIRE(valid);
        CHECK(id.z >= spec.min_zoom);
        CHECK(id.z <= spec.max_zoom);
        CHECK(spec.has_tile(*valid));
        CHECK(ge >= spec.eps_for_zoom(id.z));
        CHECK(w.tiles.emplace(id, tile["boundingVolume"]).second); // listed once
    }
    if (tile.contains("children")) {
        for (const json& child : tile["children"]) {
            walk_tile(spec, doc, child, &tile, w);
        }
    }
}

std::size_t count_layer_tiles(const TilesetSpec& spec) {
    std::size_t n = 0;
    for (int z = spec.min_zoom; z <= spec.max_zoom; ++z) {
        const TileRange r = tiles_covering(spec.scheme, spec.data_bounds, z);
        for (const ValidTile& tile : tiles_in(spec.scheme, r)) {
            n += spec.has_tile(tile) ? 1 : 0;
        }
    }
    return n;
}

} // namespace

TEST_CASE("the tileset lists exactly the layer's tiles with decreasing errors and nested regions") {
    struct Case {
        Scheme scheme;
        int min_zoom, max_zoom;
        LonLatBox box;
    };
    const Case cases[] = {
        {Scheme::Geodetic, 0, 10, {-71.5, 44.0, -71.0, 44.6}}, // two roots, 2 external levels
        {Scheme::Geodetic, 7, 13, {-71.5, 44.0, -71.0, 44.6}}, // several min_zoom tiles
        {Scheme::Mercator, 3, 12, {6.0, 45.5, 10.5, 47.9}},    // XYZ, y from the north
        {Scheme::Geodetic, 5, 5, {-10.0, -10.0, 10.0, 10.0}},  // one level, across both roots
    };
    for (const Case& c : cases) {
        CAPTURE(to_string(c.scheme));
        CAPTURE(c.min_zoom);
        CAPTURE(c.max_zoom);
        const TilesetSpec spec = make_spec(c.scheme, c.min_zoom, c.max_zoom, c.box, 0.5);
        Walk w;
        walk_document(spec, "tileset.json", nullptr, w);
        CHECK(w.tiles.size() == count_layer_tiles(spec));
        if (c.max_zoom - c.min_zoom > 4) {
            CHECK(w.reference_tiles > 0);
            CHECK(w.documents.size() == 1 + static_cast<std::size_t>(w.reference_tiles));
        } else {
            CHECK(w.documents.size() == 1); // leaves at max_zoom stay inline
        }
    }
}

TEST_CASE("tileset_document refuses paths that name no document") {
    const TilesetSpec spec = make_spec(Scheme::Geodetic, 2, 12, {-71.5, 44.0, -71.0, 44.6}, 1.0);
    std::string out;
    CHECK_FALSE(tileset_document(spec, "nope.json", out));
    CHECK_FALSE(tileset_document(spec, "tilesets/7/0/0.json", out)); // not a document level
    CHECK_FALSE(tileset_document(spec, "tilesets/6/0/0.json", out)); // no data there
    CHECK_FALSE(tileset_document(spec, "tilesets/6/1/x.json", out));
    CHECK_FALSE(tileset_document(spec, "tilesets/6/-1/2.json", out));
    CHECK_FALSE(tileset_document(spec, "tilesets/16/0/0.json", out)); // beyond max_zoom
    const TileRange r6 = tiles_covering(spec.scheme, spec.data_bounds, 6);
    CHECK_FALSE(tileset_document(
        spec, "tilesets/06/" + std::to_string(r6.x0) + "/" + std::to_string(r6.y0) + ".json", out));
    const TileRange r = tiles_covering(spec.scheme, spec.data_bounds, 6);
    CHECK(tileset_document(
        spec, "tilesets/6/" + std::to_string(r.x0) + "/" + std::to_string(r.y0) + ".json", out));
}

TEST_CASE("every decoded vertex of a tile lies inside the region the tileset gives it") {
    // A steep tile at a coarse level (large chord sag) and a fine one.
    for (int z : {6, 12}) {
        CAPTURE(z);
        const LonLatBox data{-71.5, 44.0, -71.0, 44.6};
        TilesetSpec spec = make_spec(Scheme::Geodetic, z, z, data, 2.0);
        spec.tile_size = 32;
        const TileRange range = tiles_covering(spec.scheme, data, z);
        TileRaster r;
        r.id = {z, range.x0, range.y0};
        r.bounds = tile_bounds(Scheme::Geodetic, r.id);
        r.size = 32;
        r.grid.width = r.grid.height = 33;
        for (int j = 0; j <= 32; ++j) {
            for (int i = 0; i <= 32; ++i) {
                // Heights at both layer extremes, so the region's padding is what holds them.
                r.grid.heights.push_back((i + j) % 2 == 0 ? float(spec.min_height)
                                                          : float(spec.max_height));
            }
        }
        // As the layer meshes it: edges within the zoom's max_edge, so sag within budget.sag.
        const ErrorBudget b = tile_error_budget(spec.eps_for_zoom(z), spec.scheme, z, r.size);
        const core::Mesh mesh = core::triangulate(r.grid, {b.mesh_eps, true, b.max_edge});
        const DecodedTile d = decode_glb(encode_tile(r, mesh, Format::Glb, b));
        std::string text;
        REQUIRE(tileset_document(spec, "tileset.json", text));
        const json j = json::parse(text);
        json region;
        for (const json& t : j["root"]["children"]) {
            if (t["content"]["uri"] == std::to_string(z) + "/" + std::to_string(r.id.x) + "/" +
                                           std::to_string(r.id.y) + ".glb") {
                region = t["boundingVolume"]["region"];
            }
        }
        REQUIRE(region.is_array());
        // Vertices, and points inside each triangle (where chord sag lives).
        std::vector<Ecef> pts;
        for (const auto& p : d.positions) {
            pts.push_back(
                {d.translation[0] + p[0], -(d.translation[2] + p[2]), d.translation[1] + p[1]});
        }
        for (std::size_t t = 0; t < d.indices.size(); t += 3) {
            const Ecef& a = pts[d.indices[t]];
            const Ecef& bb = pts[d.indices[t + 1]];
            const Ecef& c = pts[d.indices[t + 2]];
            pts.push_back({(a.x + bb.x + c.x) / 3, (a.y + bb.y + c.y) / 3, (a.z + bb.z + c.z) / 3});
        }
        const double deg = 3.14159265358979323846 / 180;
        for (const Ecef& p : pts) {
            const Geodetic g = to_geodetic(p);
            CHECK(g.lon * deg >= region[0].get<double>());
            CHECK(g.lat * deg >= region[1].get<double>());
            CHECK(g.lon * deg <= region[2].get<double>());
            CHECK(g.lat * deg <= region[3].get<double>());
            CHECK(g.h >= region[4].get<double>());
            CHECK(g.h <= region[5].get<double>());
        }
    }
}

TEST_CASE("chord sag bounds how far a straight triangle dips below its corners") {
    // Triangle across a z=4 geodetic tile: its centroid dips below the corners' ellipsoid.
    const LonLatBox box = tile_bounds(Scheme::Geodetic, {4, 16, 8});
    const Ecef a = to_ecef({box.west, box.south, 0}), b = to_ecef({box.east, box.south, 0}),
               c = to_ecef({box.east, box.north, 0});
    const Geodetic mid =
        to_geodetic({(a.x + b.x + c.x) / 3, (a.y + b.y + c.y) / 3, (a.z + b.z + c.z) / 3});
    CHECK(-mid.h <= chord_sag(box));
    CHECK(-mid.h > 0.2 * chord_sag(box)); // the bound is not vacuous
    CHECK(chord_sag(tile_bounds(Scheme::Geodetic, {5, 32, 16})) < chord_sag(box));
}
