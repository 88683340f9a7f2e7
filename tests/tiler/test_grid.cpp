// Pyramid arithmetic: both schemes' extents, validity, covering ranges and the sample lattice.
#include "core/error.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/tile_raster.hpp"
#include "tiler/tile_grid.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <vector>

using namespace tb::tiler;

TEST_CASE("geodetic zoom 0 has two root tiles covering the globe, y counted from the south") {
    CHECK(tiles_across(Scheme::Geodetic, 0) == 2);
    CHECK(tiles_down(Scheme::Geodetic, 0) == 1);
    const LonLatBox west = tile_bounds(Scheme::Geodetic, {0, 0, 0});
    CHECK(west.west == -180.0);
    CHECK(west.east == 0.0);
    CHECK(west.south == -90.0);
    CHECK(west.north == 90.0);
    // Zoom 1: y = 0 is the southern row.
    const LonLatBox sw = tile_bounds(Scheme::Geodetic, {1, 0, 0});
    CHECK(sw.south == -90.0);
    CHECK(sw.north == 0.0);
    for (int z = 0; z <= kMaxZoom; ++z) {
        const LonLatBox b =
            tile_bounds(Scheme::Geodetic, {z, 3 % tiles_across(Scheme::Geodetic, z), 0});
        CHECK(b.east - b.west == doctest::Approx(180.0 / std::ldexp(1.0, z)));
    }
}

TEST_CASE("mercator has one root tile up to 85.0511 degrees, y counted from the north") {
    CHECK(tiles_across(Scheme::Mercator, 0) == 1);
    CHECK(tiles_down(Scheme::Mercator, 0) == 1);
    const LonLatBox root = tile_bounds(Scheme::Mercator, {0, 0, 0});
    CHECK(root.west == doctest::Approx(-180.0));
    CHECK(root.east == doctest::Approx(180.0));
    CHECK(root.north == doctest::Approx(85.0511287798));
    CHECK(root.south == doctest::Approx(-85.0511287798));
    const LonLatBox nw = tile_bounds(Scheme::Mercator, {1, 0, 0});
    CHECK(nw.north == doctest::Approx(85.0511287798));
    CHECK(nw.south == doctest::Approx(0.0).epsilon(1e-12));
}

TEST_CASE("tile ids outside the scheme are not valid tiles") {
    for (Scheme s : {Scheme::Geodetic, Scheme::Mercator}) {
        CAPTURE(to_string(s));
        CHECK(ValidTile::of(s, {0, 0, 0}));
        CHECK_FALSE(ValidTile::of(s, {-1, 0, 0}));
        CHECK_FALSE(ValidTile::of(s, {kMaxZoom + 1, 0, 0}));
        CHECK_FALSE(ValidTile::of(s, {3, -1, 0}));
        CHECK_FALSE(ValidTile::of(s, {3, 0, -1}));
        CHECK_FALSE(ValidTile::of(s, {3, tiles_across(s, 3), 0}));
        CHECK_FALSE(ValidTile::of(s, {3, 0, tiles_down(s, 3)}));
        CHECK_FALSE(ValidTile::of(s, {2, std::int64_t{1} << 62, 0}));
        CHECK(ValidTile::of(
            s, {kMaxZoom, tiles_across(s, kMaxZoom) - 1, tiles_down(s, kMaxZoom) - 1}));
    }
    CHECK(ValidTile::of(Scheme::Geodetic, {1, 3, 1}));
    CHECK_FALSE(ValidTile::of(Scheme::Mercator, {1, 3, 1}));
}

