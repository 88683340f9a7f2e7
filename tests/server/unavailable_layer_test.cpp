// `terrabound serve` with a layer whose DEM cannot be opened: the other layers serve, the bad
// one's routes answer 503 with the reason, /layers lists it; with no layer left, it exits.
#include "serve_process.hpp"
#include "server_fixture.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

namespace {

using namespace tb;

// A config of the hills DEM as layer "good" and, for each name in `bad`, a layer of a file that
// exists (so the config is valid) but is no raster.
std::string write_config(const test::TempDir& dir, const std::vector<std::string>& bad) {
    test::write_dem(dir / "hills.asc", 129);
    std::string layers = R"({"name": "good", "sources": ["hills.asc"], "min_zoom": 5,
                             "max_zoom": 7, "tile_size": 64})";
    for (const auto& name : bad) {
        test::write_file(dir / (name + ".tif"), "this is not a GeoTIFF\n");
        layers += R"(, {"name": ")" + name + R"(", "sources": [")" + name + R"(.tif"]})";
    }
    const std::string path = dir / "serve.json";
    test::write_file(path, R"({"server": {"threads": 1}, "layers": [)" + layers + "]}");
    return path;
}

} // namespace

TEST_CASE("a layer whose DEM fails to open answers 503 with the reason; the others serve") {
    test::TempDir dir;
    test::Child child;
    const std::string log = dir / "serve.log";
    const int port = test::start_server(child, {write_config(dir, {"broken"})}, log);
    httplib::Client c("127.0.0.1", port);

    // Logged at error level, naming the layer, its file and the reason.
    const std::string text = test::read_file(log);
    const auto at = text.find("error layer broken (");
    REQUIRE(at != std::string::npos);
    const std::string line = text.substr(at, text.find('\n', at) - at);
    CHECK(line.find("broken.tif") != std::string::npos);
    CHECK(line.find("its routes answer 503") != std::string::npos);
    CHECK(text.find("1 layer(s), 1 unavailable") != std::string::npos);

    auto layers = c.Get("/layers");
    REQUIRE(layers);
    REQUIRE(layers->status == 200);
    const auto j = nlohmann::json::parse(layers->body);
    REQUIRE(j["layers"].size() == 1);
    CHECK(j["layers"][0]["name"] == "good");
    REQUIRE(j["unavailable"].size() == 1);
    CHECK(j["unavailable"][0]["name"] == "broken");
    const std::string reason = j["unavailable"][0]["error"];
    CHECK(reason.find("broken.tif") != std::string::npos);

    for (const char* url : {"/broken/tileset.json",
                            "/broken/layer.json",
                            "/broken/6/66/50.glb",
                            "/broken/6/66/50.terrain",
                            "/broken/dem/7/68/37.png",
                            "/broken/dem/tilejson.json"}) {
        INFO(url);
        auto res = c.Get(url);
        REQUIRE(res);
        CHECK(res->status == 503);
        CHECK(res->get_header_value("Content-Type") == "application/json");
        const auto e = nlohmann::json::parse(res->body, nullptr, false);
        REQUIRE((e.is_object() && e["error"].is_string()));
        CHECK(e["error"].get<std::string>().find("unavailable") != std::string::npos);
        CHECK(e["error"].get<std::string>().find("broken.tif") != std::string::npos);
    }
    auto good = c.Get("/good/tileset.json");
    REQUIRE(good);
    CHECK(good->status == 200);
    auto unknown = c.Get("/nope/tileset.json");
    REQUIRE(unknown);
    CHECK(unknown->status == 404);
    CHECK(test::metric(port, "tb_layers_unavailable") == 1);
    auto health = c.Get("/health");
    REQUIRE(health);
    CHECK(health->status == 200);
}

TEST_CASE("serve exits when no layer can be opened, naming the reason") {
    test::TempDir dir;
    const std::string config = write_config(dir, {"bad1", "bad2"});
    // Only the broken ones: drop "good" from the config.
    std::string text = test::read_file(config);
    const auto good = text.find(R"({"name": "good")");
    text.erase(good, text.find("}, ", good) + 3 - good);
    test::write_file(config, text);
    const std::string log = dir / "serve.log";
    const int code = test::run_to_exit({"serve", config, "--port", "0"}, log);
    const std::string out = test::read_file(log);
    INFO(out);
    CHECK(code == 2);
    CHECK(out.find("terrabound: none of the 2 layers can be served") != std::string::npos);
    CHECK(out.find("bad1.tif") != std::string::npos);
    CHECK(out.find("bad2.tif") != std::string::npos); // logged
    CHECK(out.find("serving http") == std::string::npos);
}

TEST_CASE("a layer whose store holds an unfinished build --update answers 503 naming the way out; "
          "the others serve") {
    test::TempDir dir;
    std::string config = write_config(dir, {});
    const std::string store = dir / "store";
    REQUIRE(test::run_to_exit({"build",
                               dir / "hills.asc",
                               "-o",
                               store,
                               "--layer",
                               "stale",
                               "--size",
                               "64",
                               "--min-zoom",
                               "5",
                               "--max-zoom",
                               "7",
                               "--formats",
                               "glb"},
                              dir / "build.log") == 0);
    // What an interrupted update leaves: the record of the build it updates (checksummed like
    // every document of a directory store).
    for (const std::string name : {"build-manifest.json", ".build-manifest.json.crc32"}) {
        const std::string to =
            name.front() == '.' ? ".build-update.json.crc32" : "build-update.json";
        test::write_file(store + "/stale/" + to, test::read_file(store + "/stale/" + name));
    }
    std::string text = test::read_file(config);
    text.insert(text.rfind(']'), R"(, {"name": "stale", "sources": ["hills.asc"], "min_zoom": 5,
                                    "max_zoom": 7, "tile_size": 64, "store": "store"})");
    test::write_file(config, text);

    test::Child child;
    const int port = test::start_server(child, {config}, dir / "serve.log");
    httplib::Client c("127.0.0.1", port);
    auto stale = c.Get("/stale/tileset.json");
    REQUIRE(stale);
    CHECK(stale->status == 503);
    CHECK(stale->body.find("has not finished") != std::string::npos);
    CHECK(stale->body.find("--update") != std::string::npos);
    auto good = c.Get("/good/tileset.json");
    REQUIRE(good);
    CHECK(good->status == 200);
}
