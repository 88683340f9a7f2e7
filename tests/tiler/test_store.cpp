// Tile stores: byte-exact round trips, names that must not escape, atomic writes.
#include "core/error.hpp"
#include "tiler/stores/store.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sqlite3.h>
#include <string>
#include <sys/mount.h>
#include <thread>
#include <unistd.h>
#include <vector>

namespace fs = std::filesystem;
using namespace tb::tiler;

namespace {

// A fresh directory under the system temp dir, removed at scope exit.
struct TempDir {
    fs::path path;
    TempDir() {
        std::string tmpl = (fs::temp_directory_path() / "tb-store-XXXXXX").string();
        REQUIRE(::mkdtemp(tmpl.data()) != nullptr);
        path = tmpl;
    }
    ~TempDir() {
        std::error_code ec;
        fs::remove_all(path, ec);
    }
};

std::string random_bytes(std::size_t n, unsigned seed) {
    std::mt19937 rng(seed);
    std::string s(n, '\0');
    for (auto& c : s) {
        c = static_cast<char>(rng() & 0xff);
    }
    return s;
}

std::vector<fs::path> temp_files_under(const fs::path& dir) {
    std::vector<fs::path> found;
    for (const auto& e : fs::recursive_directory_iterator(dir)) {
        const auto name = e.path().filename().string();
        if (name.find(".tmp-") != std::string::npos) {
            found.push_back(e.path());
        }
    }
    return found;
}

TileKey key(int z, std::int64_t x, std::int64_t y, Format f = Format::Glb, int eps = -1) {
    return TileKey{"terrain", TileId{z, x, y}, f, eps};
}

void check_round_trips(TileStore& store) {
    // Every byte value, an empty tile, a large tile, both formats, an eps variant.
    const std::string big = random_bytes(1 << 20, 1);
    const std::string small = random_bytes(300, 2);
    const std::string nul_heavy("\0\0a\0b\0", 6);
    store.put(key(0, 0, 0), small);
    store.put(key(5, 31, 7, Format::Drc), big);
    store.put(key(5, 31, 7, Format::Glb), nul_heavy);
    store.put(key(5, 31, 7, Format::Glb, 2), "");
    CHECK(store.get(key(0, 0, 0)) == small);
    CHECK(store.get(key(5, 31, 7, Format::Drc)) == big);
    CHECK(store.get(key(5, 31, 7, Format::Glb)) == nul_heavy);
    CHECK(store.get(key(5, 31, 7, Format::Glb, 2)) == std::string());
    CHECK(store.contains(key(5, 31, 7, Format::Glb, 2)));
    CHECK_FALSE(store.contains(key(5, 31, 7, Format::Glb, 0)));
    CHECK_FALSE(store.get(key(1, 0, 0)).has_value());
    CHECK_FALSE(store.contains(key(1, 0, 0)));
    // Overwrite replaces.
    store.put(key(0, 0, 0), "second");
    CHECK(store.get(key(0, 0, 0)) == "second");
    // Other layers are separate.
    CHECK_FALSE(store.contains(TileKey{"other", TileId{0, 0, 0}, Format::Glb, -1}));

    const std::string doc = "{\"asset\":{\"version\":\"1.1\"}}";
    store.put_document("terrain", "tileset.json", doc);
    store.put_document("terrain", "subtrees/0/0/0.subtree", big.substr(0, 1000));
    CHECK(store.get_document("terrain", "tileset.json") == doc);
    CHECK(store.get_document("terrain", "subtrees/0/0/0.subtree") == big.substr(0, 1000));
    CHECK_FALSE(store.get_document("terrain", "missing.json").has_value());
    CHECK_FALSE(store.get_document("other", "tileset.json").has_value());

    std::vector<StoredTile> batch;
    for (int i = 0; i < 50; ++i) {
        batch.push_back({key(7, i, 100 - i), random_bytes(100 + i, 10 + i)});
    }
    store.put_batch(batch);
    for (const auto& t : batch) {
        CHECK(store.get(t.key) == t.bytes);
    }
}

void check_rejects_escapes(TileStore& store) {
    const std::vector<std::string> bad_names = {"../x.json",
                                                "a/../../x.json",
                                                "/etc/passwd",
                                                "a\\..\\b",
                                                std::string("a\0b", 3),
                                                "a//b",
                                                "a/",
                                                "",
                                                ".hidden",
                                                "./tileset.json",
                                                "sub/..",
                                                "caf\xc3\xa9.json"};
    for (const auto& name : bad_names) {
        CAPTURE(name);
        CHECK_THROWS_AS(store.put_document("terrain", name, "x"), tb::InputError);
        CHECK_THROWS_AS(store.get_document("terrain", name), tb::InputError);
    }
    for (const std::string layer : {"..", "a/b", "", "../../tmp", "a b", "x\\y", "."}) {
        CAPTURE(layer);
        CHECK_THROWS_AS(store.put_document(layer, "tileset.json", "x"), tb::InputError);
        CHECK_THROWS_AS(store.put(TileKey{layer, TileId{0, 0, 0}, Format::Glb, -1}, "x"),
                        tb::InputError);
        CHECK_THROWS_AS(store.has_layer(layer), tb::InputError);
    }
    CHECK_THROWS_AS(store.put(key(-1, 0, 0), "x"), tb::InputError);
    CHECK_THROWS_AS(store.put(key(2, -1, 0), "x"), tb::InputError);
    CHECK_THROWS_AS(store.put(key(2, 0, 8), "x"), tb::InputError);
    CHECK_THROWS_AS(store.put(key(25, 0, 0), "x"), tb::InputError);
    CHECK_THROWS_AS(store.put(key(2, 0, 0, Format::Glb, -2), "x"), tb::InputError);
    try {
        store.put_document("terrain", "../x.json", "x");
    } catch (const tb::InputError& e) {
        CHECK(std::string(e.what()).find("../x.json") != std::string::npos);
    }
}

// Mounts a tiny tmpfs so that writes run out of space for real. Empty path when mounting is
// refused (not root, or no mount namespace rights).
struct TinyDisk {
    fs::path path;
    bool mounted = false;
    TinyDisk(const fs::path& where, const char* size) : path(where / "disk") {
        fs::create_directories(path);
        const std::string options = std::string("size=") + size;
        mounted = ::mount("tmpfs", path.c_str(), "tmpfs", 0, options.c_str()) == 0;
    }
    ~TinyDisk() {
        if (mounted) {
            ::umount(path.c_str());
        }
    }
};

} // namespace

