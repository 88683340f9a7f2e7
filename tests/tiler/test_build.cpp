// terrabound build, end to end: the real binary (TB_BINARY) on a generated GeoTIFF and on a
// real DEM, into both stores; kill and resume, shards, thread counts, bad input.
#include "core/error.hpp"
#include "terrain3d_reader.hpp"
#include "tiler/dem_tiles.hpp"
#include "tiler/formats/draco_decode.hpp"
#include "tiler/formats/quantized_mesh.hpp"
#include "tiler/gzip.hpp"
#include "tiler/pyramid/build.hpp"
#include "tiler/pyramid/hosting.hpp"
#include "tiler/stores/store.hpp"

#include <doctest/doctest.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>
#include <sqlite3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <spawn.h>
#include <sstream>
#include <string>
#include <sys/mount.h>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

extern char** environ;

namespace fs = std::filesystem;
using namespace tb::tiler;

namespace {

struct BuildDir {
    fs::path path;
    BuildDir() {
        std::string tmpl = (fs::temp_directory_path() / "tb-build-XXXXXX").string();
        REQUIRE(::mkdtemp(tmpl.data()) != nullptr);
        path = tmpl;
    }
    ~BuildDir() {
        std::error_code ec;
        fs::remove_all(path, ec);
    }
    std::string operator/(const std::string& name) const { return (path / name).string(); }
};

std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

// 129 x 129 Float32 samples over 0.5 x 0.5 degrees near the Alps: two hills, a ridge, and a
// nodata block in the south-west corner.
std::string write_dem(const std::string& path) {
    GDALAllRegister();
    GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("GTiff");
    REQUIRE(driver != nullptr);
    constexpr int n = 129;
    GDALDatasetUniquePtr ds(driver->Create(path.c_str(), n, n, 1, GDT_Float32, nullptr));
    REQUIRE(ds != nullptr);
    double gt[6] = {7.25, 0.5 / (n - 1), 0, 46.75, 0, -0.5 / (n - 1)};
    ds->SetGeoTransform(gt);
    OGRSpatialReference srs;
    srs.importFromEPSG(4326);
    ds->SetSpatialRef(&srs);
    std::vector<float> v(static_cast<std::size_t>(n) * n);
    for (int r = 0; r < n; ++r) {
        for (int c = 0; c < n; ++c) {
            const double x = c / double(n - 1), y = r / double(n - 1);
            double h = 800 + 600 * std::exp(-((x - 0.3) * (x - 0.3) + (y - 0.4) * (y - 0.4)) * 20) +
                       400 * std::exp(-((x - 0.7) * (x - 0.7) + (y - 0.7) * (y - 0.7)) * 30) +
                       150 * std::sin(9 * x + 4 * y);
            if (c < 20 && r > n - 25) {
                h = -9999;
            }
            v[static_cast<std::size_t>(r) * n + c] = static_cast<float>(h);
        }
    }
    GDALRasterBand* band = ds->GetRasterBand(1);
    band->SetNoDataValue(-9999);
    REQUIRE(band->RasterIO(GF_Write, 0, 0, n, n, v.data(), n, n, GDT_Float32, 0, 0) == CE_None);
    return path;
}

struct Run {
    int code = -1;
    std::string out, err;
};

// Starts TB_BINARY with `args`; stdout/stderr go to files in `dir`. Returns the pid.
pid_t spawn(const std::vector<std::string>& args, const fs::path& dir) {
    std::vector<std::string> words{TB_BINARY};
    words.insert(words.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& w : words) {
        argv.push_back(w.data());
    }
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(
        &fa, 1, (dir / "stdout.txt").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(
        &fa, 2, (dir / "stderr.txt").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    pid_t pid = -1;
    const int rc = posix_spawn(&pid, argv[0], &fa, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    REQUIRE(rc == 0);
    return pid;
}

Run wait_for(pid_t pid, const fs::path& dir) {
    int status = 0;
    REQUIRE(::waitpid(pid, &status, 0) == pid);
    Run r;
    r.code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    r.out = slurp(dir / "stdout.txt");
    r.err = slurp(dir / "stderr.txt");
    return r;
}

Run run(const std::vector<std::string>& args, const BuildDir& dir) {
    return wait_for(spawn(args, dir.path), dir.path);
}

// Every file under `root` (relative path -> bytes).
std::map<std::string, std::string> tree(const fs::path& root) {
    std::map<std::string, std::string> files;
    for (const auto& e : fs::recursive_directory_iterator(root)) {
        if (e.is_regular_file()) {
            files[fs::relative(e.path(), root).string()] = slurp(e.path());
        }
    }
    return files;
}

std::size_t count_tiles(const fs::path& layer_dir) {
    std::size_t n = 0;
    std::error_code ec;
    for (auto it = fs::recursive_directory_iterator(layer_dir, ec);
         !ec && it != fs::recursive_directory_iterator();
         it.increment(ec)) {
        const auto ext = it->path().extension();
        n += (ext == ".glb" || ext == ".drc") ? 1 : 0;
    }
    return n;
}

// Tiles of an SQLite store: "layer/fmt/eps/z/x/y" -> bytes.
std::map<std::string, std::string> sqlite_tiles(const std::string& path) {
    std::map<std::string, std::string> tiles;
    sqlite3* db = nullptr;
    REQUIRE(sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK);
    sqlite3_stmt* s = nullptr;
    REQUIRE(sqlite3_prepare_v2(
                db, "SELECT layer, format, eps_level, z, x, y, data FROM tiles", -1, &s, nullptr) ==
            SQLITE_OK);
    while (sqlite3_step(s) == SQLITE_ROW) {
        std::string key;
        for (int i = 0; i < 6; ++i) {
            key += std::string(reinterpret_cast<const char*>(sqlite3_column_text(s, i))) + "/";
        }
        tiles[key] = std::string(static_cast<const char*>(sqlite3_column_blob(s, 6)),
                                 static_cast<std::size_t>(sqlite3_column_bytes(s, 6)));
    }
    sqlite3_finalize(s);
    sqlite3_close(db);
    return tiles;
}

// The tile files of a directory build, in the SQLite store's key form.
std::map<std::string, std::string> dir_tiles(const fs::path& out, const std::string& layer) {
    std::map<std::string, std::string> tiles;
    for (const auto& [rel, bytes] : tree(out / layer)) {
        const fs::path p(rel);
        const auto ext = p.extension().string();
        if (ext != ".glb" && ext != ".drc") {
            continue;
        }
        // z/x/y.ext
        const std::string zxy = p.parent_path().string() + "/" + p.stem().string();
        tiles[layer + "/" + ext.substr(1) + "/-1/" + zxy + "/"] = bytes;
    }
    return tiles;
}

// Follows the tileset's "uri"s; returns the tile paths (relative to the layer) it names.
std::vector<std::string> tileset_tiles(const fs::path& layer_dir) {
    std::vector<std::string> tiles;
    std::vector<std::string> todo{"tileset.json"};
    while (!todo.empty()) {
        const std::string doc = todo.back();
        todo.pop_back();
        REQUIRE_MESSAGE(fs::exists(layer_dir / doc), doc);
        const std::string json = slurp(layer_dir / doc);
        const fs::path base = fs::path(doc).parent_path();
        for (auto at = json.find("\"uri\":\""); at != std::string::npos;
             at = json.find("\"uri\":\"", at + 1)) {
            const auto q = json.find('"', at + 7);
            const std::string target =
                (base / json.substr(at + 7, q - at - 7)).lexically_normal().string();
            if (target.ends_with(".json")) {
                todo.push_back(target);
            } else {
                tiles.push_back(target);
            }
        }
    }
    return tiles;
}

// Small pyramids, named and formatted as these tests expect (the command's own defaults are
// checked in "build without --layer or --formats ...").
const std::vector<std::string> kSmall = {
    "--size", "32", "--min-zoom", "7", "--max-zoom", "9", "--layer", "terrain", "--formats", "glb"};

// The layer a build with kSmall makes of `dem`, opened in-process.
std::shared_ptr<const Layer> small_layer(const std::string& dem) {
    LayerOptions o;
    o.sources = {dem};
    o.tile_size = 32;
    o.min_zoom = 7;
    o.max_zoom = 9;
    return Layer::open(o);
}

std::vector<std::string>
args(const std::string& dem, const std::string& out, std::vector<std::string> extra = {}) {
    std::vector<std::string> a{"build", dem, "-o", out};
    a.insert(a.end(), kSmall.begin(), kSmall.end());
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
}

} // namespace

TEST_CASE("shard parsing takes I/N 0-based and auto/N from the job index") {
    CHECK(parse_shard("0/1").index == 0);
    CHECK(parse_shard("3/8").count == 8);
    CHECK_THROWS_AS(parse_shard("8/8"), tb::InputError);
    CHECK_THROWS_AS(parse_shard("-1/8"), tb::InputError);
    CHECK_THROWS_AS(parse_shard("1/0"), tb::InputError);
    CHECK_THROWS_AS(parse_shard("1"), tb::InputError);
    CHECK_THROWS_AS(parse_shard("a/2"), tb::InputError);
    CHECK_THROWS_AS(parse_shard("1/2x"), tb::InputError);
    ::setenv("JOB_COMPLETION_INDEX", "2", 1);
    CHECK(parse_shard("auto/4").index == 2);
    ::setenv("JOB_COMPLETION_INDEX", "4", 1);
    CHECK_THROWS_AS(parse_shard("auto/4"), tb::InputError);
    ::unsetenv("JOB_COMPLETION_INDEX");
    ::setenv("SLURM_ARRAY_TASK_ID", "1", 1);
    CHECK(parse_shard("auto/4").index == 1);
    ::unsetenv("SLURM_ARRAY_TASK_ID");
    CHECK_THROWS_AS(parse_shard("auto/4"), tb::InputError);
    // Every shard gets a share of a zoom's tiles.
    std::vector<int> per(4, 0);
    for (std::int64_t x = 0; x < 16; ++x) {
        for (std::int64_t y = 0; y < 16; ++y) {
            ++per[static_cast<std::size_t>(shard_of(TileId{8, x, y}, 4))];
        }
    }
    for (int n : per) {
        CHECK(n > 30);
    }
}

TEST_CASE("build writes every tile its tileset lists, each decodable, and the same bytes into "
          "both stores whatever the thread count") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const Run a =
        run(args(dem, dir / "out", {"--threads", "1", "--formats", "glb,drc", "--json"}), dir);
    INFO(a.err);
    REQUIRE(a.code == 0);
    CHECK(a.out.find("\"failed\":0") != std::string::npos);
    CHECK(a.out.find("\"tileset_written\":true") != std::string::npos);
    CHECK(a.err.find("tiles written") != std::string::npos);

    const fs::path layer = dir.path / "out/terrain";
    const auto listed = tileset_tiles(layer);
    REQUIRE(listed.size() > 5);
    for (const auto& t : listed) {
        CAPTURE(t);
        REQUIRE(fs::exists(layer / t));
        const DecodedTile d = decode_glb(slurp(layer / t));
        CHECK(d.indices.size() >= 3);
        const auto drc = (layer / t).replace_extension(".drc");
        REQUIRE(fs::exists(drc));
        CHECK(decode_drc(slurp(drc)).indices.size() >= 3);
    }
    // Nothing beyond what the tileset lists (plus the .drc twins) was written.
    CHECK(count_tiles(layer) == 2 * listed.size());
    CHECK(fs::exists(layer / "build-manifest.json"));

    const Run b =
        run(args(dem, dir / "out.sqlite", {"--threads", "2", "--formats", "glb,drc"}), dir);
    INFO(b.err);
    REQUIRE(b.code == 0);
    const auto in_dir = dir_tiles(dir.path / "out", "terrain");
    const auto in_db = sqlite_tiles(dir / "out.sqlite");
    CHECK(in_dir.size() == 2 * listed.size());
    CHECK(in_db.size() == in_dir.size());
    CHECK((in_db == in_dir));
    auto db = TileStore::open(dir / "out.sqlite");
    CHECK(db->get_document("terrain", "tileset.json") == slurp(layer / "tileset.json"));
}

TEST_CASE("a mercator build asked for every format makes its mesh and raster DEM tiles, no globe "
          "terrain (geodetic only), and fails no tile") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const Run a = run(args(dem,
                           dir / "out",
                           {"--threads",
                            "2",
                            "--scheme",
                            "mercator",
                            "--formats",
                            "glb,drc,terrain,terrain3d,terrarium",
                            "--json"}),
                      dir);
    INFO(a.err);
    REQUIRE(a.code == 0);
    CHECK(a.out.find("\"failed\":0") != std::string::npos);
    const fs::path layer = dir.path / "out/terrain";
    const auto listed = tileset_tiles(layer);
    REQUIRE(listed.size() > 5);
    std::size_t terrain = 0, png = 0;
    for (const auto& e : fs::recursive_directory_iterator(layer)) {
        terrain += e.path().extension() == ".terrain" ? 1 : 0;
        png += e.path().extension() == ".png" ? 1 : 0;
    }
    CHECK(terrain == 0);
    CHECK(png > 0);
    CHECK_FALSE(fs::exists(layer / "layer.json"));
}

TEST_CASE("a build killed half way and resumed equals one clean run, byte for byte") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    // Zoom 7..10: enough tiles to land a kill in the middle.
    const std::vector<std::string> deep = {"--max-zoom", "11", "--threads", "1"};
    REQUIRE(run(args(dem, dir / "clean", deep), dir).code == 0);
    const auto clean = tree(dir.path / "clean");
    const std::size_t total = count_tiles(dir.path / "clean/terrain");
    REQUIRE(total > 20);

