// Request deadlines (TileServiceOptions::deadline): a tile not ready by its request's deadline
// is answered 503 with Retry-After then, and a generation every request has given up on stops
// at its next checkpoint (tiler::CancelFn); one a follower still waits for goes on. Generation
// is made slow by a layer that sleeps before meshing: a real delay in front of the real tile.
#include "config/config.hpp"
#include "config_util.hpp"
#include "core/error.hpp"
#include "server_fixture.hpp"
#include "tiler/layer.hpp"

#include <doctest/doctest.h>

#include <atomic>
#include <future>

namespace {

using namespace tb;
using test::RunningServer;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
    return std::chrono::duration<double>(Clock::now() - start).count();
}

// A layer that sleeps `delay_ms` before each make_tile, then makes the real tile with the
// caller's CancelFn: the tile's checkpoints see a cancel that came during the sleep. Counts
// the tiles the inner layer stopped with Cancelled.
class DelayedLayer final : public tiler::Layer {
public:
    explicit DelayedLayer(std::shared_ptr<const tiler::Layer> inner) : inner_(std::move(inner)) {}

    mutable std::atomic<int> delay_ms{0};
    mutable std::atomic<int> cancelled{0};

    std::string make_tile(const tiler::ValidTile& tile,
                          tiler::Format format,
                          tiler::EpsChoice eps,
                          const tiler::CancelFn& cancel) const override {
        std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms.load()));
        try {
            return inner_->make_tile(tile, format, eps, cancel);
        } catch (const tiler::Cancelled&) {
            ++cancelled;
            throw;
        }
    }

    const tiler::LayerOptions& options() const override { return inner_->options(); }
    void prepare() const override { inner_->prepare(); }
    int min_zoom() const override { return inner_->min_zoom(); }
    int max_zoom() const override { return inner_->max_zoom(); }
    double eps_for_zoom(int z) const override { return inner_->eps_for_zoom(z); }
    double terrain_eps_for_zoom(int z) const override { return inner_->terrain_eps_for_zoom(z); }
    tiler::LonLatBox data_bounds() const override { return inner_->data_bounds(); }
    const tiler::TileCover& data_cover_at(int z) const override { return inner_->data_cover_at(z); }
    tiler::TileRange tiles_at(int z) const override { return inner_->tiles_at(z); }
    std::int64_t tile_count_at(int z) const override { return inner_->tile_count_at(z); }
    bool may_have_tile(const tiler::ValidTile& tile) const override {
        return inner_->may_have_tile(tile);
    }
    bool document(const std::string& path, std::string& out) const override {
        return inner_->document(path, out);
    }
    std::vector<std::pair<tiler::Format, std::string>>
    make_tiles(const tiler::ValidTile& tile,
               std::span<const tiler::Format> formats) const override {
        return inner_->make_tiles(tile, formats);
    }
    tiler::TileRaster make_raster(const tiler::ValidTile& tile) const override {
        return inner_->make_raster(tile);
    }
    tiler::TileRaster make_terrain_raster(const tiler::ValidTile& tile) const override {
        return inner_->make_terrain_raster(tile);
    }
    std::string
    make_tile_at(const tiler::ValidTile& tile, tiler::Format format, double eps) const override {
        return inner_->make_tile_at(tile, format, eps);
    }
    tiler::MeshedTile mesh_tile_at(const tiler::ValidTile& tile, double eps) const override {
        return inner_->mesh_tile_at(tile, eps);
    }
    tiler::Guarantee guarantee() const override { return inner_->guarantee(); }
    tiler::ZoomSource zoom_source(int z) const override { return inner_->zoom_source(z); }
    double tile_error(const tiler::ValidTile& tile) const override {
        return inner_->tile_error(tile);
    }
    std::size_t tiles_over_eps() const override { return inner_->tiles_over_eps(); }
    std::string zoom_signature(int z) const override { return inner_->zoom_signature(z); }
    double min_height() const override { return inner_->min_height(); }
    double max_height() const override { return inner_->max_height(); }
    tiler::VerticalDatum source_datum() const override { return inner_->source_datum(); }
    const tiler::DemSource& source() const override { return inner_->source(); }
    tiler::LatticeBlock sample(tiler::Scheme scheme,
                               int z,
                               int size,
                               std::int64_t column0,
                               std::int64_t row0,
                               int width,
                               int height) const override {
        return inner_->sample(scheme, z, size, column0, row0, width, height);
    }

private:
    std::shared_ptr<const tiler::Layer> inner_;
};

