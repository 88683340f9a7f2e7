// Store manifests: a store's tiles are served only under the settings that made them
// (tiler/stores/manifest.hpp). Real layers on a generated DEM, both stores.
#include "core/error.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/pyramid/build.hpp"
#include "tiler/pyramid/tile_settings.hpp"

#include <doctest/doctest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>

using namespace tb::tiler;
using tb_test::ScratchDir;

namespace {

// 65 x 65 heights over a quarter degree in the Alps: a hill on a slope.
std::string write_hill(const std::string& path, double peak = 500) {
    tb_test::Fixture f;
    f.width = f.height = 65;
    f.epsg = 4326;
    f.geotransform = std::array<double, 6>{7.0, 0.25 / 64, 0, 46.25, 0, -0.25 / 64};
    for (int r = 0; r < 65; ++r) {
        for (int c = 0; c < 65; ++c) {
            const double x = c / 64.0 - 0.5, y = r / 64.0 - 0.5;
            f.values.push_back(900 + 3 * c + peak * std::exp(-(x * x + y * y) * 12));
        }
    }
    return tb_test::write_fixture(path, f);
}

LayerOptions small_options(const std::string& dem) {
    LayerOptions o;
    o.name = "hill";
    o.sources = {dem};
    o.tile_size = 32;
    o.min_zoom = 8;
    o.max_zoom = 9;
    return o;
}

const TileKey kTile{"hill", {9, 532, 387}, Format::Glb, -1}; // holds 7.1 E, 46.1 N

// A manifest's text as another Terrabound revision would have written it.
std::string from_another_revision(std::string manifest) {
    const auto at = manifest.find("\"version\": \"");
    REQUIRE(at != std::string::npos);
    return manifest.insert(at + 12, "0.0.9-");
}

// The stores both kinds of path open: a directory and an SQLite file.
std::vector<std::string> store_paths(const ScratchDir& dir) {
    return {dir.file("tiles"), dir.file("tiles.sqlite")};
}

} // namespace

TEST_CASE("serve writes its manifest into an empty store, then keeps the tiles while the "
          "settings stay") {
    ScratchDir dir;
    const auto layer = Layer::open(small_options(write_hill(dir.file("hill.tif"))));
    for (const auto& path : store_paths(dir)) {
        INFO(path);
        {
            auto store = TileStore::open(path);
            prepare_store_for_serving(*store, *layer);
            const auto text = store->get_document("hill", kServeManifest);
            REQUIRE(text);
            CHECK(*text == manifest_text(tile_settings(*layer)));
            CHECK(manifest_value(parse_manifest(*text), "eps") ==
                  manifest_value(tile_settings(*layer), "eps"));
            store->put(kTile, "tile bytes");
        }
        // A restart with the same settings, on a layer opened anew.
        auto store = TileStore::open(path);
        prepare_store_for_serving(*store, *Layer::open(small_options(dir.file("hill.tif"))));
        CHECK(store->get(kTile) == std::optional<std::string>("tile bytes"));
    }
}

TEST_CASE("a build manifest's terrain_extensions reach the server, and a serve cache records "
          "none") {
    ScratchDir dir;
    const auto layer = Layer::open(small_options(write_hill(dir.file("hill.tif"))));
    for (const auto& path : store_paths(dir)) {
        INFO(path);
        auto store = TileStore::open(path);
        CHECK(prepare_store_for_serving(*store, *layer).terrain_extensions.empty());
        store->remove_layer("hill");
        Manifest built{{"terrabound_build", "1"}};
        for (const auto& entry : tile_settings(*layer)) {
            built.push_back(entry);
        }
        built.emplace_back("terrain_extensions", R"(["metadata"])");
        store->put_document("hill", kBuildManifest, manifest_text(built));
        CHECK(prepare_store_for_serving(*store, *layer).terrain_extensions == R"(["metadata"])");
    }
}

