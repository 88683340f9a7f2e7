// A damaged stored tile is never served over HTTP: it is made again, served, and stored whole.
#include "server_fixture.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"
#include "tiler/stores/checksum.hpp"
#include "tiler/stores/store.hpp"

#include <doctest/doctest.h>
#include <sqlite3.h>

namespace {

using namespace tb;
using test::RunningServer;
using test::TempDir;

std::string damaged(const std::string& good, int kind) {
    switch (kind) {
    case 0:
        return "";
    case 1:
        return good.substr(0, good.size() - 7);
    case 2:
        return std::string(good.size(), '\x01');
    default: {
        std::string t = good;
        t.back() = static_cast<char>(t.back() ^ 0x80);
        return t;
    }
    }
}

} // namespace

TEST_CASE("a damaged tile in either store is made again over HTTP, served whole and stored") {
    log::set_level(log::Level::Error);
    TempDir dir;
    test::write_dem(dir / "hills.asc", 129);
    const auto layer = tiler::Layer::open(test::test_layer_options(dir / "hills.asc", "hills"));
    const auto r = layer->tiles_at(layer->max_zoom());
    REQUIRE(!r.empty());
    const tiler::TileId id{layer->max_zoom(), r.x0, r.y0};
    const std::string good = layer->make_tile(layer->tile(id), tiler::Format::Glb);
    const std::string url = "/hills/" + std::to_string(id.z) + "/" + std::to_string(id.x) + "/" +
                            std::to_string(id.y) + ".glb";
    const tiler::TileKey key{"hills", id, tiler::Format::Glb, -1};

    for (const std::string name : {"tiles-dir", "tiles.sqlite"}) {
        for (int kind = 0; kind < 4; ++kind) {
            CAPTURE(name);
            CAPTURE(kind);
            const std::string path = dir / (std::to_string(kind) + name);
            tiler::TileStore::open(path)->put(key, good);
            const std::string bad = damaged(good, kind);
            if (name == "tiles-dir") {
                test::write_file(path + "/hills/" + std::to_string(id.z) + "/" +
                                     std::to_string(id.x) + "/" + std::to_string(id.y) + ".glb",
                                 bad);
            } else {
                sqlite3* db = nullptr;
                REQUIRE(sqlite3_open(path.c_str(), &db) == SQLITE_OK);
                sqlite3_stmt* s = nullptr;
                REQUIRE(sqlite3_prepare_v2(db, "UPDATE tiles SET data=?1", -1, &s, nullptr) ==
                        SQLITE_OK);
                sqlite3_bind_blob(s, 1, bad.data(), static_cast<int>(bad.size()), SQLITE_TRANSIENT);
                if (bad.empty()) {
                    sqlite3_bind_zeroblob(s, 1, 0);
                }
                REQUIRE(sqlite3_step(s) == SQLITE_DONE);
                sqlite3_finalize(s);
                sqlite3_close(db);
            }
            std::shared_ptr<tiler::TileStore> store = tiler::TileStore::open(path);
            RunningServer s({{layer, {tiler::Format::Glb}, store}});
            auto c = s.client();
            auto res = c.Get(url);
            REQUIRE(res);
            CHECK(res->status == 200);
            CHECK(res->body == good);
            const std::string m = c.Get("/metrics")->body;
            CHECK(test::metric(m, "tb_store_hits_total") == 0);
            CHECK(test::metric(m, "tb_tiles_generated_total") == 1);
            CHECK(store->get(key) == good);
        }
    }
}

TEST_CASE("a tile that is a symbolic link out of a directory store is never served") {
    log::set_level(log::Level::Error);
    TempDir dir;
    test::write_dem(dir / "hills.asc", 129);
    const auto layer = tiler::Layer::open(test::test_layer_options(dir / "hills.asc", "hills"));
    const auto r = layer->tiles_at(layer->max_zoom());
    const tiler::TileId id{layer->max_zoom(), r.x0, r.y0};
    const std::string secret = "root:x:0:0:root:/root:/bin/bash\n";
    test::write_file(dir / "secret", secret);
    const std::string tile_dir =
        dir / ("out/hills/" + std::to_string(id.z) + "/" + std::to_string(id.x));
    test::fs::create_directories(tile_dir);
    test::fs::create_symlink(dir / "secret", tile_dir + "/" + std::to_string(id.y) + ".glb");
    test::write_file(tile_dir + "/." + std::to_string(id.y) + ".glb.crc32",
                     tiler::checksum_sidecar(secret));
    std::shared_ptr<tiler::TileStore> store = tiler::TileStore::open(dir / "out");
    RunningServer s({{layer, {tiler::Format::Glb}, store}});
    auto res = s.client().Get("/hills/" + std::to_string(id.z) + "/" + std::to_string(id.x) + "/" +
                              std::to_string(id.y) + ".glb");
    REQUIRE(res);
    CHECK(res->status == 200);
    CHECK(res->body == layer->make_tile(layer->tile(id), tiler::Format::Glb));
    CHECK(test::read_file(dir / "secret") == secret);
}
