// Cold work under load: a tile request whose generation cannot start within the bounded wait
// (TileServiceOptions::start_wait) gets 503 with Retry-After at once, instead of waiting for
// the whole queue before it; /health and cached tiles never wait behind cold work.
#include "config/config.hpp"
#include "core/error.hpp"
#include "server_fixture.hpp"
#include "tiler/layer.hpp"

#include <doctest/doctest.h>

#include <mutex>

namespace {

using namespace tb;
using test::RunningServer;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
    return std::chrono::duration<double>(Clock::now() - start).count();
}

// A DEM fine enough (1025 x 1025 over one degree, 512-sample tiles) that each cold tile takes
// a while, with four eps levels: 2 tiles x 2 formats x 5 eps are 20 distinct cold tiles.
struct SlowLayer {
    test::TempDir dir;
    std::shared_ptr<const tiler::Layer> layer;
    SlowLayer() {
        log::set_level(log::Level::Warn);
        test::write_dem(dir / "fine.asc", 1025);
        tiler::LayerOptions o = test::test_layer_options(dir / "fine.asc", "fine");
        o.tile_size = 512;
        o.eps_levels = {0.5, 1, 2, 4};
        layer = tiler::Layer::open(o);
    }
};

} // namespace

TEST_CASE("tile requests that cannot start generating within the wait get 503 at once") {
    SlowLayer f;
    const auto r = f.layer->tiles_at(f.layer->max_zoom());
    REQUIRE(r.count() >= 2);
    std::vector<std::string> urls;
    for (std::int64_t x = r.x0; x < r.x0 + 2; ++x) {
        for (const char* ext : {"glb", "drc"}) {
            for (const char* eps : {"", "?eps=0", "?eps=1", "?eps=2", "?eps=3"}) {
                urls.push_back("/fine/" + std::to_string(r.z) + "/" + std::to_string(x) + "/" +
                               std::to_string(r.y0) + "." + ext + eps);
            }
        }
    }
    server::TileServiceOptions options;
    options.threads = 1;
    options.queue_limit = 64; // the queue alone would take them all, one after the other
    options.start_wait = std::chrono::milliseconds(300);
    server::HttpOptions http;
    http.http_threads = 32;
    RunningServer s({{f.layer, {tiler::Format::Glb, tiler::Format::Drc}, nullptr}}, options, http);

    // Warm one tile first: it must come from the cache however busy the server is.
    const std::string warm = "/fine/" + std::to_string(r.z) + "/" + std::to_string(r.x0) + "/" +
                             std::to_string(r.y0) + ".glb";
    const auto warm_start = Clock::now();
    REQUIRE(s.client().Get(warm)->status == 200);
    const double one_tile = seconds_since(warm_start);
    MESSAGE("one cold tile: " << one_tile << " s");

    std::mutex mutex;
    int ok = 0, busy = 0, other = 0;
    double slowest_busy = 0, slowest_health = 0, slowest_cached = 0;
    bool retry_after = true;
    std::vector<std::thread> threads;
    const auto start = Clock::now();
    for (const auto& url : urls) {
        threads.emplace_back([&, url] {
            const auto t0 = Clock::now();
            auto res = s.client().Get(url);
            const double took = seconds_since(t0);
            std::lock_guard<std::mutex> lock(mutex);
            if (res && res->status == 200) {
                ++ok;
            } else if (res && res->status == 503) {
                ++busy;
                slowest_busy = std::max(slowest_busy, took);
                retry_after = retry_after && res->get_header_value("Retry-After") == "1";
            } else {
                ++other;
            }
        });
    }
    // Meanwhile /health and the warm tile answer at once.
    for (int i = 0; i < 10; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        for (const char* url : {"/health", warm.c_str()}) {
            const auto t0 = Clock::now();
            auto res = s.client().Get(url);
            REQUIRE(res);
            CHECK(res->status == 200);
            double& slowest = url == std::string("/health") ? slowest_health : slowest_cached;
            slowest = std::max(slowest, seconds_since(t0));
        }
    }
    for (auto& t : threads) {
        t.join();
    }
    const double all = seconds_since(start);
    MESSAGE(ok << " ok, " << busy << " busy (slowest " << slowest_busy << " s) of " << urls.size()
               << " in " << all << " s; /health at most " << slowest_health
               << " s, a cached tile at most " << slowest_cached << " s");
    CHECK(other == 0);
    CHECK(ok >= 1);
    CHECK(busy >= 1);
    CHECK(retry_after);
    // A refused request waited about start_wait, not for the tiles queued before it.
    CHECK(slowest_busy < 0.3 + 1.0);
    CHECK(slowest_health < 0.5);
    CHECK(slowest_cached < 0.5);
    // The cancelled generations were dropped: nothing is left running or queued.
    for (int i = 0; i < 600 && test::metric(s.port, "tb_generations_in_flight") != 0; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    CHECK(test::metric(s.port, "tb_generations_queued") == 0);
    CHECK(test::metric(s.port, "tb_tiles_generated_total") <= 1 + ok + 1);
}

TEST_CASE("the config's server.start_wait_ms is 1..600000, 10000 by default") {
    const std::string layers = R"(, "layers": [{"name": "a", "sources": ["/vsimem/x.tif"]}]})";
    CHECK(config::parse_config(R"({"server": {})" + layers, "c.json").server.start_wait_ms == 10000);
    CHECK(config::parse_config(R"({"server": {"start_wait_ms": 250})" + layers, "c.json")
              .server.start_wait_ms == 250);
    CHECK_THROWS_AS(config::parse_config(R"({"server": {"start_wait_ms": 0})" + layers, "c.json"),
                    InputError);
}
