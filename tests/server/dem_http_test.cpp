// Raster DEM tiles over real loopback HTTP: TileJSON, tiles byte-exact against the layer's own
// tiles, headers, stores, and the errors of bad requests.
#include "core/error.hpp"
#include "server_fixture.hpp"
#include "tiler/dem_tiles.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"
#include "tiler/stores/store.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

namespace {

using namespace tb;
using test::RunningServer;
using test::TempDir;

struct DemFixture {
    TempDir dir;
    std::shared_ptr<const tiler::Layer> layer;
    tiler::DemTilePlan plan;
    tiler::TileRange finest; // DEM tiles at the max zoom

    DemFixture() {
        log::set_level(log::Level::Warn);
        test::write_dem(dir / "hills.asc");
        layer = tiler::Layer::open(test::test_layer_options(dir / "hills.asc", "hills"));
        plan = tiler::dem_tile_plan(*layer);
        finest = tiler::dem_tiles_at(*layer, plan.max_zoom);
        REQUIRE_FALSE(finest.empty());
    }
    server::ServedLayer served(std::vector<tiler::Format> formats,
                               std::shared_ptr<tiler::TileStore> store = nullptr) const {
        return {layer, std::move(formats), std::move(store)};
    }
};

DemFixture& fixture() {
    static DemFixture f;
    return f;
}

const std::vector<tiler::Format> kAll = {
    tiler::Format::Glb, tiler::Format::Terrarium, tiler::Format::Mapbox};

std::string dem_url(const tiler::TileId& id, const std::string& query = "") {
    return "/hills/dem/" + std::to_string(id.z) + "/" + std::to_string(id.x) + "/" +
           std::to_string(id.y) + ".png" + query;
}

// The TileJSON template with z/x/y filled in, as a client does, less the origin.
std::string expand(std::string url, const tiler::TileId& id, const std::string& origin) {
    REQUIRE(url.rfind(origin, 0) == 0);
    url = url.substr(origin.size());
    for (const auto& [key, value] :
         {std::pair<std::string, std::string>{"{z}", std::to_string(id.z)},
          {"{x}", std::to_string(id.x)},
          {"{y}", std::to_string(id.y)}}) {
        const auto at = url.find(key);
        REQUIRE(at != std::string::npos);
        url.replace(at, key.size(), value);
    }
    return url;
}

} // namespace

