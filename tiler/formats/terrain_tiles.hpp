#pragma once
// 3D Tiles terrain, the format of CesiumJS's Cesium3DTilesTerrainProvider: a tileset.json whose
// root has two implicit quadtree children (the geodetic scheme's west and east root tiles), with
// binary .subtree files carrying each tile's availability and, as tile metadata,
// TILE_MINIMUM_HEIGHT, TILE_MAXIMUM_HEIGHT, TILE_BOUNDING_SPHERE (FLOAT64 array of 4),
// and TILE_HORIZON_OCCLUSION_POINT; and one glb per tile: positions as
// 16-bit normalized integers in a box that nodes[0].matrix places in ECEF (glTF y-up),
// compressed with EXT_meshopt_compression (float32 where 16 bits cannot keep a tile within its
// bound), as are the triangle indices and the four CESIUM_tile_edges lists; float normals; a
// default material.
//
// Layout under the layer's terrain root ("terrain/" on the server and in a store):
//   tileset.json, {root}/{level}/{x}/{y}.subtree, {root}/{level}/{x}/{y}.glb
// with root 0 (west) or 1 (east), and x, y the implicit coordinates inside that root: the
// geodetic tile (level, root * 2^level + x, y), y from the south. meshoptimizer is included
// only in terrain_tiles.cpp.
#include "tiler/formats/quantized_mesh.hpp"
#include "tiler/tile_grid.hpp"

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace tb::tiler {

// A terrain tile's content, encoded as quantized-mesh or as 3D Tiles terrain. The mesh is the
// same for both; what only one format carries (the water mask and metadata of quantized-mesh,
// the measured glb bound of 3D Tiles) is made for the format asked for.
struct TerrainTile {
    QuantizedMesh mesh;         // covers the whole tile rectangle
    QuantizedMeshExtras extras; // normals (one per vertex), water mask, metadata JSON
    double error = 0;           // what the quantized-mesh tile publishes (metadata extension)
    double glb_error = 0;       // what its 3D Tiles terrain glb publishes (asset.extras)
    bool filler = false;        // flat filler on the geoid, not meshed from the DEM
    // The glb carries float32 positions (metres in the tile's ENU frame, uncompressed) instead
    // of 16-bit ones: for a tile whose 16-bit positions would take it past its zoom's bound.
    bool exact_positions = false;
};

// The geoid's undulation (EGM96: -106.99 .. 85.39 m) stays within these heights, metres.
inline constexpr double kGeoidLowest = -110.0;
inline constexpr double kGeoidHighest = 90.0;

// Levels per subtree file.
inline constexpr int kTerrainSubtreeLevels = 4;

// The tile metadata a subtree holds for one tile.
struct TerrainTileBounds {
    double min_height = 0, max_height = 0;     // ellipsoidal metres, containing every vertex
    std::array<double, 4> bounding_sphere{};   // ECEF centre, radius
    std::array<double, 3> horizon_occlusion{}; // ellipsoid-scaled, as quantized-mesh's
};

// A conservative TerrainTileBounds of a tile whose vertices lie in `box` between min_height
// and max_height (the sphere and the horizon point hold the whole box, not just sampled points).
TerrainTileBounds terrain_tile_bounds(const LonLatBox& box, double min_height, double max_height);

// What the terrain tileset and its subtrees say about a layer.
struct TerrainTilesetSpec {
    TerrainSpec terrain;   // availability: terrain_available(terrain, z)
    double min_height = 0; // over every tile, ellipsoidal metres
    double max_height = 0;
    // The metadata of an available tile (a geodetic one).
    std::function<TerrainTileBounds(const ValidTile&)> bounds;
    // Level 0's geometricError; level z's is this / 2^z: at least the bound every tile of level
    // z is held to (flat filler below the meshed zooms: the DEM's relief).
    double root_error = 0;
};

// tileset.json (3D Tiles 1.1): the metadata schema, then a root holding the two implicit roots.
std::string terrain_tileset_json(const TerrainTilesetSpec& spec);

// The geodetic tile of implicit coordinates (root, level, x, y); nullopt when they are outside
// the root's quadtree (root 0 or 1, level 0..kMaxZoom, x and y below 2^level).
std::optional<ValidTile>
terrain_tile_id(std::int64_t root, std::int64_t level, std::int64_t x, std::int64_t y);

// The binary subtree file ("subt", version 1) rooted at implicit (root, level, x, y): tile and
// content availability (the same: every available tile has a glb), child subtree availability,
// and the tile metadata table of its available tiles in tile-index order. False when level is
// not a multiple of kTerrainSubtreeLevels, beyond the layer's levels, or the coordinates are
// outside the root; a subtree whose root tile is unavailable is never referenced, but is
// still well-formed (nothing available).
bool terrain_subtree(const TerrainTilesetSpec& spec,
                     int root,
                     int level,
                     std::int64_t x,
                     std::int64_t y,
                     std::string& out);

// The surface the tile's glb draws, as CesiumJS decodes its 16-bit positions (divided by 65535
// into float32, then the node matrix in double precision), back in the tile's lon/lat u/v
// units; edge vertices keep their edge coordinate, as CesiumJS places them. surface_error of it
// is what the glb's bound must cover (plus the chord sag).
SurfaceMesh terrain_glb_surface(const QuantizedMesh& mesh, bool exact_positions);

// The tile's glb, publishing tile.glb_error as asset.extras.geometricError.
std::string encode_terrain_glb(const TerrainTile& tile);

} // namespace tb::tiler
