#pragma once
// The summaries of a collection's members (collection_source.hpp), one per member, whatever its
// CRS (pixel_place.hpp): what a collection's coarse tiles read, so that
// they cost about their own number of samples whatever the size of the DEMs under them, as one
// DEM's coarse tiles do (summary_tile.hpp).
//
// A coarse tile of a collection meshes the collection's lattice, each point taken from the first
// member with a valid sample there (members with a summary at the zoom read it off their
// blocks' planes, the others sample their pixels), and is judged against the blocks of every
// member read from its summary and the pixels of every other member under the tile. That is a
// superset of the winning pixels (a lower member's blocks and pixels are judged where a higher
// member wins too), so the bound it publishes holds at every winning pixel; it is larger than
// the winners alone would give only where members disagree by more than the zoom's eps.
#include "tiler/layer.hpp"
#include "tiler/mesh/cell_check.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/summary/dem_summary.hpp"
#include "tiler/summary/pixel_place.hpp"

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

namespace tb::tiler {

class MemberSummaries {
public:
    // The members of `collection` (DemSource::members(), at least two) under `options` (the
    // layer's scheme and tile size, summary_dir, nodata), heights to `datum` (resolved). Both
    // must outlive it. Summaries are loaded or made on first use, each once.
    MemberSummaries(const LayerOptions& options, const DemSource& collection, VerticalDatum datum);

    // Whether member m's tiles of zoom z read its summary (a lattice step spans at least a finest
    // block), and whether any member's do.
    bool reads_summary(std::size_t m, int z) const;
    bool reads_summaries(int z) const;
    // Source pixels one tile of zoom z reads at most from the members that do not read their
    // summary (DemSource::tile_pixels).
    double tile_pixels(int z) const;

    // DemSource::sample of the collection, each member read off its summary where its pixels per
    // sample of (scheme, z, size) reach a finest block: at each point the first member with a
    // valid sample wins.
    LatticeBlock sample(Scheme scheme,
                        int z,
                        int size,
                        std::int64_t column0,
                        std::int64_t row0,
                        int width,
                        int height) const;

    // The blocks under the tile of `raster` (a lattice raster of zoom z in the layer's scheme) of
    // each member that reads its summary at z, as CheckCells (summary_cells).
    std::vector<CheckCell> cells(const TileRaster& raster, int z) const;
    // Every valid pixel in `box` of each member that does not read its summary at z, as
    // DemSource::pixels_in gives them; window_pixels: at most how many.
    void pixels_in(const LonLatBox& box, int z, const DemSource::PixelVisitor& visit) const;
    std::size_t window_pixels(const LonLatBox& box, int z) const;

    // Loads or makes now the summary of every member that a zoom of z0..z1 reads.
    void prepare(int z0, int z1) const;

    // zoom_reach of the collection at zoom z (of the layer's scheme and tile size): each tile's
    // roughest block among the summaries of the members that zoom `coarsest` reads (the layer's
    // coarsest zoom: those a served zoom makes), the median over those tiles
    // (summary_tile.hpp). A lower member's blocks count where a higher one wins too, as the
    // tiles are judged against them.
    double zoom_reach(int z, int coarsest) const;

private:
    struct Member {
        std::shared_ptr<const DemSource> source;
        std::optional<PixelPlace> place; // where its pixels lie (set once `source` is)
        mutable std::once_flag once;     // the summary, made on first use
        mutable std::optional<DemSummary> summary;
    };
    const DemSummary& summary(const Member& m) const;
    // The summary level member m reads at (scheme, z, size), or -1: its pixels.
    int level(const Member& m, Scheme scheme, int z, int size) const;

    const LayerOptions& options_;
    VerticalDatum datum_;
    std::vector<std::unique_ptr<Member>> members_; // ranked, as the collection's
};

} // namespace tb::tiler
