// The Layer: zoom plan, eps ladder, tiles per zoom, datum, errors, mosaics and encoded tiles.
#include "core/error.hpp"
#include "core/triangulate.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/formats/draco_decode.hpp"
#include "tiler/layer.hpp"
#include "tiler/mesh/pixel_tile.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/geoid.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <future>
#include <thread>

using namespace tb::tiler;
using tb_test::Fixture;
using tb_test::ScratchDir;

namespace {

std::shared_ptr<const Layer> open_layer(std::vector<std::string> sources,
                                        Scheme scheme = Scheme::Geodetic,
                                        VerticalDatum datum = VerticalDatum::Auto) {
    LayerOptions options;
    options.sources = std::move(sources);
    options.scheme = scheme;
    options.datum = datum;
    return Layer::open(options);
}

// A pixel centre or border point of grid g in lon/lat.
LonLat lonlat_of(const PixelGrid& g, Scheme scheme, double x, double y) {
    return g.lonlat ? LonLat{x, y} : native_to_lonlat(scheme, x, y);
}

// The block of two pixel tiles of fixture f, one made for an EGM96 source and one for an
// ellipsoidal one: at every valid pixel the first holds the source's height plus
// egm96_undulation at its centre, the second the source's own, bit for bit. Returns the pixels
// checked.
std::size_t check_tile_pixels(const Fixture& f,
                              const PixelGrid& g,
                              Scheme scheme,
                              const PixelTile& egm,
                              const PixelTile& ell) {
    const tb::core::HeightGrid& a = egm.raster.grid;
    std::size_t checked = 0;
    for (int j = 0; j < a.height; ++j) {
        for (int i = 0; i < a.width; ++i) {
            const std::int64_t gi = egm.column0 + i, gj = egm.row0 + j;
            const double v = f.values[static_cast<std::size_t>(gj * f.width + gi)];
            if (v == *f.nodata) {
                CHECK_FALSE(a.is_valid(i, j));
                continue;
            }
            const LonLat p = lonlat_of(g, scheme, g.x(gi), g.y(gj));
            REQUIRE(a.is_valid(i, j));
            CHECK(a.at(i, j) == static_cast<float>(v + egm96_undulation(p.lon, p.lat)));
            CHECK(ell.raster.grid.at(i, j) == static_cast<float>(v));
            ++checked;
        }
    }
    return checked;
}

// The border lines between the same two tiles and their neighbours: a mean of the source's own
// heights beside the line, plus the undulation there for the EGM96 source, and not for the
// ellipsoidal one (whose void filling moves its window to the geoid). Returns the points
// checked.
std::size_t
check_tile_borders(const PixelGrid& g, Scheme scheme, const PixelTile& egm, const PixelTile& ell) {
    std::size_t checked = 0;
    for (int side = 0; side < 4; ++side) {
        const BorderProfile& pe = egm.sides[static_cast<std::size_t>(side)];
        const BorderProfile& pl = ell.sides[static_cast<std::size_t>(side)];
        REQUIRE(pe.present == pl.present);
        REQUIRE(pe.heights.size() == pl.heights.size());
        const bool vertical = side == kWest || side == kEast;
        const double line = egm.edge[static_cast<std::size_t>(side)]; // x west/east, y north/south
        for (std::size_t k = 0; k < pe.heights.size(); ++k) {
            if (!pe.valid[k]) {
                continue;
            }
            const auto along = static_cast<std::int64_t>(k);
            const LonLat p = vertical ? lonlat_of(g, scheme, line, g.y(egm.row0 + along))
                                      : lonlat_of(g, scheme, g.x(egm.column0 + along), line);
            CHECK(double(pe.heights[k]) - double(pl.heights[k]) ==
                  doctest::Approx(egm96_undulation(p.lon, p.lat)).epsilon(1e-5));
            ++checked;
        }
    }
    return checked;
}

} // namespace