TEST_CASE("ValidTile::parse takes the last tile of each range and names the first one past it") {
    // At zoom 3 geodetic has 16 x 8 tiles, mercator 8 x 8.
    const ValidTile g = ValidTile::parse(Scheme::Geodetic, {3, 15, 7});
    CHECK(g.scheme() == Scheme::Geodetic);
    CHECK(g.id() == TileId{3, 15, 7});
    CHECK(g.z() == 3);
    CHECK(g.x() == 15);
    CHECK(g.y() == 7);
    CHECK(ValidTile::parse(Scheme::Mercator, {3, 7, 7}).id() == TileId{3, 7, 7});
    CHECK(ValidTile::parse(Scheme::Mercator, {kMaxZoom, 0, 0}).z() == kMaxZoom);
    CHECK_THROWS_WITH_AS(ValidTile::parse(Scheme::Geodetic, {3, 16, 0}),
                         "tile 3/16/0 is outside the geodetic scheme: at zoom 3, x is 0..15 and "
                         "y is 0..7",
                         tb::InputError);
    CHECK_THROWS_WITH_AS(ValidTile::parse(Scheme::Geodetic, {3, 0, 8}),
                         doctest::Contains("tile 3/0/8 is outside the geodetic scheme"),
                         tb::InputError);
    CHECK_THROWS_WITH_AS(ValidTile::parse(Scheme::Mercator, {3, 8, 0}),
                         "tile 3/8/0 is outside the mercator scheme: at zoom 3, x is 0..7 and "
                         "y is 0..7",
                         tb::InputError);
    CHECK_THROWS_WITH_AS(ValidTile::parse(Scheme::Mercator, {3, 0, 8}),
                         doctest::Contains("tile 3/0/8 is outside the mercator scheme"),
                         tb::InputError);
    for (Scheme s : {Scheme::Geodetic, Scheme::Mercator}) {
        CAPTURE(to_string(s));
        CHECK_THROWS_WITH_AS(
            ValidTile::parse(s, {kMaxZoom + 1, 0, 0}),
            doctest::Contains(("tile 25/0/0 is outside the " + std::string(to_string(s)) +
                               " scheme: zoom 25 is outside 0..24")
                                  .c_str()),
            tb::InputError);
        CHECK_THROWS_WITH_AS(ValidTile::parse(s, {-1, 0, 0}),
                             doctest::Contains("zoom -1 is outside 0..24"),
                             tb::InputError);
        CHECK_THROWS_WITH_AS(ValidTile::parse(s, {2, -1, 0}),
                             doctest::Contains("tile 2/-1/0 is outside"),
                             tb::InputError);
        CHECK_THROWS_WITH_AS(ValidTile::parse(s, {2, 0, -1}),
                             doctest::Contains("tile 2/0/-1 is outside"),
                             tb::InputError);
    }
}

TEST_CASE("the parent and the children of a valid tile are valid and hold each other") {
    for (Scheme s : {Scheme::Geodetic, Scheme::Mercator}) {
        CAPTURE(to_string(s));
        // Both roots' corners at zoom 0, the last tile of a middle zoom, and kMaxZoom's last.
        const std::vector<TileId> ids{{0, 0, 0},
                                      {0, tiles_across(s, 0) - 1, 0},
                                      {5, tiles_across(s, 5) - 1, tiles_down(s, 5) - 1},
                                      {12, 1234, 987},
                                      {kMaxZoom - 1, tiles_across(s, kMaxZoom - 1) - 1, 0},
                                      {kMaxZoom, tiles_across(s, kMaxZoom) - 1, 0}};
        for (const TileId& id : ids) {
            CAPTURE(tile_name(id));
            const ValidTile tile = ValidTile::parse(s, id);
            const std::optional<ValidTile> parent = tile.parent();
            CHECK(parent.has_value() == (id.z > 0));
            if (parent) {
                CHECK(ValidTile::of(s, parent->id()) == parent);
                const std::vector<ValidTile> siblings = parent->children();
                CHECK(std::find(siblings.begin(), siblings.end(), tile) != siblings.end());
            }
            const std::vector<ValidTile> children = tile.children();
            CHECK(children.size() == (id.z < kMaxZoom ? 4u : 0u));
            for (const ValidTile& child : children) {
                CHECK(ValidTile::of(s, child.id()) == child);
                CHECK(child.z() == id.z + 1);
                CHECK(child.parent() == tile);
                // The child's box lies inside its parent's.
                const LonLatBox a = tile_bounds(s, id), b = tile_bounds(s, child.id());
                CHECK(b.west >= a.west - 1e-9);
                CHECK(b.east <= a.east + 1e-9);
                CHECK(b.south >= a.south - 1e-9);
                CHECK(b.north <= a.north + 1e-9);
            }
        }
    }
}

TEST_CASE("tiles_in gives every tile of a covering range once, rows first") {
    for (Scheme s : {Scheme::Geodetic, Scheme::Mercator}) {
        CAPTURE(to_string(s));
        const TileRange r = tiles_covering(s, {-71.5, 44.0, -70.1, 44.9}, 9);
        REQUIRE(r.count() > 1);
        const std::vector<ValidTile> tiles = tiles_in(s, r);
        REQUIRE(static_cast<std::int64_t>(tiles.size()) == r.count());
        CHECK(tiles.front().id() == TileId{9, r.x0, r.y0});
        CHECK(tiles.back().id() == TileId{9, r.x1, r.y1});
        for (std::int64_t k = 0; k < r.count(); ++k) {
            const ValidTile& t = tiles[static_cast<std::size_t>(k)];
            CHECK(t == ValidTile::in_range(s, r, k));
            CHECK(t.scheme() == s);
            CHECK(t.y() == r.y0 + k / (r.x1 - r.x0 + 1));
        }
        CHECK(std::set<ValidTile>(tiles.begin(), tiles.end()).size() == tiles.size());
        // The whole of zoom 0: both geodetic roots, or the one mercator tile.
        CHECK(tiles_in(s, tiles_covering(s, {-180, -85, 180, 85}, 0)).size() ==
              static_cast<std::size_t>(tiles_across(s, 0)));
        CHECK(tiles_in(s, TileRange{3, 0, 0, -1, -1}).empty());
    }
}

