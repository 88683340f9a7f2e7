// The PMTiles v3 store: Hilbert tile ids, directories, archives read back byte for byte (leaf
// directories, runs, shared contents, documents), a finished archive being read-only, damaged
// files refused without a crash, and a build into OUT.pmtiles that --resume keeps.
#include "container_util.hpp"
#include "core/error.hpp"
#include "tiler/stores/pmtiles_format.hpp"
#include "tiler/stores/store.hpp"

#include <doctest/doctest.h>

#include <map>
#include <random>
#include <set>
#include <string>

using namespace tb::tiler;
using namespace container_test;

namespace {

TileKey dem_key(const TileId& id, Format f = Format::Terrarium) {
    return TileKey{"hills", id, f, -1};
}

// The header of the archive at `path`.
pmtiles::Header header_of(const std::string& path) {
    return pmtiles::decode_header(slurp(path), fs::file_size(path), path);
}

std::string random_bytes(std::mt19937& rng, std::size_t n) {
    std::string s(n, '\0');
    for (auto& c : s) {
        c = static_cast<char>(rng() & 0xff);
    }
    return s;
}

} // namespace

TEST_CASE("pmtiles tile ids follow the Hilbert curve zoom by zoom, as the spec numbers them") {
    CHECK(pmtiles::tile_id({0, 0, 0}) == 0);
    CHECK(pmtiles::tile_id({1, 0, 0}) == 1);
    CHECK(pmtiles::tile_id({1, 0, 1}) == 2);
    CHECK(pmtiles::tile_id({1, 1, 1}) == 3);
    CHECK(pmtiles::tile_id({1, 1, 0}) == 4);
    CHECK(pmtiles::tile_id({2, 0, 0}) == 5);
    CHECK(pmtiles::tile_id({12, 3423, 1763}) == 19078479);
    // Each zoom's ids are a permutation of its range, neighbours on the curve are neighbours
    // on the grid, and tile_of inverts tile_id.
    for (int z = 0; z <= 6; ++z) {
        std::map<std::uint64_t, TileId> by_id;
        for (std::int64_t x = 0; x < (1 << z); ++x) {
            for (std::int64_t y = 0; y < (1 << z); ++y) {
                const auto id = pmtiles::tile_id({z, x, y});
                by_id[id] = TileId{z, x, y};
                CHECK(pmtiles::tile_of(id) == TileId{z, x, y});
            }
        }
        REQUIRE(by_id.size() == std::size_t{1} << (2 * z));
        CHECK(by_id.begin()->first == ((std::uint64_t{1} << (2 * z)) - 1) / 3);
        CHECK(by_id.rbegin()->first + 1 == ((std::uint64_t{1} << (2 * z + 2)) - 1) / 3);
        TileId prev = by_id.begin()->second;
        for (const auto& [id, t] : by_id) {
            CHECK(std::abs(t.x - prev.x) + std::abs(t.y - prev.y) <= 1);
            prev = t;
        }
    }
    CHECK(pmtiles::tile_of(pmtiles::tile_id({24, 16777215, 3})) == TileId{24, 16777215, 3});
}

TEST_CASE("pmtiles headers and directories read back what was written") {
    pmtiles::Header h;
    h.root_offset = 127;
    h.root_length = 10;
    h.metadata_offset = 137;
    h.metadata_length = 5;
    h.data_offset = 142;
    h.data_length = 100;
    h.clustered = true;
    h.min_lon_e7 = -1800000000;
    h.max_lat_e7 = 850511287;
    h.center_zoom = 7;
    const std::string bytes = pmtiles::encode_header(h);
    REQUIRE(bytes.size() == 127);
    const pmtiles::Header back = pmtiles::decode_header(bytes, 242, "x.pmtiles");
    CHECK(back.data_length == 100);
    CHECK(back.min_lon_e7 == -1800000000);
    CHECK(back.max_lat_e7 == 850511287);
    CHECK(back.clustered);
    CHECK(back.center_zoom == 7);
    CHECK_THROWS_AS(pmtiles::decode_header(bytes, 241, "x.pmtiles"), tb::InputError);

    const std::vector<pmtiles::Entry> entries{
        {5, 0, 10, 1}, {6, 10, 4, 3}, {9, 0, 10, 1}, {300000, 14, 86, 1}};
    const auto decoded = pmtiles::decode_directory(pmtiles::encode_directory(entries), 100, 0, "x");
    REQUIRE(decoded.size() == entries.size());
    for (std::size_t i = 0; i < entries.size(); ++i) {
        CHECK(decoded[i].tile_id == entries[i].tile_id);
        CHECK(decoded[i].offset == entries[i].offset);
        CHECK(decoded[i].length == entries[i].length);
        CHECK(decoded[i].run_length == entries[i].run_length);
    }
    // An entry past the tile data is damage.
    CHECK_THROWS_AS(pmtiles::decode_directory(pmtiles::encode_directory(entries), 99, 0, "x"),
                    tb::InputError);
    CHECK(pmtiles::gunzip(pmtiles::gzip("hello"), 5, "x") == "hello");
    CHECK_THROWS_AS(pmtiles::gunzip(pmtiles::gzip("hello"), 4, "x"), tb::InputError);
}

