// The connection loop's quick path for tiles already in memory, over real loopback sockets:
// its answers are the bytes cpp-httplib's routes send for the same request (200, 304, HEAD,
// codings, CORS, keep-alive and close), it counts what they count, it takes nothing else, and
// pipelined requests stay in order whichever path answers them.
#include "server_fixture.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"

#include <doctest/doctest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <thread>
#include <vector>

namespace {

using namespace tb;

struct Fixture : test::HillsLayer {
    server::ServedLayer served() const {
        return {layer, {tiler::Format::Glb, tiler::Format::Drc, tiler::Format::Terrain}, nullptr};
    }
    // The tile's path; `escaped`: with its zoom's first digit percent-encoded, which names the
    // same tile for cpp-httplib (it decodes the path) but is not taken by the quick path.
    std::string path(const char* extension, bool escaped = false) const {
        std::string z = std::to_string(inside.z);
        if (escaped) {
            char code[4];
            std::snprintf(code, sizeof code, "%%%02X", static_cast<unsigned char>(z[0]));
            z = code + z.substr(1);
        }
        return "/hills/" + z + "/" + std::to_string(inside.x) + "/" + std::to_string(inside.y) +
               "." + extension;
    }
};

Fixture& fixture() {
    static Fixture f;
    return f;
}

using Conn = test::KeepAliveConn;

std::string
request(const std::string& method, const std::string& path, const std::string& headers = "") {
    return method + " " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\n" + headers + "\r\n";
}

double quick_answers(int port) {
    return test::metric(port, "tb_http_quick_answers_total");
}

// The answers to `requests`, pipelined on one connection, and how many the quick path gave.
struct Exchange {
    std::vector<std::string> responses;
    double quick = 0;
    bool closed = false; // the server closed the connection after the last one
};

Exchange pipeline(int port, const std::vector<std::string>& requests) {
    Exchange x;
    const double before = quick_answers(port);
    Conn c(port);
    std::string all;
    for (const auto& r : requests) {
        all += r;
    }
    // Sent by another thread while this one reads: neither side's buffers need to hold
    // everything.
    bool sent = false;
    std::thread sender([&] { sent = c.send_all(all); });
    for (const auto& r : requests) {
        x.responses.push_back(c.response(r.rfind("HEAD ", 0) == 0));
    }
    sender.join();
    CHECK(sent);
    x.closed = x.responses.back().find("\r\nConnection: close\r\n") != std::string::npos &&
               c.closed_by_server();
    x.quick = quick_answers(port) - before;
    return x;
}

// The same requests by the quick path and, escaped, by cpp-httplib's routes: every response
// must be the same bytes.
void check_same_answers(int port, const std::vector<std::pair<std::string, std::string>>& cases) {
    auto& f = fixture();
    std::vector<std::string> quick, normal;
    for (const auto& [method_ext, headers] : cases) {
        const auto space = method_ext.find(' ');
        const std::string method = method_ext.substr(0, space);
        const std::string ext = method_ext.substr(space + 1);
        quick.push_back(request(method, f.path(ext.c_str()), headers));
        normal.push_back(request(method, f.path(ext.c_str(), true), headers));
    }
    const Exchange q = pipeline(port, quick);
    const Exchange n = pipeline(port, normal);
    CHECK(q.quick == static_cast<double>(cases.size()));
    CHECK(n.quick == 0);
    REQUIRE(q.responses.size() == n.responses.size());
    for (std::size_t i = 0; i < cases.size(); ++i) {
        INFO(cases[i].first << " with headers: " << cases[i].second);
        CHECK(!q.responses[i].empty());
        CHECK(q.responses[i] == n.responses[i]);
    }
}

// Requests the glb and drc tile once through the routes, so that both are in memory.
void warm(int port) {
    auto& f = fixture();
    for (const char* ext : {"glb", "drc"}) {
        Conn c(port);
        REQUIRE(c.send_all(request("GET", f.path(ext, true))));
        const std::string r = c.response(false);
        REQUIRE(r.rfind("HTTP/1.1 200 ", 0) == 0);
    }
}

// What CesiumJS's CesiumTerrainProvider sends for .terrain tiles.
constexpr const char* kCesiumAccept =
    "Accept: application/vnd.quantized-mesh;extensions=octvertexnormals-watermask-metadata,"
    "application/octet-stream;q=0.9,*/*;q=0.01\r\n";

// Asks for the .terrain tile through the routes with each set of headers, so that every
// cut-down copy and coding those headers ask for is made and in memory.
void warm_terrain(int port, const std::vector<std::string>& header_sets) {
    auto& f = fixture();
    for (const auto& headers : header_sets) {
        Conn c(port);
        REQUIRE(c.send_all(request("GET", f.path("terrain", true), headers)));
        REQUIRE(c.response(false).rfind("HTTP/1.1 200 ", 0) == 0);
    }
}

std::string etag_of(const std::string& response) {
    const auto at = response.find("\r\nETag: ");
    REQUIRE(at != std::string::npos);
    return response.substr(at + 8, response.find("\r\n", at + 8) - at - 8);
}

} // namespace