    const pid_t pid = spawn(args(dem, dir / "killed", deep), dir.path);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (count_tiles(dir.path / "killed/terrain") < total / 3 &&
           std::chrono::steady_clock::now() < deadline) {
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    ::kill(pid, SIGKILL);
    const Run killed = wait_for(pid, dir.path);
    REQUIRE(killed.code == 128 + SIGKILL);
    const std::size_t partial = count_tiles(dir.path / "killed/terrain");
    CHECK(partial >= total / 3);
    CHECK(partial < total);
    CHECK_FALSE(fs::exists(dir.path / "killed/terrain/tileset.json"));

    // Without --resume the existing output is refused.
    const Run refused = run(args(dem, dir / "killed", deep), dir);
    CHECK(refused.code == 2);
    CHECK(refused.err.find("use --resume to continue, --update to follow changed DEMs, or "
                           "--force to overwrite") != std::string::npos);

    const Run resumed =
        run(args(dem, dir / "killed", {"--max-zoom", "11", "--resume", "--json"}), dir);
    INFO(resumed.err);
    REQUIRE(resumed.code == 0);
    CHECK(resumed.out.find("\"skipped\":" + std::to_string(partial)) != std::string::npos);
    CHECK((tree(dir.path / "killed") == clean));
}

TEST_CASE("SIGINT finishes the tiles in flight, exits non-zero, and --resume completes it") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    // Zoom 7..12 at size 64: long enough (about a second) for the signal to land mid-build.
    const std::vector<std::string> deep = {"--size", "64", "--max-zoom", "12", "--threads", "2"};
    const pid_t pid = spawn(args(dem, dir / "out.sqlite", deep), dir.path);
    // Wait until tiles are being made (the log says how many are planned first).
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (slurp(dir.path / "stderr.txt").find("thread(s), into") == std::string::npos &&
           std::chrono::steady_clock::now() < deadline) {
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    ::kill(pid, SIGINT);
    const Run stopped = wait_for(pid, dir.path);
    INFO(stopped.err);
    CHECK(stopped.code == 128 + SIGINT);
    CHECK(stopped.err.find("interrupted; run again with --resume") != std::string::npos);
    {
        auto store = TileStore::open(dir / "out.sqlite");
        CHECK_FALSE(store->get_document("terrain", "tileset.json").has_value());
    }
    const Run resumed =
        run(args(dem, dir / "out.sqlite", {"--size", "64", "--max-zoom", "12", "--resume"}), dir);
    INFO(resumed.err);
    REQUIRE(resumed.code == 0);
    REQUIRE(run(args(dem, dir / "clean.sqlite", deep), dir).code == 0);
    CHECK((sqlite_tiles(dir / "out.sqlite") == sqlite_tiles(dir / "clean.sqlite")));
}

TEST_CASE("shards 0/2 and 1/2 then --finalize give the unsharded build") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    REQUIRE(run(args(dem, dir / "whole"), dir).code == 0);

