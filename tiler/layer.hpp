#pragma once
// A layer: one or more DEMs published as one tile pyramid. This is what the `tile`, `build`
// and `serve` commands share: DEM -> tile raster -> mesh -> encoded bytes.
#include "core/error.hpp"
#include "core/mesh.hpp"
#include "core/triangulate.hpp"
#include "tiler/formats/encode.hpp"
#include "tiler/formats/format.hpp"
#include "tiler/mesh/mesh_text.hpp"
#include "tiler/mesh/tile_mesh.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/tile_raster.hpp"
#include "tiler/stores/atomic_file.hpp"
#include "tiler/tile_grid.hpp"

#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tb::tiler {
class DemSource;
}

namespace tb::tiler {

enum class VerticalDatum {
    Auto,      // egm96, unless the source CRS states WGS84 ellipsoidal heights (EPSG:4979-like)
    Egm96,     // source heights are EGM96 orthometric: add the geoid undulation
    Ellipsoid, // source heights are already WGS84 ellipsoidal
};

// The heights of the layer's raster DEM tiles (tiler/dem_tiles.hpp).
enum class DemHeights {
    SeaLevel,  // above sea level (EGM96), as web maps expect: the source's own heights for an
               // EGM96 source (no geoid applied); an ellipsoidal source has the geoid removed
    Ellipsoid, // above the WGS84 ellipsoid, as the mesh tiles
};

struct LayerOptions {
    std::string name = "terrain";     // URL-safe: [A-Za-z0-9_-]+
    std::vector<std::string> sources; // DEM paths or GDAL names (VRT, /vsicurl/, ...)
    Scheme scheme = Scheme::Geodetic;
    int tile_size = 256;                   // N: a tile raster has (N+1) x (N+1) samples
    std::optional<int> min_zoom, max_zoom; // default: from the source's extent and resolution
    std::optional<double> finest_eps;      // metres at max_zoom; eps doubles per level up
    std::vector<double> eps_levels;        // extra eps (metres) selectable per request
    VerticalDatum datum = VerticalDatum::Auto;
    int dem_tile_size = 512; // raster DEM tiles: pixels per side, 256 or 512
    DemHeights dem_heights = DemHeights::SeaLevel;
    std::optional<double> nodata; // raw nodata value replacing the sources' own (--nodata)
    // Threads meshing one tile (its two strips): 2 for a server's cold tiles, 1 where tiles are
    // made side by side (build workers). The bytes are the same for any value.
    int mesh_threads = 2;
    // How hard the mesher works for fewer triangles (core::Effort): fast, balanced or best.
    // Every level keeps the same bound; a changed level is a new tile set (store manifests
    // record it). Balanced: 3-11 % more triangles than best for 80-85 % of its work
    // (bench/README.md, "Effort levels").
    core::Effort effort = core::Effort::Balanced;
    // Where the DEM's multi-resolution summary is kept between runs (summary_file.hpp): a
    // directory, "off", or empty for the default ($XDG_CACHE_HOME or ~/.cache, /terrabound) for
    // sources of 16 Mpixel and more.
    std::string summary_dir;
    // Heights outside it are outliers, counted as nodata (--valid-range; sources/gdal_source.hpp).
    ValidRange valid_range;
    // Which DEM wins where several overlap (--priority; sources/gdal_source.hpp).
    SourcePriority priority = SourcePriority::Finest;
};

// How a layer makes its published error true at every valid pixel of the source.
enum class Guarantee {
    // The source's pixels lie on the scheme's grid: tiles are meshed on the source's own pixel
    // centres at full resolution (tiler/mesh/pixel_tile.hpp), so the bound holds by construction.
    SourcePixels,
    // Any other CRS: tiles are meshed on the zoom's lattice, and every valid source pixel centre
    // under a tile, reprojected, is checked against the drawn tile; the tile publishes the larger
    // of its eps and what was measured.
    Measured,
};
const char* to_string(Guarantee guarantee);

// A tile as meshed, before encoding.
struct MeshedTile {
    TileRaster raster; // the samples the mesher bounds: the source's pixels, or the lattice
    TileMesh mesh;
    ErrorBudget budget;
    // Measured layers: every valid source pixel centre in the tile, in raster's grid
    // coordinates, ellipsoidal heights (encode_tile checks the drawn tile against them).
    std::vector<CheckPoint> source_pixels;
    // Tiles read from the DEM's summary: its blocks under the tile, judged as wholes.
    std::vector<CheckCell> cells;
};

// Where the tiles of one zoom read their heights (Layer::zoom_source).
enum class ZoomSource {
    Pixels,  // the source's own pixels, meshed at full resolution (tiler/mesh/pixel_tile.hpp)
    Lattice, // the zoom's lattice sampled from the source, every pixel under the tile checked
    Summary, // the zoom's lattice read off the summary, its blocks checked (tiler/summary/)
    // A collection's: its members' summaries where they serve the zoom, their blocks checked,
    // and the other members sampled, every pixel of theirs checked (member_summaries.hpp)
    Summaries,
};
const char* to_string(ZoomSource source);

// Where a tile request's eps comes from: the zoom's own ladder value, or one of the layer's
// configured eps_levels (by index).
struct EpsChoice {
    int level = -1; // -1: the zoom's ladder eps; k >= 0: options().eps_levels[k]
};

// Asked at a tile's checkpoints (before reading its raster, before meshing, before encoding):
// true stops the tile there with Cancelled. A server passes it so that a tile nobody waits for
// any more stops using a core; an empty one never stops.
using CancelFn = std::function<bool()>;

// A tile stopped at a checkpoint because its CancelFn said so: nothing was made, and nothing
// is wrong with the tile (not an InputError, NotFound nor IoError).
struct Cancelled : Error {
    using Error::Error;
};
// A checkpoint: throws Cancelled ("<kind> <tile> cancelled before <before>") when `cancelled`
// says stop; an empty one never does.
void throw_if_cancelled(const CancelFn& cancelled,
                        const char* kind,
                        const TileId& id,
                        const char* before);

class Layer {
public:
    virtual ~Layer() = default;

