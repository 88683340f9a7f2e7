// Inputs found by the fuzz harnesses (tests/fuzz), kept as regression tests: each made the
// code under test crash or misbehave before its fix.
#include "config/config.hpp"
#include "core/error.hpp"
#include "server_fixture.hpp"

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
