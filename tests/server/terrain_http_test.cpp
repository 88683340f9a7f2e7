// Globe terrain over real loopback HTTP. quantized-mesh: layer.json, the Accept negotiation of
// extensions (checked with the independent reader of tests/tiler/qm_reader.hpp), Vary and
// gzip, filler at zoom 0, and the errors of tiles outside the scheme or beyond max zoom.
// 3D Tiles terrain: terrain/tileset.json, subtrees and glbs (tests/tiler/terrain3d_reader.hpp)
// and their errors.
#include "../tiler/qm_reader.hpp"
#include "../tiler/terrain3d_reader.hpp"
#include "server_fixture.hpp"
#include "tiler/formats/quantized_mesh.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"
#include "tiler/stores/store.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <set>

namespace {

using namespace tb;
using test::RunningServer;
using test::TempDir;

struct TerrainFixture {
    TempDir dir;
    std::shared_ptr<const tiler::Layer> layer;
    TerrainFixture() {
        log::set_level(log::Level::Warn);
        test::write_dem(dir / "hills.asc");
        layer = tiler::Layer::open(test::test_layer_options(dir / "hills.asc", "hills"));
    }
};

TerrainFixture& fixture() {
    static TerrainFixture f;
    return f;
}

std::string terrain_url(const tiler::TileId& id) {
    return "/hills/" + std::to_string(id.z) + "/" + std::to_string(id.x) + "/" +
           std::to_string(id.y) + ".terrain";
}

std::vector<int> extension_ids(const std::string& body) {
    std::vector<int> ids;
    for (const auto& e : tb_qm::read(body).extensions) {
        ids.push_back(e.id);
    }
    return ids;
}

constexpr const char* kCesiumAccept =
    "application/vnd.quantized-mesh;extensions=octvertexnormals-watermask-metadata,"
    "application/octet-stream;q=0.9,*/*;q=0.01";

TEST_CASE("layer.json over HTTP lists every zoom from 0, the extensions and the terrain URL") {
    auto& f = fixture();
    RunningServer server({{f.layer, {tiler::Format::Glb, tiler::Format::Terrain}, nullptr}});
    auto c = server.client();
    auto layers = c.Get("/layers");
    REQUIRE(layers);
    const auto list = nlohmann::json::parse(layers->body);
    CHECK(list["layers"][0]["layer_json"] == "/hills/layer.json");
    auto res = c.Get("/hills/layer.json");
    REQUIRE(res);
    REQUIRE(res->status == 200);
    CHECK(res->get_header_value("Content-Type") == "application/json");
    const auto j = nlohmann::json::parse(res->body);
    CHECK(j["format"] == "quantized-mesh-1.0");
    CHECK(j["scheme"] == "tms");
    CHECK(j["projection"] == "EPSG:4326");
    CHECK(j["tiles"][0] == "{z}/{x}/{y}.terrain");
    CHECK(j["extensions"] == nlohmann::json({"octvertexnormals", "watermask", "metadata"}));
    CHECK(j["metadataAvailability"] == tiler::kMetadataLevels);
    REQUIRE(j["available"].size() == static_cast<std::size_t>(f.layer->max_zoom() + 1));
    CHECK(j["available"][0][0] ==
          nlohmann::json::parse(R"({"startX":0,"startY":0,"endX":1,"endY":0})"));
    // From min_zoom on, what is available is exactly the layer's own tiles.
    for (int z = f.layer->min_zoom(); z <= f.layer->max_zoom(); ++z) {
        const auto r = f.layer->tiles_at(z);
        const auto& a = j["available"][static_cast<std::size_t>(z)][0];
        CHECK(a["startX"] == r.x0);
        CHECK(a["endX"] == r.x1);
        CHECK(a["startY"] == r.y0);
        CHECK(a["endY"] == r.y1);
    }
    CHECK(j["data"]["minzoom"] == f.layer->min_zoom());
}

TEST_CASE("the metadata of the two root tiles lists, level by level, what layer.json lists") {
    auto& f = fixture();
    RunningServer server({{f.layer, {tiler::Format::Terrain}, nullptr}});
    auto c = server.client();
    auto doc = c.Get("/hills/layer.json");
    REQUIRE(doc);
    const auto available = nlohmann::json::parse(doc->body)["available"];
    // Tiles per level, from the roots' metadata extension (child availability).
    std::vector<std::set<std::pair<std::int64_t, std::int64_t>>> listed(
        std::max<std::size_t>(available.size(), tiler::kMetadataLevels + 1));
    for (const std::int64_t x : {0, 1}) {
        auto res = c.Get(terrain_url({0, x, 0}).c_str(),
                         {{"Accept", "application/vnd.quantized-mesh;extensions=metadata"}});
        REQUIRE(res);
        const tb_qm::Tile t = tb_qm::read(res->body);
        REQUIRE(t.extensions.size() == 1);
        const auto meta = nlohmann::json::parse(t.extensions[0].data.substr(4));
        CHECK(meta["filler"] == true);
        const auto& levels = meta["available"];
        // Always kMetadataLevels levels, those past the deepest zoom empty: a deeper pyramid
        // then changes only the metadata of the tiles above its new ones.
        REQUIRE(levels.size() == tiler::kMetadataLevels);
        for (std::size_t k = available.size() - 1; k < levels.size(); ++k) {
            CHECK(levels[k].empty());
        }
        for (std::size_t k = 0; k < levels.size(); ++k) {
            for (const auto& r : levels[k]) {
                for (std::int64_t y = r["startY"]; y <= r["endY"].get<std::int64_t>(); ++y) {
                    for (std::int64_t tx = r["startX"]; tx <= r["endX"].get<std::int64_t>(); ++tx) {
                        // Under this root: x within its half of the level.
                        CHECK((tx >> (k + 1)) == x);
                        listed[k + 1].insert({tx, y});
                    }
                }
            }
        }
    }
    for (std::size_t z = 1; z < available.size() && z <= tiler::kMetadataLevels; ++z) {
        std::set<std::pair<std::int64_t, std::int64_t>> want;
        for (const auto& r : available[z]) {
            for (std::int64_t y = r["startY"]; y <= r["endY"].get<std::int64_t>(); ++y) {
                for (std::int64_t x = r["startX"]; x <= r["endX"].get<std::int64_t>(); ++x) {
                    want.insert({x, y});
                }
            }
        }
        CAPTURE(z);
        CHECK(listed[z] == want);
        CHECK_FALSE(want.empty());
    }
}

TEST_CASE("with a list of CORS origins a terrain tile also varies by Origin") {
    auto& f = fixture();
    server::HttpOptions http;
    http.cors_origins = {"https://maps.example.com"};
    RunningServer server({{f.layer, {tiler::Format::Terrain}, nullptr}}, {}, http);
    auto c = server.client();
    const auto r = f.layer->tiles_at(f.layer->max_zoom());
    const tiler::TileId id{f.layer->max_zoom(), r.x0, r.y0};
    for (const bool with_origin : {true, false}) {
        CAPTURE(with_origin);
        httplib::Headers h{{"Accept-Encoding", "gzip"}};
        if (with_origin) {
            h.emplace("Origin", "https://maps.example.com");
        }
        auto res = c.Get(terrain_url(id).c_str(), h);
        REQUIRE(res);
        REQUIRE(res->status == 200);
        CHECK(res->get_header_value("Vary") == "Origin, Accept, Accept-Encoding");
        CHECK(res->has_header("Access-Control-Allow-Origin") == with_origin);
    }
}

TEST_CASE("a terrain tile carries exactly the extensions its Accept header names, gzipped, "
          "with Vary: Accept") {
    auto& f = fixture();
    RunningServer server({{f.layer, {tiler::Format::Terrain}, nullptr}});
    auto c = server.client();
    const auto r = f.layer->tiles_at(f.layer->max_zoom());
    const tiler::TileId id{f.layer->max_zoom(), r.x0, r.y0};
    const std::string full = f.layer->make_tile(f.layer->tile(id), tiler::Format::Terrain);

    const auto get = [&](const char* accept) {
        httplib::Headers h{{"Accept-Encoding", "gzip"}};
        if (accept) {
            h.emplace("Accept", accept);
        }
        auto res = c.Get(terrain_url(id).c_str(), h);
        REQUIRE(res);
        REQUIRE(res->status == 200);
        CHECK(res->get_header_value("Content-Type") == "application/vnd.quantized-mesh");
        CHECK(res->get_header_value("Content-Encoding") == "gzip");
        CHECK(res->get_header_value("Vary").find("Accept") != std::string::npos);
        CHECK(res->get_header_value("Vary").find("Accept-Encoding") != std::string::npos);
        return res->body; // cpp-httplib has undone the gzip coding
    };
    // CesiumJS's own Accept: every extension, the layer's bytes as made.
    const std::string all = get(kCesiumAccept);
    CHECK(all == full);
    CHECK(extension_ids(all) == std::vector<int>{1, 2, 4});
    // No Accept, or one naming no extension: none.
    const std::string bare = get(nullptr);
    CHECK(extension_ids(bare).empty());
    CHECK(get("application/octet-stream,*/*") == bare);
    // Unknown names are dropped, known ones kept.
    CHECK(extension_ids(get("application/vnd.quantized-mesh;extensions=watermask-foo-bar")) ==
          std::vector<int>{2});
    CHECK(extension_ids(get("application/vnd.quantized-mesh; extensions=metadata-"
                            "octvertexnormals")) == std::vector<int>{1, 4});
    // The tile without extensions is the full tile's prefix.
    CHECK(full.compare(0, bare.size(), bare) == 0);

    // Without Accept-Encoding the body is sent as is.
    auto plain = c.Get(terrain_url(id).c_str());
    REQUIRE(plain);
    CHECK(plain->get_header_value("Content-Encoding").empty());
    CHECK(plain->body == bare);
}

TEST_CASE("a store whose .terrain tiles hold only some extensions (a build's default) is "
          "neither read nor written for terrain: clients get every extension they ask for") {
    auto& f = fixture();
    TempDir dir;
    const auto r = f.layer->tiles_at(f.layer->max_zoom());
    const tiler::TileId id{f.layer->max_zoom(), r.x0, r.y0};
    const std::string full = f.layer->make_tile(f.layer->tile(id), tiler::Format::Terrain);
    const std::string cut = tiler::select_extensions(full, tiler::kMetadata);
    auto store = std::shared_ptr<tiler::TileStore>(tiler::TileStore::open(dir / "out"));
    const tiler::TileKey key{"hills", id, tiler::Format::Terrain, -1};
    store->put(key, cut);

    server::ServedLayer served{f.layer, {tiler::Format::Terrain}, store};
    served.store_terrain = false;
    RunningServer server({served});
    auto c = server.client();
    auto res = c.Get(terrain_url(id).c_str(), {{"Accept", kCesiumAccept}});
    REQUIRE(res);
    REQUIRE(res->status == 200);
    CHECK(res->body == full);
    CHECK(extension_ids(res->body) == std::vector<int>{1, 2, 4});
    CHECK(store->get(key) == cut); // the build's tile is left as it was
    CHECK(server.metrics.store_hits == 0);
}

// Asks `server` for the terrain tile `id` as CesiumJS does, in `coding` ("identity", "gzip" or
// "br"); returns the size of the body as sent.
std::size_t get_coded(const RunningServer& server, const tiler::TileId& id, const char* coding) {
    auto c = server.client();
    c.set_decompress(false);
    auto res =
        c.Get(terrain_url(id).c_str(), {{"Accept", kCesiumAccept}, {"Accept-Encoding", coding}});
    REQUIRE(res);
    REQUIRE(res->status == 200);
    CHECK(res->get_header_value("Content-Encoding") ==
          (std::string(coding) == "identity" ? "" : coding));
    return res->body.size();
}

TEST_CASE("the gzip and br copies of a cached terrain tile count against cache_mb, once each") {
    auto& f = fixture();
    RunningServer server({{f.layer, {tiler::Format::Terrain}, nullptr}});
    const auto r = f.layer->tiles_at(f.layer->max_zoom());
    const tiler::TileId id{f.layer->max_zoom(), r.x0, r.y0};
    const auto get = [&](const char* coding) { return get_coded(server, id, coding); };
    const auto cached = [&] { return test::metric(server.port, "tb_cache_bytes"); };
    const std::size_t plain = get("identity");
    const double before = cached();
    CHECK(before > static_cast<double>(plain));
    const std::size_t gzipped = get("gzip");
    CHECK(cached() == before + static_cast<double>(gzipped));
    const std::size_t brotli = get("br");
    CHECK(cached() == before + static_cast<double>(gzipped + brotli));
    // Made and charged once: asking again changes nothing.
    CHECK(get("gzip") == gzipped);
    CHECK(get("br") == brotli);
    CHECK(cached() == before + static_cast<double>(gzipped + brotli));
}

TEST_CASE("a gzip or br copy that takes the cache past cache_mb evicts the least recent tile") {
    auto& f = fixture();
    const int z = f.layer->max_zoom();
    const auto r = f.layer->tiles_at(z);
    REQUIRE((r.x1 > r.x0 || r.y1 > r.y0));
    const tiler::TileId a{z, r.x0, r.y0};
    const tiler::TileId b =
        r.x1 > r.x0 ? tiler::TileId{z, r.x0 + 1, r.y0} : tiler::TileId{z, r.x0, r.y0 + 1};
    // What each costs, on a server with room for everything.
    double entry_a = 0, entry_b = 0, copies_a = 0;
    {
        RunningServer roomy({{f.layer, {tiler::Format::Terrain}, nullptr}});
        get_coded(roomy, a, "identity");
        entry_a = test::metric(roomy.port, "tb_cache_bytes");
        get_coded(roomy, b, "identity");
        entry_b = test::metric(roomy.port, "tb_cache_bytes") - entry_a;
        get_coded(roomy, a, "gzip");
        get_coded(roomy, a, "br");
        copies_a = test::metric(roomy.port, "tb_cache_bytes") - entry_a - entry_b;
    }
    REQUIRE(copies_a > 1);
    // Room for both tiles and all but one byte of a's copies.
    server::TileServiceOptions options;
    options.cache_bytes = static_cast<std::size_t>(entry_a + entry_b + copies_a) - 1;
    RunningServer server({{f.layer, {tiler::Format::Terrain}, nullptr}}, options);
    get_coded(server, a, "identity");
    get_coded(server, b, "identity");
    CHECK(test::metric(server.port, "tb_cache_entries") == 2);
    get_coded(server, a, "gzip");
    CHECK(test::metric(server.port, "tb_cache_entries") == 2);
    // The br copy does not fit beside b: b, asked for least recently, goes.
    get_coded(server, a, "br");
    CHECK(test::metric(server.port, "tb_cache_entries") == 1);
    CHECK(test::metric(server.port, "tb_cache_bytes") == entry_a + copies_a);
}

TEST_CASE("terrain tiles: filler at zoom 0, 404 beyond max zoom, 400 outside the scheme, 404 "
          "for a layer without terrain") {
    auto& f = fixture();
    RunningServer server(
        {{f.layer, {tiler::Format::Terrain}, nullptr},
         {tiler::Layer::open(test::test_layer_options(fixture().dir / "hills.asc", "meshonly")),
          {tiler::Format::Glb},
          nullptr}});
    auto c = server.client();
    for (const tiler::TileId id : {tiler::TileId{0, 0, 0}, tiler::TileId{0, 1, 0}}) {
        auto res = c.Get(terrain_url(id).c_str(), {{"Accept", kCesiumAccept}});
        REQUIRE(res);
        CHECK(res->status == 200);
        const tb_qm::Tile t = tb_qm::read(res->body);
        CHECK(t.vertex_count > 4);
        CHECK(t.edges[0].size() > 1);
    }
    const int beyond = f.layer->max_zoom() + 1;
    auto deep = c.Get(terrain_url({beyond, 0, 0}).c_str());
    REQUIRE(deep);
    CHECK(deep->status == 404);
    for (const tiler::TileId id :
         {tiler::TileId{0, 2, 0}, tiler::TileId{0, 0, 1}, tiler::TileId{3, 16, 0}}) {
        auto res = c.Get(terrain_url(id).c_str());
        REQUIRE(res);
        CHECK(res->status == 400);
        CHECK(res->body.find("is outside the geodetic scheme: at zoom " + std::to_string(id.z) +
                             ", x is 0..") != std::string::npos);
    }
    auto bad = c.Get("/hills/1/x/0.terrain");
    REQUIRE(bad);
    CHECK(bad->status == 400);
    auto none = c.Get("/meshonly/0/0/0.terrain");
    REQUIRE(none);
    CHECK(none->status == 404);
    auto no_json = c.Get("/meshonly/layer.json");
    REQUIRE(no_json);
    CHECK(no_json->status == 404);
}

TEST_CASE("3D Tiles terrain over HTTP: /layers names terrain/tileset.json; its subtrees and "
          "glbs are the layer's bytes; bad coordinates get 400, beyond max zoom 404") {
    auto& f = fixture();
    RunningServer server(
        {{f.layer, {tiler::Format::Terrain3d}, nullptr},
         {tiler::Layer::open(test::test_layer_options(fixture().dir / "hills.asc", "qmonly")),
          {tiler::Format::Terrain},
          nullptr}});
    auto c = server.client();
    auto layers = c.Get("/layers");
    REQUIRE(layers);
    const auto list = nlohmann::json::parse(layers->body);
    CHECK(list["layers"][0]["terrain_tileset"] == "/hills/terrain/tileset.json");
    CHECK_FALSE(list["layers"][0].contains("layer_json"));
    CHECK_FALSE(list["layers"][1].contains("terrain_tileset"));

    auto ts = c.Get("/hills/terrain/tileset.json");
    REQUIRE(ts);
    REQUIRE(ts->status == 200);
    CHECK(ts->get_header_value("Content-Type") == "application/json");
    std::string doc;
    REQUIRE(f.layer->document("terrain/tileset.json", doc));
    CHECK(ts->body == doc);

    auto sub = c.Get("/hills/terrain/0/0/0/0.subtree");
    REQUIRE(sub);
    REQUIRE(sub->status == 200);
    CHECK(sub->get_header_value("Content-Type") == "application/octet-stream");
    REQUIRE(f.layer->document("terrain/0/0/0/0.subtree", doc));
    CHECK(sub->body == doc);
    const tb_terrain3d::Subtree s = tb_terrain3d::read_subtree(sub->body);
    CHECK(s.available(s.doc["tileAvailability"], 0)); // the root tile

    // A tile of the finest zoom under the data, through its implicit coordinates.
    const tiler::TileRange r = f.layer->tiles_at(f.layer->max_zoom());
    const tiler::TileId id{r.z, r.x0, r.y0};
    const std::int64_t side = std::int64_t{1} << id.z;
    const std::string url = "/hills/terrain/" + std::to_string(id.x / side) + "/" +
                            std::to_string(id.z) + "/" + std::to_string(id.x % side) + "/" +
                            std::to_string(id.y) + ".glb";
    auto glb = c.Get(url.c_str(), {{"Accept-Encoding", "gzip"}});
    REQUIRE(glb);
    REQUIRE(glb->status == 200);
    CHECK(glb->get_header_value("Content-Type") == "model/gltf-binary");
    CHECK(glb->body == f.layer->make_tile(f.layer->tile(id), tiler::Format::Terrain3d));
    const tb_terrain3d::Glb g = tb_terrain3d::read_glb(glb->body);
    CHECK(g.drawn.indices.size() >= 6);
    CHECK(g.normals.size() == g.drawn.ecef.size());

    for (const char* bad : {"/hills/terrain/2/0/0/0.glb",
                            "/hills/terrain/0/1/2/0.glb",
                            "/hills/terrain/0/1/0/2.glb",
                            "/hills/terrain/0/x/0/0.glb",
                            "/hills/terrain/0/99/0/0.glb"}) {
        CAPTURE(bad);
        auto res = c.Get(bad);
        REQUIRE(res);
        CHECK(res->status == 400);
    }
    const std::string deep =
        "/hills/terrain/0/" + std::to_string(f.layer->max_zoom() + 1) + "/0/0.glb";
    auto beyond = c.Get(deep.c_str());
    REQUIRE(beyond);
    CHECK(beyond->status == 404);
    for (const char* missing : {"/hills/terrain/0/1/0/0.subtree",
                                "/hills/terrain/nothing.json",
                                "/qmonly/terrain/tileset.json",
                                "/qmonly/terrain/0/0/0/0.glb"}) {
        CAPTURE(missing);
        auto res = c.Get(missing);
        REQUIRE(res);
        CHECK(res->status == 404);
    }
}

} // namespace
