#pragma once
// A layer: one or more DEMs published as one tile pyramid. This is what the `tile`, `build`
// and `serve` commands share: DEM -> tile raster -> mesh -> encoded bytes.
#include "tiler/format.hpp"
#include "tiler/tile_grid.hpp"

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tb::tiler {

enum class VerticalDatum {
    Auto,       // egm96 for SRTM/DTED-like sources (.hgt, .dt0-2), otherwise as the source says
    Egm96,      // source heights are EGM96 orthometric: add the geoid undulation
    Ellipsoid,  // source heights are already WGS84 ellipsoidal
};

struct LayerOptions {
    std::string name = "terrain";             // URL-safe: [A-Za-z0-9_-]+
    std::vector<std::string> sources;         // DEM paths or GDAL names (VRT, /vsicurl/, ...)
    Scheme scheme = Scheme::Geodetic;
    int tile_size = 256;                      // N: a tile raster has (N+1) x (N+1) samples
    std::optional<int> min_zoom, max_zoom;    // default: from the source's extent and resolution
    std::optional<double> finest_eps;         // metres at max_zoom; eps doubles per level up
    std::vector<double> eps_levels;           // extra eps (metres) selectable per request
    VerticalDatum datum = VerticalDatum::Auto;
};

// Where a tile request's eps comes from: the zoom's own ladder value, or one of the layer's
// configured eps_levels (by index).
struct EpsChoice {
    int level = -1;  // -1: the zoom's ladder eps; k >= 0: options().eps_levels[k]
};

class Layer {
public:
    virtual ~Layer() = default;

    // Opens the sources (throws InputError naming the file and problem). Thread-safe after.
    static std::shared_ptr<const Layer> open(const LayerOptions& options);

    virtual const LayerOptions& options() const = 0;
    virtual int min_zoom() const = 0;
    virtual int max_zoom() const = 0;
    virtual double eps_for_zoom(int z) const = 0;      // the ladder: finest * 2^(max_zoom - z)
    virtual LonLatBox data_bounds() const = 0;         // the sources' extent in lon/lat
    virtual TileRange tiles_at(int z) const = 0;       // tiles of zoom z that may hold data
    virtual bool may_have_tile(const TileId& id) const = 0;

    // The layer's tileset documents by relative path: "tileset.json" (3D Tiles 1.1; content URIs
    // are relative: "{z}/{x}/{y}.glb" next to it) and any external tileset or subtree it refers
    // to. Returns false when the path names no document.
    virtual bool document(const std::string& path, std::string& out) const = 0;

    // The encoded tile. Throws InputError for an id outside the scheme or an unknown eps level,
    // NotFound when the tile holds no data. Safe to call from many threads at once.
    virtual std::string make_tile(const TileId& id, Format format, EpsChoice eps = {}) const = 0;
};

}  // namespace tb::tiler
