#pragma once
// Tiles of a source whose pixels lie on the scheme's own grid (DemSource::pixel_grid: SRTM,
// DTED, Copernicus and most geographic DEMs for the geodetic scheme). Such a tile is meshed on
// the source's own pixel centres, at full resolution at every zoom, so the error bound the mesher
// proves holds at every measured pixel under the tile, and nothing is resampled.
//
// The pixel centres inside the tile form a block of the source's grid. Between the block's
// outermost pixel line and the tile's border line lies a strip less than a pixel wide that holds
// no pixel centre. Where the source goes on across the border, the strip is drawn: the border
// line's heights are interpolated linearly between the two pixels either side of it (at a
// corner, bilinearly between the four around it), a pure function of those pixels, and its
// vertices are the optimal 1-D fit of that profile. The tile on the other side computes the same
// profile from the same pixels, so both give the shared border the same vertices, bit for bit,
// and the tiles meet without a crack. The strip between the block's border (core's locked
// border fit) and the border line is zipped with triangles that each join the two lines.
#include "tiler/formats/encode.hpp"
#include "tiler/layer.hpp"
#include "tiler/mesh/tile_mesh.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/tile_raster.hpp"

#include <array>
#include <cstdint>
#include <vector>

namespace tb::tiler {

enum Side { kWest = 0, kEast = 1, kNorth = 2, kSouth = 3 };

// The heights along one of the tile's border lines, at each pixel row (west, east) or column
// (north, south) of the block. Present when the source has pixels on both sides of the line.
struct BorderProfile {
    bool present = false;
    std::vector<float> heights;      // ellipsoidal metres
    std::vector<std::uint8_t> valid; // 0 where neither pixel beside it holds data
};

struct PixelTile {
    // grid: the block of pixel centres inside the tile (voids filled, `valid` marking measured
    // pixels), ellipsoidal metres; frame: those pixel centres.
    TileRaster raster;
    PixelGrid pixels;                   // the source's grid
    std::int64_t column0 = 0, row0 = 0; // the block's first pixel in the source
    std::array<double, 4> edge{}; // x of west, east; y of north, south (in the pixel grid's CRS)
    std::array<BorderProfile, 4> sides; // by Side
    std::array<float, 4> corner{};      // NW, NE, SW, SE: heights where two strips meet
    std::array<std::uint8_t, 4> corner_valid{};
};

// The pixel tile of id: reads the block plus a margin (for void filling and the border
// profiles), converts heights to the WGS84 ellipsoid (`datum`: Egm96 adds the undulation; voids
// are filled in orthometric heights, so data-free areas lie on the geoid). Throws NotFound when no
// pixel centre of the source lies in the tile, InputError when the block exceeds
// kMaxPixelsPerTile.
PixelTile make_pixel_tile(const DemSource& source,
                          const PixelGrid& pixels,
                          Scheme scheme,
                          const TileId& id,
                          VerticalDatum datum);

// The error budget of a pixel tile: error_budget(eps, sag_share) with the longest edge in pixels
// (the larger of the two pixel sides, in ground metres, is the unit), the same for every tile of
// the source.
ErrorBudget pixel_error_budget(double eps,
                               Scheme scheme,
                               const PixelGrid& pixels,
                               double sag_share = kSagShare);

// The tile's mesh: core::triangulate_strips on the block at budget.mesh_eps with locked borders,
// the border strips and corners zipped on. Every valid pixel of the block is within
// budget.mesh_eps of it; triangles holding no valid pixel, and strip triangles touching a border
// vertex with no data beside it, are left out (with drop_voids; without, every triangle is kept
// and voids are drawn at their filled heights, as a globe that must cover the tile needs);
// every edge is at most budget.max_edge pixels. `threads` caps the threads meshing the block's
// strips (the mesh is the same for any value). `check_error`: see
// core::TriangulateOptions::check_error (off when an encoder measures the drawn tile).
TileMesh mesh_pixel_tile(const PixelTile& tile,
                         const ErrorBudget& budget,
                         bool drop_voids = true,
                         int threads = 2,
                         bool check_error = true,
                         core::Effort effort = core::Effort::Balanced);

} // namespace tb::tiler
