// `terrabound serve` with a single-file container a build wrote (.mbtiles, .pmtiles) as a
// layer's store: the raster DEM tiles come from the file, every other tile is made and kept in
// memory without a refused write per tile, the file is left as built, and a .pmtiles that does
// not exist yet is refused at startup.
#include "serve_process.hpp"
#include "server_fixture.hpp"

#include <doctest/doctest.h>

#include <signal.h>

#include <filesystem>

namespace {

using namespace tb;

std::string config_for(const std::string& store) {
    return R"({"server": {"threads": 1}, "layers": [{"name": "hills", "sources": ["hills.asc"],
           "tile_size": 64, "min_zoom": 5, "max_zoom": 8, "dem_tile_size": 256,
           "store": ")" +
           store + R"("}]})";
}

} // namespace

TEST_CASE("serve reads DEM tiles from a built .mbtiles or .pmtiles, makes the rest in memory "
          "without a refused write per tile, and leaves the file as built") {
    for (const std::string file : {"hills.mbtiles", "hills.pmtiles"}) {
        CAPTURE(file);
        test::TempDir dir;
        test::write_dem(dir / "hills.asc", 257);
        REQUIRE(test::run_to_exit({"build",
                                   dir / "hills.asc",
                                   "-o",
                                   dir / file,
                                   "--layer",
                                   "hills",
                                   "--size",
                                   "64",
                                   "--min-zoom",
                                   "5",
                                   "--max-zoom",
                                   "8",
                                   "--dem-size",
                                   "256"},
                                  dir / "build.log") == 0);
        const std::string built = test::read_file(dir / file);
        test::write_file(dir / "serve.json", config_for(file));
        test::Child child;
        const int port = test::start_server(child, {dir / "serve.json"}, dir / "serve.log");
        httplib::Client c("127.0.0.1", port);
        const auto dem = c.Get("/hills/dem/8/135/77.png");
        REQUIRE(dem);
        CHECK(dem->status == 200);
        for (const char* path : {"/hills/8/272/210.glb",
                                 "/hills/8/272/210.terrain",
                                 "/hills/dem/8/135/77.png?encoding=mapbox"}) {
            CAPTURE(path);
            const auto res = c.Get(path);
            REQUIRE(res);
            CHECK(res->status == 200);
        }
        const auto metrics = c.Get("/metrics");
        REQUIRE(metrics);
        CHECK(metrics->body.find("tb_store_hits_total 1\n") != std::string::npos);
        kill(child.pid, SIGTERM);
        CHECK(child.wait_exit() == 0);
        const std::string log = test::read_file(dir / "serve.log");
        CHECK(log.find("tile not stored") == std::string::npos);
        if (file.ends_with(".pmtiles")) {
            CHECK(test::read_file(dir / file) == built); // the archive is read-only
        }
    }
}

TEST_CASE("serve refuses a .pmtiles store that does not exist, saying a build makes it") {
    test::TempDir dir;
    test::write_dem(dir / "hills.asc", 257);
    test::write_file(dir / "serve.json", config_for("new.pmtiles"));
    CHECK(test::run_to_exit({"serve", dir / "serve.json", "--port", "0"}, dir / "serve.log") == 2);
    CHECK(test::read_file(dir / "serve.log")
              .find("does not exist; serve reads a .pmtiles archive that terrabound build made") !=
          std::string::npos);
    CHECK_FALSE(std::filesystem::exists(dir / "new.pmtiles.staging"));
}
