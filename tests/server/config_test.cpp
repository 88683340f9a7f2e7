// Configuration parsing and validation: defaults, relative paths, and every problem of a file
// reported together with its JSON pointer.
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

} // namespace

TEST_CASE("a minimal config gets the documented defaults and resolves sources against its dir") {
    TempDir dir;
    tb::test::fs::create_directories(dir.path / "dems");
    write_file(dir / "dems/a.asc", "");
    const std::string path = dir / "site.json";
    const auto cfg = tb::config::parse_config(
        R"({"layers": [{"name": "alps", "sources": ["dems/a.asc"]}]})", path);
    CHECK(cfg.server.host == "127.0.0.1");
    CHECK(cfg.server.port == 8080);
    CHECK(cfg.server.threads == 0);
    CHECK(cfg.server.cache_mb == 256);
    CHECK(cfg.server.queue_limit == 64);
    CHECK(cfg.server.log_level == "info");
    REQUIRE(cfg.server.cors_origins.size() == 1);
    CHECK(cfg.server.cors_origins[0] == "*");
    REQUIRE(cfg.layers.size() == 1);
    const auto& layer = cfg.layers[0];
    CHECK(layer.options.name == "alps");
    REQUIRE(layer.options.sources.size() == 1);
    CHECK(layer.options.sources[0] == (dir.path / "dems/a.asc").string());
    CHECK(layer.options.scheme == tb::tiler::Scheme::Geodetic);
    CHECK(layer.options.tile_size == 256);
    CHECK(!layer.options.min_zoom);
    CHECK(!layer.options.finest_eps);
    CHECK(layer.formats == std::vector<tb::tiler::Format>{tb::tiler::Format::Glb,
                                                          tb::tiler::Format::Drc,
                                                          tb::tiler::Format::Terrarium,
                                                          tb::tiler::Format::Mapbox,
                                                          tb::tiler::Format::Terrain,
                                                          tb::tiler::Format::Terrain3d});
    CHECK(layer.options.dem_tile_size == 512);
    CHECK(layer.options.dem_heights == tb::tiler::DemHeights::SeaLevel);
    CHECK(!layer.store);
}

TEST_CASE("a full config fills every field") {
    TempDir dir;
    write_file(dir / "a.tif", "");
    tb::test::fs::create_directories(dir.path / "out");
    const auto cfg = tb::config::parse_config(R"({
      "server": {"host": "0.0.0.0", "port": 9000, "threads": 3, "cache_mb": 64,
                 "cors_origins": ["https://example.com", "http://localhost:3000"],
                 "log_level": "warn", "queue_limit": 5},
      "layers": [{"name": "a-1", "sources": ["a.tif", "/vsicurl/https://x/y.tif"],
                  "scheme": "mercator", "tile_size": 128, "min_zoom": 3, "max_zoom": 9,
                  "finest_eps": 0.5, "eps_levels": [1, 2.5], "datum": "ellipsoid",
                  "formats": ["drc", "mapbox"], "store": "out/tiles.sqlite",
                  "dem_tile_size": 256, "dem_heights": "ellipsoid"}]})",
                                              dir / "c.json");
    CHECK(cfg.server.host == "0.0.0.0");
    CHECK(cfg.server.port == 9000);
    CHECK(cfg.server.threads == 3);
    CHECK(cfg.server.cache_mb == 64);
    CHECK(cfg.server.cors_origins.size() == 2);
    CHECK(cfg.server.log_level == "warn");
    CHECK(cfg.server.queue_limit == 5);
    const auto& o = cfg.layers.at(0).options;
    CHECK(o.name == "a-1");
    CHECK(o.sources.size() == 2);
    CHECK(o.sources[1] == "/vsicurl/https://x/y.tif"); // GDAL names pass through untouched
    CHECK(o.scheme == tb::tiler::Scheme::Mercator);
    CHECK(o.tile_size == 128);
    CHECK(*o.min_zoom == 3);
    CHECK(*o.max_zoom == 9);
    CHECK(*o.finest_eps == 0.5);
    CHECK(o.eps_levels == std::vector<double>{1, 2.5});
    CHECK(o.datum == tb::tiler::VerticalDatum::Ellipsoid);
    CHECK(cfg.layers[0].formats ==
          std::vector<tb::tiler::Format>{tb::tiler::Format::Drc, tb::tiler::Format::Mapbox});
    CHECK(o.dem_tile_size == 256);
    CHECK(o.dem_heights == tb::tiler::DemHeights::Ellipsoid);
    CHECK(*cfg.layers[0].store == (dir.path / "out/tiles.sqlite").string());
}