TEST_CASE("a tile in memory is answered by the loop with the bytes the routes send: 200, 304, "
          "HEAD, codings, CORS '*'") {
    auto& f = fixture();
    test::RunningServer s({f.served()});
    warm(s.port);
    Conn c(s.port);
    REQUIRE(c.send_all(request("GET", f.path("glb"))));
    const std::string etag = etag_of(c.response(false));
    check_same_answers(s.port,
                       {
                           {"GET glb", ""},
                           {"GET drc", ""},
                           {"HEAD glb", ""},
                           {"GET glb", "If-None-Match: " + etag + "\r\n"},
                           {"HEAD glb", "If-None-Match: " + etag + "\r\n"},
                           {"GET glb", "if-none-match: \"x\", W/" + etag + "\r\n"},
                           {"GET glb", "If-None-Match: *\r\n"},
                           {"GET glb", "If-None-Match: \"0000000000000000-0\"\r\n"},
                           // cpp-httplib answers the first of repeated fields; blank ones count
                           // for nothing.
                           {"GET glb", "If-None-Match:  \r\nIf-None-Match: " + etag + "\r\n"},
                           {"GET glb", "If-None-Match: \"x\"\r\nIf-None-Match: " + etag + "\r\n"},
                           // Tiles are never compressed, whatever the client accepts.
                           {"GET glb", "Accept-Encoding: gzip, br\r\n"},
                           {"GET drc", "Accept-Encoding: br;q=1, gzip;q=0.5\r\n"},
                           {"GET glb", "Origin: https://maps.example.com\r\n"},
                           {"GET glb", "Connection: keep-alive\r\nUser-Agent: test\r\n"},
                           {"GET glb", "Accept: */*\r\n"},
                       });
}

