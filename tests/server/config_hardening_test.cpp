// Hostile configs: nesting 100,000 deep, hosts that are not addresses, NUL bytes in paths,
// the nodata field; each gets one clear line naming the file and the JSON pointer.
#include "config/config.hpp"
#include "config_util.hpp"
#include "core/error.hpp"
#include "server_fixture.hpp"

#include <doctest/doctest.h>

#include <sys/wait.h>

#include <cstdio>

namespace {

using tb::test::config_error;
using tb::test::run_command;
using tb::test::TempDir;
using tb::test::write_file;

std::string layer_with(const std::string& dem, const std::string& extra) {
    return R"({"layers": [{"name": "t", "sources": [")" + dem + "\"]" + extra + "}]}";
}

} // namespace

TEST_CASE("a config nested 100,000 arrays deep is one clear error, not a crash") {
    TempDir dir;
    const std::string path = dir / "deep.json";
    for (const std::string& open_close : {std::string("[]"), std::string("{}")}) {
        std::string text;
        if (open_close == "[]") {
            text = std::string(100000, '[') + std::string(100000, ']');
        } else {
            for (int i = 0; i < 100000; ++i) {
                text += "{\"a\":";
            }
            text += "1" + std::string(100000, '}');
        }
        write_file(path, text);
        std::string output;
        const int code = run_command(std::string(TB_BINARY) + " serve " + path, output);
        CHECK(code == 2);
        CHECK(output == "terrabound: " + path +
                            ": line 1: arrays and objects nested more than 64 deep; a config "
                            "nests 4 levels at most, fix the file\n");
    }
    // Brackets inside strings do not count; 64 levels are parsed (and then judged as usual).
    const std::string err = config_error(
        R"({"layers": "[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[["})",
        "c.json");
    CHECK(err.find("/layers: expected an array") != std::string::npos);
    CHECK(config_error(std::string(64, '[') + std::string(64, ']'), "c.json")
              .find("c.json: /: expected an object") != std::string::npos);
}

TEST_CASE("the host must be an IPv4 or IPv6 address or a host name, and is blamed by name") {
    TempDir dir;
    tb::test::write_dem(dir / "d.asc", 33);
    const auto host_error = [&](const std::string& host) {
        return config_error(R"({"server": {"host": ")" + host + "\"}, " +
                                layer_with(dir / "d.asc", "").substr(1),
                            "c.json");
    };
    for (const std::string ok :
         {"127.0.0.1", "0.0.0.0", "::1", "::", "localhost", "tiles.example.org", "host-1"}) {
        CAPTURE(ok);
        CHECK(host_error(ok) == "");
    }
    CHECK(host_error("999.1.1.1") ==
          "c.json: /server/host: expected an IPv4 address: four numbers 0..255 joined by '.', "
          "such as \"127.0.0.1\"; got \"999.1.1.1\"");
    for (const std::string bad : {"1.2.3", "1.2.3.4.5", "::g", "bad host", "-x.org", "a..b", ""}) {
        CAPTURE(bad);
        const std::string e = host_error(bad);
        CHECK(e.rfind("c.json: /server/host: expected ", 0) == 0);
        CHECK(e.find("port") == std::string::npos);
    }
    std::string output;
    const int code = run_command(std::string(TB_BINARY) + " serve " + (dir / "d.asc") +
                                     " --host 999.1.1.1 --port 0",
                                 output);
    CHECK(code == 2);
    CHECK(output.find("terrabound: --host: expected an IPv4 address") != std::string::npos);
    CHECK(output.find("port") == std::string::npos);
}

TEST_CASE("a NUL byte inside a source or store path is refused, not cut off") {
    TempDir dir;
    tb::test::write_dem(dir / "d.asc", 33);
    // The JSON escape \u0000 puts a real NUL into the string; cut there, the path would exist.
    const std::string err = config_error(R"({"layers": [{"name": "t", "sources": [")" +
                                             (dir / "d.asc") + R"(\u0000.bak"]}]})",
                                         "c.json");
    CHECK(err.find("c.json: /layers/0/sources/0: contains a NUL byte (\\u0000)") == 0);
    const std::string store =
        config_error(layer_with(dir / "d.asc", R"(, "store": "tiles.sqlite\u0000x")"), "c.json");
    CHECK(store.find("c.json: /layers/0/store: contains a NUL byte") == 0);
}

TEST_CASE("a layer's nodata is null by default, or a finite number") {
    TempDir dir;
    tb::test::write_dem(dir / "d.asc", 33);
    const std::string path = dir / "c.json";
    auto config = tb::config::parse_config(layer_with(dir / "d.asc", ""), path);
    CHECK_FALSE(config.layers[0].options.nodata.has_value());
    config = tb::config::parse_config(layer_with(dir / "d.asc", R"(, "nodata": null)"), path);
    CHECK_FALSE(config.layers[0].options.nodata.has_value());
    config = tb::config::parse_config(layer_with(dir / "d.asc", R"(, "nodata": -32767)"), path);
    CHECK(config.layers[0].options.nodata == -32767.0);
    CHECK(config_error(layer_with(dir / "d.asc", R"(, "nodata": "-32767")"), path) ==
          path + ": /layers/0/nodata: expected null or the raw sample value of voids (a number), "
                 "got \"-32767\"");
}
