#pragma once
// Encoding a meshed tile: glTF 2.0 + KHR_draco_mesh_compression (.glb) and raw Draco (.drc),
// and the layer's 3D Tiles 1.1 tileset. Draco is included only in tiler/draco_*.cpp.
#include "core/mesh.hpp"
#include "tiler/format.hpp"
#include "tiler/tile_raster.hpp"

#include <functional>
#include <string>

namespace tb::tiler {

// How a tile's published eps is split between the mesher and Draco's quantization.
// The quantization lattice is fixed per eps (so per level): every tile of the level snaps
// vertices to the same lattice and a shared border vertex decodes identically in both tiles.
struct ErrorBudget {
    double eps = 0;         // published bound, metres: decoded mesh vs every valid sample
    double quant_step = 0;  // lattice step of the Draco position quantization, metres
    double quant_error = 0; // worst vertical displacement quantization can cause, metres
    double mesh_eps = 0;    // eps handed to core::triangulate = eps - quant_error (> 0)
};

// Steepest mesh triangle (rise over run) for which quant_error is a proven bound. Snapping a
// vertex moves it by at most s*sqrt(3)/2 in any direction; at a fixed horizontal position the
// surface then moves by at most |dz| + |slope| * |dxy| <= (1 + slope) * s * sqrt(3)/2.
// Steeper triangles (cliffs) are not covered by this budget; encode_tile checks the snapped
// surface against every sample and snaps interior vertices finer where needed.
inline constexpr double kQuantMaxSlope = 3.0;

// s = the largest power of two with quant_error = (1 + kQuantMaxSlope) * s * sqrt(3)/2 <= eps/8,
// so the mesher keeps at least 7/8 of eps. Throws InputError unless eps is finite and > 0.
ErrorBudget error_budget(double eps);

// Encodes `mesh` (meshed from `raster` at budget.mesh_eps) as `format`.
// Positions are snapped to the budget's lattice in double precision (glb: ECEF axes, relative
// to a lattice-aligned tile centre carried by the root node translation; drc: ENU axes at a
// lattice-aligned origin) and handed to Draco with explicit quantization on that lattice, so
// Draco's float32 dequantization reproduces them exactly. Vertex and triangle counts are kept
// (no deduplication); triangles are wound counter-clockwise seen from above.
// On return the decoded tile is within budget.eps of every valid sample of raster.grid
// (heights interpolated linearly in tile grid coordinates, as the mesher measures them),
// checked here: where the level lattice breaks that (a triangle steeper than kQuantMaxSlope),
// interior vertices are snapped to s/2^k (k <= 6), of which s is a sublattice, so shared
// border vertices still decode identically in both tiles.
// Throws InputError when the tile is too large for the lattice (more than 2^23 steps across:
// raise eps or zoom in), tb::Error if Draco fails or a border cliff cannot be kept within eps.
std::string encode_tile(const TileRaster& raster,
                        const core::Mesh& mesh,
                        Format format,
                        const ErrorBudget& budget);

// What the tileset writer needs to know about a layer.
struct TilesetSpec {
    std::string layer;
    Scheme scheme = Scheme::Geodetic;
    int min_zoom = 0, max_zoom = 0;
    LonLatBox data_bounds;
    double min_height = 0, max_height = 0; // ellipsoidal metres over the whole layer
    std::function<double(int)> eps_for_zoom;
    std::function<bool(const TileId&)> has_tile; // exactly the tiles that make_tile produces
};

// The layer's documents, by path relative to the layer's URL root: "tileset.json" always,
// plus whatever else the chosen tileset layout needs (external tilesets or subtrees).
// Returns false when `path` names no document of this layer.
bool tileset_document(const TilesetSpec& spec, const std::string& path, std::string& out);

} // namespace tb::tiler
