#pragma once
// A coarse tile read from the DEM's summary (dem_summary.hpp) instead of its pixels: the zoom's
// lattice of samples, each read off the plane of the summary block it lies in, and the blocks
// under the tile as CheckCells, so the drawn tile is judged against every valid pixel without
// reading one. The work per tile is about its own number of samples, whatever the zoom.
#include "tiler/mesh/cell_check.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/summary/dem_summary.hpp"
#include "tiler/summary/pixel_place.hpp"

#include <cstdint>
#include <map>
#include <utility>
#include <vector>

namespace tb::tiler {

// The summary level a zoom reads: its blocks no wider than a lattice step, so each lattice cell
// is judged against blocks of its own size or smaller (or the summary's finest, for a source too
// large to keep kFinestLevel). -1 when the step is narrower than kFinestLevel's blocks (such a
// zoom reads pixels).
int summary_level(
    const DemSummary& summary, const PixelPlace& place, Scheme scheme, int z, int size);
// The same for a given number of source pixels per lattice step (any lattice, e.g. DEM tiles').
int summary_level(const DemSummary& summary, double pixels_per_step);

// How far zoom z's lattice cells stray from flat where the data is rough: each summary block of
// the zoom's level (at least the finest) has its residual range scaled to a lattice step (a
// block's relief grows about linearly with its width); each tile over the data takes its roughest
// block, and the zoom's reach is the median over those tiles, in metres. A coarse tile cannot be
// drawn closer to its pixels than about half its cells' ranges, whatever its triangles, so a
// layer meshes such zooms at a share of the reach instead of paying for flat-lattice detail that
// the published bound cannot show.
double
zoom_reach(const DemSummary& summary, const PixelPlace& place, Scheme scheme, int z, int size);

// The roughest block of each tile (x, y), as zoom_reach finds them, of one summary or several
// (a collection's members: merged, each tile keeping its roughest of all).
using TileRoughness = std::map<std::pair<std::int64_t, std::int64_t>, double>;
void add_roughness(const DemSummary& summary,
                   const PixelPlace& place,
                   Scheme scheme,
                   int z,
                   int size,
                   TileRoughness& roughest);
// The median over the tiles (0 with none): the zoom's reach.
double median_roughness(const TileRoughness& roughest);

// The lattice points (column0 + i, row0 + j) of (scheme, z, size), as DemSource::sample gives
// them, each the plane of the block it lies in: heights in the source's datum (EGM96 sources: the
// summary's ellipsoidal height less the undulation, which the tile raster adds back), valid where
// the point lies in a block with data.
LatticeBlock summary_lattice(const DemSummary& summary,
                             const PixelPlace& place,
                             VerticalDatum datum,
                             Scheme scheme,
                             int z,
                             int size,
                             int level,
                             std::int64_t column0,
                             std::int64_t row0,
                             int width,
                             int height);

// The blocks of `level` holding valid pixel centres inside the tile of `raster` (a lattice
// raster), each clipped to the tile, in raster's grid coordinates: axis-aligned boxes on a grid
// that serves the scheme, else the bounds projected_cells gives.
std::vector<CheckCell> summary_cells(const DemSummary& summary,
                                     const PixelPlace& place,
                                     const TileRaster& raster,
                                     int level);

} // namespace tb::tiler
