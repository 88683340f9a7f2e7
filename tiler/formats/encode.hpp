#pragma once
// Encoding a meshed tile: glTF 2.0 + KHR_draco_mesh_compression (.glb) and raw Draco (.drc),
// and the layer's 3D Tiles 1.1 tileset. Draco is included only in tiler/draco_*.cpp.
#include "core/mesh.hpp"
#include "tiler/formats/format.hpp"
#include "tiler/mesh/cell_check.hpp"
#include "tiler/mesh/tile_mesh.hpp"
#include "tiler/sources/tile_raster.hpp"

#include <array>
#include <functional>
#include <string>
#include <string_view>

namespace tb::tiler {

// How a tile's published eps is split between the mesher and Draco's quantization.
// The quantization lattice is fixed per eps (so per level): every tile of the level snaps
// vertices to the same lattice and a shared border vertex decodes identically in both tiles.
struct ErrorBudget {
    double eps = 0;         // published bound, metres: drawn tile vs every valid sample
    double quant_step = 0;  // lattice step of the Draco position quantization, metres
    double quant_error = 0; // worst vertical displacement quantization can cause, metres
    double sag = 0;         // share of eps reserved for the chord sag of straight ECEF triangles
    double max_edge_m = 0;  // longest ground edge, metres, whose sag stays within `sag`
    double mesh_eps = 0;    // eps handed to core::triangulate = eps - quant_error - sag (> 0)
    double max_edge = 0;    // max_edge_m in tile samples (tile_error_budget only; 0 otherwise)
    // The honest bound of what clients draw: eps, or more where even the shortest edges
    // allowed sag by more than 7/8 of eps (very coarse zooms; see tile_error_budget).
    double drawn_bound = 0;
};

// Chord sag. Clients draw straight triangles between ECEF vertices. Three points of a sphere of
// radius R span a plane cutting a cap; the plane lies below the sphere by at most
// R - sqrt(R^2 - r^2) ~ r^2 / (2R) where r is the triangle's circumradius (at the circumcentre
// when it is inside, i.e. acute: r = L / (2 sin C) <= L / sqrt(3) for the longest edge L, the
// angle C opposite it being >= 60 degrees, so <= L^2 / (6R)); for an obtuse triangle the depth
// over the triangle peaks on its longest edge, <= (L/2)^2 / (2R) = L^2 / (8R). So sag <= L^2/(6R)
// with R = b^2/a = 6335439 m, the smallest radius of curvature of WGS84 (vertices above the
// ellipsoid only flatten it). The mesher interpolates heights linearly in lon/lat (or
// mercator) grid space while the drawn triangle is linear in ECEF: the point of the drawn
// triangle above a sample is also shifted horizontally by up to ~L^2 tan(lat) / (8R) (the
// chart's metric varies across the triangle), which moves the surface by slope times that.
// kSagMargin = 2 covers that term for slope * tan(lat) <= 4/3 (slope 1 up to 53 degrees).
inline constexpr double kSagRadius = 6335439.0;
inline constexpr double kSagMargin = 2.0;
// The share of eps reserved for sag. A smaller share shortens the longest edge allowed (as the
// square root of the share) and leaves the mesher more of eps everywhere else. Measured on the
// SRTM cells of bench/ (tile_bench, build_bench; docs/performance.md, "The sag share"), a tenth
// against the quarter it replaced: 3-22 % fewer triangles and bytes per tile and up to 27 % less
// time on rough or mixed ground, and about the same (0.7 % more triangles) on flat ground at the
// finest zoom, where the shorter edges bind.
inline constexpr double kSagShare = 0.10;
// Globe terrain (quantized-mesh and 3D Tiles terrain) keeps a quarter: its 15-bit lattice moves
// every vertex across the slope by up to half a step (1.7 m on a zoom-8 tile), and on steep
// relief the fix-up rounds of quantize_within need the denser mesh a smaller mesh_eps gives
// (with a tenth, one z8 tile of N46E008.tif, in the Alps, ended 0.9 % over its eps).
inline constexpr double kTerrainSagShare = 0.25;

// Steepest mesh triangle (rise over run) for which quant_error is a proven bound. Snapping a
// vertex moves it by at most s*sqrt(3)/2 in any direction; at a fixed horizontal position the
// surface then moves by at most |dz| + |slope| * |dxy| <= (1 + slope) * s * sqrt(3)/2.
// Steeper triangles (cliffs) are not covered by this budget; encode_tile checks the snapped
// surface against every sample and snaps interior vertices finer where needed.
inline constexpr double kQuantMaxSlope = 3.0;

// s = the largest power of two with quant_error = (1 + kQuantMaxSlope) * s * sqrt(3)/2 <= eps/8;
// sag = eps * kSagShare and max_edge_m = sqrt(6 R sag / kSagMargin), so the mesher keeps at least
// 1 - 1/8 - kSagShare of eps (sag_share in place of kSagShare when given). Throws InputError
// unless eps is finite and > 0.
ErrorBudget error_budget(double eps, double sag_share = kSagShare);

// Ground metres per tile sample, an upper bound that is the same for every tile of zoom z
// (tile rasters of size + 1 samples per side): geodetic, the degree step times the largest
// meridian arc per degree (pi/180 * a^2/b; a parallel's arc per degree is never larger);
// mercator, the EPSG:3857 metre step (never less than the true ground step).
double sample_spacing_m(Scheme scheme, int z, int size);

// error_budget(eps) for the tiles of zoom z: max_edge = max_edge_m / sample_spacing_m, the same
// for neighbouring tiles, so their shared borders get identical vertices. Where that is below
// core::kMinMaxEdge samples (coarse zooms), max_edge is kMinMaxEdge and sag grows to its sag,
// taken from mesh_eps; where that would leave the mesher less than eps/8, mesh_eps stays eps/8
// and drawn_bound = quant_error + sag + mesh_eps > eps is what the tileset publishes.
ErrorBudget
tile_error_budget(double eps, Scheme scheme, int z, int size, double sag_share = kSagShare);

// The same rule for any grid: max_edge = max_edge_m / spacing_m samples (spacing_m: ground
// metres per sample step, an upper bound), at least min_edge samples (at least
// core::kMinMaxEdge), sag and mesh_eps following as above.
ErrorBudget
spacing_error_budget(double eps, double spacing_m, double min_edge, double sag_share = kSagShare);

// Encodes `mesh` (meshed from the samples of `raster` at budget.mesh_eps) as `format`.
// Positions are snapped to the budget's lattice in double precision (glb: ECEF axes, relative
// to a lattice-aligned tile centre carried by the root node translation; drc: ENU axes at a
// lattice-aligned origin) and handed to Draco with explicit quantization on that lattice, so
// Draco's float32 dequantization reproduces them exactly. Vertex and triangle counts are kept
// (no deduplication); triangles are wound counter-clockwise seen from above.
// On return the decoded tile is within budget.drawn_bound - budget.sag of every valid sample of
// raster.grid (heights interpolated linearly in the raster's grid coordinates, as the mesher
// measures them), checked here, so that with the chord sag the drawn tile is within
// budget.drawn_bound (eps): where the level lattice breaks that (a triangle steeper than
// kQuantMaxSlope), vertices off the border (mesh.border == 0) are snapped to s/2^k (k <= 6), of
// which s is a sublattice, so shared border vertices still decode identically in both tiles.
// A mesh without triangles (a tile whose data are all voids) encodes as an empty tile: a glb
// whose scene has no node, a drc of no point.
// Throws InputError when the tile is too large for the lattice (more than 2^23 steps across:
// raise eps or zoom in), tb::Error if Draco fails or a border cliff cannot be kept within eps.
// A measured point the drawn tile is also judged against, besides raster.grid: a source pixel
// centre in the raster's grid coordinates, with its height in ellipsoidal metres.
struct CheckPoint {
    double column = 0, row = 0;
    double height = 0;
};
// What encode_tile measured at the check points: the largest |snapped surface - height| (in
// lon/lat-linear interpolation; the chord sag comes on top, bounded by budget.sag), and how many
// points no triangle holds (they lie where the tile draws nothing).
struct EncodeReport {
    double points_error = 0;
    std::size_t points_outside = 0;
    // The bound the tile publishes (the .drc eps_m): budget.drawn_bound, or with check points
    // the larger points_error + budget.sag.
    double published = 0;
};
// Vertex normals, when given (`normals`: one unit ECEF vector per mesh vertex, in mesh order),
// go into the Draco mesh as a NORMAL attribute quantized octahedrally to kNormalBits, in the
// positions' axes: glb ECEF written y-up as (x, z, -y), drc the tile's ENU. Neither vertex
// order nor count changes, so normals stay aligned with their vertices; they move no position.
// The same input normal decodes to the same glb normal in every tile. Non-empty glbs carry one
// default material (matte, neutral terrain colour) referenced by the primitive, so clients
// shade them with their lights; without normals clients derive flat ones.
// 10 bits keep a decoded normal within about 0.25 degrees of the given one (shading cannot show
// that) for about 1.6 bytes per vertex (12 bits: 2.1 bytes; glb of N44W072.hgt, tile 9/308/382).
inline constexpr int kNormalBits = 10;
// Normals made on demand: encode_tile calls it (when no `normals` are given) once, on its second
// thread beside the check of the drawn surface when it has two.
using NormalsFn = std::function<std::vector<std::array<double, 3>>()>;
// `cells`: blocks of source pixels judged as wholes (tiler/mesh/cell_check.hpp), counted with
// the check points in the report (their bound in points_error, cells no triangle meets in
// points_outside).
// `threads` (>= 1) caps the threads encode_tile uses, the calling one included: with two, the
// Draco encoding runs beside the check of the drawn surface. The bytes are the same for any value.
std::string encode_tile(const TileRaster& raster,
                        const TileMesh& mesh,
                        Format format,
                        const ErrorBudget& budget,
                        const std::vector<CheckPoint>& points = {},
                        EncodeReport* report = nullptr,
                        const std::vector<std::array<double, 3>>* normals = nullptr,
                        int threads = 1,
                        const NormalsFn& make_normals = {},
                        const std::vector<CheckCell>& cells = {});
// The core mesh of raster's own lattice (every triangle kept), as to_tile_mesh gives it.
std::string encode_tile(const TileRaster& raster,
                        const core::Mesh& mesh,
                        Format format,
                        const ErrorBudget& budget);

// A binary glTF (.glb): the 12-byte header, the JSON chunk (padded with spaces) and, unless
// `bin` is empty, the BIN chunk (padded with zeros).
std::string glb_container(std::string json, std::string_view bin);

// What the tileset writer needs to know about a layer.
struct TilesetSpec {
    std::string layer;
    Scheme scheme = Scheme::Geodetic;
    int min_zoom = 0, max_zoom = 0;
    LonLatBox data_bounds;
    double min_height = 0, max_height = 0; // ellipsoidal metres over the whole layer
    std::function<double(int)> eps_for_zoom;
    std::function<bool(const ValidTile&)> has_tile; // exactly the tiles make_tile produces
    int tile_size = 256;                            // N: tile rasters are (N+1) x (N+1) samples
    // The budget of zoom z's tiles (quantization move and sag pad the regions); unset: the
    // lattice budget tile_error_budget(eps_for_zoom(z), scheme, z, tile_size).
    std::function<ErrorBudget(int)> budget_for_zoom;
    // A tile's geometricError; unset: the budget's drawn bound.
    std::function<double(const ValidTile&)> error_for_tile;
};

// The layer's documents, by path relative to the layer's URL root: "tileset.json" always,
// plus whatever else the chosen tileset layout needs (external tilesets or subtrees).
// Returns false when `path` names no document of this layer.
bool tileset_document(const TilesetSpec& spec, const std::string& path, std::string& out);

} // namespace tb::tiler
