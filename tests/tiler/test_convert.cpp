// build STORE.sqlite -o OUT.mbtiles|OUT.pmtiles: a Terrabound SQLite store's DEM tiles copied
// into a container equal to a build straight into it (tile for tile, metadata, and for PMTiles
// byte for byte), and what a conversion refuses, leaving no output behind.
#include "container_util.hpp"
#include "tiler/stores/store.hpp"

#include <doctest/doctest.h>
#include <sqlite3.h>

#include <string>
#include <vector>

using namespace tb::tiler;
using namespace container_test;

namespace {

// Every row of `sql` on the SQLite file at `path`, its columns joined by '|'.
std::vector<std::string> rows_of(const std::string& path, const std::string& sql) {
    sqlite3* db = nullptr;
    REQUIRE(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK);
    sqlite3_stmt* s = nullptr;
    REQUIRE(sqlite3_prepare_v2(db, sql.c_str(), -1, &s, nullptr) == SQLITE_OK);
    std::vector<std::string> rows;
    while (sqlite3_step(s) == SQLITE_ROW) {
        std::string row;
        for (int i = 0; i < sqlite3_column_count(s); ++i) {
            const void* data = sqlite3_column_blob(s, i);
            row += std::string(i ? "|" : "") +
                   (data ? std::string(static_cast<const char*>(data),
                                       static_cast<std::size_t>(sqlite3_column_bytes(s, i)))
                         : std::string("(null)"));
        }
        rows.push_back(row);
    }
    sqlite3_finalize(s);
    sqlite3_close(db);
    return rows;
}

void exec_sql(const std::string& path, const std::string& sql) {
    sqlite3* db = nullptr;
    REQUIRE(sqlite3_open(path.c_str(), &db) == SQLITE_OK);
    CHECK(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr) == SQLITE_OK);
    sqlite3_close(db);
}

// What an MBTiles file holds, for comparing two: tiles, metadata and documents.
std::vector<std::string> mbtiles_content(const std::string& path) {
    std::vector<std::string> all;
    for (const char* sql :
         {"SELECT zoom_level, tile_column, tile_row, tile_data FROM tiles ORDER BY 1, 2, 3",
          "SELECT name, value FROM metadata ORDER BY name",
          "SELECT layer, name, data FROM terrabound_documents ORDER BY 1, 2"}) {
        for (auto& row : rows_of(path, sql)) {
            all.push_back(std::move(row));
        }
    }
    return all;
}

// A store holding layer hills in glb, terrarium and mapbox, as `build -o STORE.sqlite` makes it.
std::string build_store(const TempDir& dir, const std::string& dem) {
    const std::string store = dir / "tiles.sqlite";
    const Run r = run(build_args(dem, store, "glb,terrarium,mapbox", {"--layer", "hills"}), dir);
    INFO(r.err);
    REQUIRE(r.code == 0);
    return store;
}

} // namespace

TEST_CASE("build STORE.sqlite -o OUT.mbtiles / OUT.pmtiles equals a build straight into the "
          "container, tile for tile and metadata, and leaves the store as it was") {
    TempDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const std::string store = build_store(dir, dem);
    const std::string store_bytes = slurp(store);

    for (const std::string ext : {".mbtiles", ".pmtiles"}) {
        CAPTURE(ext);
        const std::string direct = dir / ("direct" + ext), converted = dir / ("converted" + ext);
        const Run d = run(build_args(dem, direct, "terrarium", {"--layer", "hills"}), dir);
        INFO(d.err);
        REQUIRE(d.code == 0);
        const Run c =
            run({"build", store, "-o", converted, "--formats", "terrarium", "--json"}, dir);
        INFO(c.err);
        REQUIRE(c.code == 0);
        CHECK(c.err.find("converted") != std::string::npos);
        CHECK(c.out.find("\"interrupted\":false") != std::string::npos);
        if (ext == ".pmtiles") {
            CHECK(slurp(converted) == slurp(direct)); // header, metadata, directories, tiles
        } else {
            const auto want = mbtiles_content(direct);
            CHECK(want.size() > 5);
            CHECK(mbtiles_content(converted) == want);
        }
        for (const char* left : {".converting", ".build.lock", "-wal", "-journal", ".staging"}) {
            CHECK_FALSE(fs::exists(converted + left));
        }
        // Its manifest is a direct build's: --resume from the DEM finds every tile in.
        const Run resume =
            run(build_args(dem, converted, "terrarium", {"--layer", "hills", "--resume", "--json"}),
                dir);
        INFO(resume.err);
        CHECK(resume.code == 0);
        CHECK(resume.out.find("\"written\":0,") != std::string::npos);
    }

    // The other encoding, read back through the container's store.
    const std::string mapbox = dir / "mapbox.pmtiles";
    const Run m = run({"build", store, "-o", mapbox, "--formats", "mapbox"}, dir);
    INFO(m.err);
    REQUIRE(m.code == 0);
    const auto source = TileStore::open(store);
    const auto container = TileStore::open(mapbox);
    const auto expected = expected_dem_tiles(dem, Format::Mapbox);
    for (const auto& [id, bytes] : expected) {
        const TileKey key{"hills", id, Format::Mapbox, -1};
        CHECK(container->get(key) == bytes);
        CHECK(source->get(key) == bytes);
    }
    CHECK(slurp(store) == store_bytes);
}

