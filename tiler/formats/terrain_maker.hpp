#pragma once
// A layer's globe terrain (quantized-mesh under layer.json, and 3D Tiles terrain under
// terrain/): each tile meshed from the DEM where the layer has data, with its voids drawn, and
// quantized within its zoom's bound, or flat filler on the geoid elsewhere; and the terrain
// documents. Used by tiler/layer.cpp; const and thread-safe after construction.
#include "tiler/formats/format.hpp"
#include "tiler/formats/quantized_mesh.hpp"
#include "tiler/formats/terrain_tiles.hpp"
#include "tiler/layer.hpp"
#include "tiler/mesh/pixel_tile.hpp"
#include "tiler/pyramid/layer_plan.hpp"
#include "tiler/sources/gdal_source.hpp"

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace tb::tiler {

// What a globe terrain tile's two formats (quantized-mesh and 3D Tiles terrain) share: the
// mesh, quantized, with its normals, or flat filler.
struct TerrainDraft {
    TerrainTile tile;     // without what only one format carries
    MeshedTile meshed;    // what it was made from (empty for filler)
    double quantized = 0; // the quantized mesh's largest error at the samples, metres
};

class TerrainMaker {
public:
    // A tile's globe terrain mesh at eps: drawn over its voids too, at the terrain's budget
    // (the layer's mesh_at; the raster's valid mask kept).
    using MeshFn = std::function<MeshedTile(const ValidTile& tile, double eps)>;
    // Called once for each tile encoded above its zoom's bound (Layer::tiles_over_eps).
    using OverEpsFn = std::function<void()>;

    // All but the functions must outlive the maker.
    TerrainMaker(const LayerOptions& options,
                 const LayerPlan& plan,
                 const DemSource& source,
                 MeshFn mesh,
                 OverEpsFn note_over_eps);

    // What layer.json and every tile's metadata describe.
    TerrainSpec terrain_spec() const;
    // What the terrain tileset publishes (terrain/tileset.json and its subtrees).
    TerrainTilesetSpec tileset_spec() const;
    // 3D Tiles terrain documents under terrain/ (`path` without it): "tileset.json" and the
    // subtrees "{root}/{level}/{x}/{y}.subtree". False when the path names no document.
    bool document(const std::string& path, std::string& out) const;

    // A globe terrain tile's content (tiler/formats/terrain_tiles.hpp): meshed from the DEM
    // where the layer has data, flat filler on the geoid elsewhere at zooms up to max_zoom
    // (CesiumJS never asks for a tile whose parent is missing). The tile is of the layer's
    // scheme (asserted); InputError when that is not the geodetic one, NotFound beyond max zoom.
    TerrainDraft draft(const ValidTile& tile) const;
    // The draft encoded as `format` (terrain or terrain3d), with what only that format carries,
    // set on the draft itself: the water mask and metadata only quantized-mesh encodes, the
    // positions and bound only the glb does, so one draft serves both formats in either order.
    // The 3D Tiles glb's surface is measured at every sample: where its 16-bit positions would
    // take it past the bound, it carries float32 positions instead.
    std::string encode(TerrainDraft& draft, const ValidTile& tile, Format format) const;

private:
    TerrainDraft data_terrain(const ValidTile& tile, const LonLatBox& bounds) const;
    // The bound a filler tile (on the geoid) publishes: the relief over the data, 0 where the
    // tile holds no source pixel.
    double filler_error(const ValidTile& tile) const;
    std::vector<std::array<double, 3>> normals(const MeshedTile& t, const ValidTile& tile) const;
    // The heights of a pixel tile's corners beyond the DEM (cover_rectangle): the zoom's
    // lattice carried outward from the data's edge, as lattice tiles carry it.
    std::function<double(double, double)> carried_corners(const ValidTile& tile) const;

    const LayerOptions& options_;
    const LayerPlan& plan_;
    const DemSource& source_;
    MeshFn mesh_;
    OverEpsFn note_over_eps_;
};

// A pixel tile made ready to mesh its voids as data (see the layer's mesh_at): the voids of the
// block's outer rows and columns that lie on the tile's border lines (pixel centres on the
// line, which the tile beside has too), and of the border lines between pixels, filled along
// the line; the other voids keep their filled heights (those depend on the window read, which
// differs between tiles, but no other tile has them). Returns the block's valid mask.
std::vector<std::uint8_t> fill_for_terrain(PixelTile& pixel);

} // namespace tb::tiler
