#pragma once
// `build --update`: which tiles a change of a build's DEMs touches, so that an update remakes
// those alone and leaves the store as a full rebuild with the same DEMs would.
//
// A build manifest (tiler/pyramid/build.hpp) records, beside the tile settings, what an update
// compares: each DEM's lon/lat bounds ("source_bounds"), each zoom's signature
// (Layer::zoom_signature: "zooms"), the pixel grids' origins ("grid_origins") and the tile ranges
// the build planned
// ("mesh_ranges", "dem_ranges"). From the last build's manifest and this run's:
//   - every tile, when a setting every tile depends on changed (the Terrabound version, scheme,
//     tile size, effort, datum, nodata, the order of the DEMs, a grid's origin, the finest level
//     of a grid's summary, ...);
//   - every tile of a zoom whose signature changed (its eps, its budget), or that only one of
//     the two builds has;
//   - the tiles meeting a DEM added, removed or replaced (its old bounds and its new ones), or
//     the part of a pixel grid (a mosaic) that grew or shrank with it, widened by what a tile
//     reads around itself (void filling's margin, the borders it shares with its neighbours):
//     its neighbours' data decide its bytes too;
//   - the tiles that entered or left a zoom's planned range;
//   - and every ancestor of all those (a parent lists which children exist, and its error
//     covers theirs).
#include "tiler/layer.hpp"
#include "tiler/stores/manifest.hpp"
#include "tiler/tile_grid.hpp"

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace tb::tiler {

// Build manifest entries: each DEM's lon/lat bounds ([w, s, e, n], or null where GDAL gives
// none), in the order of `sources`; the tile ranges of one pyramid ([z, x0, y0, x1, y1] per
// zoom); the signatures of zooms from..to (Layer::zoom_signature); the raster DEM pyramid's
// zoom signatures (what its zoom's reads depend on beyond the data).
std::string source_bounds_entry(const std::vector<std::string>& sources);
// The pixel grids the layer reads (a file, or a mosaic of files on one grid): pixel size and
// lon/lat extent of each.
std::string source_grids_entry(const Layer& layer);
// A lon/lat box as [w, s, e, n]: the layer's data bounds, to which raster DEM tiles carry the
// data's edge (a change of them changes the tiles along both the old and the new edge).
std::string box_entry(const LonLatBox& box);
std::string ranges_entry(const std::vector<TileRange>& ranges);
std::string zooms_entry(const Layer& layer, int from, int to);
// The origin and pixel size of each pixel grid the layer reads ([x0, y0, dx, dy] each). Every
// read, of mesh and raster DEM tiles alike, is placed from a grid's origin: summary blocks and
// decimated reads are cut from it, and a lattice point's or a vertex's place among the pixels
// is a difference from it, whose last bits (so a bilinear height's or a normal's) move with
// it. The origin moves when a mosaic grows north or west; an update then remakes every tile
// (the entry is not compared piece by piece).
std::string grid_origins_entry(const Layer& layer);
// The finest level of each pixel grid's summary (summary_finest_level): it rises a level as a
// grid grows past about 537 Mpixel, and then every block of the summary changes, so every tile
// read from it. Not compared piece by piece either.
std::string summary_levels_entry(const Layer& layer);

struct UpdateScope {
    std::string everything;           // why every tile is remade; empty when only some are
    std::vector<std::string> changes; // "added PATH", "replaced PATH", "removed PATH"
    std::vector<LonLatBox> boxes;     // the old and the new bounds of every changed DEM
    std::vector<int> zooms;           // mesh and terrain zooms remade whole
    std::vector<std::string> why;     // why zooms are remade whole, for the log
};

// Compares the manifest of the last build (`was`) with this run's (`now`). InputError when
// `was` lacks what an update compares (a build made before `--update` existed).
UpdateScope update_scope(const Manifest& was, const Manifest& now);

// The tiles of one pyramid an update remakes, or removes where the new build has none: the
// scope's tiles within the ranges of either build.
class UpdateTiles {
public:
    // `was` and `now`: the two builds' ranges of this pyramid (ranges_entry), `zooms` the
    // scope's whole zooms of it, `around` how far a tile reads beyond its edges, in tiles.
    UpdateTiles(const UpdateScope& scope,
                Scheme scheme,
                const std::vector<TileRange>& was,
                const std::vector<TileRange>& now,
                const std::vector<int>& zooms,
                double around);

    bool contains(const TileId& id) const;
    // How many tiles this update touches that the new build's ranges leave out: they are
    // removed.
    std::int64_t left_out_count() const;
    // Calls fn with each of those, once, in zoom, row, column order.
    void for_each_left_out(const std::function<void(const TileId&)>& fn) const;
    // How many tiles this update touches within the new build's ranges.
    std::int64_t remade() const;

private:
    // Zoom z's touched rectangles less the new build's range there (overlapping pieces).
    std::vector<TileRange> left_out_at(int z) const;

    std::map<int, std::vector<TileRange>> touched_; // per zoom, overlapping rectangles
    std::map<int, TileRange> was_, now_;
};

// The ranges a manifest entry written by ranges_entry lists (InputError when it does not parse).
std::vector<TileRange> parse_ranges(const std::string& entry, const std::string& what);

} // namespace tb::tiler