TEST_CASE("every problem of a bad config is reported together with its JSON pointer") {
    TempDir dir;
    write_file(dir / "ok.hgt", "");
    const std::string path = dir / "bad.json";
    const std::string message = config_error(R"({
      "server": {"port": 80000, "threads": "four", "colour": "blue", "cors_origins": ["ftp://x"],
                 "log_level": "loud", "cache_mb": -1},
      "layers": [
        {"name": "a", "sources": ["missing.tif"], "finest_eps": -1, "tile_size": 1,
         "min_zoom": 9, "max_zoom": 4, "formats": ["png"], "datum": 3, "extra": true},
        {"name": "a", "sources": ["ok.hgt"], "eps_levels": [0.0001], "store": "nodir/x.sqlite",
         "dem_tile_size": 300, "dem_heights": "geoid"},
        {"name": "bad name!", "sources": "ok.hgt"},
        {"sources": []}
      ],
      "verbose": true})",
                                             path);
    INFO(message);
    const std::vector<std::string> expected = {
        path + ": /server/port: expected an integer 0..65535, got 80000",
        path + ": /server/threads: expected an integer 0..256, got \"four\"",
        path + ": /server/colour: unknown key",
        path + ": /server/cors_origins/0: expected \"*\" or an origin",
        path + ": /server/log_level: expected one of \"debug\"",
        path + ": /server/cache_mb: expected an integer 0..",
        path + ": /layers/0/sources/0: file not found: " + (dir.path / "missing.tif").string(),
        path + ": /layers/0/finest_eps: expected a number > 0, got -1",
        path + ": /layers/0/tile_size: expected an integer 2..4096, got 1",
        path + ": /layers/0/max_zoom: expected max_zoom >= min_zoom (9), got 4",
        path + ": /layers/0/formats/0: expected one of \"glb\", \"drc\", \"terrarium\", "
               "\"mapbox\", \"terrain\", \"terrain3d\", got \"png\"",
        path + ": /layers/0/datum: expected one of \"auto\"",
        path + ": /layers/0/extra: unknown key",
        path + ": /layers/1/name: duplicate layer name \"a\" (also /layers/0/name)",
        path + ": /layers/1/eps_levels/0: expected at least 0.001",
        path + ": /layers/1/dem_tile_size: expected 256 or 512, got 300",
        path + ": /layers/1/dem_heights: expected one of \"sea_level\", \"ellipsoid\", got "
               "\"geoid\"",
        path + ": /layers/1/store: directory " + (dir.path / "nodir").string() + " does not exist",
        path + ": /layers/2/name: expected 1..64 characters",
        path + ": /layers/2/sources: expected an array, got string",
        path + ": /layers/3/name: missing",
        path + ": /layers/3/sources: expected at least one DEM path",
        path + ": /verbose: unknown key",
    };
    for (const auto& line : expected) {
        CHECK_MESSAGE(message.find(line) != std::string::npos, "missing: " << line);
    }
    CHECK(message.find("23 problems in " + path) == 0);
}

TEST_CASE("a config that is not JSON names the file and the position") {
    const std::string message = config_error("{\"layers\": [\n  {\"name\": }]}", "x.json");
    CHECK(message.find("x.json: not valid JSON") == 0);
    CHECK(message.find("line 2") != std::string::npos);
    CHECK(config_error("[1, 2]", "y.json") == "y.json: /: expected an object, got array [1,2]");
    CHECK(config_error("{}", "z.json") ==
          "z.json: /layers: missing; a config needs at least one layer");
}

TEST_CASE("a JSON pointer escapes ~ and / in unknown keys") {
    TempDir dir;
    write_file(dir / "a.tif", "");
    const std::string message = config_error(
        R"({"layers": [{"name": "x", "sources": ["a.tif"], "a/b~c": 1}]})", dir / "c.json");
    CHECK(message.find("/layers/0/a~1b~0c: unknown key") != std::string::npos);
}

TEST_CASE("layer names derived from DEM paths are URL-safe") {
    using tb::config::is_valid_layer_name;
    using tb::config::layer_name_from_path;
    CHECK(layer_name_from_path("data/N57E011.hgt") == "N57E011");
    CHECK(layer_name_from_path("/x/N48W125.hgt.zip") == "N48W125");
    CHECK(layer_name_from_path("my dem (v2).tif") == "my_dem_v2");
    CHECK(layer_name_from_path("/x/%%%.tif") == "terrain");
    CHECK(is_valid_layer_name(layer_name_from_path("Ärger über Höhen.tif")));
    CHECK(!is_valid_layer_name(""));
    CHECK(!is_valid_layer_name("a/b"));
    CHECK(!is_valid_layer_name(".."));
    CHECK(is_valid_layer_name("alps_2-x"));
}