TEST_CASE("a server's cached tiles made with another eps, eps level, nodata or DEM are removed "
          "before any is served") {
    ScratchDir dir;
    const std::string dem = write_hill(dir.file("hill.tif"));
    const LayerOptions base = small_options(dem);

    struct Case {
        const char* what;
        const char* key; // the setting the warning names
        LayerOptions options;
    };
    std::vector<Case> cases;
    LayerOptions o = base;
    o.finest_eps = 0.5;
    cases.push_back({"finer eps", "eps", o});
    o = base;
    o.eps_levels = {1, 4};
    cases.push_back({"eps levels", "eps_levels", o});
    o = base;
    o.nodata = 900;
    cases.push_back({"a nodata value", "nodata", o});
    o = base;
    o.tile_size = 64;
    cases.push_back({"another tile size", "tile_size", o});

    for (const auto& path : store_paths(dir)) {
        for (const auto& c : cases) {
            INFO(path << ": " << c.what);
            auto store = TileStore::open(path);
            store->remove_layer("hill");
            prepare_store_for_serving(*store, *Layer::open(base));
            store->put(kTile, "made with the base settings");
            const auto changed = Layer::open(c.options);
            const auto change =
                first_change(parse_manifest(*store->get_document("hill", kServeManifest)),
                             tile_settings(*changed));
            REQUIRE(change);
            CHECK(change->key == c.key);
            prepare_store_for_serving(*store, *changed);
            CHECK_FALSE(store->contains(kTile));
            CHECK(store->get_document("hill", kServeManifest) ==
                  std::optional<std::string>(manifest_text(tile_settings(*changed))));
        }
    }

    // Cached by another Terrabound (or commit).
    for (const auto& path : store_paths(dir)) {
        INFO(path << ": another version");
        auto store = TileStore::open(path);
        store->remove_layer("hill");
        const auto layer = Layer::open(base);
        prepare_store_for_serving(*store, *layer);
        store->put(kTile, "made by another version");
        store->put_document("hill",
                            kServeManifest,
                            from_another_revision(*store->get_document("hill", kServeManifest)));
        prepare_store_for_serving(*store, *layer);
        CHECK_FALSE(store->contains(kTile));
    }

    // The DEM replaced in place, same name: its size or mtime tells.
    auto store = TileStore::open(dir.file("replaced.sqlite"));
    prepare_store_for_serving(*store, *Layer::open(base));
    store->put(kTile, "made from the first DEM");
    std::this_thread::sleep_for(std::chrono::milliseconds(1100)); // mtime has 1 s resolution
    write_hill(dem, 700);
    const auto replaced = Layer::open(base);
    const auto change = first_change(parse_manifest(*store->get_document("hill", kServeManifest)),
                                     tile_settings(*replaced));
    REQUIRE(change);
    CHECK(change->key == "sources");
    prepare_store_for_serving(*store, *replaced);
    CHECK_FALSE(store->contains(kTile));
}

TEST_CASE("a built store is served only with the settings it was built with; its bbox, "
          "formats and shards do not matter") {
    ScratchDir dir;
    const std::string dem = write_hill(dir.file("hill.tif"));
    for (const auto& path : store_paths(dir)) {
        INFO(path);
        BuildOptions b;
        b.layer = small_options(dem);
        b.layer.finest_eps = 2;
        b.output = path;
        b.formats = {Format::Glb, Format::Terrain};
        b.bbox = LonLatBox{7.0, 46.0, 7.1, 46.1};
        b.threads = 1;
        b.progress = ProgressMode::Off;
        const std::atomic<bool> stop{false};
        const BuildSummary summary = build_pyramid(b, stop);
        REQUIRE(summary.written > 0);
        auto store = TileStore::open(path);
        const auto built = store->get_document("hill", kBuildManifest);
        REQUIRE(built);

        // Other settings: refused, naming the setting and both values; nothing removed.
        LayerOptions other = b.layer;
        other.finest_eps = 3;
        CHECK_THROWS_WITH_AS(
            prepare_store_for_serving(*store, *Layer::open(other)),
            doctest::Contains("made by terrabound build with other settings (eps was ["),
            tb::InputError);
        // The finest zooms' eps are the ladder's own (coarser ones may follow the data's reach).
        CHECK_THROWS_WITH_AS(prepare_store_for_serving(*store, *Layer::open(other)),
                             doctest::Contains(", 2], now ["),
                             tb::InputError);
        CHECK(store->get_document("hill", kBuildManifest) == built);
        CHECK_FALSE(store->get_document("hill", kServeManifest));

        // The build's own settings: served as they are, its tiles kept.
        const TileKey tile{"hill", {9, 532, 387}, Format::Glb, -1};
        REQUIRE(store->contains(tile));
        CHECK(prepare_store_for_serving(*store, *Layer::open(b.layer)).eps_levels);
        CHECK(store->get_document("hill", kBuildManifest) == built);
        CHECK_FALSE(store->get_document("hill", kServeManifest));

        // Eps levels the build had not: its tiles served, those levels kept out of the store.
        LayerOptions levels = b.layer;
        levels.eps_levels = {1, 5};
        CHECK_FALSE(prepare_store_for_serving(*store, *Layer::open(levels)).eps_levels);

        // Built by another Terrabound to the same settings: served, tiles kept.
        store->put_document("hill", kBuildManifest, from_another_revision(*built));
        CHECK(prepare_store_for_serving(*store, *Layer::open(b.layer)).eps_levels);
        CHECK(store->contains(tile));
    }
}

