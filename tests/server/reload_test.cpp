// `terrabound serve` follows its sources without a restart: a source replaced under it (on
// SIGHUP, or found by the periodic check) is served anew, tile for tile the bytes a fresh layer
// of the new file makes, with new ETags and no old tile left in its store; a replacement that
// cannot be read makes the layer answer 503 with the reason until it is fixed.
#include "serve_process.hpp"
#include "server/layer_reload.hpp"
#include "server_fixture.hpp"
#include "tiler/stores/store.hpp"

#include <doctest/doctest.h>

#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <thread>

namespace {

using namespace tb;

constexpr const char* kTile = "/hills/8/272/210.glb";

// The response to GET `path` once `done` accepts it, polled for up to 30 s; the last one if
// none was accepted (so the test's checks say what it was).
httplib::Result
poll(int port, const std::string& path, const std::function<bool(const httplib::Result&)>& done) {
    httplib::Client c("127.0.0.1", port);
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    for (;;) {
        auto res = c.Get(path.c_str());
        if (done(res) || std::chrono::steady_clock::now() > until) {
            return res;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
}

// Writes the hills DEM of n x n samples to dir/name, then renames it over dir/hills.asc.
void replace_source(const test::TempDir& dir, int n) {
    test::write_dem(dir / "next.asc", n);
    std::filesystem::rename(dir / "next.asc", dir / "hills.asc");
}

std::string config_text(int watch_interval_s) {
    return R"({"server": {"threads": 1, "watch_interval_s": )" + std::to_string(watch_interval_s) +
           R"(}, "layers": [{"name": "hills", "sources": ["hills.asc"], "tile_size": 64,
           "min_zoom": 5, "max_zoom": 8, "eps_levels": [5, 20], "store": "tiles"}]})";
}

// The glb a layer freshly opened on dir/hills.asc makes for kTile.
std::string fresh_tile(const test::TempDir& dir) {
    const auto layer = tiler::Layer::open(test::test_layer_options(dir / "hills.asc", "hills"));
    return layer->make_tile(layer->tile(tiler::TileId{8, 272, 210}), tiler::Format::Glb);
}

// `terrabound serve` on dir/hills.asc (257 x 257 samples) with a directory store, checking its
// sources every `watch_interval_s` (0: on SIGHUP only), and the tile it first answers.
struct Serving {
    test::TempDir dir;
    test::Child child;
    int port = 0;
    std::string first;  // kTile's body
    std::string etag;   // and ETag
    std::string layers; // /layers at start

    explicit Serving(int watch_interval_s) {
        test::write_dem(dir / "hills.asc", 257);
        test::write_file(dir / "serve.json", config_text(watch_interval_s));
        port = test::start_server(child, {dir / "serve.json"}, dir / "serve.log");
        httplib::Client c("127.0.0.1", port);
        const auto res = c.Get(kTile);
        REQUIRE(res);
        REQUIRE(res->status == 200);
        first = res->body;
        etag = res->get_header_value("ETag");
        const auto listed = c.Get("/layers");
        REQUIRE(listed);
        layers = listed->body;
    }
    std::string log() const { return test::read_file(dir / "serve.log"); }
    void stop() {
        kill(child.pid, SIGTERM);
        CHECK(child.wait_exit() == 0);
    }
};

} // namespace

TEST_CASE("on SIGHUP a replaced source is served anew: the new layer's bytes, a new ETag, and "
          "no old tile left in the store; its summary is made before it serves") {
    Serving s(0);
    CHECK(s.first == fresh_tile(s.dir));
    replace_source(s.dir, 193);
    const std::string expected = fresh_tile(s.dir);
    REQUIRE(expected != s.first);
    REQUIRE(kill(s.child.pid, SIGHUP) == 0);
    const auto after = poll(s.port, kTile, [&](const httplib::Result& r) {
        return r && r->status == 200 && r->get_header_value("ETag") != s.etag;
    });
    REQUIRE(after);
    INFO(s.log());
    CHECK(after->status == 200);
    CHECK(after->body == expected);
    CHECK(after->get_header_value("ETag") != s.etag);
    CHECK(s.log().find("reload: layer hills now serves its new sources") != std::string::npos);
    // The layer's summary was made before it served, at start and again on reload: no tile
    // request waited for it.
    const std::string log = s.log();
    const auto made = log.find("summary ready");
    const auto remade = log.find("summary ready", made + 1);
    CHECK(made < log.find("serving http://"));
    CHECK(log.find("reload: layer hills: its sources changed") < remade);
    CHECK(remade < log.find("reload: layer hills now serves its new sources"));
    // /layers describes the new layer too (its bounds follow the smaller DEM).
    httplib::Client c("127.0.0.1", s.port);
    const auto listed = c.Get("/layers");
    REQUIRE(listed);
    CHECK(listed->body != s.layers);
    CHECK(listed->body.find("\"hills\"") != std::string::npos);
    // The store holds the new tile (written as it was made), never the old one.
    auto store = tiler::TileStore::open(s.dir / "tiles");
    const auto stored = store->get(tiler::TileKey{"hills", {8, 272, 210}, tiler::Format::Glb, -1});
    REQUIRE(stored);
    CHECK(*stored == expected);
    s.stop();
}

TEST_CASE("the periodic check finds a replaced source by itself; an unreadable replacement "
          "answers 503 with the reason until a readable one replaces it") {
    Serving s(1);
    const test::TempDir& dir = s.dir;
    const int port = s.port;
    httplib::Client c("127.0.0.1", port);

    test::write_file(dir / "next.asc", "ncols 3\nnrows 3\nthis is not a grid\n");
    std::filesystem::rename(dir / "next.asc", dir / "hills.asc");
    const auto broken =
        poll(port, kTile, [](const httplib::Result& r) { return r && r->status == 503; });
    REQUIRE(broken);
    INFO(s.log());
    CHECK(broken->status == 503);
    CHECK(broken->body.find("unavailable") != std::string::npos);
    CHECK(s.log().find("it answers 503 until its sources change again") != std::string::npos);
    const auto health = c.Get("/health");
    REQUIRE(health);
    CHECK(health->status == 200);

    replace_source(dir, 129);
    const std::string expected = fresh_tile(dir);
    const auto fixed =
        poll(port, kTile, [](const httplib::Result& r) { return r && r->status == 200; });
    REQUIRE(fixed);
    CHECK(fixed->status == 200);
    CHECK(fixed->body == expected);
    s.stop();
}

TEST_CASE("a directory of DEMs is checked file by file: a DEM added to it is a change") {
    test::TempDir dir;
    std::filesystem::create_directories(dir / "dems");
    test::write_dem(dir / "dems/a.asc", 33);
    const std::vector<std::string> sources{dir / "dems"};
    const auto before = server::source_stamps(sources);
    CHECK(before.size() == 1);
    CHECK(server::source_stamps(sources) == before);
    test::write_dem(dir / "dems/b.asc", 33);
    const auto after = server::source_stamps(sources);
    CHECK(after.size() == 2);
    CHECK(after != before);
}