TEST_CASE("TileJSON describes the DEM tiles and its tile URLs give the layer's tiles byte-exact") {
    auto& f = fixture();
    RunningServer s({f.served(kAll)});
    auto c = s.client();
    const std::string origin = "http://127.0.0.1:" + std::to_string(s.port);
    for (const auto& [encoding, format] :
         {std::pair{std::string("terrarium"), tiler::Format::Terrarium},
          {std::string("mapbox"), tiler::Format::Mapbox}}) {
        CAPTURE(encoding);
        auto res = c.Get(("/hills/dem/tilejson.json?encoding=" + encoding).c_str());
        REQUIRE(res);
        REQUIRE(res->status == 200);
        CHECK(res->get_header_value("Content-Type") == "application/json");
        CHECK(res->get_header_value("Access-Control-Allow-Origin") == "*");
        CHECK(!res->get_header_value("ETag").empty());
        const auto doc = nlohmann::json::parse(res->body);
        CHECK(doc["tilejson"] == "3.0.0");
        CHECK(doc["encoding"] == encoding);
        CHECK(doc["scheme"] == "xyz");
        CHECK(doc["tileSize"] == f.plan.tile_size);
        CHECK(doc["minzoom"] == f.plan.min_zoom);
        CHECK(doc["maxzoom"] == f.plan.max_zoom);
        // write_dem covers 11..12 E, 57..58 N (pixel centres).
        CHECK(doc["bounds"][0].get<double>() == doctest::Approx(11));
        CHECK(doc["bounds"][1].get<double>() == doctest::Approx(57));
        CHECK(doc["bounds"][2].get<double>() == doctest::Approx(12));
        CHECK(doc["bounds"][3].get<double>() == doctest::Approx(58));
        REQUIRE(doc["tiles"].size() == 1);
        const std::string url = doc["tiles"][0];
        for (std::int64_t y = f.finest.y0; y <= f.finest.y1; ++y) {
            for (std::int64_t x = f.finest.x0; x <= f.finest.x1; ++x) {
                const tiler::TileId id{f.plan.max_zoom, x, y};
                auto tile = c.Get(expand(url, id, origin).c_str());
                REQUIRE(tile);
                REQUIRE(tile->status == 200);
                CHECK(tile->get_header_value("Content-Type") == "image/png");
                CHECK(tile->get_header_value("Cache-Control") == "public, max-age=604800");
                CHECK(tile->get_header_value("Access-Control-Allow-Origin") == "*");
                CHECK(tile->body ==
                      tiler::make_dem_tile(
                          *f.layer, tiler::ValidTile::parse(tiler::Scheme::Mercator, id), format));
            }
        }
    }
    // Without ?encoding the TileJSON and the tiles are terrarium.
    auto plain = c.Get("/hills/dem/tilejson.json");
    REQUIRE(plain);
    CHECK(nlohmann::json::parse(plain->body)["encoding"] == "terrarium");
    const tiler::TileId first{f.plan.max_zoom, f.finest.x0, f.finest.y0};
    auto tile = c.Get(dem_url(first).c_str());
    REQUIRE(tile);
    CHECK(tile->body ==
          tiler::make_dem_tile(*f.layer,
                               tiler::ValidTile::parse(tiler::Scheme::Mercator, first),
                               tiler::Format::Terrarium));
    CHECK(tile->body !=
          tiler::make_dem_tile(*f.layer,
                               tiler::ValidTile::parse(tiler::Scheme::Mercator, first),
                               tiler::Format::Mapbox));
    // A proxy's Host is what clients reach.
    auto proxied = c.Get("/hills/dem/tilejson.json", {{"Host", "tiles.example.org"}});
    REQUIRE(proxied);
    CHECK(nlohmann::json::parse(proxied->body)["tiles"][0].get<std::string>().rfind(
              "http://tiles.example.org/hills/dem/", 0) == 0);
    // /layers points at the TileJSON.
    auto layers = c.Get("/layers");
    REQUIRE(layers);
    const auto dem = nlohmann::json::parse(layers->body)["layers"][0]["dem"];
    CHECK(dem["tilejson"] == "/hills/dem/tilejson.json");
    CHECK(dem["encodings"] == nlohmann::json::array({"terrarium", "mapbox"}));
    CHECK(dem["max_zoom"] == f.plan.max_zoom);
}

TEST_CASE("DEM tiles carry a strong ETag, answer 304 to it, and go into the layer's store") {
    auto& f = fixture();
    TempDir out;
    std::shared_ptr<tiler::TileStore> store = tiler::TileStore::open(out / "tiles");
    RunningServer s({f.served(kAll, store)});
    auto c = s.client();
    const tiler::TileId id{f.plan.max_zoom, f.finest.x1, f.finest.y1};
    auto first = c.Get(dem_url(id, "?encoding=mapbox").c_str());
    REQUIRE(first);
    REQUIRE(first->status == 200);
    const std::string etag = first->get_header_value("ETag");
    CHECK(etag.size() > 2);
    auto again = c.Get(dem_url(id, "?encoding=mapbox").c_str(), {{"If-None-Match", etag}});
    REQUIRE(again);
    CHECK(again->status == 304);
    CHECK(again->body.empty());
    // Stored under its own key: the mapbox file, not the terrarium one nor a mesh tile.
    CHECK(store->get(tiler::TileKey{"hills", id, tiler::Format::Mapbox, -1}) == first->body);
    CHECK_FALSE(store->contains(tiler::TileKey{"hills", id, tiler::Format::Terrarium, -1}));
    CHECK(test::read_file(out / ("tiles/hills/dem/mapbox/" + std::to_string(id.z) + "/" +
                                 std::to_string(id.x) + "/" + std::to_string(id.y) + ".png")) ==
          first->body);
    // A stored tile is served from the store by a fresh server.
    RunningServer fresh({f.served(kAll, store)});
    auto from_store = fresh.client().Get(dem_url(id, "?encoding=mapbox").c_str());
    REQUIRE(from_store);
    CHECK(from_store->body == first->body);
    CHECK(test::metric(fresh.port, "tb_store_hits_total") == 1);
    CHECK(test::metric(fresh.port, "tb_tiles_generated_total") == 0);
}

