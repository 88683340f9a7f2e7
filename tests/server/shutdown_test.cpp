// `terrabound serve` as a child process: startup line, and SIGTERM while tiles are being
// generated finishes every request in flight, closes the store and exits 0.
#include "serve_process.hpp"
#include "server_fixture.hpp"
#include "tiler/stores/store.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <mutex>
#include <regex>

namespace {

using namespace tb;

using test::Child;
using test::run_to_exit;
using test::start_server;

} // namespace

TEST_CASE("SIGTERM during tile generation loses no request in flight and exits 0") {
    test::TempDir dir;
    // Tiles are meshed on the DEM's own pixels, so a fine DEM (1025 x 1025 over one degree, about
    // 720 x 720 pixels per z8 tile) with two generation threads makes eight cold tiles take a
    // while: every request is in flight before the first ones are done. They all wait their
    // turn (start_wait_ms), as this is about shutdown, not shedding load.
    test::write_dem(dir / "hills.asc", 1025);
    const std::string config = dir / "serve.json";
    test::write_file(config, R"({
      "server": {"threads": 2, "log_level": "info", "start_wait_ms": 600000},
      "layers": [{"name": "hills", "sources": ["hills.asc"], "tile_size": 512, "min_zoom": 5,
                  "max_zoom": 8, "eps_levels": [0.5, 1, 2, 4], "store": "tiles.sqlite"}]})");
    Child child;
    const int port = start_server(child, {config}, dir / "serve.log");

    httplib::Client probe("127.0.0.1", port);
    auto layers = probe.Get("/layers");
    REQUIRE(layers);
    REQUIRE(layers->status == 200);

    // Eight distinct cold tiles: the four eps levels of two tiles.
    const std::string tile_a = "/hills/8/272/210";
    const std::string tile_b = "/hills/8/271/209";
    std::vector<std::string> urls;
    for (int k = 0; k < 4; ++k) {
        urls.push_back(tile_a + ".glb?eps=" + std::to_string(k));
        urls.push_back(tile_b + ".glb?eps=" + std::to_string(k));
    }
    std::mutex mutex;
    std::vector<int> statuses(urls.size(), 0);
    std::vector<std::size_t> sizes(urls.size(), 0);
    std::vector<std::thread> threads;
    for (std::size_t i = 0; i < urls.size(); ++i) {
        threads.emplace_back([&, i] {
            httplib::Client c("127.0.0.1", port);
            c.set_read_timeout(120);
            auto res = c.Get(urls[i]);
            std::lock_guard<std::mutex> lock(mutex);
            statuses[i] = res ? res->status : -1;
            sizes[i] = res ? res->body.size() : 0;
        });
    }
    // Wait until every request is inside the server (the metrics request itself is one more).
    double in_flight = 0;
    for (int i = 0; i < 500 && in_flight < static_cast<double>(urls.size()) + 1; ++i) {
        in_flight = test::metric(port, "tb_http_in_flight_requests");
        usleep(20000);
    }
    const double generated_before = test::metric(port, "tb_tiles_generated_total");
    MESSAGE("at SIGTERM: " << in_flight - 1 << " requests in flight, " << generated_before << " of "
                           << urls.size() << " tiles generated");
    CHECK(in_flight - 1 == static_cast<double>(urls.size()));
    CHECK(generated_before < static_cast<double>(urls.size()));
    REQUIRE(kill(child.pid, SIGTERM) == 0);
    for (auto& t : threads) {
        t.join();
    }
    const int code = child.wait_exit();
    const std::string log = test::read_file(dir / "serve.log");
    INFO(log);
    CHECK(code == 0);
    for (std::size_t i = 0; i < urls.size(); ++i) {
        INFO(urls[i]);
        CHECK(statuses[i] == 200);
        CHECK(sizes[i] > 0);
    }
    CHECK(log.find("received SIGTERM") != std::string::npos);
    CHECK(log.find("stopped") != std::string::npos);

    // The store was closed cleanly and holds every tile that was served.
    auto store = tiler::TileStore::open(dir / "tiles.sqlite");
    for (int k = 0; k < 4; ++k) {
        CHECK(store->contains({"hills", {8, 272, 210}, tiler::Format::Glb, k}));
        CHECK(store->contains({"hills", {8, 271, 209}, tiler::Format::Glb, k}));
    }
    // And nothing listens any more.
    httplib::Client after("127.0.0.1", port);
    after.set_connection_timeout(1);
    CHECK(!after.Get("/health"));
}

