#pragma once
// Shading normals of a tile's vertices, from the slope of the DEM under them: those of the
// mesh tiles (glb, drc) and of globe terrain's octvertexnormals.
#include "tiler/mesh/tile_mesh.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/tile_grid.hpp"

#include <array>
#include <vector>

namespace tb::tiler {

// Unit ECEF normals of the DEM surface at each vertex, from the slope of the source's
// heights at the vertex's lon/lat: a pure function of where the vertex is and of the source,
// so a vertex two tiles share gets the same normal in both. Pixel layers: central
// differences one pixel either side on the bilinear surface of the source's pixels (voids
// left out of the weights); other layers: central differences on the zoom's lattice. The
// differences are taken in the grid's own units (degrees, or EPSG:3857 metres for a
// mercator grid) and turned into ground slopes with the ellipsoid's radii at the vertex.
// `pixels`: the source's pixel grid where tile `id`'s zoom reads the source's pixels (its
// ZoomSource is Pixels), else null (the zoom's lattice of `tile_size`, from `lattice` when given,
// else DemSource::sample).
std::vector<std::array<double, 3>> vertex_normals(const TileMesh& mesh,
                                                  const TileId& id,
                                                  Scheme scheme,
                                                  int tile_size,
                                                  const DemSource& source,
                                                  const PixelGrid* pixels,
                                                  const LatticeSampler& lattice = {});

} // namespace tb::tiler