TEST_CASE("the directory store round-trips tiles and documents byte-exact") {
    TempDir dir;
    auto store = TileStore::open((dir.path / "out").string());
    CHECK(store->describe() == "directory " + (dir.path / "out").string());
    check_round_trips(*store);
    // The layout static hosting relies on.
    CHECK(fs::is_regular_file(dir.path / "out/terrain/0/0/0.glb"));
    CHECK(fs::is_regular_file(dir.path / "out/terrain/5/31/7.drc"));
    CHECK(fs::is_regular_file(dir.path / "out/terrain/eps2/5/31/7.glb"));
    CHECK(fs::is_regular_file(dir.path / "out/terrain/tileset.json"));
    CHECK(fs::is_regular_file(dir.path / "out/terrain/subtrees/0/0/0.subtree"));
    CHECK(fs::file_size(dir.path / "out/terrain/5/31/7.drc") == (1u << 20));
    CHECK(temp_files_under(dir.path).empty());
    // A second handle sees the same content.
    auto again = TileStore::open((dir.path / "out/").string());
    CHECK(again->get(key(0, 0, 0)) == "second");
}

TEST_CASE("the SQLite store round-trips tiles and documents byte-exact and keeps them on reopen") {
    TempDir dir;
    const auto path = (dir.path / "sub/tiles.sqlite").string();
    fs::create_directories(dir.path / "sub");
    {
        auto store = TileStore::open(path);
        CHECK(store->describe() == "sqlite " + path);
        check_round_trips(*store);
    }
    auto store = TileStore::open(path);
    CHECK(store->get(key(0, 0, 0)) == "second");
    CHECK(store->get(key(5, 31, 7, Format::Drc)) == random_bytes(1 << 20, 1));
    CHECK(store->get_document("terrain", "subtrees/0/0/0.subtree") ==
          random_bytes(1 << 20, 1).substr(0, 1000));
    auto db = TileStore::open((dir.path / "other.db").string());
    CHECK(db->describe().rfind("sqlite ", 0) == 0);
}

