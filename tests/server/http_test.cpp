// The HTTP server over real loopback connections: routes, caching headers, stores,
// single-flight generation, hostile URLs.
#include "core/error.hpp"
#include "server_fixture.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"
#include "tiler/stores/store.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <mutex>
#include <set>

namespace {

using namespace tb;
using test::RunningServer;
using test::TempDir;

// One DEM and its layer, shared by the tests of this file (opening a layer reads the DEM).
struct Fixture : test::HillsLayer {
    tiler::TileId outside; // a valid tile of the scheme with no data

    Fixture() {
        const auto r = layer->tiles_at(layer->max_zoom());
        outside = {layer->max_zoom(), r.x1 + 5, r.y0};
    }
    server::ServedLayer served(std::shared_ptr<tiler::TileStore> store = nullptr) const {
        return {layer, {tiler::Format::Glb, tiler::Format::Drc}, std::move(store)};
    }
};

Fixture& fixture() {
    static Fixture f;
    return f;
}

std::string tile_url(const tiler::TileId& id, const char* ext = "glb") {
    return "/hills/" + std::to_string(id.z) + "/" + std::to_string(id.x) + "/" +
           std::to_string(id.y) + "." + ext;
}

} // namespace

TEST_CASE("every route answers with its content type, CORS and cache headers") {
    auto& f = fixture();
    RunningServer s({f.served()});
    auto c = s.client();

    auto health = c.Get("/health");
    REQUIRE(health);
    CHECK(health->status == 200);
    CHECK(health->body == "{\"status\":\"ok\"}\n");

    auto landing = c.Get("/");
    REQUIRE(landing);
    CHECK(landing->status == 200);
    CHECK(landing->get_header_value("Content-Type") == "text/html; charset=utf-8");
    CHECK(landing->body.find("href=\"/hills/tileset.json\"") != std::string::npos);
    CHECK(landing->body.find(".glb\"") != std::string::npos);

    auto layers = c.Get("/layers");
    REQUIRE(layers);
    CHECK(layers->status == 200);
    CHECK(layers->get_header_value("Content-Type") == "application/json");
    const auto j = nlohmann::json::parse(layers->body);
    REQUIRE(j["layers"].size() == 1);
    CHECK(j["layers"][0]["name"] == "hills");
    CHECK(j["layers"][0]["min_zoom"] == 5);
    CHECK(j["layers"][0]["max_zoom"] == 8);
    CHECK(j["layers"][0]["eps_levels"] == nlohmann::json::array({5.0, 20.0}));
    CHECK(j["layers"][0]["tileset"] == "/hills/tileset.json");

    auto tileset = c.Get("/hills/tileset.json");
    REQUIRE(tileset);
    CHECK(tileset->status == 200);
    CHECK(tileset->get_header_value("Content-Type") == "application/json");
    CHECK(tileset->get_header_value("Cache-Control") == "public, max-age=60");
    const auto ts = nlohmann::json::parse(tileset->body);
    CHECK(ts["asset"]["version"] == "1.1");
    std::string expected_tileset;
    REQUIRE(f.layer->document("tileset.json", expected_tileset));
    CHECK(tileset->body == expected_tileset);

    auto glb = c.Get(tile_url(f.inside));
    REQUIRE(glb);
    CHECK(glb->status == 200);
    CHECK(glb->get_header_value("Content-Type") == "model/gltf-binary");
    CHECK(glb->get_header_value("Cache-Control") == "public, max-age=604800");
    CHECK(glb->get_header_value("Access-Control-Allow-Origin") == "*");
    CHECK(!glb->has_header("Content-Encoding")); // binary tiles are never re-compressed
    REQUIRE(glb->body.size() > 12);
    CHECK(glb->body.substr(0, 4) == "glTF");
    CHECK(glb->body == f.layer->make_tile(f.layer->tile(f.inside), tiler::Format::Glb));

    auto drc = c.Get(tile_url(f.inside, "drc"));
    REQUIRE(drc);
    CHECK(drc->status == 200);
    CHECK(drc->get_header_value("Content-Type") == "application/octet-stream");
    CHECK(drc->body.substr(0, 5) == "DRACO");

    auto eps = c.Get(tile_url(f.inside) + "?eps=1");
    REQUIRE(eps);
    CHECK(eps->status == 200);
    CHECK(eps->body ==
          f.layer->make_tile(f.layer->tile(f.inside), tiler::Format::Glb, tiler::EpsChoice{1}));
    CHECK(eps->body != glb->body);

    auto head = c.Head(tile_url(f.inside));
    REQUIRE(head);
    CHECK(head->status == 200);
    CHECK(head->body.empty());
    CHECK(head->get_header_value("Content-Length") == std::to_string(glb->body.size()));
    CHECK(head->get_header_value("ETag") == glb->get_header_value("ETag"));

    auto head_tileset = c.Head("/hills/tileset.json");
    REQUIRE(head_tileset);
    CHECK(head_tileset->status == 200);

    httplib::Headers preflight_headers = {{"Origin", "https://viewer.example"},
                                          {"Access-Control-Request-Method", "GET"},
                                          {"Access-Control-Request-Headers", "if-none-match"}};
    auto preflight = c.Options(tile_url(f.inside), preflight_headers);
    REQUIRE(preflight);
    CHECK(preflight->status == 204);
    CHECK(preflight->get_header_value("Access-Control-Allow-Origin") == "*");
    CHECK(preflight->get_header_value("Access-Control-Allow-Methods") == "GET, HEAD, OPTIONS");
    CHECK(preflight->get_header_value("Access-Control-Allow-Headers") == "if-none-match");

    auto metrics = c.Get("/metrics");
    REQUIRE(metrics);
    CHECK(metrics->status == 200);
    CHECK(metrics->body.find("tb_http_requests_total{route=\"tile\",status=\"200\"} 4") !=
          std::string::npos);
    CHECK(
        metrics->body.find("tb_http_request_duration_seconds_bucket{route=\"tile\",le=\"+Inf\"}") !=
        std::string::npos);
    CHECK(test::metric(metrics->body, "tb_tiles_generated_total") == 3);
    CHECK(test::metric(metrics->body, "tb_cache_hits_total") >= 2);
}