TEST_CASE("tiles with no manifest are an older server's cache in SQLite, removed, and refused "
          "and left alone in a directory") {
    ScratchDir dir;
    const auto layer = Layer::open(small_options(write_hill(dir.file("hill.tif"))));
    {
        auto store = TileStore::open(dir.file("tiles"));
        store->put(kTile, "whose?");
        CHECK_THROWS_WITH_AS(prepare_store_for_serving(*store, *layer),
                             doctest::Contains("holds tiles but no serve-manifest.json or "
                                               "build-manifest.json"),
                             tb::InputError);
        CHECK(store->get(kTile) == std::optional<std::string>("whose?"));
        CHECK_FALSE(store->get_document("hill", kServeManifest));
    }
    auto store = TileStore::open(dir.file("tiles.sqlite"));
    store->put(kTile, "an older server's");
    prepare_store_for_serving(*store, *layer);
    CHECK_FALSE(store->contains(kTile));
    CHECK(store->get_document("hill", kServeManifest) ==
          std::optional<std::string>(manifest_text(tile_settings(*layer))));
}

TEST_CASE("an entry a manifest lacks is a change: older builds did not record nodata or the DEM "
          "tiles' settings") {
    const Manifest now = {{"eps", "[2]"}, {"nodata", "null"}, {"dem_tile_size", "512"}};
    CHECK_FALSE(first_change(parse_manifest(manifest_text(now)), now));
    const auto nodata = first_change({{"eps", "[2]"}}, now);
    REQUIRE(nodata);
    CHECK(nodata->key == "nodata");
    CHECK(nodata->was == "(absent)");
    const auto dem =
        first_change({{"eps", "[2]"}, {"nodata", "null"}, {"dem_tile_size", "256"}}, now);
    REQUIRE(dem);
    CHECK(dem->key == "dem_tile_size");
    CHECK(dem->was == "256");
    // Ignored keys are not compared.
    CHECK_FALSE(first_change({{"eps", "[1]"}}, {{"eps", "[2]"}}, {"eps"}));

    // A built store whose manifest has no nodata entry is not served: its tiles may have been
    // made with any nodata value.
    ScratchDir dir;
    const auto layer = Layer::open(small_options(write_hill(dir.file("hill.tif"))));
    auto store = TileStore::open(dir.file("old.sqlite"));
    Manifest older;
    older.emplace_back("terrabound_build", "1");
    for (const auto& entry : tile_settings(*layer)) {
        if (entry.first != "nodata") {
            older.push_back(entry);
        }
    }
    store->put_document("hill", kBuildManifest, manifest_text(older));
    store->put(kTile, "built with some nodata");
    CHECK_THROWS_WITH_AS(prepare_store_for_serving(*store, *layer),
                         doctest::Contains("(nodata is not recorded (made by an older "
                                           "terrabound), now null)"),
                         tb::InputError);
    CHECK(store->contains(kTile));
}