    const Run s0 = run(args(dem, dir / "sharded", {"--shard", "0/2", "--json"}), dir);
    INFO(s0.err);
    REQUIRE(s0.code == 0);
    CHECK(s0.out.find("\"tileset_written\":false") != std::string::npos);
    CHECK_FALSE(fs::exists(dir.path / "sharded/terrain/tileset.json"));
    // Finalizing before every shard reported is refused, naming the missing shard.
    const Run early = run(args(dem, dir / "sharded", {"--finalize"}), dir);
    CHECK(early.code == 2);
    CHECK(early.err.find("shard 1/2 has not finished") != std::string::npos);
    CHECK_FALSE(fs::exists(dir.path / "sharded/terrain/tileset.json"));

    const Run s1 = run(args(dem, dir / "sharded", {"--shard", "1/2"}), dir);
    INFO(s1.err);
    REQUIRE(s1.code == 0);
    // A shard count other than the first shards' is refused.
    CHECK(run(args(dem, dir / "sharded", {"--shard", "1/3"}), dir).code == 2);
    const Run fin = run(args(dem, dir / "sharded", {"--finalize"}), dir);
    INFO(fin.err);
    REQUIRE(fin.code == 0);

    auto whole = tree(dir.path / "whole");
    auto sharded = tree(dir.path / "sharded");
    // Same tiles and tileset; the sharded build also has its shard reports, and a manifest
    // that records the shard count.
    CHECK(sharded.erase("terrain/build-shards/0-of-2.json") == 1);
    CHECK(sharded.erase("terrain/build-shards/1-of-2.json") == 1);
    CHECK(sharded.erase("terrain/build-manifest.json") == 1);
    CHECK(whole.erase("terrain/build-manifest.json") == 1);
    // ... and the checksum files of those.
    CHECK(sharded.erase("terrain/build-shards/.0-of-2.json.crc32") == 1);
    CHECK(sharded.erase("terrain/build-shards/.1-of-2.json.crc32") == 1);
    CHECK(sharded.erase("terrain/.build-manifest.json.crc32") == 1);
    CHECK(whole.erase("terrain/.build-manifest.json.crc32") == 1);
    CHECK(whole.size() > 10);
    CHECK((whole == sharded));
}