TEST_CASE("a quantized-mesh tile in memory is answered by the loop as serve_terrain answers it: "
          "extensions by Accept, codings already made, Vary, 304, HEAD") {
    auto& f = fixture();
    test::RunningServer s({f.served()});
    const std::string all = kCesiumAccept;
    const std::string normals =
        "Accept: application/vnd.quantized-mesh;extensions=octvertexnormals\r\n";
    warm_terrain(s.port,
                 {all + "Accept-Encoding: gzip, deflate, br\r\n",
                  all + "Accept-Encoding: gzip\r\n",
                  all,
                  normals + "Accept-Encoding: gzip\r\n",
                  "Accept-Encoding: br\r\n"});
    Conn c(s.port);
    REQUIRE(c.send_all(request("GET", f.path("terrain"), all)));
    const std::string etag = etag_of(c.response(false));
    check_same_answers(s.port,
                       {
                           {"GET terrain", all + "Accept-Encoding: gzip, deflate, br\r\n"},
                           {"GET terrain", all + "Accept-Encoding: gzip\r\n"},
                           {"GET terrain", all + "accept-encoding: br;q=0, gzip\r\n"},
                           {"GET terrain", all},
                           {"GET terrain", all + "Accept-Encoding: identity\r\n"},
                           {"GET terrain", normals + "Accept-Encoding: gzip\r\n"},
                           {"GET terrain", "Accept-Encoding: br\r\n"}, // no extensions
                           {"GET terrain", "Accept: */*\r\nAccept-Encoding: br\r\n"},
                           {"HEAD terrain", all + "Accept-Encoding: br\r\n"},
                           {"GET terrain", all + "If-None-Match: " + etag + "\r\n"},
                           {"HEAD terrain", all + "If-None-Match: " + etag + "\r\n"},
                           {"GET terrain", all + "Accept-Encoding:  \r\nAccept-Encoding: gzip\r\n"},
                           {"GET terrain", all + "Origin: https://maps.example.com\r\n"},
                       });
    // Counted in the terrain route's metrics, with the cache hit the routes count.
    const double ok =
        test::metric(s.port, "tb_http_requests_total{route=\"terrain\",status=\"200\"}");
    const double hits = test::metric(s.port, "tb_cache_hits_total");
    CHECK(pipeline(s.port, {request("GET", f.path("terrain"), all)}).quick == 1);
    CHECK(test::metric(s.port, "tb_http_requests_total{route=\"terrain\",status=\"200\"}") ==
          ok + 1);
    CHECK(test::metric(s.port, "tb_cache_hits_total") == hits + 1);
    // A revalidation needs no coding: a 304 for a coding not made yet (br of the normals-only
    // copy) is the loop's too, and the routes' bytes; a HEAD of it is a worker's (the routes
    // compress for a HEAD).
    Conn n(s.port);
    REQUIRE(n.send_all(request("GET", f.path("terrain"), normals + "Accept-Encoding: gzip\r\n")));
    const std::string normals_etag = etag_of(n.response(false));
    const std::string revalidate =
        normals + "Accept-Encoding: br\r\nIf-None-Match: " + normals_etag + "\r\n";
    const Exchange q304 = pipeline(s.port, {request("GET", f.path("terrain"), revalidate)});
    const Exchange n304 = pipeline(s.port, {request("GET", f.path("terrain", true), revalidate)});
    CHECK(q304.quick == 1);
    CHECK(q304.responses[0].rfind("HTTP/1.1 304 ", 0) == 0);
    CHECK(q304.responses == n304.responses);
    const double hits_before_head = test::metric(s.port, "tb_cache_hits_total");
    CHECK(
        pipeline(s.port, {request("HEAD", f.path("terrain"), normals + "Accept-Encoding: br\r\n")})
            .quick == 0);
    CHECK(test::metric(s.port, "tb_cache_hits_total") == hits_before_head + 1); // the route's
    // A coding nobody has asked for yet is made by a worker, then the loop has it too.
    const auto made_br = request("GET", f.path("terrain"), all + "Accept-Encoding: br\r\n");
    CHECK(pipeline(s.port, {made_br}).quick == 1); // br was made by the warm-up
    const auto fresh_subset = request(
        "GET",
        f.path("terrain"),
        "Accept: application/vnd.quantized-mesh;extensions=watermask\r\nAccept-Encoding: gzip\r\n");
    const Exchange first = pipeline(s.port, {fresh_subset});
    CHECK(first.quick == 0);
    CHECK(first.responses[0].rfind("HTTP/1.1 200 ", 0) == 0);
    CHECK(pipeline(s.port, {fresh_subset}).quick == 1);
}

