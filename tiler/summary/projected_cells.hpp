#pragma once
// Summary blocks as CheckCells where the source's pixel grid does not run along the tile's
// (PixelPlace::serves() false): a UTM survey under geodetic tiles, a lon/lat DEM under mercator
// ones, a rotated grid. A block's pixels then land on a slightly curved quadrilateral of the tile's
// grid, and its plane is no longer a plane there.
//
// Each block is moved into the tile at a 5 x 5 grid of probes, its corners and quarter points
// (shared with its neighbours). The affine map A through three corners stands for the true map
// T, and T - A bounds how far any pixel strays from where A puts it, per axis, taken as the
// larger of:
//   - the sum of |T - A| at the six other points of the half-block grid (corners, side middles,
//     centre), times kStrayMargin: for T quadratic over the block, the largest |T - A| is at most
//     the sum of the three of those values that fix the quadratic;
//   - the largest |T - A| over every probe, times kProbeMargin: a cubic term can vanish on the
//     half-block grid (mercator's y(lat) is odd about the equator) but not at the quarter points,
//     and along a side a cubic's largest value exceeds its quarter points' by at most 1.094.
// A map projection's higher terms are smaller again by about the block's width over the Earth's
// radius. Then:
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

// Probes per side of a block, and the margins on the two measures of its stray (above).
inline constexpr int kProbes = 5;
inline constexpr double kStrayMargin = 1.25;
inline constexpr double kProbeMargin = 1.5;

// The blocks of `level` that may hold valid pixel centres inside the tile of `raster` (a lattice
// raster), in raster's grid coordinates. Their pixels are found from the tile's lon/lat box
// (cut to the source's footprint), its outline moved to pixel coordinates and widened by a
// block; all of them when a point of the outline does not transform.
std::vector<CheckCell> projected_cells(const DemSummary& summary,
                                       const PixelPlace& place,
                                       const TileRaster& raster,
                                       int level);

} // namespace tb::tiler