TEST_CASE("JSON is gzipped when the client accepts it, tiles are not") {
    auto& f = fixture();
    RunningServer s({f.served()});
    auto c = s.client();
    c.set_decompress(false);
    const httplib::Headers gzip = {{"Accept-Encoding", "gzip"}};
    auto tileset = c.Get("/hills/tileset.json", gzip);
    REQUIRE(tileset);
    CHECK(tileset->status == 200);
    CHECK(tileset->get_header_value("Content-Encoding") == "gzip");
    CHECK(tileset->body.substr(0, 2) == std::string("\x1f\x8b"));
    auto plain = c.Get("/hills/tileset.json");
    REQUIRE(plain);
    CHECK(!plain->has_header("Content-Encoding"));
    CHECK(plain->body.front() == '{');
    auto tile = c.Get(tile_url(f.inside), gzip);
    REQUIRE(tile);
    CHECK(tile->status == 200);
    CHECK(!tile->has_header("Content-Encoding"));
    CHECK(tile->body.substr(0, 4) == "glTF");
}

TEST_CASE("a matching If-None-Match gets 304 with no body, a stale one the tile") {
    auto& f = fixture();
    RunningServer s({f.served()});
    auto c = s.client();
    for (const std::string& url : {tile_url(f.inside), std::string("/hills/tileset.json")}) {
        INFO(url);
        auto first = c.Get(url);
        REQUIRE(first);
        REQUIRE(first->status == 200);
        const std::string etag = first->get_header_value("ETag");
        CHECK(etag.size() > 2);
        CHECK(etag.front() == '"'); // strong
        CHECK(etag == server::make_etag(first->body));

        auto again = c.Get(url, {{"If-None-Match", etag}});
        REQUIRE(again);
        CHECK(again->status == 304);
        CHECK(again->body.empty());
        CHECK(again->get_header_value("ETag") == etag);

        auto listed = c.Get(url, {{"If-None-Match", "\"other\", " + etag}});
        REQUIRE(listed);
        CHECK(listed->status == 304);

        auto stale = c.Get(url, {{"If-None-Match", "\"0000000000000000-0\""}});
        REQUIRE(stale);
        CHECK(stale->status == 200);
        CHECK(stale->body == first->body);
    }
}