TEST_CASE("the quick path sends the CORS headers of the configured origins, or none") {
    auto& f = fixture();
    server::HttpOptions listed;
    listed.cors_origins = {"https://maps.example.com", "https://b.example"};
    server::HttpOptions none;
    none.cors_origins = {};
    for (const auto& http : {listed, none}) {
        INFO(http.cors_origins.size() << " origins");
        test::RunningServer s({f.served()}, {}, http);
        warm(s.port);
        warm_terrain(s.port, {std::string(kCesiumAccept) + "Accept-Encoding: gzip\r\n"});
        const std::string terrain = std::string(kCesiumAccept) + "Accept-Encoding: gzip\r\n";
        check_same_answers(s.port,
                           {
                               {"GET terrain", terrain + "Origin: https://maps.example.com\r\n"},
                               {"GET terrain", terrain + "Origin: https://evil.example\r\n"},
                               {"GET terrain", terrain},
                               {"GET glb", "Origin: https://maps.example.com\r\n"},
                               {"GET glb", "Origin: https://b.example\r\n"},
                               {"HEAD glb", "origin: https://b.example\r\n"},
                               {"GET glb", "Origin: https://evil.example\r\n"},
                               {"GET glb", "Origin: https://b.example\r\nOrigin: x\r\n"},
                               {"GET glb", ""},
                           });
    }
}

TEST_CASE("the quick path closes as the routes do: on Connection: close and on the last "
          "request a connection may make") {
    auto& f = fixture();
    server::HttpOptions http;
    http.limits.max_requests = 3;
    test::RunningServer s({f.served()}, {}, http);
    warm(s.port);
    const auto plain = request("GET", f.path("glb"));
    const auto escaped = request("GET", f.path("glb", true));
    // The third request is the connection's last: the server says so and closes.
    const Exchange q = pipeline(s.port, {plain, plain, plain});
    const Exchange n = pipeline(s.port, {escaped, escaped, escaped});
    CHECK(q.quick == 3);
    CHECK(n.quick == 0);
    CHECK(q.responses == n.responses);
    CHECK(q.closed);
    CHECK(n.closed);
    CHECK(q.responses[0].find("\r\nKeep-Alive: timeout=") != std::string::npos);
    CHECK(q.responses[2].find("\r\nConnection: close\r\n") != std::string::npos);

    const Exchange qc = pipeline(s.port, {request("GET", f.path("glb"), "Connection: close\r\n")});
    const Exchange nc =
        pipeline(s.port, {request("GET", f.path("glb", true), "Connection: close\r\n")});
    CHECK(qc.quick == 1);
    CHECK(qc.responses == nc.responses);
    CHECK(qc.closed);
}

TEST_CASE("the quick path counts a request as the routes do, in the route's metrics") {
    auto& f = fixture();
    test::RunningServer s({f.served()});
    warm(s.port);
    const auto sample = [&](const std::string& name) {
        httplib::Client c("127.0.0.1", s.port);
        const auto res = c.Get("/metrics");
        REQUIRE(res);
        const auto at = res->body.find("\n" + name + " ");
        return at == std::string::npos ? 0.0 : std::stod(res->body.substr(at + name.size() + 2));
    };
    const double hits = sample("tb_cache_hits_total");
    const double ok = sample("tb_http_requests_total{route=\"tile\",status=\"200\"}");
    const double fresh = sample("tb_http_requests_total{route=\"tile\",status=\"304\"}");
    Conn c(s.port);
    REQUIRE(c.send_all(request("GET", f.path("glb"))));
    const std::string etag = etag_of(c.response(false));
    REQUIRE(c.send_all(request("GET", f.path("glb"), "If-None-Match: " + etag + "\r\n")));
    CHECK(c.response(false).rfind("HTTP/1.1 304 ", 0) == 0);
    CHECK(sample("tb_cache_hits_total") == hits + 2);
    CHECK(sample("tb_http_requests_total{route=\"tile\",status=\"200\"}") == ok + 1);
    CHECK(sample("tb_http_requests_total{route=\"tile\",status=\"304\"}") == fresh + 1);
    CHECK(sample("tb_http_request_duration_seconds_count{route=\"tile\"}") >= 4);
}