TEST_CASE("--resume with different parameters names the one that differs, and --force "
          "starts over") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    REQUIRE(run(args(dem, dir / "out", {"--max-zoom", "8"}), dir).code == 0);
    const Run differs = run(args(dem, dir / "out", {"--max-zoom", "9", "--resume"}), dir);
    CHECK(differs.code == 2);
    CHECK(differs.err.find("max_zoom was 8, now 9") != std::string::npos);
    const Run fmt =
        run(args(dem, dir / "out", {"--max-zoom", "8", "--resume", "--formats", "drc"}), dir);
    CHECK(fmt.code == 2);
    CHECK(fmt.err.find("formats was [\"glb\"]") != std::string::npos);
    // nodata decides which samples are voids, so the tiles: recorded since the store manifests.
    const Run nodata =
        run(args(dem, dir / "out", {"--max-zoom", "8", "--resume", "--nodata", "800"}), dir);
    CHECK(nodata.code == 2);
    CHECK(nodata.err.find("nodata was null, now 800") != std::string::npos);
    // A finished build resumed again skips everything and changes nothing.
    const auto before = tree(dir.path / "out");
    const Run again = run(args(dem, dir / "out", {"--max-zoom", "8", "--resume", "--json"}), dir);
    REQUIRE(again.code == 0);
    CHECK(again.out.find("\"written\":0") != std::string::npos);
    CHECK((tree(dir.path / "out") == before));
    // --force replaces the layer: no zoom 9 leftovers after a rebuild to zoom 8.
    const auto stray = dir.path / "out/terrain/9/0/0.glb";
    fs::create_directories(stray.parent_path());
    std::ofstream(stray) << "stray";
    REQUIRE(run(args(dem, dir / "out", {"--max-zoom", "8", "--force"}), dir).code == 0);
    CHECK_FALSE(fs::exists(stray));
    CHECK((tree(dir.path / "out") == before));
}

TEST_CASE("bad build options and unusable outputs fail with clear errors") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    std::ofstream(dir / "file") << "x";
    struct Case {
        std::vector<std::string> extra;
        int code;
        std::string message;
    };
    const std::vector<Case> cases = {
        {{"--shard", "2/2"}, 2, "--shard '2/2'"},
        {{"--shard", "one/2"}, 2, "is not a whole number"},
        {{"--bbox", "1,2,3"}, 2, "expected W,S,E,N"},
        {{"--bbox", "8,47,7,46"}, 2, "-180 <= W < E <= 180"},
        {{"--bbox", "7,46,x,47"}, 2, "--bbox east: expected a number"},
        {{"--threads", "0"}, 2, "--threads 0: expected 1..1024"},
        {{"--threads", "many"}, 2, "--threads: expected a whole number"},
        {{"--formats", "glb,png"}, 2, "unknown format 'png'"},
        {{"--formats", "glb,glb"}, 2, "glb twice"},
        {{"--force", "--resume"}, 2, "--force"},
        {{"--finalize"}, 2, "nothing to finalize"},
    };
    for (const auto& c : cases) {
        CAPTURE(c.message);
        const Run r = run(args(dem, dir / "out", c.extra), dir);
        CHECK(r.code == c.code);
        CHECK(r.err.find(c.message) != std::string::npos);
        if (r.err.find(c.message) == std::string::npos) {
            MESSAGE(r.err);
        }
    }
    CHECK_FALSE(fs::exists(dir.path / "out/terrain/tileset.json"));
    // Output under a regular file: an IoError naming the path, exit 3.
    for (const std::string& out : {dir / "file/out", dir / "file/out.sqlite"}) {
        const Run r = run(args(dem, out), dir);
        CHECK(r.code == 3);
        CHECK(r.err.find(dir / "file") != std::string::npos);
    }
    const Run no_out = run({"build", dem}, dir);
    CHECK(no_out.code == 2);
    CHECK(no_out.err.find("-o OUT") != std::string::npos);
    const Run missing = run({"build", dir / "nope.tif", "-o", dir / "o2"}, dir);
    CHECK(missing.code == 2);
    CHECK(missing.err.find("nope.tif") != std::string::npos);
}

TEST_CASE("a build that fills the disk fails with exit 3, and --resume finishes it with room") {
    BuildDir dir;
    const auto disk = dir.path / "disk";
    fs::create_directories(disk);
    if (::mount("tmpfs", disk.c_str(), "tmpfs", 0, "size=64k") != 0) {
        MESSAGE("skipped: cannot mount a 64 KiB tmpfs at " << disk.string() << " (needs root)");
        return;
    }
    struct Unmount {
        fs::path p;
        ~Unmount() { ::umount(p.c_str()); }
    } unmount{disk};
    const auto dem = write_dem(dir / "dem.tif");
    const Run full = run(args(dem, (disk / "out").string(), {"--max-zoom", "10"}), dir);
    CHECK(full.code == 3);
    CHECK(full.err.find("disk is full") != std::string::npos);
    CHECK_FALSE(fs::exists(disk / "out/terrain/tileset.json"));
    // No temporary file is left, and every tile that is there is whole: compare with a clean run.
    REQUIRE(run(args(dem, dir / "clean", {"--max-zoom", "10"}), dir).code == 0);
    const auto clean = tree(dir.path / "clean");
    std::size_t present = 0;
    for (const auto& [rel, bytes] : tree(disk / "out")) {
        CAPTURE(rel);
        CHECK(rel.find(".tmp-") == std::string::npos);
        if (rel.ends_with(".glb")) {
            CHECK(clean.at(rel) == bytes);
            ++present;
        }
    }
    CHECK(present > 0);
    // Move the partial output to a roomy disk and resume there.
    fs::copy(disk / "out", dir.path / "moved", fs::copy_options::recursive);
    const Run resumed = run(args(dem, dir / "moved", {"--max-zoom", "10", "--resume"}), dir);
    INFO(resumed.err);
    REQUIRE(resumed.code == 0);
    CHECK((tree(dir.path / "moved") == clean));
}

TEST_CASE("build makes a decodable pyramid of a real DEM with nodata (elev.tif)") {
    const std::string dem = std::string(TB_SHARED_DATA) + "/elev.tif";
    if (!fs::exists(dem)) {
        MESSAGE("skipped: " << std::string(dem) << " is missing");
        return;
    }
    BuildDir dir;
    const Run r = run({"build",
                       dem,
                       "-o",
                       dir / "lux.sqlite",
                       "--size",
                       "32",
                       "--layer",
                       "lux",
                       "--formats",
                       "glb",
                       "--json"},
                      dir);
    INFO(r.err);
    REQUIRE(r.code == 0);
    CHECK(r.out.find("\"tileset_written\":true") != std::string::npos);
    auto store = TileStore::open(dir / "lux.sqlite");
    const auto tileset = store->get_document("lux", "tileset.json");
    REQUIRE(tileset.has_value());
    const auto tiles = sqlite_tiles(dir / "lux.sqlite");
    CHECK(tiles.size() > 3);
    // Tiles wholly outside the country (all voids) are empty scenes; the others draw terrain.
    std::size_t drawn = 0;
    for (const auto& [key, bytes] : tiles) {
        CAPTURE(key);
        const auto decoded = decode_glb(bytes);
        CHECK(decoded.indices.size() % 3 == 0);
        drawn += decoded.indices.empty() ? 0 : 1;
    }
    CHECK(drawn > 3);
}

