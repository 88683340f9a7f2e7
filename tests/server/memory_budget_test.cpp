// The memory budget of `terrabound serve` (server.memory_mb, --memory-mb): GDAL's block cache and
// the tile cache are set from it, and the startup log says how it is split, with the size GDAL
// itself reports for its cache.
#include "config/config.hpp"
#include "core/error.hpp"
#include "serve_process.hpp"
#include "server_fixture.hpp"

#include <doctest/doctest.h>

namespace {

using namespace tb;

// The "memory: ..." line of a serve started with `args`, or "" when there is none.
std::string memory_line(const test::TempDir& dir, std::vector<std::string> args) {
    static int runs = 0; // a log per run: an old one would show its own startup line
    const std::string log = dir / ("serve" + std::to_string(++runs) + ".log");
    test::Child child;
    args.insert(args.end(), {"--web", "none"});
    test::start_server(child, args, log);
    const std::string text = test::read_file(log);
    const auto at = text.find("info  memory: ");
    return at == std::string::npos ? "" : text.substr(at + 6, text.find('\n', at) - at - 6);
}

} // namespace

TEST_CASE("serve splits --memory-mb between GDAL's block cache and the tile cache") {
    test::TempDir dir;
    test::write_dem(dir / "hills.asc", 65);
    const std::string dem = dir / "hills.asc";
    // Without a budget: GDAL gets 64 MiB instead of its 5 % of the RAM; cache_mb as given.
    CHECK(memory_line(dir, {dem}) ==
          "memory: no budget (memory_mb): tile cache 256 MiB, GDAL block cache 64 MiB");
    // A budget: GDAL a quarter, the tile cache (256 MiB by default) capped to half, malloc's
    // arenas bounded (one per generation thread, at least 2).
    CHECK(memory_line(dir, {dem, "--memory-mb", "256", "--threads", "1"}) ==
          "memory: 256 MiB budget: tile cache 128 MiB (cache_mb 256 capped to half the budget), "
          "GDAL block cache 64 MiB, 64 MiB left for tile generation and connections, malloc "
          "arenas at most 2");
    CHECK(memory_line(dir, {dem, "--memory-mb", "256", "--threads", "3"})
              .find(", malloc arenas at most 3") != std::string::npos);
    // From the config, with a cache_mb that fits; --memory-mb over it.
    const std::string config = dir / "serve.json";
    test::write_file(config, R"({"server": {"threads": 1, "memory_mb": 2048, "cache_mb": 100},
                                 "layers": [{"name": "hills", "sources": ["hills.asc"]}]})");
    CHECK(memory_line(dir, {config}) ==
          "memory: 2048 MiB budget: tile cache 100 MiB, GDAL block cache 512 MiB, 1436 MiB left "
          "for tile generation and connections, malloc arenas at most 2");
    CHECK(memory_line(dir, {config, "--memory-mb", "0"}) ==
          "memory: no budget (memory_mb): tile cache 100 MiB, GDAL block cache 64 MiB");

    CHECK(test::run_to_exit({"serve", dem, "--memory-mb", "10"}, dir / "bad.log") == 2);
    CHECK(test::read_file(dir / "bad.log")
              .find("--memory-mb: expected 0 (no budget) or 64..1048576 MiB, got 10") !=
          std::string::npos);
}

TEST_CASE("the config's server.memory_mb is 0 or 64 MiB and more") {
    const std::string layers = R"(, "layers": [{"name": "a", "sources": ["/vsimem/x.tif"]}]})";
    CHECK(config::parse_config(R"({"server": {})" + layers, "c.json").server.memory_mb == 0);
    CHECK(config::parse_config(R"({"server": {"memory_mb": 512})" + layers, "c.json")
              .server.memory_mb == 512);
    CHECK_THROWS_WITH_AS(
        config::parse_config(R"({"server": {"memory_mb": 32})" + layers, "c.json"),
        doctest::Contains("/server/memory_mb: expected 0 (no budget) or at least 64, got 32"),
        InputError);
}
