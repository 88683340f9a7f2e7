#pragma once
// Summary blocks as CheckCells where the source's pixel grid does not run along the tile's
// (PixelPlace::serves() false): a UTM survey under geodetic tiles, a lon/lat DEM under mercator
// ones, a rotated grid. A block's pixels then land on a slightly curved quadrilateral of the tile's
// grid, and its plane is no longer a plane there.
//
// Each block is moved to the tile's grid at its corners, the middles of its sides and its centre
// (points shared with its neighbours). The affine map A through three corners stands for the
// true map T; T - A, measured at the other six points, bounds how far any pixel strays from
// where A puts it, per axis: for T quadratic over the block (a map projection at a block's
// scale, whose higher terms are smaller by about the block's width over the Earth's radius) the
// largest |T - A| is at most the sum of the three of those values that fix the quadratic, and
// the sum of all six, times kStrayMargin, is used. Then:
//   - the cell's box is A's parallelogram widened by that stray, cut to the tile;
//   - its reference is the block's plane carried through A's inverse, and its half-range is the
//     block's plus how far the plane moves over the stray.
// So every valid pixel of the block in the tile lies in the box and within `half` of the
// reference, as cell_check.hpp needs. A block whose points do not all transform gets the whole
// tile as its box and a flat reference spanning its pixels' heights, which is true anywhere.
#include "tiler/mesh/cell_check.hpp"
#include "tiler/summary/dem_summary.hpp"
#include "tiler/summary/pixel_place.hpp"

#include <vector>

namespace tb::tiler {

// The stray measured at six points of a block, summed, times this.
inline constexpr double kStrayMargin = 1.25;

// The blocks of `level` that may hold valid pixel centres inside the tile of `raster` (a lattice
// raster), in raster's grid coordinates. Their pixels are found from the tile's lon/lat box
// (cut to the source's footprint), its outline moved to pixel coordinates and widened by a
// block; all of them when a point of the outline does not transform.
std::vector<CheckCell> projected_cells(const DemSummary& summary,
                                       const PixelPlace& place,
                                       const TileRaster& raster,
                                       int level);

} // namespace tb::tiler
