// Inputs found by the fuzz harnesses (tests/fuzz), kept as regression tests: each made the
// code under test crash or misbehave before its fix.
#include "config/config.hpp"
#include "core/error.hpp"
#include "server_fixture.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"

#include <doctest/doctest.h>

TEST_CASE("a config with a number too large for a double is an InputError naming the file") {
    // fuzz_config: nlohmann-json throws out_of_range (not parse_error) for 2e308, which escaped
    // parse_config and ended `terrabound serve` with exit 1 and the library's raw message.
    tb::test::TempDir dir;
    const std::string text =
        R"({"layers":[{"name":"a","sources":["/vsicurl/https://example.com/a.tif"],)"
        R"("eps_levels":[2e308,-0*0]}]})";
    try {
        tb::config::parse_config(text, dir / "site.json");
        FAIL("parse_config accepted a number out of range");
    } catch (const tb::InputError& e) {
        const std::string what = e.what();
        CHECK(what.find(dir / "site.json") == 0);
        CHECK(what.find("2e308") != std::string::npos);
    }
}

TEST_CASE("a CORS preflight echoes Access-Control-Request-Headers only when it is a list of "
          "header names") {
    // fuzz_routes: the preflight echoed any text of the request header back in
    // Access-Control-Allow-Headers, here a path and the harness's "outside the root" marker.
    tb::log::set_level(tb::log::Level::Warn);
    tb::test::TempDir dir;
    tb::test::write_dem(dir / "hills.asc", 33);
    tb::test::RunningServer server(
        {{tb::tiler::Layer::open(tb::test::test_layer_options(dir / "hills.asc", "hills")),
          {tb::tiler::Format::Glb},
          nullptr}});
    auto c = server.client();
    const auto allowed = [&c](const std::string& asked) {
        auto res = c.Options("/layers",
                             {{"Origin", "http://a.example"},
                              {"Access-Control-Request-Method", "GET"},
                              {"Access-Control-Request-Headers", asked}});
        REQUIRE(res);
        CHECK(res->status == 204);
        return res->get_header_value("Access-Control-Allow-Headers");
    };
    CHECK(allowed("if-none-match") == "if-none-match");
    CHECK(allowed("if-none-match, x-requested-with") == "if-none-match, x-requested-with");
    CHECK(allowed("/hilOUTSIDE-THE-ROOTls/6/<%7/5 x-a") == "*");
    CHECK(allowed("a b") == "*");
    CHECK(allowed(",") == "*");
}