TEST_CASE("a pmtiles store's archive holds every tile byte for byte, with leaf directories, "
          "runs, shared contents and documents") {
    TempDir dir;
    const std::string path = dir / "out.pmtiles";
    std::mt19937 rng(7);
    std::map<TileId, std::string> tiles;
    // 40,000 distinct tiles at zoom 9 push the directory past 16 KiB, so it needs leaves.
    for (std::int64_t i = 0; i < 40000; ++i) {
        tiles[TileId{9, i % 512, i / 512}] = random_bytes(rng, 8 + rng() % 200);
    }
    // A block of sea: one content on 64 neighbouring tiles (runs along the curve, and shared
    // bytes where the curve leaves the block and comes back).
    for (std::int64_t x = 0; x < 8; ++x) {
        for (std::int64_t y = 0; y < 8; ++y) {
            tiles[TileId{6, x, y}] = "sea";
        }
    }
    tiles[TileId{0, 0, 0}] = std::string("\0root\xff", 6);
    const std::string manifest = "{\"eps\": 1,\n \"note\": \"tab\there, \xc3\xa9\"}\n";
    {
        auto store = TileStore::open(path);
        CHECK(store->describe() == "pmtiles " + path);
        store->put_document("hills", "build-manifest.json", manifest);
        std::vector<StoredTile> batch;
        for (const auto& [id, bytes] : tiles) {
            batch.push_back({dem_key(id), bytes});
        }
        store->put_batch(batch);
        CHECK(fs::exists(path + ".staging"));
        CHECK(store->get(dem_key({6, 3, 3})) == "sea"); // read from the staging file
        store->finish();
        CHECK_FALSE(fs::exists(path + ".staging"));
        CHECK(store->get(dem_key({6, 3, 3})) == "sea"); // read from the archive
    }
    const pmtiles::Header h = header_of(path);
    CHECK(h.leaf_length > 0);
    CHECK(h.root_offset + h.root_length <= 16384);
    CHECK(h.addressed_tiles == tiles.size());
    CHECK(h.tile_entries < tiles.size());
    CHECK(h.tile_contents == tiles.size() - 63);
    CHECK(h.clustered);
    CHECK(h.tile_type == pmtiles::kTileTypePng);
    CHECK(h.min_zoom == 0);
    CHECK(h.max_zoom == 9);

    auto store = TileStore::open(path);
    for (const auto& [id, bytes] : tiles) {
        REQUIRE(store->get(dem_key(id)) == bytes);
    }
    CHECK_FALSE(store->contains(dem_key({9, 511, 511})));
    CHECK_FALSE(store->contains(dem_key({6, 3, 3}, Format::Mapbox)));
    CHECK_FALSE(store->contains(TileKey{"other", {6, 3, 3}, Format::Terrarium, -1}));
    CHECK(store->get_document("hills", "build-manifest.json") == manifest);
    CHECK(store->has_layer("hills"));
    CHECK_FALSE(store->has_layer("other"));
}

TEST_CASE("a finished pmtiles archive is read-only until build --force starts it over") {
    TempDir dir;
    const std::string path = dir / "out.pmtiles";
    {
        auto store = TileStore::open(path);
        store->put_document("hills", "build-manifest.json", "{}");
        store->put(dem_key({1, 0, 0}), "a");
        store->finish();
    }
    auto store = TileStore::open(path);
    try {
        store->put(dem_key({1, 1, 0}), "b");
        FAIL("a finished archive took a tile");
    } catch (const tb::IoError& e) {
        CHECK(std::string(e.what()).find("a finished PMTiles archive is read-only; rebuild it "
                                         "with terrabound build --force") != std::string::npos);
    }
    store->put_document("hills", "build-manifest.json", "{}"); // as a resumed build does
    CHECK_THROWS_AS(store->put_document("hills", "build-manifest.json", "{\"x\":1}"), tb::IoError);
    CHECK_FALSE(fs::exists(path + ".staging"));

    store->remove_layer("hills");
    CHECK_FALSE(store->contains(dem_key({1, 0, 0})));
    store->put(dem_key({2, 1, 1}, Format::Mapbox), "c");
    store->finish();
    auto again = TileStore::open(path);
    CHECK(again->get(dem_key({2, 1, 1}, Format::Mapbox)) == "c");
    CHECK_FALSE(again->contains(dem_key({1, 0, 0})));
    CHECK_FALSE(again->get_document("hills", "build-manifest.json").has_value());
}