TEST_CASE("a --bbox build makes only the tiles meeting the box, the same bytes, and no tileset") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    REQUIRE(run(args(dem, dir / "whole"), dir).code == 0);
    const Run part = run(args(dem, dir / "part", {"--bbox", "7.3,46.3,7.4,46.4", "--json"}), dir);
    INFO(part.err);
    REQUIRE(part.code == 0);
    CHECK(part.out.find("\"tileset_written\":false") != std::string::npos);
    CHECK(part.err.find("outside --bbox") != std::string::npos);
    CHECK_FALSE(fs::exists(dir.path / "part/terrain/tileset.json"));
    const auto whole = dir_tiles(dir.path / "whole", "terrain");
    const auto some = dir_tiles(dir.path / "part", "terrain");
    CHECK(some.size() >= 3); // at least one tile per zoom 7..9
    CHECK(some.size() < whole.size());
    for (const auto& [key, bytes] : some) {
        CAPTURE(key);
        REQUIRE(whole.count(key) == 1);
        CHECK(whole.at(key) == bytes);
    }
}

TEST_CASE("build --formats glb,terrarium,mapbox writes the DEM pyramid beside the mesh tiles, "
          "tile for tile what the layer makes, into both stores, and resumes") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const std::vector<std::string> dem_args = {
        "--formats", "glb,terrarium,mapbox", "--dem-size", "256", "--json"};
    const Run a = run(args(dem, dir / "out", dem_args), dir);
    INFO(a.err);
    REQUIRE(a.code == 0);
    CHECK(a.out.find("\"tileset_written\":true") != std::string::npos);

    // The expected DEM tiles: every tile of the layer's DEM pyramid, in both encodings.
    LayerOptions o;
    o.sources = {dem};
    o.dem_tile_size = 256;
    const auto layer = Layer::open(o);
    const DemTilePlan plan = dem_tile_plan(*layer);
    std::map<std::string, std::string> expected;
    std::int64_t dem_tiles = 0;
    for (int z = plan.min_zoom; z <= plan.max_zoom; ++z) {
        const TileRange r = dem_tiles_at(*layer, z);
        for (std::int64_t y = r.y0; y <= r.y1; ++y) {
            for (std::int64_t x = r.x0; x <= r.x1; ++x) {
                const TileId id{z, x, y};
                const std::string zxy =
                    std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y);
                expected["dem/" + zxy + ".png"] = make_dem_tile(
                    *layer, ValidTile::parse(Scheme::Mercator, id), Format::Terrarium);
                expected["dem/mapbox/" + zxy + ".png"] =
                    make_dem_tile(*layer, ValidTile::parse(Scheme::Mercator, id), Format::Mapbox);
                ++dem_tiles;
            }
        }
    }
    REQUIRE(dem_tiles >= 2);
    CHECK(a.out.find("\"dem_written\":" + std::to_string(dem_tiles) + ",") != std::string::npos);
    CHECK(a.err.find("of them DEM tiles") != std::string::npos);
    std::map<std::string, std::string> written;
    for (const auto& [rel, bytes] : tree(dir.path / "out/terrain")) {
        if (rel.ends_with(".png")) {
            written[rel] = bytes;
        }
    }
    CHECK(written.size() == expected.size());
    CHECK((written == expected));
    // Mesh tiles are all there too: every tile the tileset lists.
    for (const auto& t : tileset_tiles(dir.path / "out/terrain")) {
        CHECK(fs::exists(dir.path / "out/terrain" / t));
    }

    // The SQLite store holds the same DEM tiles under their format names.
    const Run b = run(args(dem, dir / "out.sqlite", dem_args), dir);
    INFO(b.err);
    REQUIRE(b.code == 0);
    std::size_t in_db = 0;
    for (const auto& [key, bytes] : sqlite_tiles(dir / "out.sqlite")) {
        for (const char* encoding : {"terrarium", "mapbox"}) {
            const std::string prefix = std::string("terrain/") + encoding + "/-1/";
            if (key.rfind(prefix, 0) == 0) {
                std::string zxy = key.substr(prefix.size());
                zxy.pop_back(); // the trailing '/'
                const std::string rel = std::string(encoding) == "terrarium"
                                            ? "dem/" + zxy + ".png"
                                            : "dem/mapbox/" + zxy + ".png";
                CHECK(expected.at(rel) == bytes);
                ++in_db;
            }
        }
    }
    CHECK(in_db == expected.size());

    // A resumed build finds everything there; another DEM tile size is a different build.
    const Run again =
        run(args(dem,
                 dir / "out",
                 {"--formats", "glb,terrarium,mapbox", "--dem-size", "256", "--resume", "--json"}),
            dir);
    INFO(again.err);
    REQUIRE(again.code == 0);
    CHECK(again.out.find("\"written\":0,") != std::string::npos);
    const Run other =
        run(args(dem,
                 dir / "out",
                 {"--formats", "glb,terrarium,mapbox", "--dem-size", "512", "--resume"}),
            dir);
    CHECK(other.code == 2);
    CHECK(other.err.find("dem_tile_size was 256, now 512") != std::string::npos);
}

TEST_CASE("a build of DEM tiles alone writes no tileset and no mesh tile") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const Run a = run(args(dem, dir / "out", {"--formats", "terrarium", "--json"}), dir);
    INFO(a.err);
    REQUIRE(a.code == 0);
    CHECK(a.out.find("\"tileset_written\":false") != std::string::npos);
    CHECK_FALSE(fs::exists(dir.path / "out/terrain/tileset.json"));
    CHECK(count_tiles(dir.path / "out/terrain") == 0);
    std::size_t pngs = 0;
    for (const auto& [rel, bytes] : tree(dir.path / "out/terrain")) {
        pngs += rel.ends_with(".png") ? 1 : 0;
        CHECK(rel.find("mapbox") == std::string::npos);
    }
    CHECK(pngs > 0);
    CHECK(a.out.find("\"dem_written\":" + std::to_string(pngs) + ",") != std::string::npos);
    const Run bad = run(args(dem, dir / "other", {"--formats", "png"}), dir);
    CHECK(bad.code == 2);
    CHECK(bad.err.find("unknown format 'png'") != std::string::npos);
    const Run size =
        run(args(dem, dir / "other", {"--formats", "terrarium", "--dem-size", "300"}), dir);
    CHECK(size.code == 2);
    CHECK(size.err.find("--dem-size 300: expected 256 or 512") != std::string::npos);
}