TEST_CASE("a byte range gets 206 with that part, past the end 416, anything else the whole") {
    auto& f = fixture();
    RunningServer s({f.served()});
    auto c = s.client();
    const std::string url = tile_url(f.inside);
    auto whole = c.Get(url);
    REQUIRE(whole);
    REQUIRE(whole->status == 200);
    const std::string& body = whole->body;
    const std::string size = std::to_string(body.size());
    const std::string etag = whole->get_header_value("ETag");
    REQUIRE(body.size() > 40);
    struct Case {
        std::string range;
        std::size_t first, length;
    };
    for (const Case& k : {Case{"bytes=0-9", 0, 10},
                          Case{"bytes=-7", body.size() - 7, 7},
                          Case{"bytes=20-", 20, body.size() - 20},
                          Case{"bytes=5-99999999", 5, body.size() - 5},
                          Case{"BYTES=3-3", 3, 1}}) {
        INFO(k.range);
        auto part = c.Get(url, {{"Range", k.range}});
        REQUIRE(part);
        CHECK(part->status == 206);
        CHECK(part->body == body.substr(k.first, k.length));
        CHECK(part->get_header_value("Content-Range") ==
              "bytes " + std::to_string(k.first) + "-" + std::to_string(k.first + k.length - 1) +
                  "/" + size);
        CHECK(part->get_header_value("ETag") == etag);
    }
    // Starts past the end: 416 naming the length, with a JSON error.
    for (const std::string& range : {"bytes=" + size + "-", std::string("bytes=-0")}) {
        auto past = c.Get(url, {{"Range", range}});
        REQUIRE(past);
        CHECK(past->status == 416);
        CHECK(past->get_header_value("Content-Range") == "bytes */" + size);
        CHECK(past->get_header_value("Content-Type") == "application/json");
        CHECK(past->body.find("the range") != std::string::npos);
    }
    // Ignored, the whole tile as 200: several ranges, another unit, a stale If-Range.
    const std::vector<httplib::Headers> whole_cases = {
        {{"Range", "bytes=0-3,10-20"}},
        {{"Range", "items=0-3"}},
        {{"Range", "bytes=0-9"}, {"If-Range", "\"0000000000000000-0\""}},
    };
    for (const auto& headers : whole_cases) {
        auto got = c.Get(url, headers);
        REQUIRE(got);
        CHECK(got->status == 200);
        CHECK(got->body == body);
        CHECK(!got->has_header("Content-Range"));
    }
    // Two Range lines are no single range either; HEAD (RFC 9110 14.2: GET only) gets the
    // whole answer's headers.
    auto twice = c.Get(url, {{"Range", "bytes=0-1"}, {"Range", "bytes=2-3"}});
    REQUIRE(twice);
    CHECK(twice->status == 200);
    CHECK(twice->body == body);
    auto head = c.Head(url, {{"Range", "bytes=0-9"}});
    REQUIRE(head);
    CHECK(head->status == 200);
    CHECK(head->get_header_value("Content-Length") == size);
    CHECK(!head->has_header("Content-Range"));
    auto current = c.Get(url, {{"Range", "bytes=0-9"}, {"If-Range", etag}});
    REQUIRE(current);
    CHECK(current->status == 206);
    CHECK(current->body == body.substr(0, 10));
    // An error keeps its whole body, and a document its ranges too.
    auto error = c.Get(tile_url(f.outside), {{"Range", "bytes=0-3"}});
    REQUIRE(error);
    CHECK(error->status == 404);
    CHECK(!error->has_header("Content-Range"));
    CHECK(nlohmann::json::parse(error->body).contains("error"));
    auto doc = c.Get("/hills/tileset.json");
    REQUIRE(doc);
    auto doc_part = c.Get("/hills/tileset.json", {{"Range", "bytes=0-0"}});
    REQUIRE(doc_part);
    CHECK(doc_part->status == 206);
    CHECK(doc_part->body == doc->body.substr(0, 1));
    // A compressed document is sent whole: its codings share one ETag, so a range resumed
    // under another Accept-Encoding would splice two of them. Past the end too (no 416 that
    // claims a coding its error body does not have).
    for (const char* range : {"bytes=0-0", "bytes=99999999-"}) {
        INFO(std::string(range));
        test::KeepAliveConn raw(s.port);
        REQUIRE(raw.send_all("GET /hills/tileset.json HTTP/1.1\r\nHost: x\r\nAccept-Encoding: "
                             "gzip\r\nRange: " +
                             std::string(range) + "\r\n\r\n"));
        const std::string answer = raw.response(false);
        CHECK(answer.rfind("HTTP/1.1 200 ", 0) == 0);
        CHECK(answer.find("\r\nContent-Encoding: gzip\r\n") != std::string::npos);
        CHECK(answer.find("\r\nContent-Range:") == std::string::npos);
    }
}