TEST_CASE("damaged pmtiles archives are refused naming the file, never read out of bounds") {
    TempDir dir;
    const std::string good_path = dir / "good.pmtiles";
    {
        auto store = TileStore::open(good_path);
        for (std::int64_t x = 0; x < 4; ++x) {
            store->put(dem_key({2, x, 1}), "tile" + std::to_string(x));
        }
        store->finish();
    }
    const std::string good = slurp(good_path);
    const std::string bad_path = dir / "bad.pmtiles";
    const auto try_open = [&](const std::string& bytes) {
        {
            std::ofstream out(bad_path, std::ios::binary | std::ios::trunc);
            out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
        }
        try {
            auto store = TileStore::open(bad_path);
            for (std::int64_t x = 0; x < 4; ++x) {
                const auto tile = store->get(dem_key({2, x, 1}));
                CHECK((!tile || tile->size() < 1000));
            }
            return std::string("opened");
        } catch (const tb::Error& e) {
            CHECK_MESSAGE(std::string(e.what()).find(bad_path) != std::string::npos, e.what());
            return std::string(e.what());
        }
    };
    CHECK(try_open(std::string(200, 'x')).find("not a PMTiles archive") != std::string::npos);
    CHECK(try_open(good.substr(0, 100)).find("shorter than a PMTiles header") != std::string::npos);
    for (std::size_t cut = 127; cut < good.size(); cut += 7) {
        CHECK(try_open(good.substr(0, cut)) != "opened");
    }
    std::string v2 = good;
    v2[7] = 2;
    CHECK(try_open(v2).find("PMTiles version 2") != std::string::npos);
    std::mt19937 rng(3);
    for (int i = 0; i < 300; ++i) {
        std::string flipped = good;
        flipped[rng() % flipped.size()] ^= static_cast<char>(1 + rng() % 255);
        try_open(flipped); // a refusal or tiles; never a crash
    }
}

TEST_CASE("build -o OUT.pmtiles writes every DEM tile of the layer, and --resume keeps the "
          "archive as it is") {
    TempDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const std::string out = dir / "out.pmtiles";
    const Run a = run(build_args(dem, out, "mapbox", {"--layer", "hills"}), dir);
    INFO(a.err);
    REQUIRE(a.code == 0);
    CHECK_FALSE(fs::exists(out + ".staging"));
    CHECK_FALSE(fs::exists(out + ".build.lock"));
    CHECK(a.err.find("pmtiles: wrote " + out) != std::string::npos);
    const auto expected = expected_dem_tiles(dem, Format::Mapbox);
    REQUIRE(expected.size() >= 2);
    {
        auto store = TileStore::open(out);
        for (const auto& [id, bytes] : expected) {
            CHECK(store->get(dem_key(id, Format::Mapbox)) == bytes);
        }
        CHECK(store->get_document("hills", "build-manifest.json").has_value());
    }
    const pmtiles::Header h = header_of(out);
    CHECK(h.addressed_tiles == expected.size());
    CHECK(h.min_zoom == expected.begin()->first.z);
    CHECK(h.max_zoom == expected.rbegin()->first.z);
    const std::string archive = slurp(out);

    const Run b =
        run(build_args(dem, out, "mapbox", {"--layer", "hills", "--resume", "--json"}), dir);
    INFO(b.err);
    REQUIRE(b.code == 0);
    CHECK(b.out.find("\"written\":0,") != std::string::npos);
    CHECK(slurp(out) == archive);

    const Run c = run(build_args(dem, out, "terrarium", {"--layer", "hills", "--force"}), dir);
    INFO(c.err);
    REQUIRE(c.code == 0);
    auto store = TileStore::open(out);
    const auto& [id, bytes] = *expected.begin();
    CHECK_FALSE(store->contains(dem_key(id, Format::Mapbox)));
    CHECK(store->get(dem_key(id, Format::Terrarium)) ==
          expected_dem_tiles(dem, Format::Terrarium).at(id));

    const Run glb = run({"build", dem, "-o", dir / "mesh.pmtiles", "--formats", "glb"}, dir);
    CHECK(glb.code == 2);
    CHECK(glb.err.find("a PMTiles archive holds raster DEM tiles") != std::string::npos);
}