TEST_CASE("a tile's own box, shrunk slightly, is covered by exactly that tile (seed 7)") {
    std::mt19937 rng(7);
    for (Scheme s : {Scheme::Geodetic, Scheme::Mercator}) {
        for (int k = 0; k < 500; ++k) {
            const int z = static_cast<int>(rng() % (kMaxZoom + 1));
            std::uniform_int_distribution<std::int64_t> dx(0, tiles_across(s, z) - 1);
            std::uniform_int_distribution<std::int64_t> dy(0, tiles_down(s, z) - 1);
            const TileId id{z, dx(rng), dy(rng)};
            LonLatBox b = tile_bounds(s, id);
            const double w = (b.east - b.west) * 1e-6, h = (b.north - b.south) * 1e-6;
            b = {b.west + w, b.south + h, b.east - w, b.north - h};
            const TileRange r = tiles_covering(s, b, z);
            REQUIRE(r.count() == 1);
            CHECK(r.x0 == id.x);
            CHECK(r.y0 == id.y);
        }
    }
}

TEST_CASE("a box touching tile edges does not select the tiles beyond them") {
    // One degree cell [-72,-71] x [44,45] at zoom 0..: exactly the tiles it overlaps.
    const LonLatBox cell{-72, 44, -71, 45};
    const TileRange z0 = tiles_covering(Scheme::Geodetic, cell, 0);
    CHECK(z0.count() == 1);
    CHECK(z0.x0 == 0);
    // Zoom 7: tiles are 1.40625 degrees wide; 45 degrees north is the edge of row 96.
    const TileRange z7 = tiles_covering(Scheme::Geodetic, cell, 7);
    CHECK(z7.y0 == 95);
    CHECK(z7.y1 == 95);
    CHECK(z7.x0 == 76);
    CHECK(z7.x1 == 77);
    CHECK(tiles_covering(Scheme::Geodetic, {10, 10, 10, 20}, 3).empty());
    CHECK(tiles_covering(Scheme::Mercator, {0, 86, 1, 89}, 3).empty()); // beyond mercator
    const TileRange world = tiles_covering(Scheme::Mercator, {-180, -90, 180, 90}, 2);
    CHECK(world.count() == 16);
}

TEST_CASE("neighbouring tiles share their border lattice coordinates bit for bit") {
    for (Scheme s : {Scheme::Geodetic, Scheme::Mercator}) {
        const int z = 11, n = 256;
        const TileId a{z, 1234, 567}, right{z, 1235, 567};
        const TileId above = s == Scheme::Geodetic ? TileId{z, 1234, 568} : TileId{z, 1234, 566};
        // a's east column == right's west column; a's north row == above's south row.
        CHECK(tile_first_column(s, a, n) + n == tile_first_column(s, right, n));
        CHECK(tile_first_row(s, above, n) + n == tile_first_row(s, a, n));
        // The lattice reproduces tile_bounds at the corners.
        const LonLatBox b = tile_bounds(s, a);
        const LonLat nw = native_to_lonlat(s,
                                           lattice_x(s, z, n, tile_first_column(s, a, n)),
                                           lattice_y(s, z, n, tile_first_row(s, a, n)));
        CHECK(nw.lon == doctest::Approx(b.west).epsilon(1e-12));
        CHECK(nw.lat == doctest::Approx(b.north).epsilon(1e-12));
        const LonLat se = native_to_lonlat(s,
                                           lattice_x(s, z, n, tile_first_column(s, a, n) + n),
                                           lattice_y(s, z, n, tile_first_row(s, a, n) + n));
        CHECK(se.lon == doctest::Approx(b.east).epsilon(1e-12));
        CHECK(se.lat == doctest::Approx(b.south).epsilon(1e-12));
    }
}

TEST_CASE("tile grid coordinates and lon/lat convert both ways") {
    for (Scheme s : {Scheme::Geodetic, Scheme::Mercator}) {
        TileRaster r;
        r.scheme = s;
        r.id = {9, 300, 200};
        r.size = 64;
        r.bounds = tile_bounds(s, r.id);
        const LonLat corner = grid_to_lonlat(r, 64, 0);
        CHECK(corner.lon == doctest::Approx(r.bounds.east).epsilon(1e-12));
        CHECK(corner.lat == doctest::Approx(r.bounds.north).epsilon(1e-12));
        for (double c : {0.0, 13.25, 64.0}) {
            for (double row : {0.0, 40.5, 64.0}) {
                double c2 = 0, r2 = 0;
                lonlat_to_grid(r, grid_to_lonlat(r, c, row), c2, r2);
                CHECK(c2 == doctest::Approx(c).epsilon(1e-9));
                CHECK(r2 == doctest::Approx(row).epsilon(1e-9));
            }
        }
    }
}

