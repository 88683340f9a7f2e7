// A layer's pyramid plan (layer_plan.hpp): zoom range, eps ladder and reach, height range,
// error budgets, and which tiles may hold data.
#include "tiler/pyramid/layer_plan.hpp"

#include "core/error.hpp"
#include "tiler/formats/terrain_tiles.hpp"
#include "tiler/json_number.hpp"
#include "tiler/log.hpp"
#include "tiler/mesh/pixel_tile.hpp"
#include "tiler/sources/geoid.hpp"
#include "tiler/summary/layer_summary.hpp"
#include "tiler/summary/summary_tile.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

namespace tb::tiler {
namespace {

// The default eps ladder follows the lattice, not the data: eps(z) = e0 / 2^z, e0 the ground
// size of a zoom-0 lattice step at the data's middle latitude (the geometric mean of its sides
// east and north, as a DEM's resolution_m measures a pixel) over kStepPerEps, on a step of
// on_step. So a DEM finer than all before (a survey over SRTM) deepens the pyramid without
// moving any zoom's eps, and build --update remakes only the tiles over it.
// kStepPerEps = 45 * 2^18 / (180 * 1200): in the geodetic scheme with tiles of 2^k samples, the
// lattice step at SRTM 3"'s own zoom is 216000/262144 of its pixel, so DEMs of 3"/2^k keep the eps
// they had when it was their resolution / 45: 2 m for SRTM 3" (~90 m) at its zoom. That is a third
// of SRTM's relative vertical accuracy (about 6 m, 90% linear error) and four times its 1 m integer
// quantization, so the mesh error stays well below the data's own noise while the meshes stay
// small; it is also far below CesiumJS's level geometric error (77067 m / 2^z, about 75 m at SRTM
// 3"'s z = 10). Other resolutions, tile sizes and the mercator scheme get 0.61-1.21 times their
// resolution / 45 at their finest zoom (SRTM 1": 0.75), whose lattice step lies between half a
// pixel and a pixel.
constexpr double kStepPerEps = 45.0 * 216000.0 / 262144.0;

// Ground metres of one lattice step of zoom z at latitude `lat` (degrees), the geometric mean
// of its east and north sides.
double lattice_step_m(Scheme scheme, int z, int size, double lat) {
    constexpr double kPi = 3.14159265358979323846;
    const double step = lattice_x(scheme, z, size, 1) - lattice_x(scheme, z, size, 0);
    const double c = std::cos(lat * kPi / 180);
    return scheme == Scheme::Geodetic ? step * 6378137.0 * kPi / 180 * std::sqrt(c) : step * c;
}

// Data-driven eps (the default finest eps, a zoom's reach share) is rounded to the nearest step
// of 2^(1/kStepsPerOctave), within 4.4 % of the statistic either way: the statistics behind it
// move a little whenever the DEMs change (the resolution in metres with the extent's middle
// latitude, a zoom's median roughness with every tile), and every tile of a zoom whose eps
// moved must be made again (build --update). On steps they rarely move. Rounded to the nearest
// rather than down, the meshes are as heavy as without steps on average (both statistics are
// tuned defaults, not bounds: what a tile publishes is measured).
constexpr double kStepsPerOctave = 8;

double on_step(double eps) {
    return std::exp2(std::round(std::log2(eps) * kStepsPerOctave) / kStepsPerOctave);
}

// The step between two heights an integer DEM can store, metres (its scale), or 0 for floating
// point data. The default eps is never below it: stored heights are rounded to it, so a mesh held
// closer than one step follows the rounding's staircase, a contour line at every step, instead
// of the terrain. On a 6 m Int16 DEM (N48W125 resampled 4x, resolution / 45 = 0.14 m) the median
// 3D Tiles tile of the finest zoom had 16.4k triangles at 0.14 m and 3.2k at 1 m.
double height_step(const DemInfo& info) {
    const std::string& t = info.data_type;
    const bool integer = t.find("Int") != std::string::npos || t == "Byte";
    return integer ? std::abs(info.scale) : 0.0;
}

// CesiumJS's geometric error of a geodetic terrain level at zoom 0, metres: the equator's
// length / 4 over a 65-sample tile, two tiles across (getLevelMaximumGeometricError).
constexpr double kCesiumLevelError = 6378137.0 * 2 * 3.14159265358979323846 * 0.25 / (65 * 2);
// The share of a zoom's reach (zoom_reach: how far its rough cells stray from flat) it is meshed
// at, at least. Below it the mesher spends triangles on the lattice's planes to within an eps the
// published bound cannot show, since the cells' own ranges dominate it: on N44W072 (SRTM 3")
// the median glb tile of z7/z8/z9 falls from 13.8k/13.5k/37.6k triangles at the ladder to
// 4.3k/4.5k/13.5k, and the median published bound rises from 215/94/41 m to 366/166/55 m.
constexpr double kReachShare = 0.25;
// The share of it globe terrain is meshed at, at least (see terrain_eps_for_zoom): a quarter at
// the finest zoom, which clients draw closest and upsample beyond; half above it, where a
// finer tile takes over as the camera nears. With a quarter everywhere, tiles over the DEM's
// own pixels at the zoom above the finest (twice its pixels, twice its eps) and the globe-wide
// tiles of zooms 0-1 (edges short enough for the sag) were heavier than the finest zoom's: on
// N44W072 the median z0/z1/z9 tile had 3.9k/4.1k/3.8k triangles against z10's 2.8k; with half,
// 1.8k/1.6k/1.6k, and the pyramid's .terrain bytes 935 kB -> 738 kB.
constexpr double kTerrainLevelShare = 0.25;
constexpr double kTerrainCoarseShare = 0.5;
// The largest share of eps globe terrain keeps for sag (terrain_budget_at).
constexpr double kTerrainSagMost = 0.75;

// v with 4 significant digits, for a message.
std::string short_number(double v) {
    char text[32];
    std::snprintf(text, sizeof text, "%.4g", v);
    return text;
}

// At most this many overlapping pairs are named, one warning each; a last one counts the rest.
constexpr std::size_t kOverlapWarnings = 5;

// Warns of files of one mosaic that overlap and differ there by more than the ladder's eps
// (finest_eps at max_zoom, doubling up) at their own deepest zoom: the tiles show the one given
// first, which may not be what the user meant.
void warn_overlaps(const DemSource& source,
                   const LayerOptions& options,
                   int max_zoom,
                   double finest_eps) {
    std::vector<const DemSource*> groups;
    for (const auto& m : source.members()) {
        groups.push_back(m.get());
    }
    if (groups.empty()) {
        groups.push_back(&source);
    }
    std::size_t named = 0, more = 0;
    for (const DemSource* g : groups) {
        const int deepest = std::min(max_zoom, native_zoom(*g, options.scheme, options.tile_size));
        const double eps = finest_eps * std::ldexp(1.0, max_zoom - deepest);
        for (const FileOverlap& o : g->overlaps()) {
            if (o.max_diff <= eps) {
                continue;
            }
            if (named++ >= kOverlapWarnings) {
                ++more;
                continue;
            }
            log::warn(o.first + " and " + o.second + " overlap (" + std::to_string(o.pixels) +
                      " pixels valid in both) and differ there by up to " +
                      short_number(o.max_diff) + " m, more than the eps of their finest zoom (" +
                      short_number(eps) + " m at zoom " + std::to_string(deepest) +
                      "): " + o.first +
                      " wins where both have data, being given first; give the one that "
                      "should win first, or cut the other");
        }
    }
    if (more > 0) {
        log::warn(std::to_string(more) + " more pair(s) of overlapping DEM files differ by more "
                                         "than eps; the file given first wins in each");
    }
}

} // namespace

LayerPlan::LayerPlan(const LayerOptions& options, const DemSource& source)
    : options_(options), source_(source) {
    const DemInfo& info = source_.info();
    footprint_ = source_.footprint();
    for (int z = 0; z <= kMaxZoom; ++z) {
        std::vector<TileRange> ranges;
        for (const LonLatBox& box : source_.footprints_at(options_.scheme, z, options_.tile_size)) {
            ranges.push_back(tiles_in_families(options_.scheme, box, footprint_, z));
        }
        covers_.emplace_back(z, ranges);
    }
    pixels_ = source_.pixel_grid(options_.scheme);
    if (source_.members().empty()) {
        place_.emplace(source_, options_.scheme);
    }
    summary_ok_ = place_.has_value();
    datum_ = options_.datum;
    if (datum_ == VerticalDatum::Auto) {
        datum_ = source_.ellipsoidal_heights() ? VerticalDatum::Ellipsoid : VerticalDatum::Egm96;
    }
    if (source_.members().size() >= 2) {
        members_.emplace(options_, source_, datum_);
    }
    plan_zooms();
    // The lattice's ladder (kStepPerEps) at max_zoom, unless the data's height step (or
    // kMinEps) is larger there: then the ladder doubles up from that.
    const double lat = 0.5 * (footprint_.south + footprint_.north);
    const double zero_eps =
        on_step(lattice_step_m(options_.scheme, 0, options_.tile_size, lat) / kStepPerEps);
    finest_eps_ = options_.finest_eps
                      ? *options_.finest_eps
                      : std::max({kMinEps, std::ldexp(zero_eps, -max_zoom_), height_step(info)});
    compute_height_range();
    warn_overlaps(source_, options_, max_zoom_, finest_eps_);
}

// The ladder, finest_eps * 2^(max_zoom - z), raised where the summary (a collection's: its
// members') shows a zoom's cells to be rougher than that (kReachShare of its reach).
double LayerPlan::eps_for_zoom(int z) const {
    const double ladder = finest_eps_ * std::ldexp(1.0, max_zoom_ - z);
    if (!(summary_ok_ || members_) || z < 0 || z >= max_zoom_ ||
        zoom_source(z) == ZoomSource::Pixels) {
        return ladder;
    }
    const double r = reach()[static_cast<std::size_t>(z)];
    return r > 0 ? std::max(ladder, on_step(kReachShare * r)) : ladder;
}

// The eps globe terrain is meshed at: the ladder, or a share of CesiumJS's own level error
// (kTerrainLevelShare at the finest zoom, kTerrainCoarseShare above it) where that is larger.
// CesiumJS picks quantized-mesh levels by its level error alone (kCesiumLevelError / 2^z), so a
// tile drawn closer than that costs bytes no view shows; and at coarse zooms straight triangles
// must follow the Earth's curve (the chord sag), which at the ladder's eps takes a full lattice of
// triangles (131,072 at zoom 0).
double LayerPlan::terrain_eps_for_zoom(int z) const {
    const double share = z < max_zoom_ ? kTerrainCoarseShare : kTerrainLevelShare;
    return std::max(eps_for_zoom(z), kCesiumLevelError / std::exp2(z) * share);
}

std::string LayerPlan::zoom_signature(int z) const {
    // Appended piece by piece: GCC 12 at -O3 warns (-Wrestrict, wrongly) on "[" + a + ...
    const auto budget = [](const ErrorBudget& b) {
        std::string text = "[";
        for (const double v : {b.mesh_eps, b.drawn_bound, b.max_edge, b.max_edge_m}) {
            text += json_number(v);
            text += ", ";
        }
        text += json_number(b.quant_step);
        return text + "]";
    };
    std::string out = "[";
    out += std::to_string(z);
    out += ", \"";
    out += to_string(zoom_source(z));
    out += "\", ";
    out += json_number(eps_for_zoom(z));
    out += ", ";
    out += budget(budget_at(z, eps_for_zoom(z)));
    out += ", ";
    out += json_number(terrain_eps_for_zoom(z));
    out += ", ";
    out += budget(terrain_budget_at(z, terrain_eps_for_zoom(z)));
    // Globe terrain coarser than its data's zooms is flat filler, whose error over the data is
    // the layer's relief.
    if (z < terrain_min_zoom_) {
        const LonLatBox& f = footprint_;
        out += ", [" + json_number(relief()) + ", " + json_number(f.west) + ", " +
               json_number(f.south) + ", " + json_number(f.east) + ", " + json_number(f.north) +
               "]";
    }
    return out + "]";
}

ZoomSource LayerPlan::zoom_source(int z) const {
    // As max_zoom is planned: the first zoom whose lattice is as fine as the pixels.
    if (pixels_ && source_.pixels_per_sample(options_.scheme, z, options_.tile_size) <= 1 + 1e-9) {
        return ZoomSource::Pixels;
    }
    if (summary_ok_) {
        // A zoom whose tiles would read more pixels than one tile may (pixels longer one way
        // than the other, or a grid turned against the tiles') reads the summary too.
        const double pps = place_->pixels_per_step(options_.scheme, z, options_.tile_size);
        const bool summary = pps >= std::exp2(kFinestLevel) ||
                             (pps > 1 + 1e-9 && tile_pixels(z) > kMaxPixelsPerTile);
        return summary ? ZoomSource::Summary : ZoomSource::Lattice;
    }
    return members_ && members_->reads_summaries(z) ? ZoomSource::Summaries : ZoomSource::Lattice;
}

int LayerPlan::summary_level_at(Scheme scheme, int z, int size) const {
    const DemSummary& sum = summary();
    const int level = summary_level(sum, *place_, scheme, z, size);
    return level < 0 ? sum.finest_level() : level;
}

LatticeSampler LayerPlan::lattice_sampler(int z) const {
    switch (zoom_source(z)) {
    case ZoomSource::Summary:
        return
            [this](
                Scheme scheme, int zoom, int size, std::int64_t c0, std::int64_t r0, int w, int h) {
                return summary_sample(scheme, zoom, size, c0, r0, w, h);
            };
    case ZoomSource::Summaries:
        return
            [this](
                Scheme scheme, int zoom, int size, std::int64_t c0, std::int64_t r0, int w, int h) {
                return members_->sample(scheme, zoom, size, c0, r0, w, h);
            };
    case ZoomSource::Pixels:
    case ZoomSource::Lattice:
        break;
    }
    return {};
}

LatticeBlock LayerPlan::summary_sample(Scheme scheme,
                                       int z,
                                       int size,
                                       std::int64_t column0,
                                       std::int64_t row0,
                                       int width,
                                       int height) const {
    return summary_lattice(summary(),
                           *place_,
                           datum_,
                           scheme,
                           z,
                           size,
                           summary_level_at(scheme, z, size),
                           column0,
                           row0,
                           width,
                           height);
}

const TileCover& LayerPlan::cover_at(int z) const {
    TB_ASSERT(z >= 0 && z <= kMaxZoom);
    return covers_[static_cast<std::size_t>(z)];
}

TileRange LayerPlan::tiles_at(int z) const {
    if (z < min_zoom_ || z > max_zoom_) {
        return TileRange{z, 0, 0, -1, -1};
    }
    return cover_at(z).bounding();
}

std::int64_t LayerPlan::tile_count_at(int z) const {
    if (z < min_zoom_ || z > max_zoom_) {
        return 0;
    }
    return cover_at(z).count();
}

bool LayerPlan::may_have_tile(const ValidTile& tile) const {
    TB_ASSERT(tile.scheme() == options_.scheme);
    return tile.z() >= min_zoom_ && tile.z() <= max_zoom_ && in_families(tile);
}

bool LayerPlan::in_families(const ValidTile& tile) const {
    return cover_at(tile.z()).contains(tile.x(), tile.y());
}

void LayerPlan::check_data(const ValidTile& tile) const {
    if (!may_have_tile(tile)) {
        throw NotFound("tile " + tile_name(tile.id()) + ": layer '" + options_.name +
                       "' has no data there (zooms " + std::to_string(min_zoom_) + ".." +
                       std::to_string(max_zoom_) + ")");
    }
}

bool LayerPlan::terrain_has_data(const ValidTile& tile) const {
    TB_ASSERT(tile.scheme() == options_.scheme);
    if (tile.z() < terrain_min_zoom_ || tile.z() > max_zoom_) {
        return false;
    }
    return in_families(tile);
}

void LayerPlan::check_terrain_data(const ValidTile& tile) const {
    if (!terrain_has_data(tile)) {
        check_data(tile); // names the layer's zooms
        throw NotFound("tile " + tile_name(tile.id()) + ": no globe terrain data there");
    }
}

ErrorBudget LayerPlan::terrain_budget_at(int z, double eps) const {
    const double spare = 1 - 1.0 / 8 - relief() / eps;
    return budget_with(z, eps, std::max(kTerrainSagShare, std::min(kTerrainSagMost, spare)));
}

ErrorBudget LayerPlan::budget_with(int z, double eps, double sag_share) const {
    return zoom_source(z) == ZoomSource::Pixels
               ? pixel_error_budget(eps, options_.scheme, *pixels_, sag_share)
               : tile_error_budget(eps, options_.scheme, z, options_.tile_size, sag_share);
}

double LayerPlan::relief() const {
    return std::max(max_height_ - kGeoidLowest, kGeoidHighest - min_height_);
}

// zoom_reach of every zoom 0..max_zoom - 1 (0 where a zoom reads pixels; a collection's from
// its members' summaries), made no smaller
// toward coarser zooms, so that eps never shrinks from one zoom to the next coarser one.
const std::vector<double>& LayerPlan::reach() const {
    std::call_once(reach_once_, [this] {
        reach_.assign(static_cast<std::size_t>(max_zoom_) + 1, 0.0);
        for (int z = max_zoom_ - 1; z >= 0; --z) {
            const auto k = static_cast<std::size_t>(z);
            if (members_) {
                // Only the summaries a served zoom reads (prepare makes those).
                const int coarsest = std::min(min_zoom_, terrain_min_zoom_);
                reach_[k] = z >= coarsest ? members_->zoom_reach(z, coarsest) : 0.0;
            } else if (zoom_source(z) != ZoomSource::Pixels) {
                reach_[k] = zoom_reach(summary(), *place_, options_.scheme, z, options_.tile_size);
            }
            reach_[k] = std::max(reach_[k], reach_[k + 1]);
        }
    });
    return reach_;
}

void LayerPlan::prepare() const {
    if (summary_ok_ || members_) {
        reach(); // and the summaries it reads
    }
    if (members_) {
        members_->prepare(std::min(min_zoom_, terrain_min_zoom_), max_zoom_);
    }
}

const DemSummary& LayerPlan::summary() const {
    std::call_once(summary_once_, [this] {
        summary_.emplace(
            load_or_make_summary(options_, options_.sources, source_, *place_, datum_));
    });
    return *summary_;
}

// max_zoom: the first zoom whose lattice spacing reaches the source's pixel size.
// min_zoom: the deepest zoom at which the data still spans at most 2 x 2 tiles.
void LayerPlan::plan_zooms() {
    int max_z = native_zoom(source_, options_.scheme, options_.tile_size);
    if (options_.max_zoom) {
        max_z = *options_.max_zoom;
    }
    int min_z = 0;
    for (int z = 0; z <= max_z; ++z) {
        if (tiles_covering(options_.scheme, footprint_, z).count() <= 4) {
            min_z = z;
        }
    }
    // Every zoom reads the full-resolution pixels under a tile (meshed on them, or checked
    // against them), so a zoom whose tiles would hold more than kMaxPixelsPerTile is not
    // offered.
    int coarsest = 0;
    // Zooms read from the summary read about their own number of samples, whatever the zoom
    // (a collection's: those of its members that read their summaries).
    while (coarsest <= max_z && zoom_source(coarsest) != ZoomSource::Summary &&
           tile_pixels(coarsest) > kMaxPixelsPerTile) {
        ++coarsest;
    }
    if (coarsest > max_z) {
        throw InputError(
            "layer '" + options_.name + "': a tile at max zoom " + std::to_string(max_z) +
            " would hold " + std::to_string(std::llround(tile_pixels(max_z))) +
            " source pixels, more than one tile reads (" +
            std::to_string(std::llround(kMaxPixelsPerTile)) + "); set a finer max_zoom");
    }
    if (options_.min_zoom) {
        min_z = *options_.min_zoom;
        if (min_z < coarsest) {
            throw InputError("layer '" + options_.name + "': min zoom " + std::to_string(min_z) +
                             ": its tiles would hold up to " +
                             std::to_string(std::llround(tile_pixels(min_z))) +
                             " source pixels, more than one tile reads at full resolution (" +
                             std::to_string(std::llround(kMaxPixelsPerTile)) +
                             "; every zoom is held to the full-resolution DEM); use min zoom " +
                             std::to_string(coarsest) + " or finer");
        }
    } else if (min_z < coarsest) {
        log::info("layer '" + options_.name + "': starts at zoom " + std::to_string(coarsest) +
                  " instead of " + std::to_string(min_z) +
                  ": coarser tiles would hold more source pixels than one tile reads (" +
                  std::to_string(std::llround(kMaxPixelsPerTile)) + ")");
        min_z = coarsest;
    }
    if (min_z > max_z) {
        throw InputError("layer '" + options_.name + "': min zoom " + std::to_string(min_z) +
                         " is above max zoom " + std::to_string(max_z));
    }
    if (tiles_covering(options_.scheme, footprint_, max_z).empty()) {
        throw InputError(source_.info().path + ": lies outside the " + to_string(options_.scheme) +
                         " scheme's extent");
    }
    min_zoom_ = min_z;
    // Globe terrain is meshed from the data from zoom 0 where the summary reaches that far, or
    // a collection's zoom 0 can be read (filler on the geoid below min_zoom otherwise, and where
    // a tile holds no data).
    terrain_min_zoom_ =
        (summary_ok_ || (members_ && coarsest == 0)) && !options_.min_zoom ? 0 : min_z;
    max_zoom_ = max_z;
}

// Source pixels one tile of zoom z reads at most: its extent in pixels, clipped to the
// source's size.
double LayerPlan::tile_pixels(int z) const {
    const DemInfo& info = source_.info();
    if (pixels_) {
        // Exact for a pixel grid: the tile's width over the pixel's (a mercator tile spans
        // no more latitude than longitude, and no more EPSG:3857 metres than its width).
        const LonLatBox b = tile_bounds(options_.scheme, {z, 0, 0});
        const double width = pixels_->lonlat ? b.east - b.west
                                             : lattice_x(options_.scheme, z, 1, 1) -
                                                   lattice_x(options_.scheme, z, 1, 0);
        return std::min<double>(width / pixels_->dx + 1, info.width) *
               std::min<double>(width / pixels_->dy + 1, info.height);
    }
    if (members_ && members_->reads_summaries(z)) {
        return members_->tile_pixels(z);
    }
    return source_.tile_pixels(options_.scheme, z, options_.tile_size);
}

// Ellipsoidal range of every sample a tile can hold: the data's range, sea level where
// voids may be filled with it, plus the geoid's range over the footprint.
void LayerPlan::compute_height_range() {
    const DemInfo& info = source_.info();
    double lo = info.min_height, hi = info.max_height;
    if (!info.range_exact) {
        // GDAL's approximate pass can miss the extremes, and a bounding volume that does
        // not hold the surface makes clients cull tiles they should draw. Take in the
        // Earth's whole relief instead (Challenger Deep to Everest, orthometric).
        constexpr double kDeepest = -11100, kHighest = 8900;
        log::warn(info.path + ": height range " + std::to_string(std::llround(lo)) + " .. " +
                  std::to_string(std::llround(hi)) +
                  " m is approximate (too large to read whole); tileset bounding volumes "
                  "span " +
                  std::to_string(std::llround(kDeepest)) + " .. " +
                  std::to_string(std::llround(kHighest)) + " m instead");
        lo = std::min(lo, kDeepest);
        hi = std::max(hi, kHighest);
    }
    // Voids (nodata, or bounding-box corners of a projected DEM) may lie at 0 m orthometric.
    if (info.nodata || !info.geographic) {
        lo = std::min(lo, 0.0);
        hi = std::max(hi, 0.0);
    }
    double n_lo = INFINITY, n_hi = -INFINITY;
    constexpr int kSteps = 32;
    for (int j = 0; j <= kSteps; ++j) {
        for (int i = 0; i <= kSteps; ++i) {
            const double lon = footprint_.west + (footprint_.east - footprint_.west) * i / kSteps;
            const double lat =
                footprint_.south + (footprint_.north - footprint_.south) * j / kSteps;
            const double n = egm96_undulation(lon, lat);
            n_lo = std::min(n_lo, n), n_hi = std::max(n_hi, n);
        }
    }
    // Between the probes the 15' geoid grid can vary a little more; 2 m covers it.
    if (datum_ == VerticalDatum::Egm96) {
        lo += n_lo - 2, hi += n_hi + 2;
    } else if (info.nodata || !info.geographic) {
        lo = std::min(lo, n_lo - 2), hi = std::max(hi, n_hi + 2);
    }
    min_height_ = lo - 1;
    max_height_ = hi + 1;
}

} // namespace tb::tiler