TEST_CASE("build --resume re-makes every damaged tile (0 bytes, truncated, garbage, a flipped "
          "byte) in both stores") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const std::vector<std::string> damage_names = {"0 bytes", "truncated", "garbage", "flipped"};
    const auto damage = [](const std::string& good, std::size_t kind) {
        switch (kind) {
        case 0:
            return std::string();
        case 1:
            return good.substr(0, good.size() / 2);
        case 2:
            return std::string(good.size(), '\x5a');
        default: {
            std::string t = good;
            t[t.size() / 3] = static_cast<char>(t[t.size() / 3] ^ 0x20);
            return t;
        }
        }
    };

    // Directory store.
    REQUIRE(run(args(dem, dir / "out"), dir).code == 0);
    const auto clean = tree(dir.path / "out");
    std::vector<fs::path> tiles;
    for (const auto& [name, bytes] : clean) {
        if (fs::path(name).extension() == ".glb") {
            tiles.push_back(dir.path / "out" / name);
        }
    }
    REQUIRE(tiles.size() > damage_names.size());
    for (std::size_t k = 0; k < damage_names.size(); ++k) {
        std::ofstream(tiles[k], std::ios::binary | std::ios::trunc) << damage(slurp(tiles[k]), k);
    }
    const Run resumed = run(args(dem, dir / "out", {"--resume", "--json"}), dir);
    INFO(resumed.err);
    REQUIRE(resumed.code == 0);
    CHECK(resumed.out.find("\"written\":4") != std::string::npos);
    CHECK(resumed.err.find("damaged") != std::string::npos);
    CHECK((tree(dir.path / "out") == clean));

    // SQLite store.
    const std::string db_path = dir / "out.sqlite";
    REQUIRE(run(args(dem, db_path), dir).code == 0);
    const auto clean_rows = sqlite_tiles(db_path);
    {
        sqlite3* db = nullptr;
        REQUIRE(sqlite3_open(db_path.c_str(), &db) == SQLITE_OK);
        sqlite3_stmt* rows = nullptr;
        REQUIRE(
            sqlite3_prepare_v2(
                db, "SELECT rowid, data FROM tiles ORDER BY rowid LIMIT 4", -1, &rows, nullptr) ==
            SQLITE_OK);
        std::vector<std::pair<sqlite3_int64, std::string>> picked;
        while (sqlite3_step(rows) == SQLITE_ROW) {
            const auto* data = static_cast<const char*>(sqlite3_column_blob(rows, 1));
            picked.emplace_back(sqlite3_column_int64(rows, 0),
                                std::string(data, sqlite3_column_bytes(rows, 1)));
        }
        sqlite3_finalize(rows);
        REQUIRE(picked.size() == 4);
        for (std::size_t k = 0; k < picked.size(); ++k) {
            sqlite3_stmt* update = nullptr;
            REQUIRE(sqlite3_prepare_v2(
                        db, "UPDATE tiles SET data=?1 WHERE rowid=?2", -1, &update, nullptr) ==
                    SQLITE_OK);
            const std::string bad = damage(picked[k].second, k);
            sqlite3_bind_blob(
                update, 1, bad.data(), static_cast<int>(bad.size()), SQLITE_TRANSIENT);
            sqlite3_bind_int64(update, 2, picked[k].first);
            CHECK(sqlite3_step(update) == SQLITE_DONE);
            sqlite3_finalize(update);
        }
        sqlite3_close(db);
    }
    REQUIRE(sqlite_tiles(db_path) != clean_rows);
    const Run resumed_db = run(args(dem, db_path, {"--resume", "--json"}), dir);
    INFO(resumed_db.err);
    REQUIRE(resumed_db.code == 0);
    CHECK(resumed_db.out.find("\"written\":4") != std::string::npos);
    CHECK((sqlite_tiles(db_path) == clean_rows));
}

TEST_CASE("build -o under a directory that does not exist fails with exit 3 and creates nothing") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    for (const std::string out : {"missing/dir/out", "missing/dir/out.sqlite"}) {
        CAPTURE(out);
        const Run r = run(args(dem, dir / out), dir);
        CHECK(r.code == 3);
        CHECK(r.err.find((dir.path / "missing/dir").string() +
                         " does not exist; create it first") != std::string::npos);
        CHECK_FALSE(fs::exists(dir.path / "missing"));
    }
}