TEST_CASE("DEM tiles never collide with mesh tiles of the same z/x/y, in either store") {
    TempDir dir;
    for (const std::string name : {"out", "out.sqlite"}) {
        CAPTURE(name);
        auto store = TileStore::open((dir.path / name).string());
        // Same z/x/y in all four formats, each with its own bytes.
        const Format formats[] = {Format::Glb, Format::Drc, Format::Terrarium, Format::Mapbox};
        for (unsigned k = 0; k < 4; ++k) {
            store->put(key(9, 272, 155, formats[k]), random_bytes(5000 + k, 10 + k));
        }
        for (unsigned k = 0; k < 4; ++k) {
            CHECK(store->get(key(9, 272, 155, formats[k])) == random_bytes(5000 + k, 10 + k));
        }
        CHECK_FALSE(store->contains(key(9, 272, 156, Format::Terrarium)));
        // DEM tiles have one height per pixel and no eps variants.
        CHECK_THROWS_AS(store->put(key(9, 272, 155, Format::Mapbox, 0), "x"), tb::InputError);
        CHECK_THROWS_AS(store->get(key(9, 272, 155, Format::Terrarium, 1)), tb::InputError);
    }
    // The directory layout: terrarium at the server's URL (without ?encoding), mapbox beside.
    CHECK(fs::file_size(dir.path / "out/terrain/dem/9/272/155.png") == 5002);
    CHECK(fs::file_size(dir.path / "out/terrain/dem/mapbox/9/272/155.png") == 5003);
    CHECK(fs::file_size(dir.path / "out/terrain/9/272/155.glb") == 5000);
    CHECK(temp_files_under(dir.path).empty());
}

TEST_CASE("both stores reject layer and document names that would escape the output") {
    TempDir dir;
    auto directory = TileStore::open((dir.path / "out").string());
    check_rejects_escapes(*directory);
    auto sqlite = TileStore::open((dir.path / "out.sqlite").string());
    check_rejects_escapes(*sqlite);
    // Nothing was written anywhere: not outside the output, not inside it.
    std::vector<std::string> entries;
    for (const auto& e : fs::recursive_directory_iterator(dir.path)) {
        entries.push_back(fs::relative(e.path(), dir.path).string());
    }
    std::sort(entries.begin(), entries.end());
    CHECK(entries ==
          std::vector<std::string>{"out", "out.sqlite", "out.sqlite-shm", "out.sqlite-wal"});
    CHECK_FALSE(sqlite->has_layer("terrain"));
}

TEST_CASE("the directory store leaves no temporary file after many concurrent writes") {
    TempDir dir;
    auto store = TileStore::open((dir.path / "out").string());
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t) {
        threads.emplace_back([&store, t] {
            for (int i = 0; i < 50; ++i) {
                // Every thread writes the same 10 tiles over and over: the last rename wins.
                store->put(key(4, i % 10, 3), random_bytes(2000, static_cast<unsigned>(i % 10)));
                store->put(key(6, t, i), random_bytes(100, static_cast<unsigned>(t * 100 + i)));
            }
        });
    }
    for (auto& th : threads) {
        th.join();
    }
    CHECK(temp_files_under(dir.path).empty());
    for (int i = 0; i < 10; ++i) {
        CHECK(store->get(key(4, i, 3)) == random_bytes(2000, static_cast<unsigned>(i)));
    }
    for (int t = 0; t < 4; ++t) {
        for (int i = 0; i < 50; ++i) {
            CHECK(store->get(key(6, t, i)) ==
                  random_bytes(100, static_cast<unsigned>(t * 100 + i)));
        }
    }
}

TEST_CASE("the SQLite store serves many threads at once") {
    TempDir dir;
    auto store = TileStore::open((dir.path / "t.sqlite").string());
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t) {
        threads.emplace_back([&store, t] {
            for (int i = 0; i < 40; ++i) {
                const auto bytes = random_bytes(500, static_cast<unsigned>(t * 1000 + i));
                store->put(key(8, t, i), bytes);
                CHECK(store->get(key(8, t, i)) == bytes);
            }
        });
    }
    for (auto& th : threads) {
        th.join();
    }
    for (int t = 0; t < 4; ++t) {
        for (int i = 0; i < 40; ++i) {
            CHECK(store->contains(key(8, t, i)));
        }
    }
}

TEST_CASE("has_layer, remove_layer and clean_up work on both stores") {
    TempDir dir;
    for (const auto& name : {"out", "out.sqlite"}) {
        CAPTURE(name);
        auto store = TileStore::open((dir.path / name).string());
        CHECK_FALSE(store->has_layer("terrain"));
        store->put_document("terrain", "build-manifest.json", "{}");
        CHECK(store->has_layer("terrain"));
        store->put(key(3, 1, 1), "abc");
        store->put(TileKey{"keep", TileId{3, 1, 1}, Format::Glb, -1}, "kept");
        store->remove_layer("terrain");
        CHECK_FALSE(store->has_layer("terrain"));
        CHECK_FALSE(store->contains(key(3, 1, 1)));
        CHECK_FALSE(store->get_document("terrain", "build-manifest.json").has_value());
        CHECK(store->get(TileKey{"keep", TileId{3, 1, 1}, Format::Glb, -1}) == "kept");
    }
    // clean_up removes what a killed writer leaves behind, and nothing else.
    auto store = TileStore::open((dir.path / "out").string());
    store->put(key(3, 1, 1), "abc");
    const auto stale = dir.path / "out/terrain/3/1/.1.glb.tmp-999-1";
    std::ofstream(stale) << "partial";
    store->clean_up("terrain");
    CHECK_FALSE(fs::exists(stale));
    CHECK(store->get(key(3, 1, 1)) == "abc");
}

