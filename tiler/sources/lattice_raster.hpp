#pragma once
// A tile raster from samples of the zoom's lattice (DemSource::sample, or the summary's planes):
// the datum applied and voids filled, as every lattice-meshed tile of a layer is made.
#include "tiler/layer.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/tile_raster.hpp"

namespace tb::tiler {

// Samples read around a tile so that void filling near its border sees what its neighbours
// see (fill_voids step 1 radius).
inline constexpr int kLatticeFillMargin = 16;

// Tile `id`'s raster of (tile_size + 1)^2 ellipsoidal heights from `block`, the lattice samples
// of the tile and kLatticeFillMargin around it ((tile_size + 1 + 2 * margin)^2 from the tile's
// first column and row less the margin), heights in `datum` (Egm96 or Ellipsoid). Voids are
// filled in orthometric heights, so data-free areas sit on the geoid (sea level); the valid
// mask is kept where some sample is void.
TileRaster lattice_tile_raster(
    const TileId& id, const LatticeBlock& block, Scheme scheme, int tile_size, VerticalDatum datum);

} // namespace tb::tiler
