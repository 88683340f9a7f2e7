#pragma once
// A tile raster: the (N+1) x (N+1) heights one tile is meshed from, plus where they are.
#include "core/mesh.hpp"
#include "tiler/tile_grid.hpp"

namespace tb::tiler {

struct TileRaster {
    TileId id;
    Scheme scheme = Scheme::Geodetic;
    LonLatBox bounds; // the tile's lon/lat box
    int size = 256;   // N: the grid has N+1 columns and N+1 rows
    // Heights in metres above the WGS84 ellipsoid (datum conversion already applied). Column 0
    // is the west edge, row 0 the north edge. Sample (i, j) sits at the scheme's native
    // coordinates x = x_west + i * (x_east - x_west) / N, y = y_north - j * (y_north - y_south) / N
    // (degrees for geodetic, EPSG:3857 metres for mercator), so neighbouring tiles share their
    // border samples exactly. Voids are filled; `grid.valid` marks the measured samples.
    core::HeightGrid grid;
};

struct LonLat {
    double lon = 0, lat = 0; // degrees
};

// Lon/lat of a point given in tile grid coordinates (column, row), fractional allowed.
LonLat grid_to_lonlat(const TileRaster& raster, double column, double row);
// The inverse: tile grid coordinates (column, row) of a lon/lat.
void lonlat_to_grid(const TileRaster& raster, const LonLat& p, double& column, double& row);

} // namespace tb::tiler
