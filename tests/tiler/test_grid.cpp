// Pyramid arithmetic: both schemes' extents, validity, covering ranges and the sample lattice.
#include "core/error.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/tile_raster.hpp"
#include "tiler/tile_grid.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <random>

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

TEST_CASE("tile ids outside the scheme are not valid") {
    for (Scheme s : {Scheme::Geodetic, Scheme::Mercator}) {
        CHECK(is_valid(s, {0, 0, 0}));
        CHECK_FALSE(is_valid(s, {-1, 0, 0}));
        CHECK_FALSE(is_valid(s, {kMaxZoom + 1, 0, 0}));
        CHECK_FALSE(is_valid(s, {3, -1, 0}));
        CHECK_FALSE(is_valid(s, {3, 0, -1}));
        CHECK_FALSE(is_valid(s, {3, tiles_across(s, 3), 0}));
        CHECK_FALSE(is_valid(s, {3, 0, tiles_down(s, 3)}));
        CHECK_FALSE(is_valid(s, {2, std::int64_t{1} << 62, 0}));
        CHECK(is_valid(s, {kMaxZoom, tiles_across(s, kMaxZoom) - 1, tiles_down(s, kMaxZoom) - 1}));
    }
    CHECK(is_valid(Scheme::Geodetic, {1, 3, 1}));
    CHECK_FALSE(is_valid(Scheme::Mercator, {1, 3, 1}));
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
