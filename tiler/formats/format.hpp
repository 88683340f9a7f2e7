#pragma once
// Encoded tile formats, with their names, file extensions and media types.
#include <optional>
#include <string_view>

namespace tb::tiler {

enum class Format {
    Glb, // glTF 2.0 binary, KHR_draco_mesh_compression, ECEF relative to the tile centre
    Drc, // raw Draco, local ENU metres z-up, with geometry metadata
    // Raster DEM tiles (EPSG:3857 XYZ PNG, tiler/dem_tiles.hpp), one per height encoding:
    Terrarium, // h = R * 256 + G + B / 256 - 32768
    Mapbox,    // Terrain-RGB: h = -10000 + (R * 65536 + G * 256 + B) * 0.1
    // quantized-mesh-1.0 for CesiumJS's globe (tiler/formats/quantized_mesh.hpp), geodetic
    // layers only, with every extension; the server strips those a request does not accept.
    Terrain,
    // 3D Tiles terrain for CesiumJS's Cesium3DTilesTerrainProvider (tiler/formats/terrain_tiles.hpp):
    // glb with EXT_meshopt_compression under the layer's terrain/ tileset, geodetic layers only.
    Terrain3d,
};

// "glb" | "drc" | "terrarium" | "mapbox" | "terrain" | "terrain3d": how configs, build options, stores and caches
// name a format (unique per format).
std::optional<Format> parse_format(std::string_view name);
const char* format_name(Format format);
const char* extension(Format format); // "glb" | "drc" | "png" | "terrain" (terrain3d: "glb")
// model/gltf-binary | application/octet-stream | image/png | application/vnd.quantized-mesh
const char* media_type(Format format);
// True for the raster DEM formats (terrarium, mapbox), which tile EPSG:3857 whatever the
// layer's scheme.
bool is_dem_format(Format format);
// True for the globe terrain formats (terrain, terrain3d): every zoom from 0, filler where the
// layer has no data, the geodetic scheme only.
bool is_terrain_format(Format format);

} // namespace tb::tiler