TEST_CASE("build --formats glb,terrain writes layer.json and every terrain tile it lists from "
          "zoom 0, the layer's own bytes with only the metadata extension, gzip-compressed in a "
          "directory and raw in SQLite; a --bbox build writes no layer.json") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const Run a = run(args(dem, dir / "out", {"--formats", "glb,terrain", "--json"}), dir);
    INFO(a.err);
    REQUIRE(a.code == 0);
    CHECK(a.out.find("\"tileset_written\":true") != std::string::npos);
    const fs::path root = dir.path / "out/terrain";
    REQUIRE(fs::exists(root / "layer.json"));

    const auto layer = small_layer(dem);
    std::string layer_json;
    REQUIRE(layer->document("layer.json", layer_json));
    CHECK(slurp(root / "layer.json") == layer_json_with_extensions(layer_json, kMetadata));
    CHECK(slurp(root / "layer.json").find("\"extensions\":[\"metadata\"],") != std::string::npos);
    CHECK(layer_json.find("\"format\":\"quantized-mesh-1.0\"") != std::string::npos);

    // Every available range of layer.json, read back from its text, is on disk.
    std::map<std::string, std::string> expected;
    std::size_t level = 0, at = layer_json.find("\"available\":[") + 13;
    const std::size_t end = layer_json.find("]]", at);
    while (at < end) {
        const std::size_t open = layer_json.find('[', at);
        const std::size_t close = layer_json.find(']', open);
        const std::string ranges = layer_json.substr(open, close - open);
        for (std::size_t r = ranges.find("startX"); r != std::string::npos;
             r = ranges.find("startX", r + 1)) {
            const auto field = [&](const char* name) {
                return std::stoll(ranges.substr(ranges.find(name, r) + std::strlen(name) + 2));
            };
            for (auto y = field("startY"); y <= field("endY"); ++y) {
                for (auto x = field("startX"); x <= field("endX"); ++x) {
                    const TileId id{static_cast<int>(level), x, y};
                    expected[std::to_string(level) + "/" + std::to_string(x) + "/" +
                             std::to_string(y) + ".terrain"] =
                        select_extensions(layer->make_tile(layer->tile(id), Format::Terrain),
                                          kMetadata);
                }
            }
        }
        ++level;
        at = close + 1;
    }
    CHECK(level == static_cast<std::size_t>(layer->max_zoom() + 1));
    std::map<std::string, std::string> written;
    for (const auto& [rel, bytes] : tree(root)) {
        if (rel.ends_with(".terrain")) {
            REQUIRE(looks_gzipped(bytes));
            written[rel] = gzip_decompress(bytes, std::size_t{1} << 30).value_or("(damaged)");
        }
    }
    CHECK(written.size() == expected.size());
    CHECK((written == expected));
    CHECK(written.count("0/0/0.terrain") == 1);
    CHECK(written.count("0/1/0.terrain") == 1);

    const Run b = run(args(dem, dir / "out.sqlite", {"--formats", "glb,terrain"}), dir);
    INFO(b.err);
    REQUIRE(b.code == 0);
    std::size_t in_db = 0;
    for (const auto& [key, bytes] : sqlite_tiles(dir / "out.sqlite")) {
        const std::string prefix = "terrain/terrain/-1/";
        if (key.rfind(prefix, 0) == 0) {
            std::string zxy = key.substr(prefix.size());
            zxy.pop_back();
            CHECK(expected.at(zxy + ".terrain") == bytes);
            ++in_db;
        }
    }
    CHECK(in_db == expected.size());
    CHECK(TileStore::open(dir / "out.sqlite")->get_document("terrain", "layer.json") ==
          layer_json_with_extensions(layer_json, kMetadata));

    const Run part =
        run(args(dem, dir / "part", {"--formats", "terrain", "--bbox", "7.3,46.3,7.4,46.4"}), dir);
    INFO(part.err);
    REQUIRE(part.code == 0);
    CHECK(part.err.find("layer.json not written") != std::string::npos);
    CHECK_FALSE(fs::exists(dir.path / "part/terrain/layer.json"));
}

TEST_CASE("build --terrain-extensions all keeps the layer's whole terrain tiles and lists every "
          "extension; resuming with another list is refused, naming it") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const Run a =
        run(args(dem, dir / "out", {"--formats", "terrain", "--terrain-extensions", "all"}), dir);
    INFO(a.err);
    REQUIRE(a.code == 0);
    const auto layer = small_layer(dem);
    std::string layer_json;
    REQUIRE(layer->document("layer.json", layer_json));
    CHECK(slurp(dir.path / "out/terrain/layer.json") == layer_json);
    auto store = TileStore::open(dir / "out");
    for (const TileId id : {TileId{0, 0, 0}, TileId{0, 1, 0}}) {
        CAPTURE(id.x);
        CHECK(store->get(TileKey{"terrain", id, Format::Terrain, -1}) ==
              layer->make_tile(layer->tile(id), Format::Terrain));
    }

    const Run other = run(args(dem, dir / "out", {"--formats", "terrain", "--resume"}), dir);
    CHECK(other.code != 0);
    CHECK(other.err.find(R"(terrain_extensions was ["octvertexnormals","watermask","metadata"], )"
                         R"(now ["metadata"])") != std::string::npos);
    const Run bad = run(args(dem, dir / "bad", {"--terrain-extensions", "normals"}), dir);
    CHECK(bad.code != 0);
    CHECK(bad.err.find("unknown name 'normals'") != std::string::npos);
}

TEST_CASE("build without --layer or --formats names the layer after its first input, as serve "
          "does, and makes glb, terrain, terrain3d and terrarium with their documents") {
    BuildDir dir;
    const auto dem = write_dem(dir / "Alps_10m.v2.tif");
    const Run a =
        run({"build", dem, "-o", dir / "out", "--size", "32", "--min-zoom", "7", "--max-zoom", "8"},
            dir);
    INFO(a.err);
    REQUIRE(a.code == 0);
    const fs::path layer = dir.path / "out/Alps_10m";
    for (const char* doc : {"tileset.json",
                            "layer.json",
                            "terrain/tileset.json",
                            "dem/tilejson.json",
                            "build-manifest.json"}) {
        CAPTURE(doc);
        CHECK(fs::exists(layer / doc));
    }
    CHECK(fs::exists(layer / "0/0/0.terrain"));
    CHECK_FALSE(fs::exists(layer / "dem/mapbox"));
    CHECK(slurp(layer / "build-manifest.json")
              .find(R"("formats": ["glb", "terrain", "terrain3d", "terrarium"])") !=
          std::string::npos);
}

