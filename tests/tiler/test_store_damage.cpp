// Stored bytes are verified: a tile or document that is empty, truncated, garbage or has one
// flipped byte reads as missing (so it is made again) in both stores, an SQLite store of
// schema 1 is migrated, and no symbolic link inside a directory store is ever followed.
#include "core/error.hpp"
#include "tiler/stores/checksum.hpp"
#include "tiler/stores/store.hpp"

#include "tests/tiler/test_raster_util.hpp"

#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sqlite3.h>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

namespace fs = std::filesystem;
using namespace tb::tiler;
using tb_test::slurp;
using tb_test::spill;

namespace {

using TempDir = tb_test::ScratchDir;

std::string random_bytes(std::size_t n, unsigned seed) {
    std::mt19937 rng(seed);
    std::string s(n, '\0');
    for (auto& c : s) {
        c = static_cast<char>(rng() & 0xff);
    }
    return s;
}

// The four kinds of damage, each a function of the good bytes.
struct Damage {
    const char* name;
    std::function<std::string(const std::string&)> apply;
};
const std::vector<Damage>& damages() {
    static const std::vector<Damage> kinds = {
        {"0 bytes", [](const std::string&) { return std::string(); }},
        {"truncated", [](const std::string& s) { return s.substr(0, s.size() - 1); }},
        {"garbage", [](const std::string& s) { return random_bytes(s.size(), 99); }},
        {"one flipped byte",
         [](const std::string& s) {
             std::string t = s;
             t[t.size() / 2] = static_cast<char>(t[t.size() / 2] ^ 0x01);
             return t;
         }},
    };
    return kinds;
}

const TileKey kKey{"terrain", TileId{5, 31, 7}, Format::Glb, -1};

// Replaces the data of the tile row of kKey behind the store's back.
void overwrite_sqlite_tile(const std::string& path, const std::string& bytes) {
    sqlite3* db = nullptr;
    REQUIRE(sqlite3_open(path.c_str(), &db) == SQLITE_OK);
    sqlite3_stmt* s = nullptr;
    REQUIRE(sqlite3_prepare_v2(db,
                               "UPDATE tiles SET data=?1 WHERE layer='terrain' AND z=5 AND x=31"
                               " AND y=7 AND format='glb'",
                               -1,
                               &s,
                               nullptr) == SQLITE_OK);
    if (bytes.empty()) {
        sqlite3_bind_zeroblob(s, 1, 0);
    } else {
        sqlite3_bind_blob(s, 1, bytes.data(), static_cast<int>(bytes.size()), SQLITE_TRANSIENT);
    }
    REQUIRE(sqlite3_step(s) == SQLITE_DONE);
    CHECK(sqlite3_changes(db) == 1);
    sqlite3_finalize(s);
    sqlite3_close(db);
}

void exec(const std::string& path, const char* sql) {
    sqlite3* db = nullptr;
    REQUIRE(sqlite3_open(path.c_str(), &db) == SQLITE_OK);
    char* error = nullptr;
    const int rc = sqlite3_exec(db, sql, nullptr, nullptr, &error);
    INFO((error ? error : ""));
    CHECK(rc == SQLITE_OK);
    sqlite3_free(error);
    sqlite3_close(db);
}

// The store holds a damaged copy of kKey and of tileset.json: neither is served or counted,
// and putting `good` again repairs both.
void require_damaged_then_repaired(TileStore& store, const std::string& good) {
    CHECK_FALSE(store.get(kKey).has_value());
    CHECK_FALSE(store.contains(kKey));
    CHECK_FALSE(store.get_document("terrain", "tileset.json").has_value());
    store.put(kKey, good);
    store.put_document("terrain", "tileset.json", good);
    CHECK(store.get(kKey) == good);
    CHECK(store.contains(kKey));
    CHECK(store.get_document("terrain", "tileset.json") == good);
}

} // namespace