TEST_CASE("an SRTM cell gets zooms 7..10, a doubling eps ladder and consistent tile sets") {
    const auto path = tb_test::shared_dem("N44W072.hgt");
    if (!path) {
        return;
    }
    const auto layer = open_layer({*path});
    CHECK(layer->min_zoom() == 7);
    CHECK(layer->max_zoom() == 10);
    // Pixel centres of an .hgt lie on whole degrees: the footprint is the degree cell.
    const LonLatBox b = layer->data_bounds();
    CHECK(b.west == doctest::Approx(-72));
    CHECK(b.east == doctest::Approx(-71));
    CHECK(b.south == doctest::Approx(44));
    CHECK(b.north == doctest::Approx(45));
    // 3" pixels at 44.5 N: about 78 m, so the finest eps is about 1.74 m, rounded to the
    // nearest step of 2^(1/8): 2^(6/8) = 1.68 m.
    CHECK(layer->eps_for_zoom(10) == doctest::Approx(std::exp2(6.0 / 8)).epsilon(1e-9));
    // The ladder doubles per coarser zoom, raised where the zoom's cells are rougher (a share of
    // zoom_reach), never shrinking toward coarser zooms.
    for (int z = 0; z < 10; ++z) {
        CAPTURE(z);
        CHECK(layer->eps_for_zoom(z) >= layer->eps_for_zoom(10) * std::exp2(10 - z) * (1 - 1e-12));
        CHECK(layer->eps_for_zoom(z) >= layer->eps_for_zoom(z + 1));
    }
    CHECK(layer->tiles_at(6).empty());
    CHECK(layer->tiles_at(11).empty());
    CHECK(layer->tiles_at(7).count() == 2);
    for (int z = 7; z <= 10; ++z) {
        const TileRange r = layer->tiles_at(z);
        CHECK(r.count() > 0);
        CHECK(layer->may_have_tile(layer->tile({z, r.x0, r.y0})));
        CHECK(layer->may_have_tile(layer->tile({z, r.x1, r.y1})));
        CHECK_FALSE(layer->may_have_tile(layer->tile({z, r.x0 - 1, r.y0})));
        CHECK_FALSE(layer->may_have_tile(layer->tile({z, r.x1, r.y1 + 1})));
    }
    CHECK(layer->min_height() < 115 - 28); // lowest sample plus the geoid (about -28 m)
    CHECK(layer->max_height() > 1908 - 30);
    CHECK(layer->source_datum() == VerticalDatum::Egm96);
    std::string doc;
    CHECK(layer->document("tileset.json", doc));
    CHECK(doc.find("\"asset\"") != std::string::npos);
}

TEST_CASE("tile ids outside the scheme are input errors, tiles outside the data not found") {
    const auto path = tb_test::shared_dem("N44W072.hgt");
    if (!path) {
        return;
    }
    const auto layer = open_layer({*path});
    // An id is parsed in the layer's scheme before any stage sees it.
    CHECK_THROWS_WITH_AS(layer->tile({25, 0, 0}),
                         doctest::Contains("outside the geodetic scheme: zoom 25 is outside 0..24"),
                         tb::InputError);
    CHECK_THROWS_WITH_AS(layer->tile({3, 16, 0}),
                         doctest::Contains("at zoom 3, x is 0..15 and y is 0..7"),
                         tb::InputError);
    CHECK_THROWS_AS(layer->tile({3, -1, 0}), tb::InputError);
    const auto mercator = open_layer({*path}, Scheme::Mercator);
    CHECK_THROWS_WITH_AS(mercator->tile({3, 8, 0}),
                         doctest::Contains("outside the mercator scheme"),
                         tb::InputError);
    CHECK(mercator->tile({3, 7, 0}).scheme() == Scheme::Mercator);
    CHECK_THROWS_WITH_AS(layer->make_raster(layer->tile({10, 0, 0})),
                         doctest::Contains("has no data there"),
                         tb::NotFound);
    CHECK_THROWS_AS(layer->make_raster(layer->tile({5, 9, 22})), tb::NotFound); // above min zoom
    const TileRange r = layer->tiles_at(10);
    CHECK_THROWS_WITH_AS(layer->make_tile(layer->tile({10, r.x0, r.y0}), Format::Glb, EpsChoice{3}),
                         doctest::Contains("eps level 3"),
                         tb::InputError);
    CHECK_THROWS_AS(layer->make_tile_at(layer->tile({10, r.x0, r.y0}), Format::Glb, 0.0),
                    tb::InputError);
    CHECK_THROWS_AS(layer->make_tile_at(layer->tile({10, r.x0, r.y0}), Format::Glb, NAN),
                    tb::InputError);
}