TEST_CASE("on-demand, SQLite-store and directory-store tiles are the same bytes") {
    auto& f = fixture();
    const std::vector<std::pair<tiler::TileId, tiler::Format>> wanted = {
        {f.inside, tiler::Format::Glb},
        {f.inside, tiler::Format::Drc},
        {{f.inside.z - 1, f.inside.x / 2, f.inside.y / 2}, tiler::Format::Glb}};

    std::vector<std::string> on_demand;
    {
        RunningServer s({f.served()});
        auto c = s.client();
        for (const auto& [id, format] : wanted) {
            auto res = c.Get(tile_url(id, tiler::extension(format)));
            REQUIRE(res);
            REQUIRE(res->status == 200);
            on_demand.push_back(res->body);
        }
    }

    for (const std::string& name : {std::string("tiles.sqlite"), std::string("tiles-dir")}) {
        INFO(name);
        const std::string path = f.dir / name;
        {
            auto store = tiler::TileStore::open(path);
            for (std::size_t i = 0; i < wanted.size(); ++i) {
                store->put({"hills", wanted[i].first, wanted[i].second, -1}, on_demand[i]);
            }
        }
        std::shared_ptr<tiler::TileStore> store = tiler::TileStore::open(path);
        RunningServer s({f.served(store)});
        auto c = s.client();
        for (std::size_t i = 0; i < wanted.size(); ++i) {
            auto res = c.Get(tile_url(wanted[i].first, tiler::extension(wanted[i].second)));
            REQUIRE(res);
            CHECK(res->status == 200);
            CHECK(res->body == on_demand[i]);
        }
        const std::string m = c.Get("/metrics")->body;
        CHECK(test::metric(m, "tb_store_hits_total") == 3);
        CHECK(test::metric(m, "tb_tiles_generated_total") == 0);
    }
}

TEST_CASE("a generated tile is written to the layer's store") {
    auto& f = fixture();
    const std::string path = f.dir / "written.sqlite";
    std::string body;
    {
        std::shared_ptr<tiler::TileStore> store = tiler::TileStore::open(path);
        RunningServer s({f.served(store)});
        auto res = s.client().Get(tile_url(f.inside, "drc") + "?eps=0");
        REQUIRE(res);
        REQUIRE(res->status == 200);
        body = res->body;
        CHECK(test::metric(s.port, "tb_tiles_generated_total") == 1);
    }
    auto store = tiler::TileStore::open(path);
    const auto stored = store->get({"hills", f.inside, tiler::Format::Drc, 0});
    REQUIRE(stored);
    CHECK(*stored == body);
}