TEST_CASE("terrabound serve with a bad config lists every error and exits 2 without starting") {
    TempDir dir;
    const std::string path = dir / "bad.json";
    write_file(path, R"({"server": {"port": -5},
                         "layers": [{"name": "t", "sources": ["nope.hgt"], "finest_eps": -1}]})");
    std::string output;
    const int code = run_command(std::string(TB_BINARY) + " serve " + path, output);
    INFO(output);
    CHECK(code == 2);
    CHECK(output.find(path + ": /server/port: expected an integer 0..65535, got -5") !=
          std::string::npos);
    CHECK(output.find(path + ": /layers/0/sources/0: file not found") != std::string::npos);
    CHECK(output.find(path + ": /layers/0/finest_eps: expected a number > 0, got -1") !=
          std::string::npos);
    CHECK(output.find("serving") == std::string::npos);
}

TEST_CASE("the example configs in config/ are valid") {
    const std::string dem = std::string(TB_SOURCE_DIR) + "/data/N57E011.hgt";
    if (!tb::test::fs::exists(dem)) {
        MESSAGE("skipped: " << dem << " is missing (scripts/setup.sh downloads it)");
        return;
    }
    for (const char* name : {"demo.json", "example.json"}) {
        const std::string path = std::string(TB_SOURCE_DIR) + "/config/" + name;
        INFO(path);
        const auto cfg = tb::config::load_config(path);
        CHECK(!cfg.layers.empty());
        for (const auto& layer : cfg.layers) {
            CHECK(layer.options.sources.at(0) == tb::test::fs::path(dem).lexically_normal());
        }
    }
}

TEST_CASE("summary_dir: off, or a directory resolved against the config's; anything else is "
          "named") {
    TempDir dir;
    write_file(dir / "a.asc", "");
    const std::string path = dir / "site.json";
    const auto parse = [&](const std::string& value) {
        return tb::config::parse_config(
            R"({"layers": [{"name": "a", "sources": ["a.asc"], "summary_dir": )" + value + "}]}",
            path);
    };
    CHECK(parse("null").layers[0].options.summary_dir.empty());
    CHECK(parse(R"("off")").layers[0].options.summary_dir == "off");
    CHECK(parse(R"("cache/sums")").layers[0].options.summary_dir == dir / "cache/sums");
    CHECK(parse(R"("/var/cache/tb")").layers[0].options.summary_dir == "/var/cache/tb");
    for (const char* bad : {R"("")", "3", "[]"}) {
        CAPTURE(bad);
        CHECK_THROWS_WITH_AS(parse(bad),
                             doctest::Contains("/layers/0/summary_dir: expected null, \"off\" or "
                                               "a directory"),
                             tb::InputError);
    }
}

TEST_CASE("valid_range: [MIN, MAX] with MIN < MAX; anything else is named") {
    TempDir dir;
    write_file(dir / "a.asc", "");
    const std::string path = dir / "site.json";
    const auto parse = [&](const std::string& value) {
        return tb::config::parse_config(
            R"({"layers": [{"name": "a", "sources": ["a.asc"], "valid_range": )" + value + "}]}",
            path);
    };
    const auto r = parse("[-500, 12000]").layers[0].options.valid_range;
    CHECK(r.low == -500);
    CHECK(r.high == 12000);
    for (const char* bad : {"null", "[1]", "[5, 1]", "[1, 1]", R"(["a", 2])", "[1, 2, 3]"}) {
        CAPTURE(bad);
        CHECK_THROWS_WITH_AS(
            parse(bad),
            doctest::Contains(
                "/layers/0/valid_range: expected [MIN, MAX] in metres with MIN < MAX"),
            tb::InputError);
    }
}

TEST_CASE("priority: \"finest\" (the default) or \"listed\"; anything else is named") {
    TempDir dir;
    write_file(dir / "a.asc", "");
    const std::string path = dir / "site.json";
    const auto parse = [&](const std::string& field) {
        return tb::config::parse_config(
            R"({"layers": [{"name": "a", "sources": ["a.asc"])" + field + "}]}", path);
    };
    CHECK(parse("").layers[0].options.priority == tb::tiler::SourcePriority::Finest);
    CHECK(parse(R"(, "priority": "listed")").layers[0].options.priority ==
          tb::tiler::SourcePriority::Listed);
    CHECK_THROWS_WITH_AS(parse(R"(, "priority": "first")"),
                         doctest::Contains(R"(/layers/0/priority: expected one of "finest", )"
                                           R"("listed", got "first")"),
                         tb::InputError);
    CHECK_THROWS_WITH_AS(
        parse(R"(, "priority": 1)"), doctest::Contains("/layers/0/priority"), tb::InputError);
}