TEST_CASE("bad DEM tile requests get 400, tiles beyond the zooms or the data 404") {
    auto& f = fixture();
    RunningServer s({f.served(kAll)});
    auto c = s.client();
    const auto status = [&](const std::string& url) {
        auto res = c.Get(url.c_str());
        REQUIRE(res);
        if (res->status >= 400) {
            CHECK(res->get_header_value("Content-Type") == "application/json");
            CHECK(res->body.find("\"error\"") != std::string::npos);
        }
        return res->status;
    };
    const int z = f.plan.max_zoom;
    const tiler::TileId in{z, f.finest.x0, f.finest.y0};
    CHECK(status(dem_url(in, "?encoding=png")) == 400);
    CHECK(status("/hills/dem/tilejson.json?encoding=webp") == 400);
    CHECK(status("/hills/dem/a/0/0.png") == 400);
    CHECK(status("/hills/dem/25/0/0.png") == 400);
    CHECK(status(dem_url({3, 8, 0})) == 400); // x beyond 2^z
    // The 400s of ids outside EPSG:3857 XYZ say which range they miss.
    const auto error = [&](const std::string& url) { return c.Get(url.c_str())->body; };
    CHECK(error("/hills/dem/25/0/0.png")
              .find("tile 25/0/0 is outside the mercator scheme: zoom "
                    "25 is outside 0..24") != std::string::npos);
    CHECK(error(dem_url({3, 8, 0}))
              .find("tile 3/8/0 is outside the mercator scheme: at zoom 3, "
                    "x is 0..7 and y is 0..7") != std::string::npos);
    CHECK(status(dem_url({z + 1, 2 * in.x, 2 * in.y})) == 404);
    CHECK(status(dem_url({z, f.finest.x1 + 3, f.finest.y0})) == 404);
    if (f.plan.min_zoom > 0) {
        CHECK(status(dem_url({0, 0, 0})) == 404);
    }
    CHECK(status("/nosuch/dem/tilejson.json") == 404);
    CHECK(status(dem_url(in)) == 200);
    // Encodings are spelled as MapLibre spells them.
    auto uppercase = c.Get(dem_url(in, "?encoding=Mapbox").c_str());
    REQUIRE(uppercase);
    CHECK(uppercase->status == 400);
    CHECK(uppercase->body.find("terrarium or mapbox") != std::string::npos);
}

TEST_CASE("a layer that does not serve DEM formats answers 404 for its DEM tiles and TileJSON") {
    auto& f = fixture();
    RunningServer s({f.served({tiler::Format::Glb, tiler::Format::Terrarium})});
    auto c = s.client();
    const tiler::TileId in{f.plan.max_zoom, f.finest.x0, f.finest.y0};
    auto terrarium = c.Get(dem_url(in).c_str());
    REQUIRE(terrarium);
    CHECK(terrarium->status == 200);
    auto mapbox = c.Get(dem_url(in, "?encoding=mapbox").c_str());
    REQUIRE(mapbox);
    CHECK(mapbox->status == 404);
    auto tilejson = c.Get("/hills/dem/tilejson.json?encoding=mapbox");
    REQUIRE(tilejson);
    CHECK(tilejson->status == 404);
    auto layers = c.Get("/layers");
    REQUIRE(layers);
    CHECK(nlohmann::json::parse(layers->body)["layers"][0]["dem"]["encodings"] ==
          nlohmann::json::array({"terrarium"}));

    RunningServer mesh_only({f.served({tiler::Format::Glb})});
    auto m = mesh_only.client();
    auto none = m.Get(dem_url(in).c_str());
    REQUIRE(none);
    CHECK(none->status == 404);
    auto no_json = m.Get("/hills/dem/tilejson.json");
    REQUIRE(no_json);
    CHECK(no_json->status == 404);
    auto mesh_layers = m.Get("/layers");
    REQUIRE(mesh_layers);
    CHECK_FALSE(nlohmann::json::parse(mesh_layers->body)["layers"][0].contains("dem"));
}