// The hills layer behind a DelayedLayer, served as glb and terrain on one generation thread,
// with a deadline of `deadline_ms`; `warm` is a glb tile already in the memory cache.
struct SlowServer {
    test::HillsLayer hills;
    std::shared_ptr<DelayedLayer> layer = std::make_shared<DelayedLayer>(hills.layer);
    std::unique_ptr<RunningServer> server;
    std::string warm;
    tiler::TileId slow; // beside the warm tile, with data too

    explicit SlowServer(int deadline_ms) {
        server::TileServiceOptions options;
        options.threads = 1;
        options.deadline = std::chrono::milliseconds(deadline_ms);
        server = std::make_unique<RunningServer>(
            std::vector<server::ServedLayer>{
                {layer, {tiler::Format::Glb, tiler::Format::Terrain}, nullptr}},
            options);
        warm = url(hills.inside, "glb");
        slow = {hills.inside.z, hills.inside.x + 1, hills.inside.y};
        REQUIRE(hills.layer->may_have_tile(hills.layer->tile(slow)));
        const auto res = server->client().Get(warm);
        REQUIRE(res);
        REQUIRE(res->status == 200);
    }

    std::string url(const tiler::TileId& id, const std::string& ext) const {
        return "/hills/" + std::to_string(id.z) + "/" + std::to_string(id.x) + "/" +
               std::to_string(id.y) + "." + ext;
    }
    double metric(const std::string& name) const { return test::metric(server->port, name); }
    // Polls until `name` reaches `value` or ten seconds pass; its last value.
    double await_metric(const std::string& name, double value) const {
        double v = metric(name);
        for (int i = 0; i < 200 && v != value; ++i) {
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
            v = metric(name);
        }
        return v;
    }
};

struct Answer {
    int status = 0;
    std::string retry_after;
    double seconds = 0;
};

Answer get(const RunningServer& s, const std::string& url) {
    const auto t0 = Clock::now();
    auto res = s.client().Get(url);
    Answer a;
    a.seconds = seconds_since(t0);
    if (res) {
        a.status = res->status;
        a.retry_after = res->get_header_value("Retry-After");
    }
    return a;
}

} // namespace

TEST_CASE("a tile not ready by its deadline gets 503 then, and its generation stops unfinished") {
    SlowServer s(300);
    s.layer->delay_ms = 2000;
    const tiler::TileId slow = s.slow;
    for (const std::string ext : {"glb", "terrain"}) {
        CAPTURE(ext);
        const double cancelled_before = s.metric("tb_generations_cancelled_total");
        auto pending =
            std::async(std::launch::async, [&] { return get(*s.server, s.url(slow, ext)); });
        // Meanwhile /health and the cached tile answer at once: they never wait behind cold work.
        double slowest = 0;
        for (int i = 0; i < 10; ++i) {
            std::this_thread::sleep_for(std::chrono::milliseconds(30));
            for (const std::string& url : {std::string("/health"), s.warm}) {
                const Answer a = get(*s.server, url);
                CHECK(a.status == 200);
                slowest = std::max(slowest, a.seconds);
            }
        }
        const Answer a = pending.get();
        MESSAGE(ext << ": 503 after " << a.seconds << " s; /health and the cached tile at most "
                    << slowest << " s");
        CHECK(a.status == 503);
        CHECK(a.retry_after == "1");
        CHECK(a.seconds >= 0.3);
        CHECK(a.seconds < 1.5); // at the deadline, not when the 2 s generation would be done
        CHECK(slowest < 0.5);
        // Nobody waits for it any more: it stops at the checkpoint after the delay.
        CHECK(s.await_metric("tb_generations_cancelled_total", cancelled_before + 1) ==
              cancelled_before + 1);
    }
    CHECK(s.layer->cancelled == 2);
    CHECK(s.metric("tb_deadline_expiries_total") == 2);
    CHECK(s.metric("tb_tiles_generated_total") == 1); // the warm tile alone
    CHECK(s.metric("tb_generations_in_flight") == 0);
    // The next request for the tile starts afresh rather than joining the cancelled generation.
    s.layer->delay_ms = 0;
    CHECK(get(*s.server, s.url(slow, "glb")).status == 200);
    CHECK(s.metric("tb_tiles_generated_total") == 2);
}

TEST_CASE("a generation goes on while a follower waits, though its first request gave up") {
    SlowServer s(2000);
    s.layer->delay_ms = 3000;
    const std::string url = s.url(s.slow, "glb");
    auto first = std::async(std::launch::async, [&] { return get(*s.server, url); });
    std::this_thread::sleep_for(std::chrono::milliseconds(1500));
    // Its deadline is 3.5 s after the first request's start: after the generation is done.
    auto follower = std::async(std::launch::async, [&] { return get(*s.server, url); });
    const Answer a = first.get();
    const Answer b = follower.get();
    MESSAGE("first: " << a.status << " after " << a.seconds << " s; follower: " << b.status
                      << " after " << b.seconds << " s");
    CHECK(a.status == 503);
    CHECK(a.retry_after == "1");
    CHECK(b.status == 200);
    CHECK(s.metric("tb_single_flight_waits_total") == 1);
    CHECK(s.metric("tb_generations_cancelled_total") == 0);
    CHECK(s.metric("tb_tiles_generated_total") == 2);
    CHECK(s.layer->cancelled == 0);
}