TEST_CASE("EGM96 heights become ellipsoidal by adding the geoid undulation") {
    const auto path = tb_test::shared_dem("N44W072.hgt");
    if (!path) {
        return;
    }
    const auto egm = open_layer({*path}, Scheme::Geodetic, VerticalDatum::Egm96);
    const auto ell = open_layer({*path}, Scheme::Geodetic, VerticalDatum::Ellipsoid);
    const TileId id{9, 308, 382};
    const TileRaster a = egm->make_raster(egm->tile(id)), b = ell->make_raster(ell->tile(id));
    for (int k : {0, 77, 128, 256}) {
        const LonLat p = grid_to_lonlat(a, k, 256 - k);
        const double n = egm96_undulation(p.lon, p.lat);
        CHECK(n == doctest::Approx(-28).epsilon(0.15));
        CHECK(a.grid.at(k, 256 - k) - b.grid.at(k, 256 - k) == doctest::Approx(n).epsilon(1e-4));
    }
}

TEST_CASE("a pixel tile holds each source pixel plus the EGM96 undulation at its centre, bit "
          "for bit, and an ellipsoidal source's own heights") {
    // make_pixel_tile evaluates the geoid by column and row; this pins it to egm96_undulation
    // at every pixel centre, in both schemes, with voids in the window.
    if (!std::filesystem::exists(kEgm96GridPath)) {
        MESSAGE("skipped: " << std::string(kEgm96GridPath)
                            << " is missing (Debian package proj-data)");
        return;
    }
    ScratchDir dir;
    const auto check = [&](const std::string& name, Fixture f, Scheme scheme) {
        f.width = 300, f.height = 240;
        f.type = GDT_Float64;
        f.nodata = -9999;
        for (int j = 0; j < f.height; ++j) {
            for (int i = 0; i < f.width; ++i) {
                const bool void_pixel = (i * 7 + j * 3) % 41 == 0;
                f.values.push_back(void_pixel ? -9999.0
                                              : 800 + 90 * std::sin(i * 0.31) +
                                                    40 * std::cos(j * 0.17) + i * 1e-7);
            }
        }
        const std::string path = tb_test::write_fixture(dir.file(name), f);
        const auto source = DemSource::open({path});
        const std::optional<PixelGrid> g = source->pixel_grid(scheme);
        REQUIRE(g.has_value());
        const auto layer = open_layer({path}, scheme);
        const int z = layer->max_zoom();
        const TileRange r = layer->tiles_at(z);
        std::size_t pixels = 0, profiles = 0;
        for (std::int64_t x = r.x0; x <= r.x1; ++x) {
            for (std::int64_t y = r.y0; y <= r.y1; ++y) {
                try {
                    const TileId id{z, x, y};
                    const PixelTile egm =
                        make_pixel_tile(*source, *g, scheme, id, VerticalDatum::Egm96);
                    const PixelTile ell =
                        make_pixel_tile(*source, *g, scheme, id, VerticalDatum::Ellipsoid);
                    pixels += check_tile_pixels(f, *g, scheme, egm, ell);
                    profiles += check_tile_borders(*g, scheme, egm, ell);
                } catch (const tb::NotFound&) {
                    // no pixel centre in this tile
                }
            }
        }
        CHECK(pixels > 3000);
        CHECK(profiles > 40);
    };
    // 0.001 degree pixels near 8 E, 46 N; 60 m EPSG:3857 pixels there.
    Fixture geodetic;
    geodetic.epsg = 4326;
    geodetic.geotransform = std::array<double, 6>{8.0, 0.001, 0, 46.06, 0, -0.001};
    check("geodetic.tif", geodetic, Scheme::Geodetic);
    Fixture mercator;
    mercator.epsg = 3857;
    mercator.geotransform = std::array<double, 6>{890555.9, 60.0, 0, 5780000.0, 0, -60.0};
    check("mercator.tif", mercator, Scheme::Mercator);
}

TEST_CASE("a raster without georeferencing or without data cannot be tiled, with clear errors") {
    ScratchDir dir;
    Fixture plain;
    plain.values.assign(16, 10.0);
    const std::string no_georef = tb_test::write_fixture(dir.file("plain.tif"), plain);
    CHECK_THROWS_WITH_AS(
        open_layer({no_georef}), doctest::Contains("has no georeferencing"), tb::InputError);
    Fixture empty;
    empty.geotransform = std::array<double, 6>{10, 0.01, 0, 45, 0, -0.01};
    empty.epsg = 4326;
    empty.nodata = -9999;
    empty.values.assign(16, -9999);
    const std::string all_nodata = tb_test::write_fixture(dir.file("empty.tif"), empty);
    CHECK_THROWS_WITH_AS(
        open_layer({all_nodata}), doctest::Contains("every sample"), tb::InputError);
    CHECK_THROWS_WITH_AS(
        open_layer({dir.file("missing.tif")}), doctest::Contains("no such file"), tb::InputError);
    LayerOptions bad;
    bad.sources = {no_georef};
    bad.name = "has space";
    CHECK_THROWS_WITH_AS(Layer::open(bad), doctest::Contains("letters, digits"), tb::InputError);
}

