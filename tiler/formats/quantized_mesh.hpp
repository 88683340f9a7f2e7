#pragma once
// quantized-mesh-1.0, the terrain format of CesiumJS's CesiumTerrainProvider (CesiumGS/
// quantized-mesh README): a header (tile centre, height range, bounding sphere, horizon occlusion
// point), vertices as zig-zag deltas of 15-bit u/v/height, triangles as high-water-mark indices
// (32-bit above 65,536 vertices), the four edge-index lists, then extensions, each an id byte, a
// little-endian uint32 length and its bytes. Tiles are geodetic (EPSG:4326 TMS): u runs from the
// tile's west edge (0) to its east edge (32767), v from south (0) to north (32767).
#include "tiler/formats/encode.hpp"
#include "tiler/mesh/tile_mesh.hpp"
#include "tiler/sources/tile_raster.hpp"
#include "tiler/tile_grid.hpp"

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace tb::tiler {

inline constexpr int kQuantizedMax = 32767;

// Extension ids as the format numbers them; each is also its bit in an extension mask.
enum QuantizedMeshExtension : unsigned {
    kOctVertexNormals = 1, // 2 bytes per vertex: oct-encoded unit normal in ECEF
    kWaterMask = 2,        // 1 byte (0 land, 255 water) or 256 x 256 bytes, north row first
    kMetadata = 4,         // uint32 length, then JSON: {"available": [...], ...}
};
inline constexpr unsigned kAllQuantizedMeshExtensions = kOctVertexNormals | kWaterMask | kMetadata;

// A mask from a comma-separated list of the names layer.json and CesiumJS use
// ("octvertexnormals", "watermask", "metadata"), or "all", or "none". InputError naming the
// unknown name and the known ones otherwise.
unsigned parse_terrain_extensions(std::string_view list);
// The names of a mask's extensions as a JSON array, in id order: ["watermask","metadata"].
std::string terrain_extensions_json(unsigned mask);

// A mesh on the tile's rectangle quantized as the format stores it: vertex i at
// u[i], v[i] in 0..32767 over the rectangle and height min_height + h[i] / 32767 * (max_height -
// min_height). Vertices exactly on the rectangle's border lines (x == west, ...) get 0 or 32767;
// every other vertex is kept strictly inside (1..32766), so the edge lists hold exactly the border
// vertices. An interior vertex that quantization moves takes the mesh's height at its new
// place (border vertices keep theirs). Vertices and triangles keep the mesh's order.
struct QuantizedMesh {
    LonLatBox bounds;
    float min_height = 0, max_height = 0;
    std::vector<std::uint16_t> u, v, h;
    std::vector<std::uint32_t> triangles;
    double lon(std::size_t i) const;
    double lat(std::size_t i) const;
    double height(std::size_t i) const; // as a client decodes it (in double precision)
};
QuantizedMesh quantize_mesh(const TileMesh& mesh, const LonLatBox& bounds);

// A surface over the tile's rectangle in the same u/v units (0..32767 west to east, south to
// north) at real positions: a quantized mesh as decoded, or a tile whose vertices moved off the
// 15-bit lattice (3D Tiles terrain's 16-bit ECEF positions, decoded back to lon/lat/height).
struct SurfaceMesh {
    LonLatBox bounds;
    std::vector<double> u, v, h; // h: ellipsoidal metres
    std::vector<std::uint32_t> triangles;
};
SurfaceMesh to_surface(const QuantizedMesh& q);

// The largest |drawn height - sample| over the valid samples of raster.grid and the check
// points, the drawn surface being the quantized triangles interpolated linearly in lon/lat (the
// chord sag of straight ECEF triangles comes on top). `uncovered`, when given, counts samples no
// quantized triangle holds (they are left out of the maximum).
// `cells` (tiler/mesh/cell_check.hpp) are judged too, their bound taken into the maximum.
double quantized_error(const QuantizedMesh& q,
                       const TileRaster& raster,
                       const std::vector<CheckPoint>& points,
                       std::size_t* uncovered = nullptr,
                       const std::vector<CheckCell>& cells = {});

// quantized_error of any surface mesh.
double surface_error(const SurfaceMesh& mesh,
                     const TileRaster& raster,
                     const std::vector<CheckPoint>& points,
                     std::size_t* uncovered = nullptr,
                     const std::vector<CheckCell>& cells = {});

// quantize_mesh, refined until the quantized surface is within `allowed` of every valid sample
// of raster.grid and every check point: each round splits every triangle whose worst sample is
// past `allowed` in three at that sample (a new vertex with the sample's height; samples on the
// tile's border lines or on a triangle's edge are not used, so the border lines keep their
// vertices and neighbouring tiles still share them; check points are measured but never made
// vertices), at most 8 rounds. `cells` add no vertex:
// their bound is measured on the final surface and taken into `error`. `mesh` gets the new
// vertices; `error` is the final largest |drawn - sample| (as quantized_error).
QuantizedMesh quantize_within(TileMesh& mesh,
                              const LonLatBox& bounds,
                              const TileRaster& raster,
                              const std::vector<CheckPoint>& points,
                              double allowed,
                              double& error,
                              std::size_t* uncovered = nullptr,
                              const std::vector<CheckCell>& cells = {});

struct QuantizedMeshExtras {
    std::vector<std::array<double, 3>> normals; // unit ECEF normal per mesh vertex; empty: none
    std::vector<std::uint8_t> water_mask;       // 1 or 256 * 256 bytes; empty: none
    std::string metadata;                       // JSON text; empty: none
};

// The vertices of q in order of first use by its triangles (then the unused ones): order[i] is
// vertex i's new index, old_of[k] the vertex at new index k.
struct VertexOrder {
    std::vector<std::uint32_t> order, old_of;
};
VertexOrder first_use_order(const QuantizedMesh& q);

// The new indices (of old_of) of the vertices on each side of the tile, west, south, east,
// north, each sorted along its side.
std::array<std::vector<std::uint32_t>, 4> edge_lists(const QuantizedMesh& q,
                                                     const std::vector<std::uint32_t>& old_of);

// The tile's bytes: vertices reordered by first use (as high-water-mark indexing needs), the
// header computed from the decoded positions (centre of their box, a sphere around them, the
// horizon occlusion point as CesiumJS's EllipsoidalOccluder computes it, on the ellipsoid
// shrunk by the minimum height when that is negative), extensions in id order. Requires at
// least one triangle.
std::string encode_quantized_mesh(const QuantizedMesh& q, const QuantizedMeshExtras& extras);

// The tile with only the extensions in `mask` (a tile from encode_quantized_mesh). Throws
// InputError if the bytes are not such a tile.
std::string select_extensions(std::string_view tile, unsigned mask);

// The horizon occlusion point, in the ellipsoid-scaled space of WGS84 (or of the WGS84 ellipsoid
// shrunk by -min_height when min_height < 0), of ECEF points seen along `direction`: the
// smallest multiple of the scaled direction from which every point is hidden behind the
// ellipsoid. Returns false when no such point exists (a point below the horizon plane).
bool horizon_occlusion_point(const std::array<double, 3>& direction,
                             const std::vector<std::array<double, 3>>& points,
                             double min_height,
                             std::array<double, 3>& out);

// horizon_occlusion_point along `centre`, or where none exists (a tile reaching beyond 90
// degrees of its centre's direction, at zoom 0) a point far out along it.
std::array<double, 3> tile_horizon_point(const std::array<double, 3>& centre,
                                         const std::vector<std::array<double, 3>>& points,
                                         double min_height);

// Two bytes: a unit vector oct-encoded as CesiumJS's AttributeCompression.octEncode (8 bits
// per component).
std::array<std::uint8_t, 2> oct_encode(const std::array<double, 3>& n);

} // namespace tb::tiler

