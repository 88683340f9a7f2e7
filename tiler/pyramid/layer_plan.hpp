#pragma once
// A layer's pyramid plan: which zooms it offers, where each zoom's tiles read their heights, the
// eps ladder (raised to a share of each coarse zoom's reach), the error budgets a zoom's tiles are
// meshed at, the height range every tile stays within, and which tiles may hold data. Made once
// when a layer opens (tiler/layer.cpp); const and thread-safe after.
#include "tiler/formats/encode.hpp"
#include "tiler/layer.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/summary/dem_summary.hpp"
#include "tiler/summary/member_summaries.hpp"
#include "tiler/summary/pixel_place.hpp"
#include "tiler/tile_grid.hpp"

#include <mutex>
#include <optional>
#include <vector>

namespace tb::tiler {

// The smallest published eps, metres (check_eps).
inline constexpr double kMinEps = 0.001;

class LayerPlan {
public:
    // Plans the pyramid of `source` (georeferenced, with data) under `options` (validated).
    // Both must outlive the plan. Throws InputError when no zoom can be offered.
    LayerPlan(const LayerOptions& options, const DemSource& source);

    int min_zoom() const { return min_zoom_; }
    int max_zoom() const { return max_zoom_; }
    // The first zoom globe terrain is meshed from the data at (filler on the geoid above it).
    int terrain_min_zoom() const { return terrain_min_zoom_; }
    LonLatBox footprint() const { return footprint_; }
    // The tiles of zoom z (0..kMaxZoom) over the data that goes that deep
    // (DemSource::footprints_at: each file's footprint, or for a collection those of the files
    // that go that deep), in whole families (tiles_in_families). Zooms outside
    // min_zoom..max_zoom too: globe terrain lists its filler zooms by them.
    const TileCover& cover_at(int z) const;
    // The source's pixel grid in the scheme's CRS, if it has one (Layer::guarantee).
    const std::optional<PixelGrid>& pixels() const { return pixels_; }
    // Where the pixels of a single DEM or mosaic lie, whatever its CRS (what its summary is cut
    // along); null for a collection, whose members have their own.
    const PixelPlace* place() const { return place_ ? &*place_ : nullptr; }
    VerticalDatum datum() const { return datum_; }
    double min_height() const { return min_height_; }
    double max_height() const { return max_height_; }

    // Layer::eps_for_zoom, Layer::terrain_eps_for_zoom, Layer::zoom_source.
    double eps_for_zoom(int z) const;
    double terrain_eps_for_zoom(int z) const;
    ZoomSource zoom_source(int z) const;

    // Layer::tiles_at and Layer::may_have_tile. Tiles are of the layer's scheme (asserted).
    TileRange tiles_at(int z) const;
    std::int64_t tile_count_at(int z) const;
    bool may_have_tile(const ValidTile& tile) const;
    // Throws NotFound, naming the layer's zooms, for a tile with no data.
    void check_data(const ValidTile& tile) const;
    // Whether a globe terrain tile is meshed from the data (else filler on the geoid).
    bool terrain_has_data(const ValidTile& tile) const;
    // check_data for a globe terrain tile meshed from the data.
    void check_terrain_data(const ValidTile& tile) const;

    // The error budget of zoom z's tiles at eps: in source pixels for pixel tiles, in lattice
    // samples otherwise (the longest edge must be the same for every tile of a zoom).
    ErrorBudget budget_at(int z, double eps) const { return budget_with(z, eps, kSagShare); }
    // The same for globe terrain (quantized-mesh and 3D Tiles terrain), which keeps its own
    // share for sag (kTerrainSagShare).
    // Where eps is far above the DEM's relief (coarse zooms, whose eps follows CesiumJS's level
    // error), the mesher needs little of it: its share for sag grows up to kTerrainSagMost while
    // the mesher keeps the relief plus an eighth, and the longer edges that allows follow the
    // Earth's curve with fewer triangles (zoom 0 of N44W072: 14.7k triangles at a quarter).
    ErrorBudget terrain_budget_at(int z, double eps) const;
    ErrorBudget budget_with(int z, double eps, double sag_share) const;

    // Layer::zoom_signature.
    std::string zoom_signature(int z) const;

    // The largest vertical distance between the geoid and any height of the DEM.
    double relief() const;

    // The source's summary (not a collection's), made or loaded on first use (once, whichever
    // thread asks first; tiler/summary/layer_summary.hpp).
    const DemSummary& summary() const;
    // The summary level zoom z of `scheme` reads: blocks no wider than a lattice step, or the
    // finest for a zoom read from the summary whose step is narrower (zoom_source).
    int summary_level_at(Scheme scheme, int z, int size) const;
    // The lattice points (column0 + i, row0 + j) of (scheme, z, size) off the summary's planes at
    // the zoom's level (summary_lattice): what a Summary zoom's tiles are meshed from.
    LatticeBlock summary_sample(Scheme scheme,
                                int z,
                                int size,
                                std::int64_t column0,
                                std::int64_t row0,
                                int width,
                                int height) const;
    // A collection's members' summaries (what its ZoomSource::Summaries zooms read), or null.
    const MemberSummaries* members() const { return members_ ? &*members_ : nullptr; }
    // How zoom z's lattice is read beside its tiles (their normals): off the summary's planes at
    // a Summary zoom and the members' summaries at a Summaries zoom, the surface those tiles are
    // meshed from (a coarse tile reads no pixel of the DEM), else empty (DemSource::sample).
    LatticeSampler lattice_sampler(int z) const;

    // Loads or makes now what the first tiles would otherwise wait for: the summary and the
    // zooms' reach, and each member's summary.
    void prepare() const;

private:
    // Whether the tile lies in cover_at(its zoom).
    bool in_families(const ValidTile& tile) const;
    void plan_zooms();
    double tile_pixels(int z) const;
    void compute_height_range();
    const std::vector<double>& reach() const;

    const LayerOptions& options_;
    const DemSource& source_;
    std::optional<PixelGrid> pixels_;
    std::optional<PixelPlace> place_;
    bool summary_ok_ = false; // the source has a summary (not a collection)
    mutable std::once_flag summary_once_;
    mutable std::optional<DemSummary> summary_;
    std::optional<MemberSummaries> members_; // a collection's
    mutable std::once_flag reach_once_;
    mutable std::vector<double> reach_;
    LonLatBox footprint_;
    std::vector<TileCover> covers_; // cover_at, zooms 0..kMaxZoom
    VerticalDatum datum_ = VerticalDatum::Egm96;
    int min_zoom_ = 0, max_zoom_ = 0;
    int terrain_min_zoom_ = 0;
    double finest_eps_ = 1;
    double min_height_ = 0, max_height_ = 0;
};

} // namespace tb::tiler