TEST_CASE("two SRTM cells mosaic into one layer that matches each cell where it is alone") {
    const auto south = tb_test::shared_dem("N44W072.hgt");
    const auto north = tb_test::shared_dem("N45W072.hgt");
    if (!south || !north) {
        return;
    }
    const auto both = open_layer({*south, *north});
    const auto alone = open_layer({*south});
    CHECK(both->data_bounds().south == doctest::Approx(44));
    CHECK(both->data_bounds().north == doctest::Approx(46));
    const TileId inside{10, 617, 765};
    const TileRaster a = both->make_raster(both->tile(inside)),
                     b = alone->make_raster(alone->tile(inside));
    CHECK(a.grid.heights == b.grid.heights);
    // A tile across the 45 N seam has data on both sides.
    const TileId seam{10, 617, 768}; // rows 45.0 - 45.17 N... and below
    const TileRaster s = both->make_raster(both->tile(seam));
    CHECK(s.grid.valid.empty());
}

TEST_CASE("a projected DEM tiles in both schemes, voids outside its outline") {
    const auto path = tb_test::shared_dem("elev_vinschgau.tif");
    if (!path) {
        return;
    }
    for (Scheme scheme : {Scheme::Geodetic, Scheme::Mercator}) {
        const auto layer = open_layer({*path}, scheme);
        const int z = layer->min_zoom();
        const TileRange r = layer->tiles_at(z);
        REQUIRE(r.count() >= 1);
        REQUIRE(r.count() <= 4);
        bool some_valid = false;
        for (std::int64_t x = r.x0; x <= r.x1; ++x) {
            for (std::int64_t y = r.y0; y <= r.y1; ++y) {
                const TileRaster t = layer->make_raster(layer->tile({z, x, y}));
                CHECK_FALSE(t.grid.valid.empty()); // part of every tile lies outside the DEM
                for (std::size_t k = 0; k < t.grid.heights.size(); ++k) {
                    CHECK(std::isfinite(t.grid.heights[k]));
                    some_valid = some_valid || t.grid.valid[k];
                    if (t.grid.valid[k]) {
                        CHECK(t.grid.heights[k] > 388 + 40); // geoid about +47 m here
                    }
                }
            }
        }
        CHECK(some_valid);
    }
}

TEST_CASE("encoded tiles decode, and many threads get the same bytes as one") {
    const auto path = tb_test::shared_dem("N44W072.hgt");
    if (!path) {
        return;
    }
    LayerOptions options;
    options.sources = {*path};
    options.tile_size = 64; // small tiles keep this Debug test fast
    const auto layer = Layer::open(options);
    const int z = layer->min_zoom() + 1;
    const TileRange r = layer->tiles_at(z);
    std::vector<TileId> ids;
    for (std::int64_t x = r.x0; x <= r.x1 && ids.size() < 4; ++x) {
        ids.push_back({z, x, r.y0});
    }
    std::vector<std::string> sequential;
    for (const auto& id : ids) {
        sequential.push_back(layer->make_tile(layer->tile(id), Format::Glb));
    }
    std::vector<std::future<std::string>> parallel;
    for (const auto& id : ids) {
        parallel.push_back(std::async(std::launch::async, [&, id] {
            return layer->make_tile(layer->tile(id), Format::Glb);
        }));
    }
    for (std::size_t k = 0; k < ids.size(); ++k) {
        CHECK(parallel[k].get() == sequential[k]);
    }
    const DecodedTile decoded = decode_glb(sequential[0]);
    CHECK(decoded.indices.size() >= 6);
    CHECK(decoded.positions.size() >= 4);
    const DecodedTile drc = decode_drc(layer->make_tile(layer->tile(ids[0]), Format::Drc));
    CHECK(drc.indices.size() == decoded.indices.size());
}