TEST_CASE("requests the quick path cannot answer exactly are left to the routes") {
    auto& f = fixture();
    test::RunningServer s({f.served()});
    const auto glb = f.path("glb");
    // Not in memory yet: generated by a worker, then the quick path has it.
    Exchange first = pipeline(s.port, {request("GET", glb)});
    CHECK(first.quick == 0);
    CHECK(first.responses[0].rfind("HTTP/1.1 200 ", 0) == 0);
    CHECK(pipeline(s.port, {request("GET", glb)}).quick == 1);
    const std::string slashes = "/hills//" + glb.substr(7);
    const std::vector<std::pair<std::string, int>> cases = {
        {request("GET", glb, "Range: bytes=0-9\r\n"), 206},
        {request("GET", glb + "?eps=1"), 200},
        {request("GET", slashes), 200},
        {request("GET", glb, "Expect: 100-continue\r\n"), 0}, // a 100 Continue first
        {request("POST", glb, "Content-Length: 0\r\n"), 405},
        {request("DELETE", glb), 405},
        {"GET " + glb + " HTTP/1.0\r\n\r\n", 200},
        {request("GET", "/web/8/1/1.glb"), 404},
        {request("GET", f.path("glb").substr(0, glb.size() - 4) + "x.glb"), 400},
        {request("GET", "/hills/99/1/1.glb"), 400},
        {request("GET", "/nope/8/1/1.glb"), 404},
        {request("GET", glb, "Origin: a%20b\r\n"), 200},
    };
    for (const auto& [text, status] : cases) {
        INFO(text);
        const Exchange x = pipeline(s.port, {text});
        CHECK(x.quick == 0);
        if (status != 0) {
            CHECK(x.responses[0].rfind("HTTP/1.1 " + std::to_string(status) + " ", 0) == 0);
        }
    }
}

TEST_CASE("pipelined requests answered by the loop and by workers keep their order") {
    auto& f = fixture();
    test::RunningServer s({f.served()});
    warm(s.port);
    const auto glb = f.path("glb");
    const std::vector<std::pair<std::string, std::string>> requests = {
        {request("GET", glb), "200"},
        {request("GET", "/health"), "200"},
        {request("HEAD", glb), "200"},
        {request("GET", "/hills/8/0/0.drc?eps=0"), "404"},
        {request("GET", f.path("drc")), "200"},
        {request("GET", "/hills/99/1/1.glb"), "400"},
        {request("GET", glb, "If-None-Match: *\r\n"), "304"},
        {request("GET", glb + "?eps=1"), "200"},
        {request("GET", glb), "200"},
    };
    std::vector<std::string> texts;
    for (const auto& r : requests) {
        texts.push_back(r.first);
    }
    const Exchange x = pipeline(s.port, texts);
    CHECK(x.quick == 5);
    for (std::size_t i = 0; i < requests.size(); ++i) {
        INFO(requests[i].first);
        CHECK(x.responses[i].substr(0, 13) == "HTTP/1.1 " + requests[i].second + " ");
    }
    CHECK(x.responses[0] == x.responses[8]);
}

TEST_CASE("hundreds of pipelined quick requests in one write are all answered, in order") {
    auto& f = fixture();
    test::RunningServer s({f.served()});
    warm(s.port);
    // HEAD: the answers are small and seldom wait for the socket, so the loop answers request
    // after request from what it has read, as deep as the client pipelines.
    constexpr int kRequests = 900; // under the 1000 a connection may make
    std::vector<std::string> texts(kRequests, request("HEAD", f.path("glb")));
    texts.back() = request("GET", f.path("glb"), "Connection: close\r\n");
    const Exchange x = pipeline(s.port, texts);
    CHECK(x.quick == kRequests);
    REQUIRE(x.responses.size() == kRequests);
    for (int i = 0; i < kRequests; ++i) {
        if (x.responses[i].rfind("HTTP/1.1 200 OK\r\n", 0) != 0) {
            FAIL("response " << i << " is not a 200: " << x.responses[i].substr(0, 40));
        }
    }
    CHECK(x.closed);
}