TEST_CASE("scheme names parse, and an unknown one is an input error naming it") {
    CHECK(parse_scheme("geodetic") == Scheme::Geodetic);
    CHECK(parse_scheme("mercator") == Scheme::Mercator);
    CHECK(std::string(to_string(Scheme::Mercator)) == "mercator");
    try {
        parse_scheme("utm");
        FAIL("no error");
    } catch (const tb::InputError& e) {
        CHECK(std::string(e.what()).find("'utm'") != std::string::npos);
    }
}

TEST_CASE("a tile cover holds exactly the union of its ranges, as disjoint rectangles (seed 11)") {
    std::mt19937 rng(11);
    std::uniform_int_distribution<std::int64_t> at(0, 40), size(0, 9);
    for (int round = 0; round < 50; ++round) {
        CAPTURE(round);
        std::vector<TileRange> ranges;
        const int n = 1 + round % 12;
        for (int k = 0; k < n; ++k) {
            const std::int64_t x0 = at(rng), y0 = at(rng);
            ranges.push_back({5, x0, y0, x0 + size(rng), y0 + size(rng)});
        }
        ranges.push_back({5, 3, 3, 2, 2}); // an empty range adds nothing
        const TileCover cover(5, ranges);
        std::set<std::pair<std::int64_t, std::int64_t>> truth;
        for (const TileRange& r : ranges) {
            for (std::int64_t y = r.y0; y <= r.y1; ++y) {
                for (std::int64_t x = r.x0; x <= r.x1; ++x) {
                    truth.insert({x, y});
                }
            }
        }
        CHECK(cover.count() == static_cast<std::int64_t>(truth.size()));
        CHECK(union_count(ranges) == cover.count());
        for (std::int64_t y = -1; y <= 51; ++y) {
            for (std::int64_t x = -1; x <= 51; ++x) {
                REQUIRE(cover.contains(x, y) == (truth.count({x, y}) > 0));
            }
        }
        // The rectangles are disjoint and hold the union: their counts add up to it.
        std::int64_t listed = 0;
        for (const TileRange& r : cover.ranges()) {
            CHECK(r.z == 5);
            CHECK_FALSE(r.empty());
            listed += r.count();
        }
        CHECK(listed == cover.count());
        // Cut to a window: exactly the union's tiles inside it, once each.
        const TileRange window{5, at(rng), at(rng), at(rng) + 8, at(rng) + 8};
        std::set<std::pair<std::int64_t, std::int64_t>> within;
        for (const TileRange& r : cover.ranges_within(window)) {
            for (std::int64_t y = r.y0; y <= r.y1; ++y) {
                for (std::int64_t x = r.x0; x <= r.x1; ++x) {
                    CHECK(within.insert({x, y}).second);
                }
            }
        }
        std::size_t inside = 0;
        for (const auto& [x, y] : truth) {
            inside += window.contains(x, y) ? 1 : 0;
            CHECK(within.count({x, y}) == (window.contains(x, y) ? 1u : 0u));
        }
        CHECK(within.size() == inside);
        const TileRange box = cover.bounding(), want = bounding(5, ranges);
        CHECK((box.x0 == want.x0 && box.y0 == want.y0 && box.x1 == want.x1 && box.y1 == want.y1));
    }
}

TEST_CASE("a tile cover joins the ranges of a regular grid of files into one rectangle, and "
          "keeps scattered ones apart") {
    std::vector<TileRange> grid;
    for (std::int64_t j = 0; j < 30; ++j) {
        for (std::int64_t i = 0; i < 40; ++i) {
            // Each file's tiles, overlapping its neighbours' by one tile, as families do.
            grid.push_back({9, 100 + 4 * i, 50 + 4 * j, 100 + 4 * i + 4, 50 + 4 * j + 4});
        }
    }
    const std::vector<TileRange> one = TileCover(9, grid).ranges();
    REQUIRE(one.size() == 1);
    CHECK((one[0].x0 == 100 && one[0].y0 == 50 && one[0].x1 == 260 && one[0].y1 == 170));
    const TileCover apart(9, {{9, 0, 0, 1, 1}, {9, 10, 0, 11, 1}, {9, 0, 10, 1, 11}});
    CHECK(apart.ranges().size() == 3);
    CHECK(apart.count() == 12);
    CHECK_FALSE(apart.contains(5, 0));
    CHECK(TileCover(9, {}).empty());
    CHECK_FALSE(TileCover(9, {}).contains(0, 0));
    CHECK(TileCover(9, {}).bounding().empty());
}
