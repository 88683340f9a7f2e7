#pragma once
// A tile raster: the (N+1) x (N+1) heights one tile is meshed from, plus where they are.
#include "core/mesh.hpp"
#include "tiler/tile_grid.hpp"

#include <cstdint>

namespace tb::tiler {

// Where a raster's samples sit: sample (column i, row j) at the scheme's native coordinates
// x = x0 + i * dx, y = y0 - j * dy (degrees for geodetic, EPSG:3857 metres for mercator), or at
// lon/lat (x, y) when `lonlat` is set.
struct GridFrame {
    double x0 = 0, y0 = 0;
    double dx = 0, dy = 0; // > 0; dx == 0 means the zoom's lattice (see TileRaster)
    bool lonlat = false;   // x, y are lon/lat degrees whatever the scheme (a geographic source)
};

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
    // A raster of a source's own pixels (see tiler/pixel_tile.hpp) sets `frame` instead: its
    // samples are the source pixel centres inside the tile, and N is not its width.
    core::HeightGrid grid;
    GridFrame frame;
};

// The frame of raster's samples: raster.frame when set, else the zoom's lattice.
GridFrame frame_of(const TileRaster& raster);

struct LonLat {
    double lon = 0, lat = 0; // degrees
};

// Lon/lat of a point given in tile grid coordinates (column, row), fractional allowed (in the
// raster's frame).
LonLat grid_to_lonlat(const TileRaster& raster, double column, double row);
// The inverse: tile grid coordinates (column, row) of a lon/lat.
void lonlat_to_grid(const TileRaster& raster, const LonLat& p, double& column, double& row);

// ---- Tile lattice arithmetic (tiler/sources/tile_raster.cpp) ----
// The global sample lattice of zoom z for tiles of `size` samples: column c sits at native
// x = x_min + c * step, row r at native y = y_max - r * step (degrees for geodetic, EPSG:3857
// metres for mercator), step = tile width / size. Row 0 is the scheme's north edge. A tile's
// sample (i, j) is lattice point (x * size + i, row_of_tile_top + j), so neighbours share
// border samples exactly.
double lattice_x(Scheme scheme, int z, int size, std::int64_t column);
double lattice_y(Scheme scheme, int z, int size, std::int64_t row);
std::int64_t tile_first_column(Scheme scheme, const TileId& id, int size);
std::int64_t tile_first_row(Scheme scheme, const TileId& id, int size);
LonLat native_to_lonlat(Scheme scheme, double x, double y);
void lonlat_to_native(Scheme scheme, const LonLat& p, double& x, double& y);

} // namespace tb::tiler
