// build --update: after DEMs are added, replaced or removed, the store equals a full build of
// the new DEMs byte for byte (directory and SQLite, sharded or not), with fewer tiles made.
#include "core/error.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/pyramid/build.hpp"
#include "tiler/pyramid/update.hpp"
#include "tiler/stores/manifest.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>
#include <sqlite3.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>

using namespace tb::tiler;
using namespace tb_test;

namespace {

// A geographic Float32 DEM of w x h pixels of `step` degrees (dx = step * aspect, dy = step /
// aspect) from (west, north): hills whose shape `seed` varies, and a void in its south-west
// corner.
std::string write_dem(const std::string& path,
                      double west,
                      double north,
                      int w,
                      int h,
                      double step,
                      double seed,
                      double aspect = 1) {
    Fixture f;
    f.width = w, f.height = h;
    const double dx = step * aspect, dy = step / aspect;
    f.geotransform = std::array<double, 6>{west, dx, 0, north, 0, -dy};
    f.epsg = 4326;
    f.nodata = -9999;
    for (int r = 0; r < h; ++r) {
        for (int c = 0; c < w; ++c) {
            const double x = west + c * dx, y = north - r * dy;
            double v = 900 + 400 * std::sin(7 * x + seed) * std::cos(5 * y - seed) +
                       120 * std::sin(31 * x * y + 2 * seed);
            if (c < w / 8 && r > h - h / 8) {
                v = -9999;
            }
            f.values.push_back(v);
        }
    }
    return write_fixture(path, f);
}

// The tests' 0.8 degree cell (a.tif), and a finer block inside it (c.tif).
std::string cell_a(const ScratchDir& dir) {
    return write_dem(dir.file("a.tif"), 8.0, 47.0, 193, 193, 0.8 / 192, 0);
}
std::string finer_block_c(const ScratchDir& dir) {
    return write_dem(dir.file("c.tif"), 8.2, 46.5, 97, 97, 0.1 / 96, 2);
}

// Two overlapping DEMs of one grid in a scratch directory, and where their build goes.
struct TwoDems {
    ScratchDir dir;
    std::string a = cell_a(dir);
    std::string b = write_dem(dir.file("b.tif"), 8.6, 46.7, 97, 49, 0.8 / 192, 1);
    std::string out = dir.file("out");
};

BuildOptions options(const std::vector<std::string>& dems, const std::string& out) {
    BuildOptions o;
    o.layer.sources = dems;
    o.layer.tile_size = 32;
    o.layer.summary_dir = "off";
    o.output = out;
    o.formats = {Format::Glb, Format::Drc, Format::Terrain, Format::Terrain3d, Format::Terrarium};
    o.threads = 2;
    o.progress = ProgressMode::Off;
    return o;
}

// Runs `o` as `terrabound build` does, in a process of its own: each build opens the DEMs
// afresh, as users run it (a DEM replaced in place is read anew). InputError with the
// command's message when it fails.
BuildSummary build(BuildOptions o, bool update = false) {
    o.update = o.update || update;
    std::string command = std::string(TB_BINARY) + " build";
    for (const auto& dem : o.layer.sources) {
        command += " " + dem;
    }
    command += " -o " + o.output + " --layer terrain --size 32 --summary-dir off --threads 2 " +
               "--json --formats ";
    for (std::size_t i = 0; i < o.formats.size(); ++i) {
        command += (i ? "," : "") + std::string(format_name(o.formats[i]));
    }
    command += o.update ? " --update" : "";
    command += o.resume ? " --resume" : "";
    command += o.force ? " --force" : "";
    command += o.finalize ? " --finalize" : "";
    if (o.shard) {
        command +=
            " --shard " + std::to_string(o.shard->index) + "/" + std::to_string(o.shard->count);
    }
    const std::string out = o.output + ".stdout", err = o.output + ".stderr";
    const int status = std::system((command + " >" + out + " 2>" + err).c_str());
    const std::string json_line = slurp(out), messages = slurp(err);
    fs::remove(out);
    fs::remove(err);
    if (status != 0) {
        throw tb::InputError(messages);
    }
    const auto number = [&](const std::string& key) {
        const auto at = json_line.find("\"" + key + "\":");
        REQUIRE(at != std::string::npos);
        return std::atoll(json_line.c_str() + at + key.size() + 3);
    };
    BuildSummary s;
    s.written = number("written");
    s.removed = number("removed");
    s.failed = number("failed");
    s.tileset_written = json_line.find("\"tileset_written\":true") != std::string::npos;
    return s;
}

// Every file under a directory store, or every tile and document of an SQLite one.
std::map<std::string, std::string> contents(const std::string& out) {
    std::map<std::string, std::string> all;
    if (!out.ends_with(".sqlite")) {
        for (const auto& e : fs::recursive_directory_iterator(out)) {
            if (e.is_regular_file()) {
                all[fs::relative(e.path(), out).string()] = slurp(e.path());
            }
        }
        return all;
    }
    sqlite3* db = nullptr;
    REQUIRE(sqlite3_open_v2(out.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK);
    for (const char* sql : {"SELECT layer || '/' || format || '/' || eps_level || '/' || z || '/' "
                            "|| x || '/' || y, data FROM tiles",
                            "SELECT layer || '/' || name, data FROM documents"}) {
        sqlite3_stmt* s = nullptr;
        REQUIRE(sqlite3_prepare_v2(db, sql, -1, &s, nullptr) == SQLITE_OK);
        while (sqlite3_step(s) == SQLITE_ROW) {
            all[reinterpret_cast<const char*>(sqlite3_column_text(s, 0))] =
                std::string(static_cast<const char*>(sqlite3_column_blob(s, 1)),
                            static_cast<std::size_t>(sqlite3_column_bytes(s, 1)));
        }
        sqlite3_finalize(s);
    }
    sqlite3_close(db);
    return all;
}

// Checks that `out` holds exactly what a full build of `dems` into `fresh` holds.
// `full` makes the reference build into `fresh` (by default one unsharded build of `dems`).
void check_same_as_full(
    const std::vector<std::string>& dems,
    const std::string& out,
    const std::string& fresh,
    const BuildSummary& updated,
    bool fewer = true,
    const std::function<BuildSummary(const std::string&)>& make_full = nullptr) {
    const BuildSummary full = make_full ? make_full(fresh) : build(options(dems, fresh));
    const auto a = contents(out), b = contents(fresh);
    CHECK(a.size() == b.size());
    for (const auto& [name, bytes] : b) {
        CAPTURE(name);
        const auto it = a.find(name);
        REQUIRE(it != a.end());
        CHECK(it->second == bytes);
    }
    CHECK(updated.failed == 0);
    CHECK(updated.tileset_written);
    // The update made fewer tiles than the full build (unless every tile changed).
    CHECK((updated.written < full.written || !fewer));
    fs::remove_all(fresh);
    fs::remove(fresh);
}

void touch_later(const std::string& path) {
    fs::last_write_time(path, fs::last_write_time(path) + std::chrono::seconds(5));
}

} // namespace

TEST_CASE("build --update after a DEM is added, replaced or removed equals a full build, byte "
          "for byte, in a directory and in SQLite") {
    ScratchDir dir;
    // A 0.8 degree cell, a block on its grid at its east edge (a mosaic that grows), a finer
    // block inside it (a collection of two resolutions), and later one at its north-west corner.
    const std::string a = cell_a(dir);
    const std::string b = write_dem(dir.file("b.tif"), 8.6, 46.7, 97, 49, 0.8 / 192, 1);
    const std::string c = finer_block_c(dir);
    for (const std::string ext : {"", ".sqlite"}) {
        CAPTURE(ext);
        const std::string out = dir.file("out" + ext), fresh = dir.file("fresh" + ext);
        build(options({a}, out));
        INFO("added b");
        check_same_as_full({a, b}, out, fresh, build(options({a, b}, out), true));
        INFO("added c");
        // One pixel grid becomes a collection of two: every zoom is read another way.
        check_same_as_full({a, b, c}, out, fresh, build(options({a, b, c}, out), true), false);
        // Replaced in place: new heights, a later mtime.
        write_dem(b, 8.6, 46.7, 97, 49, 0.8 / 192, 5);
        touch_later(b);
        INFO("replaced b");
        check_same_as_full({a, b, c}, out, fresh, build(options({a, b, c}, out), true));
        INFO("removed b");
        const BuildSummary removed = build(options({a, c}, out), true);
        CHECK(removed.removed > 0); // the tiles east of a held b's data alone
        check_same_as_full({a, c}, out, fresh, removed);
        INFO("added d, growing a's grid north-west");
        // The grid's origin moves, and every read is placed from it.
        const double step = 0.8 / 192;
        const std::string d =
            write_dem(dir.file("d.tif"), 8.0 - 24 * step, 47.0 + 24 * step, 48, 48, step, 3);
        check_same_as_full({a, c, d}, out, fresh, build(options({a, c, d}, out), true), false);
        INFO("added e, of another grid, beyond a's east edge");
        // The data's bounds grow: raster DEM tiles carry a's edge out to them no longer.
        const std::string e = write_dem(dir.file("e.tif"), 9.1, 46.6, 49, 49, 0.2 / 48, 4);
        check_same_as_full(
            {a, c, d, e}, out, fresh, build(options({a, c, d, e}, out), true), false);
        const auto store = TileStore::open(out);
        CHECK_FALSE(store->get_document("terrain", kUpdateRecord));
    }
}

TEST_CASE("a DEM finer than all before leaves the eps ladder; the update adding it equals a full "
          "build and makes fewer tiles") {
    // The eps ladder follows the lattice (eps(z) = e0 / 2^z), so deepening the pyramid leaves
    // every zoom's ladder: a 0.8 degree cell with a finer block (a collection), then a block finer
    // still in another corner of the cell (next year's survey). Only a zoom whose eps is raised
    // to its reach may move, where the new DEM's blocks are rougher per lattice step than those
    // before: here the coarsest, whose four tiles' median the survey's tile sets.
    ScratchDir dir;
    const std::string a = cell_a(dir), c = finer_block_c(dir);
    const std::string f = write_dem(dir.file("f.tif"), 8.55, 46.9, 81, 81, 0.02 / 80, 6);
    const std::string out = dir.file("out"), fresh = dir.file("fresh");
    build(options({a, c}, out));
    const auto eps_of = [&] {
        const Manifest m = parse_manifest(slurp(out + "/terrain/" + kBuildManifest));
        return nlohmann::json::parse(manifest_value(m, "eps")).get<std::vector<double>>();
    };
    const std::vector<double> before = eps_of();
    check_same_as_full({a, c, f}, out, fresh, build(options({a, c, f}, out), true));
    const std::vector<double> after = eps_of();
    REQUIRE(after.size() == before.size() + 2); // f's two deeper zooms
    for (std::size_t k = 1; k < after.size(); ++k) {
        CAPTURE(k);
        CHECK(after[k] == after.back() * std::exp2(double(after.size() - 1 - k))); // the ladder
        CHECK((k >= before.size() || after[k] == before[k]));
    }
}

TEST_CASE("an update after which two grids swap rank (a file of one listed before the other's) "
          "equals a full build") {
    // Grids of pixels equally fine (the same area) rank by their first file given: w1's grid
    // (pixels twice as wide as a's, half as tall) ranks below a's until w2, of w1's grid, is
    // listed first. Then w1 wins over a where they overlap, outside w2's box.
    ScratchDir dir;
    const double step = 0.8 / 192;
    const std::string a = cell_a(dir);
    const std::string w1 = write_dem(dir.file("w1.tif"), 8.3, 46.8, 24, 96, step, 7, 2);
    const std::string w2 = write_dem(dir.file("w2.tif"), 8.6, 46.4, 24, 96, step, 8, 2);
    const std::string out = dir.file("out");
    build(options({a, w1}, out));
    check_same_as_full(
        {w2, a, w1}, out, dir.file("fresh"), build(options({w2, a, w1}, out), true), false);
}

namespace {

// The layer the tests' builds make of `dems` (32-sample tiles, no summaries).
std::shared_ptr<const Layer> open_layer(const std::vector<std::string>& dems) {
    LayerOptions o;
    o.sources = dems;
    o.tile_size = 32;
    o.summary_dir = "off";
    return Layer::open(o);
}

// Whether the layer may have a tile of zoom z at (lon, lat).
bool may_have_at(const Layer& layer, int z, double lon, double lat) {
    const TileRange r =
        tiles_covering(Scheme::Geodetic, {lon - 1e-9, lat - 1e-9, lon + 1e-9, lat + 1e-9}, z);
    return layer.may_have_tile(layer.tile({z, r.x0, r.y0}));
}

// How many tiles of zoom z the layer may have, counted one by one over tiles_at(z).
std::int64_t may_have_count(const Layer& layer, int z) {
    const TileRange all = layer.tiles_at(z);
    std::int64_t tiles = 0;
    for (std::int64_t y = all.y0; y <= all.y1; ++y) {
        for (std::int64_t x = all.x0; x <= all.x1; ++x) {
            tiles += layer.may_have_tile(layer.tile({z, x, y})) ? 1 : 0;
        }
    }
    return tiles;
}

// How many tiles one zoom of layer.json's "available" lists, overlaps counted twice.
std::int64_t listed_count(const nlohmann::json& zoom) {
    std::int64_t listed = 0;
    for (const auto& r : zoom) {
        listed += (r["endX"].get<std::int64_t>() - r["startX"].get<std::int64_t>() + 1) *
                  (r["endY"].get<std::int64_t>() - r["startY"].get<std::int64_t>() + 1);
    }
    return listed;
}

} // namespace

TEST_CASE("depth follows each DEM: the zooms only two far-apart blocks reach have tiles over "
          "each block, none over the land between them") {
    ScratchDir dir;
    const std::string a = cell_a(dir), c = finer_block_c(dir);
    const std::string f = write_dem(dir.file("f.tif"), 8.55, 46.9, 81, 81, 0.02 / 80, 6);
    const auto layer = open_layer({a, c, f});
    const int cell_deepest = open_layer({a})->max_zoom();
    const LonLatBox cb = DemSource::open({c})->footprint(), fb = DemSource::open({f})->footprint();
    const double mid_lon = (cb.east + fb.west) / 2, mid_lat = (cb.north + fb.south) / 2;
    std::string layer_json;
    REQUIRE(layer->document("layer.json", layer_json));
    const auto available = nlohmann::json::parse(layer_json)["available"];
    REQUIRE(layer->max_zoom() > cell_deepest);
    int both_zooms = 0; // zooms deeper than a's with tiles over c and f
    for (int z = cell_deepest + 1; z <= layer->max_zoom(); ++z) {
        CAPTURE(z);
        const auto over = [&](double lon, double lat) { return may_have_at(*layer, z, lon, lat); };
        // f goes deeper than c: c's tiles stop at its own deepest zoom, f's go on; while both
        // have tiles, none lies between them.
        CHECK(over((fb.west + fb.east) / 2, (fb.south + fb.north) / 2));
        const bool both = over((cb.west + cb.east) / 2, (cb.south + cb.north) / 2);
        both_zooms += both ? 1 : 0;
        CHECK_FALSE(over(mid_lon, mid_lat));
        const TileRange all = layer->tiles_at(z);
        const std::int64_t tiles = may_have_count(*layer, z);
        // No more than the blocks' own families (each block's tiles, widened by one each way).
        const auto families = [&](const LonLatBox& b) {
            const TileRange r = tiles_covering(Scheme::Geodetic, b, z);
            return (r.x1 - r.x0 + 3) * (r.y1 - r.y0 + 3);
        };
        CHECK(tiles <= families(cb) + families(fb));
        CHECK(layer->tile_count_at(z) == tiles); // what info prints
        CHECK((tiles < all.count() || !both));
        // layer.json lists the same tiles, range by range.
        const std::int64_t listed = listed_count(available[static_cast<std::size_t>(z)]);
        CHECK(listed >= tiles);
        CHECK((listed < all.count() || !both));
    }
    CHECK(both_zooms >= 2);
}

TEST_CASE("depth follows each file of one grid: far-apart blocks of one survey get deep tiles "
          "over each block only, and the update adding a third equals a full build") {
    // c and c2 share a pixel grid (one mosaic, one DEM group), 0.4 degrees apart, over the
    // coarser cell a; c3 later fills a third corner of the square they span.
    ScratchDir dir;
    const double step = 0.1 / 96;
    const std::string a = cell_a(dir), c = finer_block_c(dir);
    const std::string c2 = write_dem(dir.file("c2.tif"), 8.6, 46.9, 97, 97, step, 3);
    const std::string c3 = write_dem(dir.file("c3.tif"), 8.6, 46.5, 97, 97, step, 4);
    const auto layer = open_layer({a, c, c2});
    const int cell_deepest = open_layer({a})->max_zoom();
    REQUIRE(layer->source().members().size() == 2); // a, and the mosaic of c and c2
    const LonLatBox cb = DemSource::open({c})->footprint(),
                    c2b = DemSource::open({c2})->footprint();
    std::string layer_json;
    REQUIRE(layer->document("layer.json", layer_json));
    const auto available = nlohmann::json::parse(layer_json)["available"];
    REQUIRE(layer->max_zoom() > cell_deepest);
    for (int z = cell_deepest + 1; z <= layer->max_zoom(); ++z) {
        CAPTURE(z);
        const auto over = [&](double lon, double lat) { return may_have_at(*layer, z, lon, lat); };
        CHECK(over((cb.west + cb.east) / 2, (cb.south + cb.north) / 2));
        CHECK(over((c2b.west + c2b.east) / 2, (c2b.south + c2b.north) / 2));
        CHECK_FALSE(over((cb.east + c2b.west) / 2, (cb.north + c2b.south) / 2)); // between
        CHECK_FALSE(over((c2b.west + c2b.east) / 2, (cb.south + cb.north) / 2)); // c3's corner
        const TileRange all = layer->tiles_at(z);
        const std::int64_t tiles = may_have_count(*layer, z);
        CHECK(layer->tile_count_at(z) == tiles);
        CHECK(tiles < all.count());
        // layer.json lists exactly those tiles, in rectangles that do not overlap.
        const std::int64_t listed = listed_count(available[static_cast<std::size_t>(z)]);
        CHECK(listed == tiles);
    }
    const std::string out = dir.file("out");
    build(options({a, c, c2}, out));
    check_same_as_full(
        {a, c, c2, c3}, out, dir.file("fresh"), build(options({a, c, c2, c3}, out), true));
    // c3 removed again: its deep tiles go, though the box around c and c2 still holds them.
    check_same_as_full({a, c, c2}, out, dir.file("fresh"), build(options({a, c, c2}, out), true));
}

TEST_CASE("an interrupted update is finished by running it again; --resume alone is refused "
          "while it is pending") {
    const TwoDems two;
    const std::string &a = two.a, &b = two.b, &out = two.out;
    const ScratchDir& dir = two.dir;
    build(options({a}, out));
    BuildOptions o = options({a, b}, out);
    o.update = true;
    const std::atomic<bool> stop{true}; // stops before the first tile
    CHECK(build_pyramid(o, stop).interrupted);
    CHECK(TileStore::open(out)->get_document("terrain", kUpdateRecord));
    BuildOptions resume = options({a, b}, out);
    resume.resume = true;
    CHECK_THROWS_WITH_AS(build(resume),
                         doctest::Contains("an update of it (build --update) was interrupted"),
                         tb::InputError);
    // Nothing serves or converts the half-updated layer, and an update to other DEMs must
    // wait: the tiles the interrupted one wrote would go unseen.
    CHECK_THROWS_WITH_AS(prepare_store_for_serving(*TileStore::open(out), "terrain", Manifest{}),
                         doctest::Contains("has not finished"),
                         tb::InputError);
    CHECK_THROWS_WITH_AS(build(options({a}, out), true),
                         doctest::Contains("an update to other DEMs or settings was interrupted"),
                         tb::InputError);
    check_same_as_full({a, b}, out, dir.file("fresh"), build(options({a, b}, out), true));

    const std::string store = dir.file("tiles.sqlite"), err = dir.file("convert.err");
    build(options({a}, store));
    o.output = store;
    CHECK(build_pyramid(o, stop).interrupted);
    const std::string convert = std::string(TB_BINARY) + " build " + store + " -o " +
                                dir.file("dem.pmtiles") + " --formats terrarium 2>" + err;
    CHECK(std::system(convert.c_str()) != 0);
    CHECK(slurp(err).find("has not finished") != std::string::npos);
}

TEST_CASE("a sharded update and --finalize equal a sharded full build; the earlier build's "
          "shard records do not count") {
    const TwoDems two;
    const std::string &a = two.a, &b = two.b, &out = two.out;
    const ScratchDir& dir = two.dir;
    const auto shard =
        [](const std::vector<std::string>& dems, const std::string& to, int i, bool update) {
            BuildOptions o = options(dems, to);
            o.shard = ShardSpec{i, 2};
            return build(o, update);
        };
    const auto finalize = [](const std::vector<std::string>& dems, const std::string& to) {
        BuildOptions o = options(dems, to);
        o.finalize = true;
        return build(o);
    };
    shard({a}, out, 0, false);
    shard({a}, out, 1, false);
    finalize({a}, out);
    BuildSummary total = shard({a, b}, out, 0, true);
    // Shard 1 reported for the build before the update, not for this one.
    CHECK_THROWS_WITH_AS(
        finalize({a, b}, out), doctest::Contains("shard 1/2 has not finished"), tb::InputError);
    const BuildSummary second = shard({a, b}, out, 1, true);
    total.written += second.written;
    total.tileset_written = finalize({a, b}, out).tileset_written;
    check_same_as_full({a, b}, out, dir.file("fresh"), total, true, [&](const std::string& to) {
        BuildSummary full = shard({a, b}, to, 0, false);
        full.written += shard({a, b}, to, 1, false).written;
        finalize({a, b}, to);
        return full;
    });
}

TEST_CASE("an update remakes every tile when a grid's summary changes its finest level") {
    // A grid past about 537 Mpixel reads its summary from a coarser finest level, whose every
    // block differs; no test can write such a grid, so the manifests are compared directly.
    ScratchDir dir;
    const std::string a = cell_a(dir);
    build(options({a}, dir.file("out")));
    const Manifest was = parse_manifest(slurp(dir.file("out/terrain/") + kBuildManifest));
    CHECK(manifest_value(was, "summary_levels") == "[3]");
    CHECK(update_scope(was, was).everything.empty());
    Manifest now = was;
    for (auto& [key, value] : now) {
        if (key == "summary_levels") {
            value = "[4]";
        }
    }
    CHECK(update_scope(was, now).everything ==
          "a pixel grid's summary's finest level changed (was 3, now 4)");
}

TEST_CASE("--update refuses what it cannot update, naming the way out") {
    ScratchDir dir;
    const std::string a = cell_a(dir);
    CHECK_THROWS_WITH_AS(build(options({a}, dir.file("none")), true),
                         doctest::Contains("nothing to update"),
                         tb::InputError);
    BuildOptions o = options({a}, dir.file("out"));
    o.force = true;
    CHECK_THROWS_WITH_AS(build(o, true), doctest::Contains("--force starts over"), tb::InputError);
    // Formats dropped would leave their tiles behind.
    build(options({a}, dir.file("out")));
    o = options({a}, dir.file("out"));
    o.formats = {Format::Glb};
    CHECK_THROWS_WITH_AS(build(o, true),
                         doctest::Contains("an update keeps a build's formats and --bbox"),
                         tb::InputError);
    o = options({a}, dir.file("dem.mbtiles"));
    o.formats = {Format::Terrarium};
    build(o);
    CHECK_THROWS_WITH_AS(
        build(o, true), doctest::Contains("cannot be updated in place"), tb::InputError);
}

TEST_CASE("an update touches the tiles meeting a changed DEM, their ancestors, and the tiles "
          "that entered or left a zoom's range") {
    UpdateScope scope;
    scope.boxes.push_back({8.01, 46.01, 8.02, 46.02});
    const TileRange t = tiles_covering(Scheme::Geodetic, scope.boxes[0], 10);
    REQUIRE(t.count() == 1);
    const std::int64_t x = t.x0, y = t.y0;
    const std::vector<TileRange> was = {{8, x / 4 - 5, y / 4 - 5, x / 4 + 5, y / 4 + 5},
                                        {10, x - 20, y - 20, x + 20, y + 20}};
    std::vector<TileRange> now = was;
    now[1].x1 = x + 21; // zoom 10 gains a column
    const UpdateTiles tiles(scope, Scheme::Geodetic, was, now, {}, 0.25);
    CHECK(tiles.contains(TileId{10, x, y}));
    CHECK(tiles.contains(TileId{8, x / 4, y / 4})); // its ancestor
    CHECK_FALSE(tiles.contains(TileId{10, x - 17, y}));
    CHECK(tiles.contains(TileId{10, x + 21, y + 3}));            // entered the range
    CHECK(tiles.contains(TileId{8, (x + 21) / 4, (y + 3) / 4})); // and its ancestor
    CHECK_FALSE(tiles.contains(TileId{8, x / 4 - 4, y / 4 - 4}));
    CHECK(tiles.left_out_count() == 0);
    // remade() counts the touched tiles within the new ranges, each once.
    std::int64_t counted = 0;
    for (const TileRange& r : now) {
        for (std::int64_t ty = r.y0; ty <= r.y1; ++ty) {
            for (std::int64_t tx = r.x0; tx <= r.x1; ++tx) {
                counted += tiles.contains(TileId{r.z, tx, ty}) ? 1 : 0;
            }
        }
    }
    CHECK(counted > 41);
    CHECK(tiles.remade() == counted);
    // The other way round, the column is left out.
    const UpdateTiles back(scope, Scheme::Geodetic, now, was, {}, 0.25);
    CHECK(back.left_out_count() == 41);
    std::int64_t listed = 0;
    back.for_each_left_out([&](const TileId& id) {
        const bool column = (id.z == 10 && id.x == x + 21) || (id.z == 8 && id.x == (x + 21) / 4);
        CHECK(column);
        ++listed;
    });
    CHECK(listed == 41);
    // A whole zoom.
    const UpdateTiles whole(UpdateScope{}, Scheme::Geodetic, was, was, {8}, 0.25);
    CHECK(whole.contains(TileId{8, x / 4 - 4, y / 4 - 4}));
    CHECK_FALSE(whole.contains(TileId{10, x - 17, y}));
}
