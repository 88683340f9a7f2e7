// Inputs tests/fuzz/fuzz_mesh.cpp found, each the smallest tile that shows the problem.
#include "core/error.hpp"
#include "tiler/formats/encode.hpp"
#include "tiler/layer.hpp"

#include <doctest/doctest.h>

#include <string>

using namespace tb::tiler;

namespace {

TileRaster flat_tile(const TileId& id, int n, float h) {
    TileRaster r;
    r.id = id;
    r.scheme = Scheme::Geodetic;
    r.bounds = tile_bounds(Scheme::Geodetic, id);
    r.size = n;
    r.grid.width = r.grid.height = n + 1;
    r.grid.heights.assign(static_cast<std::size_t>(n + 1) * (n + 1), h);
    return r;
}

} // namespace

TEST_CASE("a tile narrower than its eps's lattice step is refused, not encoded as a sliver") {
    // Zoom 18 at 89.3 N: the tile is 0.93 m wide (16 samples 5.8 cm apart east-west), and
    // eps 81.92 m quantizes to a 2 m lattice. In .drc's ENU frame that put every vertex of this
    // flat tile on one meridian: two triangles of zero area over 289 samples; in .glb's ECEF
    // lattice the tile came out sheared by up to 17 columns (fuzz_mesh found both).
    const TileRaster r = flat_tile(TileId{18, 522240, 261120}, 16, -0.5f);
    const ErrorBudget budget = tile_error_budget(81.92, r.scheme, r.id.z, r.size);
    REQUIRE(budget.quant_step == 2);
    const auto mesh = mesh_tile(r, budget);
    for (Format f : {Format::Glb, Format::Drc}) {
        try {
            encode_tile(r, mesh, f, budget);
            FAIL("expected an InputError");
        } catch (const tb::InputError& e) {
            const std::string what = e.what();
            CHECK(what.find(
                      "tile 18/522240/261120: eps 81.92 m gives a quantization step of 2 m") == 0);
            CHECK(what.find("use a smaller eps") != std::string::npos);
        }
    }
    // The same tile at an eps whose lattice fits it encodes.
    const ErrorBudget fine = tile_error_budget(0.16, r.scheme, r.id.z, r.size);
    for (Format f : {Format::Glb, Format::Drc}) {
        CHECK_FALSE(encode_tile(r, mesh_tile(r, fine), f, fine).empty());
    }
}
