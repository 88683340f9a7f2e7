// The MBTiles 1.3 store: byte-exact round trips with TMS rows, the spec's metadata, what one
// file refuses, and a build that GDAL's MBTiles driver reads back tile for tile.
#include "container_util.hpp"
#include "core/error.hpp"
#include "tiler/stores/store.hpp"

#include <doctest/doctest.h>
#include <gdal.h>
#include <sqlite3.h>

#include <cstdio>
#include <map>
#include <string>

using namespace tb::tiler;
using namespace container_test;

namespace {

TileKey dem_key(int z, std::int64_t x, std::int64_t y, Format f = Format::Terrarium) {
    return TileKey{"hills", TileId{z, x, y}, f, -1};
}

// metadata(name, value) of an MBTiles file, read with SQLite alone.
std::map<std::string, std::string> metadata_of(const std::string& path) {
    std::map<std::string, std::string> meta;
    sqlite3* db = nullptr;
    REQUIRE(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK);
    sqlite3_stmt* s = nullptr;
    REQUIRE(sqlite3_prepare_v2(db, "SELECT name, value FROM metadata", -1, &s, nullptr) ==
            SQLITE_OK);
    while (sqlite3_step(s) == SQLITE_ROW) {
        meta[reinterpret_cast<const char*>(sqlite3_column_text(s, 0))] =
            reinterpret_cast<const char*>(sqlite3_column_text(s, 1));
    }
    sqlite3_finalize(s);
    sqlite3_close(db);
    return meta;
}

// The tile_data of (zoom_level, tile_column, tile_row), or "(none)".
std::string raw_tile(const std::string& path, int z, std::int64_t col, std::int64_t row) {
    sqlite3* db = nullptr;
    REQUIRE(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK);
    sqlite3_stmt* s = nullptr;
    REQUIRE(sqlite3_prepare_v2(db,
                               "SELECT tile_data FROM tiles WHERE zoom_level=?1 AND "
                               "tile_column=?2 AND tile_row=?3",
                               -1,
                               &s,
                               nullptr) == SQLITE_OK);
    sqlite3_bind_int(s, 1, z);
    sqlite3_bind_int64(s, 2, col);
    sqlite3_bind_int64(s, 3, row);
    std::string out = "(none)";
    if (sqlite3_step(s) == SQLITE_ROW) {
        out.assign(static_cast<const char*>(sqlite3_column_blob(s, 0)),
                   static_cast<std::size_t>(sqlite3_column_bytes(s, 0)));
    }
    sqlite3_finalize(s);
    sqlite3_close(db);
    return out;
}

// Runs `sql` on the SQLite file at `path`, as another program would.
void raw_exec(const std::string& path, const std::string& sql) {
    sqlite3* db = nullptr;
    REQUIRE(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE, nullptr) == SQLITE_OK);
    char* message = nullptr;
    const int rc = sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &message);
    INFO(sql << ": " << (message ? message : ""));
    sqlite3_free(message);
    sqlite3_close(db);
    REQUIRE(rc == SQLITE_OK);
}

// The pixels (all bands, band-interleaved) of `ds`'s window, as GDAL reads them.
std::vector<unsigned char> pixels(GDALDatasetH ds, int x, int y, int w, int h, int bands) {
    std::vector<unsigned char> out(static_cast<std::size_t>(w) * h * bands);
    REQUIRE(GDALDatasetRasterIO(
                ds, GF_Read, x, y, w, h, out.data(), w, h, GDT_Byte, bands, nullptr, 0, 0, 0) ==
            CE_None);
    return out;
}

} // namespace