TEST_CASE("50 parallel requests for one missing tile generate it once") {
    auto& f = fixture();
    // Bigger tiles than the other tests, so the generation outlasts the burst of requests.
    auto options = test::test_layer_options(f.dir / "hills.asc", "hills");
    options.tile_size = 256;
    const server::ServedLayer slow{tiler::Layer::open(options), {tiler::Format::Glb}, nullptr};
    server::HttpOptions http;
    http.http_threads = 64;
    RunningServer s({slow}, {}, http);
    const std::string url = tile_url(f.inside, "glb");
    std::mutex mutex;
    std::set<std::string> bodies;
    int ok = 0;
    std::vector<std::thread> threads;
    for (int i = 0; i < 50; ++i) {
        threads.emplace_back([&] {
            auto c = s.client();
            auto res = c.Get(url);
            std::lock_guard<std::mutex> lock(mutex);
            if (res && res->status == 200) {
                ++ok;
                bodies.insert(res->body);
            }
        });
    }
    for (auto& t : threads) {
        t.join();
    }
    CHECK(ok == 50);
    CHECK(bodies.size() == 1);
    const std::string m = s.client().Get("/metrics")->body;
    CHECK(test::metric(m, "tb_tiles_generated_total") == 1);
    const double waits = test::metric(m, "tb_single_flight_waits_total");
    CHECK(test::metric(m, "tb_cache_hits_total") + waits == 49);
    CHECK(waits >= 1); // some requests really did wait for the running generation
    MESSAGE("requests that joined the running generation: " << waits);
}

TEST_CASE("hostile and malformed URLs get 4xx JSON errors and the server keeps serving") {
    auto& f = fixture();
    RunningServer s({f.served()});
    auto c = s.client();
    const std::string z = std::to_string(f.inside.z);
    const std::vector<std::pair<std::string, int>> cases = {
        {"/hills/../../../etc/passwd", 400},
        {"/hills/%2e%2e/%2e%2e/etc/passwd", 400},
        {"/hills/..%2f..%2fetc/passwd", 400},
        {"/hills/tileset.json%00.glb", 400},
        {"/hills/" + z + "/1%2f2/3.glb", 400},
        {"/hills/" + z + "/-1/3.glb", 400},
        {"/hills/-3/1/1.glb", 400},
        {"/hills/" + z + "/1/99999999999999999999.glb", 400},
        {"/hills/99/1/1.glb", 400},
        {"/hills/25/1/1.glb", 400},
        {"/hills/" + z + "/1000000/1.glb", 400}, // outside the scheme
        {"/hills/" + z + "/a/b.glb", 400},
        {"/hills/" + z + "/1.5/2.glb", 400},
        {"/hills/" + z + "//2.glb", 400},
        {"/hills//" + z + "/" + std::to_string(f.inside.x) + "//" + std::to_string(f.inside.y) +
             ".glb",
         200}, // repeated slashes are merged
        {"//hills//tileset.json", 200},
        {"/hills/tileset.json?from=a%2Fb", 200}, // an encoded '/' in the query is no separator
        {tile_url(f.inside) + "?eps=7", 400},
        {tile_url(f.inside) + "?eps=-1", 400},
        {tile_url(f.inside) + "?eps=fine", 400},
        {tile_url(f.outside), 404},
        {"/nope/" + z + "/1/1.glb", 404},
        {"/nope/tileset.json", 404},
        {"/hills/nothing.json", 404},
        {"/hills/" + z + "/1/1.png", 404},
        {"/", 200},
        {"/" + std::string(10 * 1024, 'a'), 414},
        {"/hills/" + std::string(3000, 'x') + ".glb", 414},
    };
    for (const auto& [url, status] : cases) {
        INFO(url.substr(0, 100));
        auto res = c.Get(url);
        REQUIRE(res);
        CHECK(res->status == status);
        if (status >= 400) {
            CHECK(res->get_header_value("Content-Type") == "application/json");
            CHECK(res->body.size() < 512);
            const auto j = nlohmann::json::parse(res->body, nullptr, false);
            CHECK((j.is_object() && j["error"].is_string()));
            CHECK(!res->has_header("EXCEPTION_WHAT"));
        }
        auto health = c.Get("/health");
        REQUIRE(health);
        CHECK(health->status == 200);
    }
    auto post = c.Post("/hills/tileset.json", "x", "text/plain");
    REQUIRE(post);
    CHECK(post->status == 405);

    // The raw request line, byte for byte, with no client-side normalisation.
    httplib::Client raw("127.0.0.1", s.port);
    auto nul = raw.Get("/hills/%00/x");
    REQUIRE(nul);
    CHECK(nul->status == 400);
}