TEST_CASE("the store checksum is zlib's CRC-32 and its sidecar names it with the size") {
    CHECK(store_checksum("") == 0u);
    CHECK(store_checksum("123456789") == 0xcbf43926u); // the CRC-32 check value
    CHECK(checksum_sidecar("123456789") == "crc32 cbf43926 9\n");
}

TEST_CASE("the directory store never serves a damaged tile or document, and a put repairs it") {
    for (const auto& damage : damages()) {
        CAPTURE(damage.name);
        TempDir dir;
        auto store = TileStore::open((dir.path / "out").string());
        const std::string good = random_bytes(5000, 1);
        store->put(kKey, good);
        store->put_document("terrain", "tileset.json", good);
        const fs::path tile = dir.path / "out/terrain/5/31/7.glb";
        const fs::path doc = dir.path / "out/terrain/tileset.json";
        REQUIRE(slurp(tile) == good);
        CHECK(slurp(dir.path / "out/terrain/5/31/.7.glb.crc32") == checksum_sidecar(good));
        spill(tile, damage.apply(good));
        spill(doc, damage.apply(good));
        require_damaged_then_repaired(*store, good);
    }
}

TEST_CASE("the directory store treats a tile without its checksum file, or a damaged checksum "
          "file, as damaged") {
    TempDir dir;
    auto store = TileStore::open((dir.path / "out").string());
    const std::string good = random_bytes(700, 2);
    store->put(kKey, good);
    const fs::path sidecar = dir.path / "out/terrain/5/31/.7.glb.crc32";
    fs::remove(sidecar);
    CHECK_FALSE(store->get(kKey).has_value());
    store->put(kKey, good);
    std::string text = slurp(sidecar);
    text[7] = text[7] == '0' ? '1' : '0';
    spill(sidecar, text);
    CHECK_FALSE(store->contains(kKey));
    store->put(kKey, good);
    CHECK(store->get(kKey) == good);
}

TEST_CASE("the SQLite store never serves a damaged tile or document, and a put repairs it") {
    for (const auto& damage : damages()) {
        CAPTURE(damage.name);
        TempDir dir;
        const std::string path = (dir.path / "tiles.sqlite").string();
        const std::string good = random_bytes(5000, 3);
        {
            auto store = TileStore::open(path);
            store->put(kKey, good);
            store->put_document("terrain", "tileset.json", good);
        }
        overwrite_sqlite_tile(path, damage.apply(good));
        exec(path, "UPDATE documents SET data=substr(data, 1, length(data) - 1)");
        auto store = TileStore::open(path);
        require_damaged_then_repaired(*store, good);
    }
}

TEST_CASE("an SQLite store of schema version 1 is migrated: checksums from its data, then "
          "damage is caught") {
    TempDir dir;
    const std::string path = (dir.path / "old.sqlite").string();
    // The schema 1 layout, as terrabound 0.1 wrote it.
    exec(path,
         "CREATE TABLE meta(name TEXT PRIMARY KEY, value TEXT NOT NULL);"
         "CREATE TABLE tiles(layer TEXT NOT NULL, format TEXT NOT NULL, eps_level INTEGER NOT "
         "NULL, z INTEGER NOT NULL, x INTEGER NOT NULL, y INTEGER NOT NULL, data BLOB NOT NULL,"
         " PRIMARY KEY(layer, format, eps_level, z, x, y));"
         "CREATE TABLE documents(layer TEXT NOT NULL, name TEXT NOT NULL, data BLOB NOT NULL,"
         " PRIMARY KEY(layer, name));"
         "INSERT INTO meta VALUES('schema_version', '1');"
         "INSERT INTO tiles VALUES('terrain', 'glb', -1, 5, 31, 7, x'0102030405');"
         "INSERT INTO documents VALUES('terrain', 'tileset.json', '{}');");
    {
        auto store = TileStore::open(path);
        CHECK(store->get(kKey) == std::string("\x01\x02\x03\x04\x05"));
        CHECK(store->get_document("terrain", "tileset.json") == "{}");
    }
    sqlite3* db = nullptr;
    REQUIRE(sqlite3_open(path.c_str(), &db) == SQLITE_OK);
    sqlite3_stmt* s = nullptr;
    REQUIRE(sqlite3_prepare_v2(
                db, "SELECT value FROM meta WHERE name='schema_version'", -1, &s, nullptr) ==
            SQLITE_OK);
    REQUIRE(sqlite3_step(s) == SQLITE_ROW);
    CHECK(std::string(reinterpret_cast<const char*>(sqlite3_column_text(s, 0))) == "2");
    sqlite3_finalize(s);
    sqlite3_close(db);
    overwrite_sqlite_tile(path, "\x01\x02\x03\x04\x06");
    auto store = TileStore::open(path);
    CHECK_FALSE(store->get(kKey).has_value());
}