TEST_CASE("a request that waited for a generation to start has no more than its deadline") {
    // start_wait longer than the deadline: the wait for a start is cut to the deadline, and the
    // generation queued behind the slow one is dropped unstarted, not cancelled.
    test::HillsLayer hills;
    auto layer = std::make_shared<DelayedLayer>(hills.layer);
    layer->delay_ms = 1500;
    server::TileServiceOptions options;
    options.threads = 1;
    options.start_wait = std::chrono::milliseconds(60000);
    options.deadline = std::chrono::milliseconds(400);
    REQUIRE(hills.layer->may_have_tile(
        hills.layer->tile({hills.inside.z, hills.inside.x + 1, hills.inside.y})));
    RunningServer s({{layer, {tiler::Format::Glb}, nullptr}}, options);
    const auto url = [&](std::int64_t dx) {
        return "/hills/" + std::to_string(hills.inside.z) + "/" +
               std::to_string(hills.inside.x + dx) + "/" + std::to_string(hills.inside.y) + ".glb";
    };
    auto running = std::async(std::launch::async, [&] { return get(s, url(0)); });
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const Answer queued = get(s, url(1));
    const Answer first = running.get();
    CHECK(first.status == 503);
    CHECK(queued.status == 503);
    CHECK(queued.retry_after == "1");
    CHECK(queued.seconds < 1.2); // about the 0.4 s deadline, not start_wait's minute
    CHECK(test::metric(s.port, "tb_deadline_expiries_total") == 1); // the running one
    CHECK(test::metric(s.port, "tb_queue_rejections_total") == 1);  // the one never started
    for (int i = 0; i < 100 && test::metric(s.port, "tb_generations_cancelled_total") != 1; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    CHECK(test::metric(s.port, "tb_generations_cancelled_total") == 1);
    CHECK(test::metric(s.port, "tb_tiles_generated_total") == 0);
}

TEST_CASE(
    "the config's server.deadline_ms is 1..600000, 10000 by default, and holds start_wait_ms") {
    const std::string layers = R"(, "layers": [{"name": "a", "sources": ["/vsimem/x.tif"]}]})";
    const auto server = [&](const std::string& fields) {
        return config::parse_config(R"({"server": {)" + fields + "}" + layers, "c.json").server;
    };
    CHECK(server("").deadline_ms == 10000);
    CHECK(server(R"("deadline_ms": 250)").deadline_ms == 250);
    // With the deadline alone, the default start wait (10 s) is shortened to it.
    CHECK(server(R"("deadline_ms": 250)").start_wait_ms == 250);
    CHECK(server(R"("deadline_ms": 30000)").start_wait_ms == 10000);
    CHECK(server(R"("deadline_ms": 3000, "start_wait_ms": 1000)").start_wait_ms == 1000);
    CHECK(server(R"("deadline_ms": 3000, "start_wait_ms": 3000)").start_wait_ms == 3000);
    for (const char* bad : {"0", "600001", "1.5", "\"10\""}) {
        CAPTURE(bad);
        const std::string e = test::config_error(
            R"({"server": {"deadline_ms": )" + std::string(bad) + "}" + layers, "c.json");
        CHECK(e.find("c.json: /server/deadline_ms: expected ") == 0);
    }
    CHECK(test::config_error(R"({"server": {"deadline_ms": 2000, "start_wait_ms": 5000})" + layers,
                             "c.json") ==
          "c.json: /server/start_wait_ms: expected at most deadline_ms (2000), got 5000: a "
          "request waits for its tile to start within its deadline; lower start_wait_ms or "
          "raise deadline_ms");
}

TEST_CASE("serve --deadline-ms takes 1..600000 and names the flag otherwise") {
    test::TempDir dir;
    test::write_dem(dir / "d.asc", 33);
    for (const char* bad : {"0", "600001", "x"}) {
        CAPTURE(bad);
        std::string output;
        const int code = test::run_command(std::string(TB_BINARY) + " serve " + (dir / "d.asc") +
                                               " --port 0 --deadline-ms " + bad,
                                           output);
        CHECK(code == 2);
        CHECK(output.find("terrabound: --deadline-ms: ") != std::string::npos);
    }
}