namespace tb::tiler {

// What a layer's layer.json and its tiles' metadata extension say.
struct TerrainSpec {
    std::string name;
    int min_zoom = 0, max_zoom = 0; // the zooms meshed from the DEM; coarser ones are filler
    LonLatBox data_bounds;
    std::function<double(int)> eps_for_zoom;
    // The tiles of zoom z over the data that goes that deep (Layer::data_cover_at; geodetic);
    // without it, those over data_bounds in whole families.
    std::function<const TileCover&(int)> available_at;
};

// Levels of child availability each tile's metadata extension lists (layer.json's
// metadataAvailability).
inline constexpr int kMetadataLevels = 10;

// The tiles layer.json lists as available at zoom z (0..max_zoom): both root tiles at zoom 0,
// below it the tiles covering the data (zooms under min_zoom hold flat filler there; CesiumJS
// upsamples every tile not listed from its parent, so no other tile is ever asked for).
std::vector<TileRange> terrain_available(const TerrainSpec& spec, int z);
// Whether terrain_available(spec, id.z) holds tile id (geodetic), without listing the ranges.
bool terrain_lists(const TerrainSpec& spec, const TileId& id);

// layer.json for CesiumTerrainProvider: tiles "{z}/{x}/{y}.terrain" relative to it, every
// extension, the availability of every zoom, and where the meshed data begins.
std::string terrain_layer_json(const TerrainSpec& spec);

// A layer.json of terrain_layer_json listing only the extensions in `mask` (those its tiles
// hold), without metadataAvailability when the metadata extension is left out: CesiumJS asks
// for, and trusts, exactly what layer.json lists. InputError if `layer_json` has no extension
// list.
std::string layer_json_with_extensions(std::string_view layer_json, unsigned mask);

// The metadata extension's JSON of tile id: the available tiles under it for the next
// kMetadataLevels zooms (up to kMaxZoom; those past max_zoom hold none), and the error it
// publishes (null for filler).
std::string terrain_metadata(const TerrainSpec& spec, const TileId& id, double error, bool filler);

// A flat filler tile on the geoid (sea level): 16 x 16 cells over the rectangle.
TileMesh terrain_filler(const LonLatBox& bounds);

// Adds triangles covering the part of `bounds` outside the mesh's vertex extent (a tile at the
// edge of the source), from the mesh's outline to the rectangle's corners. A corner takes
// corner_height(lon, lat) (ellipsoidal metres), or lies on the geoid where that is NaN or
// not given. The mesh must cover its own extent (a rectangle).
void cover_rectangle(TileMesh& mesh,
                     const LonLatBox& bounds,
                     const std::function<double(double lon, double lat)>& corner_height = {});

// The water mask of a tile raster: 255 where the nearest sample is a void or at or below sea
// level (EGM96, within 1 cm), else 0; a single byte when the whole tile is one or the other.
std::vector<std::uint8_t> terrain_water_mask(const TileRaster& raster, const LonLatBox& bounds);

} // namespace tb::tiler