TEST_CASE("the directory store never follows a symbolic link inside it, for reading or writing") {
    TempDir dir;
    auto store = TileStore::open((dir.path / "out").string());
    const std::string secret = "root:x:0:0:root:/root:/bin/bash\n";
    spill(dir.path / "secret", secret);
    // A tile and a document that are links to a file outside the root, each with a sidecar
    // that matches the file, so only the refusal to follow links can keep it out.
    fs::create_directories(dir.path / "out/terrain/5/31");
    fs::create_symlink(dir.path / "secret", dir.path / "out/terrain/5/31/7.glb");
    spill(dir.path / "out/terrain/5/31/.7.glb.crc32", checksum_sidecar(secret));
    fs::create_symlink("/etc/passwd", dir.path / "out/terrain/tileset.json");
    spill(dir.path / "out/terrain/.tileset.json.crc32", checksum_sidecar(slurp("/etc/passwd")));
    CHECK_FALSE(store->get(kKey).has_value());
    CHECK_FALSE(store->contains(kKey));
    CHECK_FALSE(store->get_document("terrain", "tileset.json").has_value());
    // Writing replaces the link itself; the file it pointed at is untouched.
    store->put(kKey, "tile");
    store->put_document("terrain", "tileset.json", "{}");
    CHECK(store->get(kKey) == "tile");
    CHECK(store->get_document("terrain", "tileset.json") == "{}");
    CHECK_FALSE(fs::is_symlink(dir.path / "out/terrain/5/31/7.glb"));
    CHECK(slurp(dir.path / "secret") == secret);

    // A linked directory on the way: neither read through nor written through.
    fs::create_directories(dir.path / "outside/31");
    spill(dir.path / "outside/31/8.glb", secret);
    spill(dir.path / "outside/31/.8.glb.crc32", checksum_sidecar(secret));
    fs::create_directories(dir.path / "out/terrain/eps0");
    fs::create_symlink(dir.path / "outside", dir.path / "out/terrain/eps0/5");
    const TileKey linked{"terrain", TileId{5, 31, 8}, Format::Glb, 0};
    CHECK_FALSE(store->get(linked).has_value());
    CHECK_THROWS_AS(store->put(linked, "tile"), tb::IoError);
    CHECK(slurp(dir.path / "outside/31/8.glb") == secret);
}

TEST_CASE("a store whose parent directory does not exist is refused, and nothing is created") {
    TempDir dir;
    for (const std::string name : {"missing/dir/out", "missing/dir/out.sqlite"}) {
        CAPTURE(name);
        const std::string path = (dir.path / name).string();
        try {
            TileStore::open(path);
            FAIL("expected an IoError");
        } catch (const tb::IoError& e) {
            const std::string what = e.what();
            CHECK(what.find((dir.path / "missing/dir").string()) != std::string::npos);
            CHECK(what.find("does not exist; create it first") != std::string::npos);
        }
        CHECK_FALSE(fs::exists(dir.path / "missing"));
    }
}