TEST_CASE("an mbtiles store round-trips DEM tiles byte for byte in TMS rows, with documents") {
    TempDir dir;
    const std::string path = dir / "out.mbtiles";
    {
        auto store = TileStore::open(path);
        CHECK(store->describe() == "mbtiles " + path);
        CHECK_FALSE(store->has_layer("hills"));
        store->put_document("hills", "build-manifest.json", "{\"eps\": 1}\n");
        store->put(dem_key(0, 0, 0), std::string("\0png\xff", 5));
        store->put(dem_key(3, 5, 1), "z3");
        store->put(dem_key(3, 5, 1), "z3 again"); // replaces
        store->put(dem_key(12, 4095, 4095), "");
        store->finish();
    }
    auto store = TileStore::open(path); // what was written is in the file
    CHECK(store->has_layer("hills"));
    CHECK(store->get(dem_key(0, 0, 0)) == std::string("\0png\xff", 5));
    CHECK(store->get(dem_key(3, 5, 1)) == "z3 again");
    CHECK(store->get(dem_key(12, 4095, 4095)) == "");
    CHECK_FALSE(store->contains(dem_key(3, 5, 2)));
    CHECK_FALSE(store->get(dem_key(3, 5, 1, Format::Mapbox)).has_value());
    CHECK(store->get_document("hills", "build-manifest.json") == "{\"eps\": 1}\n");
    CHECK_FALSE(store->get_document("hills", "tileset.json").has_value());
    // XYZ row y is stored as TMS row 2^z - 1 - y.
    CHECK(raw_tile(path, 3, 5, 6) == "z3 again");
    CHECK(raw_tile(path, 12, 4095, 0) == "");
    CHECK(raw_tile(path, 3, 5, 1) == "(none)");

    const auto meta = metadata_of(path);
    CHECK(meta.at("name") == "hills");
    CHECK(meta.at("format") == "png");
    CHECK(meta.at("encoding") == "terrarium");
    CHECK(meta.at("type") == "baselayer");
    CHECK(meta.at("minzoom") == "0");
    CHECK(meta.at("maxzoom") == "12");
    CHECK(meta.count("description") == 1);
    // Zoom 12's only tile, the south-east corner of the world.
    double w = 0, s = 0, e = 0, n = 0;
    REQUIRE(std::sscanf(meta.at("bounds").c_str(), "%lf,%lf,%lf,%lf", &w, &s, &e, &n) == 4);
    CHECK(w == doctest::Approx(180 - 360.0 / 4096));
    CHECK(s == doctest::Approx(-85.0511287798));
    CHECK(e == doctest::Approx(180));
    CHECK(n == doctest::Approx(-85.0435409457));
    CHECK(meta.at("center").ends_with(",6"));

    store->remove_layer("hills");
    CHECK_FALSE(store->has_layer("hills"));
    CHECK_FALSE(store->get(dem_key(0, 0, 0)).has_value());
    CHECK(metadata_of(path).empty());
}

TEST_CASE("a damaged mbtiles or pmtiles-staging tile reads as missing, is made again, and "
          "stops a pmtiles archive from being assembled") {
    TempDir dir;
    const std::string path = dir / "out.mbtiles";
    {
        auto store = TileStore::open(path);
        store->put(dem_key(3, 5, 1), "good bytes");
        store->put(dem_key(3, 5, 2), "other bytes");
        store->finish();
    }
    // One bit of (3, 5, 1) flipped (TMS row 6), and a tile another program added (no checksum).
    raw_exec(path,
             "UPDATE tiles SET tile_data = CAST('good byteS' AS BLOB) WHERE zoom_level=3"
             " AND tile_column=5 AND tile_row=6;"
             "INSERT INTO tiles VALUES(4, 0, 15, CAST('theirs' AS BLOB));");
    {
        auto store = TileStore::open(path);
        CHECK_FALSE(store->get(dem_key(3, 5, 1)).has_value());
        CHECK_FALSE(store->contains(dem_key(3, 5, 1))); // so --resume makes it again
        CHECK(store->get(dem_key(3, 5, 2)) == "other bytes");
        CHECK(store->get(dem_key(4, 0, 0)) == "theirs");
        store->put(dem_key(3, 5, 1), "good bytes");
        CHECK(store->get(dem_key(3, 5, 1)) == "good bytes");
    }
    // The PMTiles store stages its tiles in such a file: a damaged staged tile is refused when
    // the archive is assembled, naming it, instead of being published.
    const std::string archive = dir / "out.pmtiles";
    {
        auto store = TileStore::open(archive);
        store->put(dem_key(2, 1, 1), "staged bytes");
    }
    raw_exec(archive + ".staging", "UPDATE tiles SET tile_data = CAST('staged bytez' AS BLOB);");
    auto store = TileStore::open(archive);
    CHECK_FALSE(store->get(dem_key(2, 1, 1)).has_value());
    try {
        store->finish();
        FAIL("a damaged staged tile was published");
    } catch (const tb::IoError& e) {
        CHECK(std::string(e.what()).find("tile 2/1/1 is damaged") != std::string::npos);
    }
}

TEST_CASE("an mbtiles store refuses mesh formats, a second layer or encoding, and non-XYZ tiles") {
    TempDir dir;
    const std::string path = dir / "out.mbtiles";
    auto store = TileStore::open(path);
    store->put(dem_key(1, 1, 0), "a");
    const auto refuses = [&](const TileKey& key, const std::string& words) {
        try {
            store->put(key, "b");
            FAIL("accepted " << words);
        } catch (const tb::InputError& e) {
            CHECK_MESSAGE(std::string(e.what()).find(words) != std::string::npos, e.what());
        }
    };
    refuses(dem_key(1, 1, 0, Format::Glb), "raster DEM tiles (terrarium or mapbox) only, not glb");
    refuses(dem_key(1, 1, 0, Format::Mapbox), "holds terrarium DEM tiles");
    refuses(TileKey{"other", TileId{1, 1, 0}, Format::Terrarium, -1}, "holds layer 'hills'");
    refuses(dem_key(1, 1, 2), "outside EPSG:3857 XYZ");
    CHECK_THROWS_AS(store->put_document("other", "build-manifest.json", "{}"), tb::InputError);
    // A refused batch leaves nothing of itself behind.
    const std::vector<StoredTile> batch{{dem_key(2, 0, 0), "c"},
                                        {dem_key(2, 0, 1, Format::Drc), "d"}};
    CHECK_THROWS_AS(store->put_batch(batch), tb::InputError);
    CHECK_FALSE(store->contains(dem_key(2, 0, 0)));
    CHECK(store->get(dem_key(1, 1, 0)) == "a");
}