TEST_CASE("a tile outside the scheme gets a 400 naming the tile and the scheme's ranges") {
    auto& f = fixture();
    RunningServer s({f.served()});
    auto c = s.client();
    const std::string z = std::to_string(f.inside.z);
    const std::int64_t columns = tiler::tiles_across(tiler::Scheme::Geodetic, f.inside.z);
    const std::int64_t rows = tiler::tiles_down(tiler::Scheme::Geodetic, f.inside.z);
    const std::string ranges = "at zoom " + z + ", x is 0.." + std::to_string(columns - 1) +
                               " and y is 0.." + std::to_string(rows - 1);
    const std::vector<std::pair<std::string, std::string>> cases = {
        {"/hills/25/1/1.glb",
         "tile 25/1/1 is outside the geodetic scheme: zoom 25 is outside 0..24"},
        {"/hills/99/0/0.drc",
         "tile 99/0/0 is outside the geodetic scheme: zoom 99 is outside 0..24"},
        {"/hills/" + z + "/" + std::to_string(columns) + "/0.glb",
         "tile " + z + "/" + std::to_string(columns) +
             "/0 is outside the geodetic scheme: " + ranges},
        {"/hills/" + z + "/0/" + std::to_string(rows) + ".glb",
         "tile " + z + "/0/" + std::to_string(rows) + " is outside the geodetic scheme: " + ranges},
    };
    // Twice: the second request may take the connection loop's quick path first, which finds
    // nothing cached for such an id and leaves it to the route.
    for (int pass = 0; pass < 2; ++pass) {
        for (const auto& [url, message] : cases) {
            INFO(url);
            auto res = c.Get(url);
            REQUIRE(res);
            CHECK(res->status == 400);
            const auto j = nlohmann::json::parse(res->body, nullptr, false);
            REQUIRE((j.is_object() && j["error"].is_string()));
            CHECK(j["error"].get<std::string>() == message);
        }
    }
}

TEST_CASE("a full generation queue answers 503 with Retry-After") {
    auto& f = fixture();
    server::TileServiceOptions options;
    options.threads = 1;
    options.queue_limit = 0;
    server::HttpOptions http;
    http.http_threads = 32;
    RunningServer s({f.served()}, options, http);
    const auto r = f.layer->tiles_at(f.layer->max_zoom());
    std::vector<tiler::TileId> ids;
    for (auto y = r.y0; y <= r.y1; ++y) {
        for (auto x = r.x0; x <= r.x1; ++x) {
            ids.push_back({r.z, x, y});
        }
    }
    REQUIRE(ids.size() >= 4);
    std::mutex mutex;
    int ok = 0, busy = 0, other = 0;
    bool retry_after = true;
    std::vector<std::thread> threads;
    for (const auto& id : ids) {
        for (const char* ext : {"glb", "drc"}) {
            threads.emplace_back([&, id, ext] {
                auto res = s.client().Get(tile_url(id, ext) + "?eps=0");
                std::lock_guard<std::mutex> lock(mutex);
                if (res && res->status == 200) {
                    ++ok;
                } else if (res && res->status == 503) {
                    ++busy;
                    retry_after = retry_after && res->get_header_value("Retry-After") == "1";
                } else {
                    ++other;
                }
            });
        }
    }
    for (auto& t : threads) {
        t.join();
    }
    INFO("ok " << ok << ", busy " << busy);
    CHECK(other == 0);
    CHECK(ok >= 1);
    CHECK(busy >= 1);
    CHECK(retry_after);
    CHECK(test::metric(s.port, "tb_queue_rejections_total") == busy);
    auto health = s.client().Get("/health");
    REQUIRE(health);
    CHECK(health->status == 200);
}

