#pragma once
// Raster DEM tiles of a layer: EPSG:3857 XYZ PNGs of heights (terrarium or mapbox encoding,
// tiler/formats/dem_png.hpp), the tiles MapLibre GL's raster-dem sources and deck.gl's
// TerrainLayer read. They form their own pyramid, whatever the layer's mesh scheme:
//   - a tile has P x P pixels (P = LayerOptions::dem_tile_size, 256 or 512); pixel (i, j) is the
//     DEM sampled at the pixel's centre, i.e. lattice point (x * 2P + 2i + 1, y * 2P + 2j + 1) of
//     DemSource::sample at (mercator, z, 2P): bilinear in the band or overview read_level
//     chooses there, nodata neighbours dropping out as for mesh tiles;
//   - voids (nodata, and pixels beyond the source) are filled as mesh tiles fill them
//     (fill_voids with a margin of kDemFillMargin pixels; sea level far from data), so every
//     pixel is opaque and a client never decodes a void as a -32768 m pit;
//   - heights are above sea level (DemHeights::SeaLevel) or the WGS84 ellipsoid;
//   - the encoding's rounding is the only loss: at most half a step (1/512 m terrarium, 0.05 m
//     mapbox).
// Zooms: max = the first zoom whose pixel is as fine as the source's pixel; min = 0 (clients
// draw no terrain below a source's minzoom). A tile pixel spanning 8 source pixels or more
// reads the layer's summary (Layer::sample) where the source has one.
#include "tiler/formats/format.hpp"
#include "tiler/layer.hpp"
#include "tiler/tile_grid.hpp"

#include <string>
#include <vector>

namespace tb::tiler {

// Pixels read around a tile for void filling (fill_voids step 1 radius).
inline constexpr int kDemFillMargin = 16;

struct DemTilePlan {
    int tile_size = 512;
    int min_zoom = 0, max_zoom = 0;
    LonLatBox bounds; // the data's lon/lat box, latitudes clamped to EPSG:3857's extent
};

// The layer's DEM pyramid. Throws InputError for a tile size other than 256 or 512.
DemTilePlan dem_tile_plan(const Layer& layer);
// Tiles of zoom z that may hold data: empty outside min_zoom..max_zoom.
TileRange dem_tiles_at(const Layer& layer, int z);

// The P x P heights of a DEM tile (row 0 at the north), metres, before encoding. The tile is
// a mercator one (asserted; ValidTile::parse(Scheme::Mercator, id) where a request names it),
// whatever the layer's scheme. Throws NotFound beyond the zooms or the data, and Cancelled when
// `cancelled` says so (asked before reading, every 32 rows read, and before returning).
std::vector<double>
dem_tile_heights(const Layer& layer, const ValidTile& tile, const CancelFn& cancelled = {});
// The tile as PNG in `format` (Terrarium or Mapbox). Same errors as dem_tile_heights.
std::string make_dem_tile(const Layer& layer,
                          const ValidTile& tile,
                          Format format,
                          const CancelFn& cancelled = {});

DemHeights parse_dem_heights(const std::string& name); // "sea_level" | "ellipsoid"
const char* to_string(DemHeights heights);

} // namespace tb::tiler