TEST_CASE("converting refuses what is not a Terrabound store, and an encoding or layer it lacks, "
          "listing what the store holds") {
    TempDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const std::string store = build_store(dir, dem);
    const std::string out = dir / "out.pmtiles";

    const std::string garbage = dir / "garbage.sqlite";
    std::ofstream(garbage) << "not an SQLite file at all, but long enough to look at........";
    const Run g = run({"build", garbage, "-o", out}, dir);
    CHECK(g.code == 2);
    CHECK(g.err.find("garbage.sqlite: not a Terrabound store") != std::string::npos);

    const std::string other = dir / "other.db";
    exec_sql(other, "CREATE TABLE t(a)");
    const Run o = run({"build", other, "-o", out}, dir);
    CHECK(o.code == 2);
    CHECK(o.err.find("other.db: not a Terrabound store") != std::string::npos);
    CHECK(rows_of(other, "SELECT name FROM sqlite_master") == std::vector<std::string>{"t"});

    const Run two = run({"build", store, "-o", out}, dir);
    CHECK(two.code == 2);
    CHECK(two.err.find("layer hills holds glb ") != std::string::npos);
    CHECK(two.err.find(", mapbox ") != std::string::npos);
    CHECK(two.err.find("choose one encoding with --formats terrarium or --formats mapbox") !=
          std::string::npos);

    const Run layer = run({"build", store, "-o", out, "--layer", "nope"}, dir);
    CHECK(layer.code == 2);
    CHECK(layer.err.find("holds layer hills (glb ") != std::string::npos);
    CHECK(layer.err.find("no layer nope") != std::string::npos);

    const Run glb = run({"build", store, "-o", out, "--formats", "glb"}, dir);
    CHECK(glb.code == 2);
    CHECK(glb.err.find("raster DEM tiles only") != std::string::npos);

    const Run dir_out = run({"build", store, "-o", dir / "tree", "--formats", "mapbox"}, dir);
    CHECK(dir_out.code == 2);
    CHECK(dir_out.err.find("name it -o OUT.mbtiles or -o OUT.pmtiles") != std::string::npos);

    const Run resume = run({"build", store, "-o", out, "--formats", "mapbox", "--resume"}, dir);
    CHECK(resume.code == 2);
    CHECK(resume.err.find("--resume does not apply when converting") != std::string::npos);

    // Tiles a server cached (no build manifest) are no pyramid.
    const std::string cache = dir / "cache.sqlite";
    TileStore::open(cache)->put(TileKey{"hills", TileId{0, 0, 0}, Format::Terrarium, -1}, "png");
    const Run cached = run({"build", cache, "-o", out}, dir);
    CHECK(cached.code == 2);
    CHECK(cached.err.find("has no build-manifest.json") != std::string::npos);
    CHECK_FALSE(fs::exists(out));
}

TEST_CASE("converting over an existing output needs --force, and a damaged tile leaves the "
          "output as it was") {
    TempDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const std::string store = build_store(dir, dem);
    for (const std::string ext : {".mbtiles", ".pmtiles"}) {
        CAPTURE(ext);
        const std::string out = dir / ("out" + ext);
        const std::vector<std::string> args{"build", store, "-o", out, "--formats", "terrarium"};
        REQUIRE(run(args, dir).code == 0);
        const std::string first = slurp(out);
        const Run again = run(args, dir);
        CHECK(again.code == 2);
        CHECK(again.err.find(out + " exists; use --force to replace it") != std::string::npos);
        auto forced = args;
        forced.push_back("--force");
        const Run f = run(forced, dir);
        INFO(f.err);
        CHECK(f.code == 0);
        CHECK(slurp(out) == first);
    }

    // One flipped byte in the middle of the copy: exit 3, naming the tile, nothing replaced.
    exec_sql(store,
             "UPDATE tiles SET data = CAST('broken' AS BLOB) WHERE format='terrarium' AND "
             "rowid = (SELECT rowid FROM tiles WHERE format='terrarium' ORDER BY z DESC LIMIT 1)");
    for (const std::string ext : {".mbtiles", ".pmtiles"}) {
        CAPTURE(ext);
        const std::string out = dir / ("out" + ext);
        const std::string before = slurp(out);
        const Run r = run({"build", store, "-o", out, "--formats", "terrarium", "--force"}, dir);
        CHECK(r.code == 3);
        CHECK(r.err.find("is damaged") != std::string::npos);
        CHECK(r.err.find("--resume") != std::string::npos);
        CHECK(slurp(out) == before);
        CHECK_FALSE(fs::exists(out + ".converting"));
        for (const auto& entry : fs::directory_iterator(dir.path)) {
            CHECK(entry.path().filename().string().find(".tmp-") == std::string::npos);
        }
    }
}