TEST_CASE("build -o OUT.mbtiles writes what GDAL's MBTiles driver reads, tile for tile, and "
          "--resume keeps it") {
    TempDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const std::string out = dir / "out.mbtiles";
    const Run a = run(build_args(dem, out, "terrarium", {"--layer", "hills"}), dir);
    INFO(a.err);
    REQUIRE(a.code == 0);
    CHECK_FALSE(fs::exists(out + "-wal"));
    CHECK_FALSE(fs::exists(out + ".build.lock"));

    const auto expected = expected_dem_tiles(dem, Format::Terrarium);
    REQUIRE(expected.size() >= 2);
    int min_z = 99, max_z = -1;
    auto store = TileStore::open(out);
    for (const auto& [id, bytes] : expected) {
        CHECK(store->get(TileKey{"hills", id, Format::Terrarium, -1}) == bytes);
        min_z = std::min(min_z, id.z);
        max_z = std::max(max_z, id.z);
    }
    store.reset();
    const auto meta = metadata_of(out);
    CHECK(meta.at("name") == "hills");
    CHECK(meta.at("format") == "png");
    CHECK(meta.at("encoding") == "terrarium");
    CHECK(meta.at("minzoom") == std::to_string(min_z));
    CHECK(meta.at("maxzoom") == std::to_string(max_z));

    // GDAL: the finest zoom's tiles make the full-resolution raster, coarser zooms its
    // overviews, and the north-west tile's pixels are that tile's PNG (rows flipped right).
    const char* drivers[] = {"MBTiles", nullptr};
    GDALDatasetH ds =
        GDALOpenEx(out.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, drivers, nullptr, nullptr);
    REQUIRE(ds != nullptr);
    std::int64_t x0 = INT64_MAX, x1 = -1, y0 = INT64_MAX, y1 = -1;
    for (const auto& [id, bytes] : expected) {
        if (id.z == max_z) {
            x0 = std::min(x0, id.x), x1 = std::max(x1, id.x);
            y0 = std::min(y0, id.y), y1 = std::max(y1, id.y);
        }
    }
    CHECK(GDALGetRasterXSize(ds) == (x1 - x0 + 1) * 256);
    CHECK(GDALGetRasterYSize(ds) == (y1 - y0 + 1) * 256);
    CHECK(GDALGetRasterCount(ds) >= 3); // GDAL adds an alpha band to RGB tiles
    CHECK(GDALGetRasterColorInterpretation(GDALGetRasterBand(ds, 1)) == GCI_RedBand);
    const auto item = [&](const char* key) {
        const char* value = GDALGetMetadataItem(ds, key, nullptr);
        return std::string(value ? value : "(none)");
    };
    CHECK(item("ZOOM_LEVEL") == std::to_string(max_z));
    CHECK(item("minzoom") == std::to_string(min_z));
    CHECK(item("encoding") == "terrarium");
    const std::string png = expected.at(TileId{max_z, x0, y0});
    VSIFCloseL(VSIFileFromMemBuffer("/vsimem/tb-nw.png",
                                    reinterpret_cast<GByte*>(const_cast<char*>(png.data())),
                                    static_cast<vsi_l_offset>(png.size()),
                                    FALSE));
    GDALDatasetH tile = GDALOpen("/vsimem/tb-nw.png", GA_ReadOnly);
    REQUIRE(tile != nullptr);
    CHECK(pixels(ds, 0, 0, 256, 256, 3) == pixels(tile, 0, 0, 256, 256, 3));
    GDALClose(tile);
    VSIUnlink("/vsimem/tb-nw.png");
    GDALClose(ds);

    const Run b =
        run(build_args(dem, out, "terrarium", {"--layer", "hills", "--resume", "--json"}), dir);
    INFO(b.err);
    REQUIRE(b.code == 0);
    CHECK(b.out.find("\"written\":0,") != std::string::npos);
    CHECK(metadata_of(out) == meta);
}

TEST_CASE("build -o OUT.mbtiles refuses mesh formats and two DEM encodings, saying what to do") {
    TempDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const std::string out = dir / "out.mbtiles";
    const Run glb = run({"build", dem, "-o", out, "--formats", "glb"}, dir);
    CHECK(glb.code == 2);
    CHECK(glb.err.find("holds raster DEM tiles (terrarium or mapbox, EPSG:3857 XYZ PNG) only, not "
                       "glb; build --formats terrarium") != std::string::npos);
    const Run two = run(build_args(dem, out, "terrarium,mapbox"), dir);
    CHECK(two.code == 2);
    CHECK(two.err.find("exactly one DEM encoding, and --formats names terrarium and mapbox; build "
                       "each encoding into its own file") != std::string::npos);
    CHECK_FALSE(fs::exists(out));
}