TEST_CASE("CORS answers only the configured origins when '*' is not configured") {
    auto& f = fixture();
    server::HttpOptions http;
    http.cors_origins = {"https://maps.example.com"};
    RunningServer s({f.served()}, {}, http);
    auto c = s.client();
    auto allowed = c.Get("/layers", {{"Origin", "https://maps.example.com"}});
    REQUIRE(allowed);
    CHECK(allowed->get_header_value("Access-Control-Allow-Origin") == "https://maps.example.com");
    CHECK(allowed->get_header_value("Vary").find("Origin") != std::string::npos);
    auto other = c.Get("/layers", {{"Origin", "https://evil.example"}});
    REQUIRE(other);
    CHECK(other->status == 200);
    CHECK(!other->has_header("Access-Control-Allow-Origin"));
    // Every answer varies by Origin, one asked without it too (a shared cache must not hand it
    // to a listed origin's page): documents, tiles from a worker and from the connection loop.
    const auto varies = [](const httplib::Result& r, const std::string& name) {
        for (auto [it, end] = r->headers.equal_range("Vary"); it != end; ++it) {
            std::stringstream list(it->second);
            for (std::string v; std::getline(list, v, ',');) {
                v.erase(0, v.find_first_not_of(' '));
                if (v == name) {
                    return true;
                }
            }
        }
        return false;
    };
    for (const std::string& url :
         {std::string("/layers"), tile_url(f.inside), tile_url(f.inside)}) {
        INFO(url);
        auto plain = c.Get(url);
        REQUIRE(plain);
        CHECK(plain->status == 200);
        CHECK(!plain->has_header("Access-Control-Allow-Origin"));
        CHECK(varies(plain, "Origin"));
    }
}

namespace {

// `uri` relative to the document at `base` (an absolute path), with ./ and ../ resolved.
std::string resolve_uri(const std::string& base, const std::string& uri) {
    std::vector<std::string> parts;
    const std::string joined = base.substr(0, base.rfind('/') + 1) + uri;
    std::size_t begin = 1;
    while (begin <= joined.size()) {
        std::size_t end = joined.find('/', begin);
        if (end == std::string::npos) {
            end = joined.size();
        }
        const std::string segment = joined.substr(begin, end - begin);
        if (segment == "..") {
            if (!parts.empty()) {
                parts.pop_back();
            }
        } else if (segment != "." && !segment.empty()) {
            parts.push_back(segment);
        }
        begin = end + 1;
    }
    std::string out;
    for (const auto& p : parts) {
        out += "/" + p;
    }
    return out;
}

void collect_uris(const nlohmann::json& tile, std::vector<std::string>& uris) {
    if (tile.contains("content") && tile["content"].contains("uri")) {
        uris.push_back(tile["content"]["uri"].get<std::string>());
    }
    if (tile.contains("children")) {
        for (const auto& child : tile["children"]) {
            collect_uris(child, uris);
        }
    }
}

} // namespace