    // Opens the sources (throws InputError naming the file and problem). Thread-safe after.
    static std::shared_ptr<const Layer> open(const LayerOptions& options);

    virtual const LayerOptions& options() const = 0;
    // Loads or makes now what tiles read on first use (the multi-resolution summaries, each
    // zoom's reach), so that no request waits for them: serve calls it before serving a layer.
    virtual void prepare() const = 0;
    virtual int min_zoom() const = 0;
    virtual int max_zoom() const = 0;
    virtual double eps_for_zoom(int z) const = 0; // the ladder: finest * 2^(max_zoom - z)
    // The eps globe terrain (quantized-mesh, 3D Tiles terrain) is meshed at: the ladder, or a
    // share of CesiumJS's own level error where that is larger.
    virtual double terrain_eps_for_zoom(int z) const = 0;
    virtual LonLatBox data_bounds() const = 0; // the sources' extent in lon/lat
    // The tiles of zoom z (0..kMaxZoom, whatever the layer's zooms) over the data that goes
    // that deep, in whole families: over each DEM file's footprint, not the box around them
    // (LayerPlan::cover_at).
    virtual const TileCover& data_cover_at(int z) const = 0;
    virtual TileRange tiles_at(int z) const = 0; // tiles of zoom z that may hold data
    // How many tiles of zoom z may hold data (may_have_tile): tiles_at(z)'s, or fewer for a
    // collection whose groups lie apart.
    virtual std::int64_t tile_count_at(int z) const = 0;
    // Whether a tile of the layer's scheme lies in tiles_at of its zoom.
    virtual bool may_have_tile(const ValidTile& tile) const = 0;
    // The id as a tile of the layer's scheme (ValidTile::parse: InputError outside it).
    ValidTile tile(const TileId& id) const { return ValidTile::parse(options().scheme, id); }

    // The layer's tileset documents by relative path: "tileset.json" (3D Tiles 1.1; content URIs
    // are relative: "{z}/{x}/{y}.glb" next to it) and any external tileset or subtree it refers
    // to. Returns false when the path names no document.
    virtual bool document(const std::string& path, std::string& out) const = 0;

    // Every function below that takes a ValidTile takes one of the layer's scheme (asserted):
    // a tile of another scheme is the caller's bug, not the request's.

    // The encoded tile. Throws InputError for an unknown eps level, NotFound when the tile
    // holds no data, Cancelled when `cancelled` returns true at one of its checkpoints. Safe to
    // call from many threads at once.
    virtual std::string make_tile(const ValidTile& tile,
                                  Format format,
                                  EpsChoice eps = {},
                                  const CancelFn& cancelled = {}) const = 0;
    // The tile in each of `formats` (mesh and terrain formats, at the zoom's eps), in that
    // order: for each, the bytes make_tile(id, format) gives, with each mesh made once (glb and
    // drc share one, terrain and terrain3d another). A format make_tile would answer NotFound
    // for is left out. InputError for a DEM format.
    virtual std::vector<std::pair<Format, std::string>>
    make_tiles(const ValidTile& tile, std::span<const Format> formats) const = 0;