TEST_CASE("a max_zoom below the native zoom keeps the lattice's eps ladder at that zoom") {
    const auto path = tb_test::shared_dem("N44W072.hgt");
    if (!path) {
        return;
    }
    LayerOptions options;
    options.sources = {*path};
    options.max_zoom = 8;
    const auto layer = Layer::open(options);
    const auto native = open_layer({*path});
    // The default ladder follows the lattice (eps(z) = e0 / 2^z), whatever the deepest zoom: the
    // native ladder's 4 x 1.68 m at z8, never the native finest eps (whose lattice z8 tiles
    // cannot hold).
    CHECK(layer->eps_for_zoom(8) == 4 * native->eps_for_zoom(10));
    const TileRange r = layer->tiles_at(8);
    const std::string glb = layer->make_tile(layer->tile({8, r.x0, r.y0}), Format::Glb, {});
    CHECK(glb.size() > 1000);
}

TEST_CASE("the default finest eps is never below an integer DEM's height step") {
    // 0.0001 degree pixels (about 8 m at 46 N): resolution / 45 is about 0.18 m, below the 1 m
    // an Int16 DEM in metres can tell apart, so its default is that step; at a scale of 0.1 m
    // the step is 0.1 m and resolution / 45 rules again, as it does for Float32 heights.
    ScratchDir dir;
    const auto finest_eps = [&](const std::string& name, GDALDataType type, double scale) {
        Fixture f;
        f.width = 200, f.height = 200;
        f.type = type;
        f.scale = scale;
        f.epsg = 4326;
        f.geotransform = std::array<double, 6>{8.0, 0.0001, 0, 46.02, 0, -0.0001};
        for (int k = 0; k < f.width * f.height; ++k) {
            f.values.push_back(std::round(300 + 40 * std::sin(k % 200 * 0.05) + k / 200 * 0.2));
        }
        const auto layer = open_layer({tb_test::write_fixture(dir.file(name), f)});
        return layer->eps_for_zoom(layer->max_zoom());
    };
    const double float_eps = finest_eps("float.tif", GDT_Float32, 1.0);
    CHECK(float_eps > 0.1);
    CHECK(float_eps < 0.5);
    CHECK(finest_eps("int16.tif", GDT_Int16, 1.0) == 1.0);
    CHECK(finest_eps("uint16.tif", GDT_UInt16, 1.0) == 1.0);
    CHECK(finest_eps("decimetres.tif", GDT_Int16, 0.1) == doctest::Approx(float_eps));
}

TEST_CASE("a DEM too large to read whole gets bounding volumes over the Earth's whole relief") {
    ScratchDir dir;
    // 64 x 64 samples of 100 m with one spike of 5000 m, over a degree square.
    Fixture small;
    small.width = small.height = 64;
    small.values.assign(64 * 64, 100.0);
    small.values[static_cast<std::size_t>(37 * 64 + 21)] = 5000.0;
    small.geotransform = std::array<double, 6>{10, 1.0 / 64, 0, 46, 0, -1.0 / 64};
    small.epsg = 4326;
    const std::string tif = tb_test::write_fixture(dir.file("small.tif"), small);

    // Up to the limit the range is exact, spike included; below it GDAL's pass is approximate.
    const DemInfo exact = inspect_dem(tif);
    CHECK(exact.range_exact);
    CHECK(exact.min_height == 100.0);
    CHECK(exact.max_height == 5000.0);
    CHECK_FALSE(inspect_dem(tif, 1000).range_exact);

    // The same square stretched to 40000 x 40000 samples (1.6 Gpixel) by a VRT: above the
    // limit. Each spike sample grows to a block of about 625 x 625.
    const std::string vrt = dir.file("huge.vrt");
    {
        std::ofstream out(vrt);
        out << "<VRTDataset rasterXSize=\"40000\" rasterYSize=\"40000\"><SRS>EPSG:4326</SRS>"
               "<GeoTransform>10, 0.000025, 0, 46, 0, -0.000025</GeoTransform>"
               "<VRTRasterBand dataType=\"Float32\" band=\"1\"><SimpleSource>"
               "<SourceFilename relativeToVRT=\"0\">"
            << tif
            << "</SourceFilename><SourceBand>1</SourceBand>"
               "<SrcRect xOff=\"0\" yOff=\"0\" xSize=\"64\" ySize=\"64\"/>"
               "<DstRect xOff=\"0\" yOff=\"0\" xSize=\"40000\" ySize=\"40000\"/>"
               "</SimpleSource></VRTRasterBand></VRTDataset>";
    }
    CHECK_FALSE(inspect_dem(vrt).range_exact);
    const auto layer = open_layer({vrt}, Scheme::Geodetic, VerticalDatum::Ellipsoid);
    CHECK(layer->min_height() <= -11100.0);
    CHECK(layer->max_height() >= 8900.0);
    // An exact source keeps its own range: bounding volumes stay tight.
    const auto tight = open_layer({tif}, Scheme::Geodetic, VerticalDatum::Ellipsoid);
    CHECK(tight->min_height() < 100.0);
    CHECK(tight->min_height() > 90.0);
    CHECK(tight->max_height() > 5000.0);
    CHECK(tight->max_height() < 5010.0);
}

