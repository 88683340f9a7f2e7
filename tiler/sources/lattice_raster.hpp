#pragma once
// A tile raster from samples of the zoom's lattice (DemSource::sample, or the summary's planes):
// the datum applied and voids filled, as every lattice-meshed tile of a layer is made.
#include "tiler/layer.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/tile_raster.hpp"

#include <cstdint>

namespace tb::tiler {

// Samples read around a tile so that void filling near its border sees what its neighbours
// see (fill_voids step 1 radius).
inline constexpr int kLatticeFillMargin = 16;

// Slope (metres down per metre across) of the surface drawn beyond the data's footprint: the
// footprint's edge height carried outward and lowered toward sea level at this grade (about
// 27 degrees: a 700 m edge reaches sea level 1.4 km out), at every zoom. Gentler grades carry
// the edge further, past the tiles that hold data, where CesiumJS draws a coarser ancestor's
// surface instead and its skirts show as walls.
inline constexpr double kEdgeGrade = 0.5;

// `sampler`, or where it is empty, DemSource::sample of `source` (which must outlive it).
LatticeSampler sampler_or_source(LatticeSampler sampler, const DemSource& source);

// The data's footprint on one zoom's lattice (the lattice points inside the layer's lon/lat
// box, inclusive; where the box holds none, the nearest column or row), and how to read the
// lattice (heights in the layer's datum).
struct LatticeFootprint {
    std::int64_t first_column = 0, last_column = -1, first_row = 0, last_row = -1;
    LatticeSampler sample;
};
LatticeFootprint
lattice_footprint(Scheme scheme, int z, int tile_size, const LonLatBox& box, LatticeSampler sample);

// The ellipsoidal height lattice_tile_raster carries to lattice point (column, row) of zoom z
// beyond `footprint` (see there), read on its own: for a tile meshed off the lattice whose
// corners lie beyond the data (tiler/formats/quantized_mesh.hpp, cover_rectangle). NaN when
// the footprint point nearest to it is void.
double carried_height(Scheme scheme,
                      int z,
                      int tile_size,
                      std::int64_t column,
                      std::int64_t row,
                      const LatticeFootprint& footprint,
                      VerticalDatum datum);

// Tile `id`'s raster of (tile_size + 1)^2 ellipsoidal heights from `block`, the lattice samples
// of the tile and kLatticeFillMargin around it ((tile_size + 1 + 2 * margin)^2 from the tile's
// first column and row less the margin), heights in `datum` (Egm96 or Ellipsoid).
//   - With a `footprint` (globe terrain, which draws past the data), a void beyond it takes the
//     orthometric height of the footprint point nearest it (column and row clamped), lowered
//     toward sea level by kEdgeGrade per metre from a lattice step beyond that point, when it is
//     valid: the DEM's edge carried outward on a slope, not a cliff, and a function of the
//     lattice point alone, so neighbouring tiles agree. Meshes that leave voids out (3D Tiles,
//     Draco) pass none: their kept triangles span from the data into the first voids, and
//     there the nearest values fill_voids gives keep the surface closest to the pixels between.
//   - Other voids are filled in orthometric heights (fill_voids), so data-free areas sit on
//     the geoid (sea level).
// The valid mask is kept where some sample is void; carried and filled samples are not valid.
TileRaster lattice_tile_raster(const TileId& id,
                               const LatticeBlock& block,
                               Scheme scheme,
                               int tile_size,
                               VerticalDatum datum,
                               const LatticeFootprint* footprint);

} // namespace tb::tiler