    // ---- the stages of make_tile, for the `tile` command, tests and benchmarks ----

    // The tile raster a tile is meshed from: (N+1) x (N+1) ellipsoidal heights, voids filled
    // (see fill_voids in tiler/gdal_source.hpp; a tile with no data near it lies at 0 m
    // orthometric, i.e. on the geoid). Same errors as make_tile.
    virtual TileRaster make_raster(const ValidTile& tile) const = 0;
    // The raster globe terrain is meshed from at a zoom meshed off the lattice: make_raster's,
    // with the data's edge carried outward past the footprint (lattice_tile_raster).
    virtual TileRaster make_terrain_raster(const ValidTile& tile) const = 0;
    // The encoded tile at an explicit published eps (metres, >= 0.001): raster, then
    // core::triangulate at error_budget(eps).mesh_eps with locked borders, then encode_tile with
    // the vertex normals of the DEM's slope (those of the terrain tiles' octvertexnormals).
    virtual std::string make_tile_at(const ValidTile& tile, Format format, double eps) const = 0;
    // The mesh make_tile_at encodes, with its samples and budget. Same errors as make_tile.
    virtual MeshedTile mesh_tile_at(const ValidTile& tile, double eps) const = 0;

    virtual Guarantee guarantee() const = 0;
    // What zoom z's tiles read: Pixels at the zooms whose lattice is as fine as a pixel-grid
    // source's pixels, Summary where a lattice step spans a summary block or more, Lattice in
    // between and for every zoom of a source in another CRS.
    virtual ZoomSource zoom_source(int z) const = 0;
    // The error a tile publishes at its zoom's eps (its tileset geometricError and .drc eps_m):
    // the budget's drawn bound, or for Measured layers the larger measured bound of that tile
    // (meshed here once if it was not made yet). Throws like make_tile.
    virtual double tile_error(const ValidTile& tile) const = 0;
    // Tiles made so far whose measured error exceeded their zoom's eps: Measured layers' tiles,
    // and globe terrain tiles whose quantization left them above it (once per format made).
    virtual std::size_t tiles_over_eps() const = 0;

    // What decides every tile of zoom z beyond the data under it and the pixel grids' origins,
    // as one line of JSON: where the zoom reads its heights, its eps and the budgets its mesh
    // and globe terrain tiles are made to. `build --update` remakes a
    // whole zoom whose line changed (tiler/pyramid/update.hpp).
    virtual std::string zoom_signature(int z) const = 0;

    // Ellipsoidal height range every tile's mesh stays within (padded by 1 m), metres.
    virtual double min_height() const = 0;
    virtual double max_height() const = 0;
    // The datum the source heights are taken in (Auto resolved: Egm96 unless the source's CRS
    // states WGS84 ellipsoidal heights).
    virtual VerticalDatum source_datum() const = 0;
    // The DEM (or mosaic) the layer reads, e.g. for what each zoom reads (read_level).
    virtual const DemSource& source() const = 0;
    // Samples of the DEM at the lattice points of (scheme, z, size), as DemSource::sample gives
    // them; where a lattice step spans a block of the source's summary or more (a source on a
    // pixel grid), the planes of the summary's blocks there instead, so a coarse zoom reads
    // about its own number of samples (tiler/summary/summary_tile.hpp). Thread-safe.
    virtual LatticeBlock sample(Scheme scheme,
                                int z,
                                int size,
                                std::int64_t column0,
                                std::int64_t row0,
                                int width,
                                int height) const = 0;
};

// Checks a published eps (metres) and throws InputError naming `what` unless it is finite and
// at least 0.001 m (below that, float32 heights cannot honour it).
void check_eps(double eps, const std::string& what);

// The tile mesh exactly as encoded: core::triangulate_strips(raster.grid, ..., 2) at
// budget.mesh_eps with locked borders and budget.max_edge (see tile_error_budget): two strips
// meshed on up to `threads` threads, stitched along a locked middle column. Without
// `check_error` core does not measure the mesh's error at every sample (the caller's encoder
// measures the drawn tile's; see core::TriangulateOptions::check_error).
core::Mesh mesh_tile(const TileRaster& raster,
                     const ErrorBudget& budget,
                     int threads = 2,
                     bool check_error = true,
                     core::Effort effort = core::Effort::Balanced);

VerticalDatum parse_datum(const std::string& name); // "auto" | "egm96" | "ellipsoid"
const char* to_string(VerticalDatum datum);

} // namespace tb::tiler