TEST_CASE("every content URI of the served tileset, external tilesets included, resolves") {
    auto& f = fixture();
    // Zooms 3..8: deep enough that the tileset refers to external tilesets (every 4 levels).
    auto options = test::test_layer_options(f.dir / "hills.asc", "hills");
    options.min_zoom = 3;
    const server::ServedLayer layer{tiler::Layer::open(options), {tiler::Format::Glb}, nullptr};
    RunningServer s({layer});
    auto c = s.client();
    std::vector<std::string> documents = {"/hills/tileset.json"};
    int tiles = 0, externals = 0;
    for (std::size_t d = 0; d < documents.size() && d < 8; ++d) {
        INFO(documents[d]);
        auto res = c.Get(documents[d]);
        REQUIRE(res);
        REQUIRE(res->status == 200);
        const auto doc = nlohmann::json::parse(res->body);
        std::vector<std::string> uris;
        collect_uris(doc["root"], uris);
        for (const auto& uri : uris) {
            const std::string url = resolve_uri(documents[d], uri);
            INFO(uri << " -> " << url);
            if (url.size() > 5 && url.substr(url.size() - 5) == ".json") {
                documents.push_back(url);
                ++externals;
                continue;
            }
            if (tiles >= 12) {
                continue;
            }
            auto tile = c.Get(url);
            REQUIRE(tile);
            CHECK(tile->status == 200);
            CHECK(tile->body.substr(0, 4) == "glTF");
            ++tiles;
        }
    }
    CHECK(tiles >= 4);
    CHECK(externals >= 1);
    MESSAGE(tiles << " tiles and " << externals << " external tilesets fetched");
}

TEST_CASE("a real SRTM tile is served cold, then from memory with the same bytes") {
    const std::string dem = std::string(TB_SHARED_DATA) + "/N44W072.hgt";
    if (!test::fs::exists(dem)) {
        MESSAGE("skipped: " << dem << " is missing");
        return;
    }
    tiler::LayerOptions options;
    options.name = "srtm";
    options.sources = {dem};
    const server::ServedLayer layer{tiler::Layer::open(options), {tiler::Format::Glb}, nullptr};
    RunningServer s({layer});
    auto c = s.client();
    const auto r = layer.layer->tiles_at(layer.layer->max_zoom());
    REQUIRE(!r.empty());
    const std::string url = "/srtm/" + std::to_string(r.z) + "/" +
                            std::to_string((r.x0 + r.x1) / 2) + "/" +
                            std::to_string((r.y0 + r.y1) / 2) + ".glb";
    auto cold = c.Get(url);
    REQUIRE(cold);
    CHECK(cold->status == 200);
    CHECK(cold->body.substr(0, 4) == "glTF");
    auto warm = c.Get(url);
    REQUIRE(warm);
    CHECK(warm->body == cold->body);
    const std::string m = c.Get("/metrics")->body;
    CHECK(test::metric(m, "tb_tiles_generated_total") == 1);
    CHECK(test::metric(m, "tb_cache_hits_total") == 1);
    auto tileset = c.Get("/srtm/tileset.json");
    REQUIRE(tileset);
    CHECK(tileset->status == 200);
}

TEST_CASE("an eps too fine for a big tile is a 400, remembered without remeshing") {
    auto& f = fixture();
    auto options = test::test_layer_options(f.dir / "hills.asc", "hills");
    options.eps_levels = {0.001}; // far below what a zoom-5 tile's quantization can honour
    const server::ServedLayer layer{tiler::Layer::open(options), {tiler::Format::Glb}, nullptr};
    RunningServer s({layer});
    auto c = s.client();
    const auto r = layer.layer->tiles_at(5);
    REQUIRE(!r.empty());
    const std::string url =
        "/hills/5/" + std::to_string(r.x0) + "/" + std::to_string(r.y0) + ".glb?eps=0";
    auto first = c.Get(url);
    REQUIRE(first);
    CHECK(first->status == 400);
    INFO(first->body);
    CHECK(first->body.find("eps") != std::string::npos);
    auto second = c.Get(url);
    REQUIRE(second);
    CHECK(second->status == 400);
    CHECK(second->body == first->body);
    const std::string m = c.Get("/metrics")->body;
    CHECK(test::metric(m, "tb_cache_hits_total") == 1);
    CHECK(test::metric(m, "tb_cache_misses_total") == 1);
}