TEST_CASE("opening a store where none can be made fails with an IoError naming the path") {
    TempDir dir;
    const auto file = dir.path / "plain-file";
    std::ofstream(file) << "not a directory";
    for (const auto& path : {file, file / "below", file / "below.sqlite"}) {
        CAPTURE(path);
        try {
            TileStore::open(path.string());
            FAIL("expected an IoError");
        } catch (const tb::IoError& e) {
            CHECK(std::string(e.what()).find(file.string()) != std::string::npos);
        }
    }
    // A file that is not an SQLite database.
    const auto corrupt = dir.path / "corrupt.sqlite";
    std::ofstream(corrupt) << std::string(4096, 'x');
    try {
        TileStore::open(corrupt.string());
        FAIL("expected an IoError");
    } catch (const tb::IoError& e) {
        const std::string what = e.what();
        CHECK(what.find(corrupt.string()) != std::string::npos);
        CHECK(what.find("not an SQLite database") != std::string::npos);
    }
    // An SQLite database of some other program, with a different 'tiles' table.
    const auto foreign = dir.path / "foreign.sqlite";
    {
        sqlite3* db = nullptr;
        REQUIRE(sqlite3_open(foreign.c_str(), &db) == SQLITE_OK);
        CHECK(sqlite3_exec(db,
                           "CREATE TABLE tiles(zoom_level INTEGER, tile_data BLOB)",
                           nullptr,
                           nullptr,
                           nullptr) == SQLITE_OK);
        sqlite3_close(db);
    }
    try {
        TileStore::open(foreign.string());
        FAIL("expected an IoError");
    } catch (const tb::IoError& e) {
        CHECK(std::string(e.what()).find(foreign.string()) != std::string::npos);
    }
    // A directory where the SQLite file should be.
    fs::create_directories(dir.path / "dir.sqlite");
    CHECK_THROWS_AS(TileStore::open((dir.path / "dir.sqlite").string()), tb::IoError);
}

TEST_CASE("a write that runs out of disk leaves no tile and no temporary file behind") {
    TempDir dir;
    // 64 KiB holds a few tiles; the SQLite store needs room for its tables, WAL and -shm first.
    SUBCASE("directory store") {
        TinyDisk disk(dir.path, "64k");
        if (!disk.mounted) {
            MESSAGE("skipped: cannot mount a tmpfs at " << disk.path.string() << " (needs root)");
            return;
        }
        auto store = TileStore::open((disk.path / "out").string());
        int written = 0;
        bool failed = false;
        for (int i = 0; i < 100 && !failed; ++i) {
            try {
                store->put(key(10, i, 0), random_bytes(8000, static_cast<unsigned>(i)));
                ++written;
            } catch (const tb::IoError& e) {
                failed = true;
                const std::string what = e.what();
                CHECK(what.find("disk is full") != std::string::npos);
                CHECK(what.find("/10/" + std::to_string(i) + "/0.glb") != std::string::npos);
                CHECK_FALSE(store->contains(key(10, i, 0)));
            }
        }
        REQUIRE(failed);
        CHECK(written > 0);
        CHECK(temp_files_under(disk.path).empty());
        for (int i = 0; i < written; ++i) {
            CHECK(store->get(key(10, i, 0)) == random_bytes(8000, static_cast<unsigned>(i)));
        }
    }
    SUBCASE("SQLite store: a batch is all or nothing") {
        TinyDisk disk(dir.path, "256k");
        if (!disk.mounted) {
            MESSAGE("skipped: cannot mount a tmpfs at " << disk.path.string() << " (needs root)");
            return;
        }
        auto store = TileStore::open((disk.path / "t.sqlite").string());
        store->put(key(1, 0, 0), "first");
        std::vector<StoredTile> batch;
        for (int i = 0; i < 60; ++i) {
            batch.push_back({key(10, i, 1), random_bytes(8000, static_cast<unsigned>(i))});
        }
        try {
            store->put_batch(batch);
            FAIL("expected an IoError for 480 KB on a 256 KiB disk");
        } catch (const tb::IoError& e) {
            const std::string what = e.what();
            CHECK(what.find("t.sqlite") != std::string::npos);
            CHECK(what.find("disk is full") != std::string::npos);
        }
        for (const auto& t : batch) {
            CHECK_FALSE(store->contains(t.key));
        }
        CHECK(store->get(key(1, 0, 0)) == "first");
    }
}