TEST_CASE("a directory build writes the host files, whose rules cover every file it holds, and "
          "the DEM TileJSON with relative or --base-url tile URLs") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const Run a = run(
        args(dem, dir / "out", {"--formats", "glb,drc,terrarium,mapbox,terrain,terrain3d"}), dir);
    INFO(a.err);
    REQUIRE(a.code == 0);
    for (const HostFile& f : host_files()) {
        CHECK(slurp(dir.path / "out" / f.name) == f.text);
    }
    std::set<std::string> kinds;
    for (const auto& [rel, bytes] : tree(dir.path / "out")) {
        const std::string file = fs::path(rel).filename().string();
        if (file.front() == '.' || file == "_headers" || file == "terrabound-nginx.conf") {
            continue; // checksums and locks: hidden, never served
        }
        kinds.insert(fs::path(rel).extension().string().substr(1));
    }
    CHECK(kinds.size() >= 6); // glb drc png terrain subtree json
    for (const std::string& kind : kinds) {
        CAPTURE(kind);
        CHECK(std::any_of(host_rules().begin(), host_rules().end(), [&](const HostRule& r) {
            return r.extension == kind;
        }));
        CHECK(host_files()[0].text.find("location ~ \\." + kind + "$ {") != std::string::npos);
        CHECK(host_files()[1].text.find("/*." + kind + "\n") != std::string::npos);
    }
    const auto rule = std::find_if(host_rules().begin(), host_rules().end(), [](const HostRule& r) {
        return r.extension == "terrain";
    });
    REQUIRE(rule != host_rules().end());
    CHECK(rule->encoding == "gzip");
    CHECK(rule->media_type == "application/vnd.quantized-mesh");

    const auto layer = small_layer(dem);
    const std::string terrarium = slurp(dir.path / "out/terrain/dem/tilejson.json");
    CHECK(terrarium == dem_tilejson(*layer, Format::Terrarium, "{z}/{x}/{y}.png"));
    CHECK(terrarium.find(R"("encoding":"terrarium")") != std::string::npos);
    CHECK(slurp(dir.path / "out/terrain/dem/mapbox/tilejson.json") ==
          dem_tilejson(*layer, Format::Mapbox, "{z}/{x}/{y}.png"));

    const Run b = run(args(dem,
                           dir / "hosted",
                           {"--formats", "terrarium", "--base-url", "https://example.com/t/"}),
                      dir);
    INFO(b.err);
    REQUIRE(b.code == 0);
    CHECK(slurp(dir.path / "hosted/terrain/dem/tilejson.json")
              .find(R"("tiles":["https://example.com/t/terrain/dem/{z}/{x}/{y}.png"])") !=
          std::string::npos);
    const Run db = run(args(dem, dir / "out.sqlite", {"--formats", "mapbox"}), dir);
    REQUIRE(db.code == 0);
    CHECK(
        TileStore::open(dir / "out.sqlite")->get_document("terrain", "dem/mapbox/tilejson.json") ==
        dem_tilejson(*layer, Format::Mapbox, "{z}/{x}/{y}.png"));
    CHECK_FALSE(fs::exists(dir.path / "_headers"));
    const Run bad = run(args(dem, dir / "bad", {"--base-url", "example.com"}), dir);
    CHECK(bad.code != 0);
    CHECK(bad.err.find("--base-url 'example.com': expected where OUT will be hosted") !=
          std::string::npos);
}

TEST_CASE("build --formats terrain3d writes terrain/tileset.json, every subtree it reaches and "
          "every glb they list, where its URI templates point, the layer's own bytes, into both "
          "stores") {
    BuildDir dir;
    const auto dem = write_dem(dir / "dem.tif");
    const Run a = run(args(dem, dir / "out", {"--formats", "terrain3d"}), dir);
    INFO(a.err);
    REQUIRE(a.code == 0);
    const fs::path root = dir.path / "out/terrain/terrain";
    REQUIRE(fs::exists(root / "tileset.json"));

    const auto layer = small_layer(dem);
    std::string tileset;
    REQUIRE(layer->document("terrain/tileset.json", tileset));
    CHECK(slurp(root / "tileset.json") == tileset);
    const auto doc = nlohmann::json::parse(tileset);
    const int levels = doc["root"]["children"][0]["implicitTiling"]["subtreeLevels"];

    // From each root's subtree file, through the child subtrees each lists.
    std::map<std::string, std::string> expected; // relative path -> bytes
    for (int r = 0; r < 2; ++r) {
        std::vector<std::array<std::int64_t, 3>> todo{{0, 0, 0}};
        while (!todo.empty()) {
            const auto [level, sx, sy] = todo.back();
            todo.pop_back();
            const std::string at = std::to_string(r) + "/" + std::to_string(level) + "/" +
                                   std::to_string(sx) + "/" + std::to_string(sy);
            std::string bytes;
            REQUIRE(layer->document("terrain/" + at + ".subtree", bytes));
            expected[at + ".subtree"] = bytes;
            const tb_terrain3d::Subtree s = tb_terrain3d::read_subtree(bytes);
            std::size_t offset = 0;
            for (int l = 0; l < levels && level + l <= layer->max_zoom(); ++l) {
                const std::int64_t side = std::int64_t{1} << l;
                for (std::int64_t j = 0; j < side; ++j) {
                    for (std::int64_t i = 0; i < side; ++i) {
                        if (!s.available(s.doc["tileAvailability"],
                                         offset + tb_terrain3d::morton(i, j))) {
                            continue;
                        }
                        const int z = static_cast<int>(level) + l;
                        const std::int64_t x = sx * side + i, y = sy * side + j;
                        expected[std::to_string(r) + "/" + std::to_string(z) + "/" +
                                 std::to_string(x) + "/" + std::to_string(y) + ".glb"] =
                            layer->make_tile(layer->tile(TileId{z, (std::int64_t{r} << z) + x, y}),
                                             Format::Terrain3d);
                    }
                }
                offset += static_cast<std::size_t>(side * side);
            }
            if (level + levels <= layer->max_zoom()) {
                const std::int64_t side = std::int64_t{1} << levels;
                for (std::int64_t j = 0; j < side; ++j) {
                    for (std::int64_t i = 0; i < side; ++i) {
                        if (s.available(s.doc["childSubtreeAvailability"],
                                        tb_terrain3d::morton(i, j))) {
                            todo.push_back({level + levels, sx * side + i, sy * side + j});
                        }
                    }
                }
            }
        }
    }
    std::map<std::string, std::string> written;
    for (const auto& [rel, bytes] : tree(root)) {
        if (rel.ends_with(".glb") || rel.ends_with(".subtree")) { // not the .crc32 sidecars
            written[rel] = bytes;
        }
    }
    for (const auto& [rel, bytes] : written) {
        CHECK_MESSAGE(expected.count(rel) == 1, rel << " was written but is listed nowhere");
    }
    CHECK(written.size() == expected.size());
    CHECK((written == expected));
    CHECK(written.count("0/0/0/0.glb") == 1);
    CHECK(written.count("1/0/0/0.glb") == 1);
    CHECK(written.count("0/0/0/0.subtree") == 1);

    const Run b = run(args(dem, dir / "out.sqlite", {"--formats", "terrain3d"}), dir);
    INFO(b.err);
    REQUIRE(b.code == 0);
    const auto store = TileStore::open(dir / "out.sqlite");
    CHECK(store->get_document("terrain", "terrain/tileset.json") == tileset);
    for (const auto& [rel, bytes] : expected) {
        if (rel.ends_with(".subtree")) {
            CHECK(store->get_document("terrain", "terrain/" + rel) == bytes);
        }
    }
    std::size_t in_db = 0;
    for (const auto& [key, bytes] : sqlite_tiles(dir / "out.sqlite")) {
        in_db += key.rfind("terrain/terrain3d/", 0) == 0 ? 1 : 0;
    }
    CHECK(in_db == static_cast<std::size_t>(
                       std::count_if(expected.begin(), expected.end(), [](const auto& e) {
                           return e.first.ends_with(".glb");
                       })));
}