TEST_CASE("terrabound serve DEM... makes one layer per file, and --store keeps its tiles") {
    test::TempDir dir;
    test::fs::create_directories(dir.path / "a");
    test::fs::create_directories(dir.path / "b");
    test::write_dem(dir / "a/my hills (v2).asc", 65);
    test::write_dem(dir / "a/ridge.asc", 65, 12, 57);
    test::write_dem(dir / "b/ridge.asc", 65, 13, 57);
    Child child;
    const int port = start_server(child,
                                  {dir / "a/my hills (v2).asc",
                                   dir / "a/ridge.asc",
                                   dir / "b/ridge.asc",
                                   "--store",
                                   dir / "tiles"},
                                  dir / "serve.log");
    httplib::Client c("127.0.0.1", port);
    auto layers = c.Get("/layers");
    REQUIRE(layers);
    REQUIRE(layers->status == 200);
    const auto j = nlohmann::json::parse(layers->body);
    REQUIRE(j["layers"].size() == 3);
    CHECK(j["layers"][0]["name"] == "my_hills_v2");
    CHECK(j["layers"][1]["name"] == "ridge");
    CHECK(j["layers"][2]["name"] == "ridge_2");
    CHECK(j["layers"][2]["stored"] == true);

    const int z = j["layers"][1]["max_zoom"];
    const auto r = j["layers"][1]["bounds"];
    // The tile holding the DEM's centre, geodetic: 180 / 2^z degrees, y from the south.
    const double size = 180.0 / std::ldexp(1.0, z);
    const auto x = static_cast<long long>((12.5 + 180) / size);
    const auto y = static_cast<long long>((57.5 + 90) / size);
    CHECK(r["west"].get<double>() < 12.5);
    const std::string url =
        "/ridge/" + std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y) + ".glb";
    auto tile = c.Get(url);
    REQUIRE(tile);
    CHECK(tile->status == 200);
    REQUIRE(kill(child.pid, SIGTERM) == 0);
    CHECK(child.wait_exit() == 0);
    const std::string stored = test::read_file(dir / ("tiles" + url));
    CHECK(stored == tile->body);
}

TEST_CASE("terrabound serve with a missing DEM exits 2 naming it") {
    test::TempDir dir;
    const std::string missing = dir / "nope.hgt";
    CHECK(run_to_exit({"serve", missing}, dir / "log") == 2);
    const std::string log = test::read_file(dir / "log");
    INFO(log);
    CHECK(log.find(missing) != std::string::npos);
    CHECK(log.find("serving") == std::string::npos);
}

TEST_CASE("terrabound serve replaces its own stored tiles when the eps changes, and refuses a "
          "built store made with another eps") {
    test::TempDir dir;
    test::write_dem(dir / "hills.asc", 129);
    const auto config = [&](const std::string& name, double eps, const std::string& store) {
        const std::string path = dir / name;
        test::write_file(path,
                         R"({"layers": [{"name": "hills", "sources": ["hills.asc"], "tile_size": 64,
                              "min_zoom": 6, "max_zoom": 7, "finest_eps": )" +
                             std::to_string(eps) + R"(, "store": ")" + store + R"("}]})");
        return path;
    };
    const std::string url = "/hills/7/136/104.glb"; // the tile holding 11.5 E, 57.5 N
    const auto serve_once = [&](const std::string& cfg, const std::string& log) {
        Child child;
        const int port = start_server(child, {cfg}, log);
        httplib::Client c("127.0.0.1", port);
        auto tile = c.Get(url);
        REQUIRE(tile);
        REQUIRE(tile->status == 200);
        REQUIRE(kill(child.pid, SIGTERM) == 0);
        CHECK(child.wait_exit() == 0);
        return tile->body;
    };

    const std::string first = serve_once(config("fine.json", 1, "tiles"), dir / "fine.log");
    CHECK(test::read_file(dir / "tiles" + url) == first);
    const std::string second = serve_once(config("coarse.json", 40, "tiles"), dir / "coarse.log");
    const std::string log = test::read_file(dir / "coarse.log");
    INFO(log);
    // Zoom 6's eps follows the hills' reach (a quarter of it) where that beats the ladder's 2.
    CHECK(log.find("holds tiles made with other settings (eps was [") != std::string::npos);
    CHECK(log.find(", 1], now [80, 40]); removing them") != std::string::npos);
    CHECK(second != first);
    CHECK(test::read_file(dir / "tiles" + url) == second);

    // A store `terrabound build` made at eps 1 is not served at eps 40.
    REQUIRE(run_to_exit({"build",
                         dir / "hills.asc",
                         "-o",
                         dir / "built.sqlite",
                         "--layer",
                         "hills",
                         "--size",
                         "64",
                         "--min-zoom",
                         "6",
                         "--max-zoom",
                         "7",
                         "--eps-finest",
                         "1",
                         "--formats",
                         "glb"},
                        dir / "build.log") == 0);
    CHECK(run_to_exit({"serve", config("coarse.json", 40, "built.sqlite"), "--port", "0"},
                      dir / "refused.log") == 2);
    const std::string why = test::read_file(dir / "refused.log");
    INFO(why);
    CHECK(why.find("its tiles were made by terrabound build with other settings (eps was [") !=
          std::string::npos);
    CHECK(why.find(", 1], now [80, 40])") != std::string::npos);
    CHECK(why.find("serving") == std::string::npos);
}
