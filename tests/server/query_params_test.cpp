// Query parameters of the tile routes over real loopback HTTP: a bad ?eps gets the same 400 and
// message on every tile format, and parameters the routes do not take are ignored.
#include "server_fixture.hpp"
#include "tiler/dem_tiles.hpp"
#include "tiler/layer.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <map>

namespace {

using namespace tb;
using test::RunningServer;

test::HillsLayer& hills() {
    static test::HillsLayer f;
    return f;
}

// A tile URL holding data, per format, of the hills layer serving all six formats.
std::map<std::string, std::string> tile_urls(const tiler::Layer& layer, const tiler::TileId& id) {
    const std::string zxy =
        std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
    const std::int64_t side = std::int64_t{1} << id.z;
    const tiler::TileRange dem = tiler::dem_tiles_at(layer, tiler::dem_tile_plan(layer).max_zoom);
    return {
        {"glb", "/hills/" + zxy + ".glb"},
        {"drc", "/hills/" + zxy + ".drc"},
        {"terrain", "/hills/" + zxy + ".terrain"},
        {"terrain3d",
         "/hills/terrain/" + std::to_string(id.x / side) + "/" + std::to_string(id.z) + "/" +
             std::to_string(id.x % side) + "/" + std::to_string(id.y) + ".glb"},
        {"terrarium",
         "/hills/dem/" + std::to_string(dem.z) + "/" + std::to_string(dem.x0) + "/" +
             std::to_string(dem.y0) + ".png"},
    };
}

} // namespace

TEST_CASE("a bad ?eps gets the same 400 and message on every tile format") {
    auto& f = hills();
    RunningServer s({{f.layer,
                      {tiler::Format::Glb,
                       tiler::Format::Drc,
                       tiler::Format::Terrarium,
                       tiler::Format::Mapbox,
                       tiler::Format::Terrain,
                       tiler::Format::Terrain3d},
                      nullptr}});
    auto c = s.client();
    const auto urls = tile_urls(*f.layer, f.inside);
    // The layer has eps_levels {5, 20}: 2 is past them, the others are no index at all.
    for (const char* query : {"?eps=2", "?eps=99", "?eps=-1", "?eps=fine", "?eps=", "?eps=1.5"}) {
        std::string first_body;
        for (const auto& [format, url] : urls) {
            INFO(format << " " << url << query);
            auto res = c.Get(url + query);
            REQUIRE(res);
            CHECK(res->status == 400);
            CHECK(res->get_header_value("Content-Type") == "application/json");
            const auto j = nlohmann::json::parse(res->body, nullptr, false);
            REQUIRE((j.is_object() && j["error"].is_string()));
            CHECK(j["error"].get<std::string>().find("eps") != std::string::npos);
            if (first_body.empty()) {
                first_body = res->body;
            }
            CHECK(res->body == first_body);
        }
    }
    // A level the layer has: the mesh tiles at it; formats made at their zoom's eps refuse it
    // rather than answer a tile that is not at the eps asked for.
    for (const auto& [format, url] : urls) {
        INFO(format << " " << url);
        auto res = c.Get(url + "?eps=1");
        REQUIRE(res);
        const bool levels = format == "glb" || format == "drc";
        CHECK(res->status == (levels ? 200 : 400));
        if (!levels) {
            CHECK(res->body.find("apply to .glb and .drc tiles only") != std::string::npos);
        }
        // Parameters a route does not take (a client's cache buster) change nothing.
        auto plain = c.Get(url);
        auto busted = c.Get(url + "?v=1.2.0");
        REQUIRE(plain);
        REQUIRE(busted);
        CHECK(plain->status == 200);
        CHECK(busted->status == 200);
        CHECK(busted->body == plain->body);
    }
    // The DEM tiles' own parameter is checked as before, whatever else the query holds.
    auto bad_encoding = c.Get(urls.at("terrarium") + "?encoding=png&eps=0");
    REQUIRE(bad_encoding);
    CHECK(bad_encoding->status == 400);
    CHECK(bad_encoding->body.find("encoding") != std::string::npos);
}