TEST_CASE("make_tiles gives, format by format, exactly make_tile's bytes, on pixel and measured "
          "layers, with voids, and for filler terrain") {
    ScratchDir dir;
    // 97 x 97 heights with a void block: in lon/lat (meshed on its own pixels) and in UTM
    // (meshed on the zoom's lattice and measured).
    // The third has only voids in its western third, so some tiles hold voids alone (no .drc).
    struct Input {
        const char* name;
        int epsg;
        std::array<double, 6> geotransform;
        int void_columns;
    };
    const Input inputs[] = {
        {"lonlat.tif", 4326, {8.0, 0.25 / 96, 0, 47.25, 0, -0.25 / 96}, 0},
        {"utm.tif", 32632, {400000, 200, 0, 5235000, 0, -200}, 0},
        {"west.tif", 4326, {8.0, 0.25 / 96, 0, 47.25, 0, -0.25 / 96}, 40},
    };
    for (const Input& in : inputs) {
        tb_test::Fixture f;
        f.width = f.height = 97;
        f.epsg = in.epsg;
        f.geotransform = in.geotransform;
        f.nodata = -9999;
        for (int r = 0; r < 97; ++r) {
            for (int c = 0; c < 97; ++c) {
                const bool hole = (r > 60 && r < 70 && c > 20 && c < 34) || c < in.void_columns;
                f.values.push_back(
                    hole ? -9999 : 600 + 4 * r + 80 * std::sin(c * 0.2) * std::cos(r * 0.15));
            }
        }
        LayerOptions options;
        options.sources = {tb_test::write_fixture(dir.file(in.name), f)};
        options.tile_size = 32;
        const auto layer = Layer::open(options);
        INFO(in.name << ": " << to_string(layer->guarantee()));
        const std::vector<Format> formats = {
            Format::Glb, Format::Terrain, Format::Drc, Format::Terrain3d};
        std::vector<TileId> ids;
        for (int z : {layer->min_zoom(), layer->max_zoom()}) {
            const TileRange r = layer->tiles_at(z);
            for (std::int64_t y = r.y0; y <= r.y1; ++y) {
                for (std::int64_t x = r.x0; x <= r.x1; ++x) {
                    ids.push_back({z, x, y});
                }
            }
        }
        ids.push_back({layer->min_zoom(), 0, 0}); // no data: terrain filler only
        std::size_t made = 0, no_drc = 0;
        for (const TileId& id : ids) {
            CAPTURE(id.z);
            CAPTURE(id.x);
            CAPTURE(id.y);
            std::vector<std::pair<Format, std::string>> one_by_one;
            for (Format format : formats) {
                try {
                    one_by_one.emplace_back(format, layer->make_tile(layer->tile(id), format));
                } catch (const tb::NotFound&) {
                }
            }
            const auto together = layer->make_tiles(layer->tile(id), formats);
            REQUIRE(together.size() == one_by_one.size());
            for (std::size_t k = 0; k < together.size(); ++k) {
                CHECK(together[k].first == one_by_one[k].first);
                CHECK(together[k].second == one_by_one[k].second);
            }
            // In the reverse order too: a format's bytes do not depend on what came before.
            const std::vector<Format> reversed(formats.rbegin(), formats.rend());
            const auto backwards = layer->make_tiles(layer->tile(id), reversed);
            REQUIRE(backwards.size() == together.size());
            for (std::size_t k = 0; k < backwards.size(); ++k) {
                CHECK(backwards[k] == together[together.size() - 1 - k]);
            }
            made += together.size();
            no_drc += layer->may_have_tile(layer->tile(id)) &&
                      std::none_of(together.begin(), together.end(), [](const auto& t) {
                          return t.first == Format::Drc;
                      });
        }
        CHECK(made > 2 * ids.size()); // mostly tiles with data, in all four formats
        if (in.void_columns > 0) {
            CHECK(no_drc > 0);
        }
        CHECK_THROWS_AS(
            layer->make_tiles(layer->tile({1, 0, 0}), std::vector<Format>{Format::Terrarium}),
            tb::InputError);
    }
}
