// gzip through zlib, and the directory store's gzip-compressed globe terrain tiles: a .terrain
// file on disk is one gzip member of the tile's bytes, get gives the bytes back, a store
// written before tiles were compressed still reads, and a damaged file is never served.
#include "tiler/gzip.hpp"
#include "tiler/stores/checksum.hpp"
#include "tiler/stores/store.hpp"

#include "tests/tiler/test_raster_util.hpp"

#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

namespace fs = std::filesystem;
using namespace tb::tiler;
using tb_test::slurp;
using tb_test::spill;

namespace {

// Bytes that compress a little, like a tile: random low bits over a slow ramp.
std::string tile_like_bytes(std::size_t n, unsigned seed) {
    std::mt19937 rng(seed);
    std::string s(n, '\0');
    for (std::size_t i = 0; i < n; ++i) {
        s[i] = static_cast<char>((i / 64) + (rng() & 0x0f));
    }
    return s;
}

const TileKey kTerrain{"terrain", TileId{3, 9, 2}, Format::Terrain, -1};

} // namespace

TEST_CASE("gzip round-trips bytes, and refuses what is not one whole gzip member") {
    const std::string bytes = tile_like_bytes(200000, 1);
    const std::string packed = gzip_compress(bytes);
    CHECK(looks_gzipped(packed));
    CHECK(packed.size() < bytes.size());
    CHECK(gzip_decompress(packed, bytes.size()) == bytes);
    CHECK(gzip_decompress(gzip_compress(""), 0) == std::string());

    CHECK_FALSE(gzip_decompress(packed, bytes.size() - 1)); // inflates past the limit
    CHECK_FALSE(gzip_decompress(packed.substr(0, packed.size() - 1), bytes.size())); // cut
    CHECK_FALSE(gzip_decompress(packed + "x", bytes.size()));                        // trailer
    CHECK_FALSE(gzip_decompress(bytes, bytes.size()));                               // raw
    std::string flipped = packed;
    flipped[packed.size() - 6] = static_cast<char>(flipped[packed.size() - 6] ^ 0x10); // CRC
    CHECK_FALSE(gzip_decompress(flipped, bytes.size()));
}

TEST_CASE("the directory store keeps .terrain tiles gzip-compressed and gives them back raw; "
          "other formats and the SQLite store keep the bytes as they are") {
    tb_test::ScratchDir dir;
    const std::string tile = tile_like_bytes(30000, 2);
    auto store = TileStore::open((dir.path / "out").string());
    store->put(kTerrain, tile);
    const fs::path file = dir.path / "out/terrain/3/9/2.terrain";
    const std::string on_disk = slurp(file);
    REQUIRE(looks_gzipped(on_disk));
    CHECK(gzip_decompress(on_disk, tile.size()) == tile);
    CHECK(slurp(dir.path / "out/terrain/3/9/.2.terrain.crc32") == checksum_sidecar(on_disk));
    CHECK(store->get(kTerrain) == tile);
    CHECK(store->contains(kTerrain));

    TileKey glb = kTerrain;
    glb.format = Format::Glb;
    store->put(glb, tile);
    CHECK(slurp(dir.path / "out/terrain/3/9/2.glb") == tile);

    auto db = TileStore::open((dir.path / "out.sqlite").string());
    db->put(kTerrain, tile);
    CHECK(db->get(kTerrain) == tile);
}

TEST_CASE("a .terrain file stored raw (before tiles were compressed) reads as it is; a damaged "
          "compressed one reads as missing") {
    tb_test::ScratchDir dir;
    const std::string tile = tile_like_bytes(30000, 3);
    auto store = TileStore::open((dir.path / "out").string());
    store->put(kTerrain, tile);
    const fs::path file = dir.path / "out/terrain/3/9/2.terrain";
    const fs::path sidecar = dir.path / "out/terrain/3/9/.2.terrain.crc32";

    spill(file, tile);
    spill(sidecar, checksum_sidecar(tile));
    CHECK(store->get(kTerrain) == tile);

    store->put(kTerrain, tile);
    std::string damaged = slurp(file);
    damaged[damaged.size() / 2] = static_cast<char>(damaged[damaged.size() / 2] ^ 0x01);
    spill(file, damaged);
    CHECK_FALSE(store->get(kTerrain).has_value());
    CHECK_FALSE(store->contains(kTerrain));
}
