// Who may read /metrics (HttpOptions::metrics, the config's "metrics", --metrics): loopback
// answers this machine only, and not through a proxy; on answers anyone; off answers nobody.
#include "config/config.hpp"
#include "core/error.hpp"
#include "serve_process.hpp"
#include "server_fixture.hpp"

#include <doctest/doctest.h>

#include <arpa/inet.h>
#include <ifaddrs.h>

namespace {

using namespace tb;
using test::RunningServer;

test::HillsLayer& hills() {
    static test::HillsLayer f;
    return f;
}

server::ServedLayer served() {
    return {hills().layer, {tiler::Format::Glb}, nullptr};
}

RunningServer start(server::MetricsAccess access, const std::string& host = "127.0.0.1") {
    server::HttpOptions options;
    options.host = host;
    options.metrics = access;
    return RunningServer({served()}, {}, options);
}

int status(httplib::Client& c, const httplib::Headers& headers = {}) {
    auto res = c.Get("/metrics", headers);
    return res ? res->status : -1;
}

// An IPv4 address of this machine other than loopback, or "" when it has none.
std::string outside_address() {
    ifaddrs* list = nullptr;
    if (getifaddrs(&list) != 0) {
        return "";
    }
    std::string found;
    for (ifaddrs* a = list; a && found.empty(); a = a->ifa_next) {
        if (a->ifa_addr && a->ifa_addr->sa_family == AF_INET) {
            char text[INET_ADDRSTRLEN] = {};
            inet_ntop(AF_INET,
                      &reinterpret_cast<const sockaddr_in*>(a->ifa_addr)->sin_addr,
                      text,
                      sizeof text);
            if (std::string(text).rfind("127.", 0) != 0) {
                found = text;
            }
        }
    }
    freeifaddrs(list);
    return found;
}

} // namespace

TEST_CASE("/metrics on loopback answers this machine, and refuses proxied requests with 403") {
    RunningServer s = start(server::MetricsAccess::Loopback);
    auto c = s.client();
    CHECK(status(c) == 200);
    for (const char* header : {"X-Forwarded-For", "Forwarded", "X-Real-IP"}) {
        INFO(header);
        auto res = c.Get("/metrics", {{header, "203.0.113.9"}});
        REQUIRE(res);
        CHECK(res->status == 403);
        CHECK(res->get_header_value("Content-Type") == "application/json");
        CHECK(res->body.find("this machine only") != std::string::npos);
    }
    auto head = c.Head("/metrics", {{"X-Forwarded-For", "203.0.113.9"}});
    REQUIRE(head);
    CHECK(head->status == 403);
    auto health = c.Get("/health", {{"X-Forwarded-For", "203.0.113.9"}});
    REQUIRE(health);
    CHECK(health->status == 200); // only /metrics is limited
}

TEST_CASE("/metrics on loopback refuses a peer on another address of the machine") {
    const std::string address = outside_address();
    if (address.empty()) {
        MESSAGE("skipped: this machine has no IPv4 address besides loopback");
        return;
    }
    RunningServer s = start(server::MetricsAccess::Loopback, "0.0.0.0");
    httplib::Client outside(address, s.port);
    CHECK(status(outside) == 403);
    auto health = outside.Get("/health");
    REQUIRE(health);
    CHECK(health->status == 200);
    auto c = s.client();
    CHECK(status(c) == 200);

    RunningServer open = start(server::MetricsAccess::On, "0.0.0.0");
    httplib::Client outside_open(address, open.port);
    CHECK(status(outside_open) == 200);
}

TEST_CASE("/metrics on answers proxied requests, off answers none") {
    RunningServer on = start(server::MetricsAccess::On);
    auto c = on.client();
    CHECK(status(c, {{"X-Forwarded-For", "203.0.113.9"}}) == 200);

    RunningServer off = start(server::MetricsAccess::Off);
    auto d = off.client();
    auto res = d.Get("/metrics");
    REQUIRE(res);
    CHECK(res->status == 404);
    CHECK(res->body.find("off") != std::string::npos);
}

TEST_CASE("the config's server.metrics is loopback by default, and on, off or loopback") {
    const std::string layers = R"(, "layers": [{"name": "a", "sources": ["/vsimem/x.tif"]}]})";
    CHECK(config::parse_config(R"({"server": {})" + layers, "c.json").server.metrics == "loopback");
    CHECK(config::parse_config(R"({"server": {"metrics": "on"})" + layers, "c.json")
              .server.metrics == "on");
    CHECK_THROWS_WITH_AS(
        config::parse_config(R"({"server": {"metrics": "public"})" + layers, "c.json"),
        doctest::Contains("/server/metrics"),
        InputError);
    CHECK(server::parse_metrics_access("off", "--metrics") == server::MetricsAccess::Off);
    CHECK_THROWS_WITH_AS(server::parse_metrics_access("yes", "--metrics"),
                         "--metrics: expected loopback, on or off, got 'yes'",
                         InputError);
}

TEST_CASE("serve takes metrics from the config and --metrics over it") {
    test::TempDir dir;
    test::write_dem(dir / "hills.asc", 65);
    const std::string config = dir / "serve.json";
    test::write_file(config, R"({"server": {"threads": 1, "metrics": "off"},
                                 "layers": [{"name": "hills", "sources": ["hills.asc"]}]})");
    {
        test::Child child;
        const int port = test::start_server(child, {config, "--web", "none"}, dir / "off.log");
        httplib::Client c("127.0.0.1", port);
        CHECK(status(c) == 404);
    }
    {
        test::Child child;
        const int port = test::start_server(
            child, {config, "--web", "none", "--metrics", "loopback"}, dir / "loopback.log");
        httplib::Client c("127.0.0.1", port);
        CHECK(status(c) == 200);
        CHECK(status(c, {{"X-Forwarded-For", "203.0.113.9"}}) == 403);
    }
    CHECK(test::run_to_exit({"serve", config, "--metrics", "public"}, dir / "bad.log") == 2);
    CHECK(test::read_file(dir / "bad.log").find("--metrics: expected loopback, on or off") !=
          std::string::npos);
}
