// A layer's globe terrain tiles and documents (terrain_maker.hpp).
#include "tiler/formats/terrain_maker.hpp"

#include "core/error.hpp"
#include "tiler/log.hpp"
#include "tiler/mesh/vertex_normals.hpp"
#include "tiler/sources/lattice_raster.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <string_view>
#include <utility>

namespace tb::tiler {
namespace {

// 3D Tiles terrain tiles wider than this (zoom 6 and coarser) carry float32 positions: the
// 16-bit box is level at the tile's centre, and far from it a step of the box moves a vertex's
// height (4.7 m a step at zoom 6, hundreds of metres on a hemisphere at zoom 0).
constexpr double kExactPositionsDegrees = 2.0;

// The ellipsoid's unit normal at lon/lat (degrees), ECEF.
std::array<double, 3> up_vector(double lon, double lat) {
    constexpr double kDeg = 3.14159265358979323846 / 180;
    return {std::cos(lat * kDeg) * std::cos(lon * kDeg),
            std::cos(lat * kDeg) * std::sin(lon * kDeg),
            std::sin(lat * kDeg)};
}

// Fills the points of a line with no data (valid 0) linearly along the line between the
// nearest points with data, and marks every point valid. A line without data keeps its
// heights. A function of the line alone: two tiles that share the line fill it alike.
void fill_line(std::vector<float>& heights, std::vector<std::uint8_t>& valid) {
    const std::size_t n = heights.size();
    std::size_t last = n; // the previous point with data
    for (std::size_t k = 0; k <= n; ++k) {
        if (k < n && !valid[k]) {
            continue;
        }
        if (last == n && k < n) {
            std::fill(
                heights.begin(), heights.begin() + static_cast<std::ptrdiff_t>(k), heights[k]);
        } else if (last != n && k == n) {
            std::fill(heights.begin() + static_cast<std::ptrdiff_t>(last + 1),
                      heights.end(),
                      heights[last]);
        } else if (last != n) {
            for (std::size_t i = last + 1; i < k; ++i) {
                const double t = static_cast<double>(i - last) / static_cast<double>(k - last);
                heights[i] = static_cast<float>((1 - t) * heights[last] + t * heights[k]);
            }
        }
        last = k;
    }
    std::fill(valid.begin(), valid.end(), std::uint8_t{1});
}

} // namespace

std::vector<std::uint8_t> fill_for_terrain(PixelTile& pixel) {
    core::HeightGrid& g = pixel.raster.grid;
    std::vector<std::uint8_t> valid;
    valid.swap(g.valid);
    if (!valid.empty()) {
        const int w = g.width, h = g.height;
        for (int s = 0; s < 4; ++s) {
            if (pixel.sides[static_cast<std::size_t>(s)].present) {
                continue; // the line lies between pixels: its profile, below
            }
            const bool column = s == kWest || s == kEast;
            const int fixed = s == kWest ? 0 : s == kEast ? w - 1 : s == kNorth ? 0 : h - 1;
            const int n = column ? h : w;
            std::vector<float> line(static_cast<std::size_t>(n));
            std::vector<std::uint8_t> ok(static_cast<std::size_t>(n));
            const auto at = [&](int k) {
                return column ? static_cast<std::size_t>(k) * w + fixed
                              : static_cast<std::size_t>(fixed) * w + k;
            };
            for (int k = 0; k < n; ++k) {
                line[static_cast<std::size_t>(k)] = g.heights[at(k)];
                ok[static_cast<std::size_t>(k)] = valid[at(k)];
            }
            fill_line(line, ok);
            for (int k = 0; k < n; ++k) {
                g.heights[at(k)] = line[static_cast<std::size_t>(k)];
            }
        }
    }
    for (BorderProfile& side : pixel.sides) {
        fill_line(side.heights, side.valid);
    }
    pixel.corner_valid.fill(1);
    return valid;
}

TerrainMaker::TerrainMaker(const LayerOptions& options,
                           const LayerPlan& plan,
                           const DemSource& source,
                           MeshFn mesh,
                           OverEpsFn note_over_eps)
    : options_(options), plan_(plan), source_(source), mesh_(std::move(mesh)),
      note_over_eps_(std::move(note_over_eps)) {}

TerrainSpec TerrainMaker::terrain_spec() const {
    return TerrainSpec{options_.name,
                       plan_.terrain_min_zoom(),
                       plan_.max_zoom(),
                       plan_.footprint(),
                       [this](int z) { return plan_.terrain_eps_for_zoom(z); },
                       [this](int z) -> const TileCover& { return plan_.cover_at(z); }};
}

// What the terrain tileset publishes. Heights: every tile's vertices lie within the
// layer's range or on the geoid (filler, and the corners covering a rectangle beyond the
// DEM where no edge is carried to them), whose undulation stays within
// kGeoidLowest..kGeoidHighest, or between the two (the edge carried outward, lowered toward
// the geoid). Level errors: a tile at a
// meshed zoom is held to its zoom's bound (data_terrain measures what its glb draws); a filler
// tile over the data is as far from it as the DEM's heights are from the geoid.
TerrainTilesetSpec TerrainMaker::tileset_spec() const {
    TerrainTilesetSpec spec;
    spec.terrain = terrain_spec();
    spec.min_height = std::min(plan_.min_height(), kGeoidLowest);
    spec.max_height = std::max(plan_.max_height(), kGeoidHighest);
    spec.root_error = plan_.relief() * std::exp2(std::max(plan_.terrain_min_zoom() - 1, 0));
    for (int z = plan_.terrain_min_zoom(); z <= plan_.max_zoom(); ++z) {
        spec.root_error = std::max(
            spec.root_error,
            plan_.terrain_budget_at(z, plan_.terrain_eps_for_zoom(z)).drawn_bound * std::exp2(z));
    }
    const double lo = spec.min_height, hi = spec.max_height;
    spec.bounds = [lo, hi](const ValidTile& tile) {
        return terrain_tile_bounds(tile_bounds(Scheme::Geodetic, tile.id()), lo, hi);
    };
    return spec;
}

bool TerrainMaker::document(const std::string& path, std::string& out) const {
    const TerrainTilesetSpec spec = tileset_spec();
    if (path == "tileset.json") {
        out = terrain_tileset_json(spec);
        return true;
    }
    constexpr std::string_view kSuffix = ".subtree";
    if (path.size() <= kSuffix.size() ||
        path.compare(path.size() - kSuffix.size(), kSuffix.size(), kSuffix) != 0) {
        return false;
    }
    std::int64_t part[4] = {0, 0, 0, 0};
    std::size_t at = 0;
    const std::size_t end = path.size() - kSuffix.size();
    for (int k = 0; k < 4; ++k) {
        const std::size_t stop = k < 3 ? path.find('/', at) : end;
        if (stop == std::string::npos || stop > end || stop == at || stop - at > 10) {
            return false;
        }
        for (std::size_t c = at; c < stop; ++c) {
            if (path[c] < '0' || path[c] > '9') {
                return false;
            }
            part[k] = part[k] * 10 + (path[c] - '0');
        }
        at = stop + 1;
    }
    if (part[0] > 1 || part[1] > kMaxZoom) {
        return false;
    }
    return terrain_subtree(
        spec, static_cast<int>(part[0]), static_cast<int>(part[1]), part[2], part[3], out);
}

TerrainDraft TerrainMaker::draft(const ValidTile& tile) const {
    if (options_.scheme != Scheme::Geodetic) {
        throw InputError("layer '" + options_.name + "': globe terrain needs the geodetic scheme");
    }
    TB_ASSERT(tile.scheme() == options_.scheme);
    if (tile.z() > plan_.max_zoom()) {
        throw NotFound("tile " + tile_name(tile.id()) + ": beyond layer '" + options_.name +
                       "''s max zoom " + std::to_string(plan_.max_zoom()) +
                       " (clients upsample its parent)");
    }
    const LonLatBox bounds = tile_bounds(options_.scheme, tile.id());
    if (plan_.terrain_has_data(tile)) {
        try {
            return data_terrain(tile, bounds);
        } catch (const NotFound&) {
            // no source pixel centre lies in the tile: filler
        }
    }
    const TileMesh filler = terrain_filler(bounds);
    TerrainDraft draft;
    TerrainTile& terrain = draft.tile;
    terrain.filler = true;
    terrain.extras.normals.resize(filler.vertex_count());
    for (std::size_t v = 0; v < filler.vertex_count(); ++v) {
        terrain.extras.normals[v] = up_vector(filler.x[v], filler.y[v]);
    }
    terrain.extras.water_mask = {255};
    terrain.extras.metadata = terrain_metadata(terrain_spec(), tile.id(), 0, true);
    terrain.mesh = quantize_mesh(filler, bounds);
    terrain.glb_error = filler_error(tile);
    // Float positions: a 16-bit step of a coarse filler tile's box is tens of metres.
    terrain.exact_positions = true;
    return draft;
}

TerrainDraft TerrainMaker::data_terrain(const ValidTile& tile, const LonLatBox& bounds) const {
    // The 15-bit quantization moves vertices by up to half a step (about 1/65534 of the
    // tile) across the slope: it is measured at every sample, and where it takes the tile
    // past its bound the worst samples become vertices (quantize_within). The border lines
    // keep the vertices the zoom's eps gave them, so neighbouring tiles still share them.
    const double eps = plan_.terrain_eps_for_zoom(tile.z());
    const double target = plan_.terrain_budget_at(tile.z(), eps).drawn_bound;
    TerrainDraft draft;
    MeshedTile& t = draft.meshed;
    t = mesh_(tile, eps); // quantize_within measures every valid sample
    if (t.mesh.triangle_count() == 0) {
        throw NotFound("tile " + tile_name(tile.id()) + ": no triangle from the DEM"); // filler
    }
    cover_rectangle(t.mesh, bounds, carried_corners(tile));
    TerrainTile& terrain = draft.tile;
    std::size_t uncovered = 0;
    double error = 0;
    terrain.mesh = quantize_within(t.mesh,
                                   bounds,
                                   t.raster,
                                   t.source_pixels,
                                   target - t.budget.sag,
                                   error,
                                   &uncovered,
                                   t.cells);
    if (uncovered > 0) {
        log::debug("tile " + tile_name(tile.id()) + ": " + std::to_string(uncovered) +
                   " sample(s) lie in no quantized triangle");
    }
    draft.quantized = error;
    terrain.error = std::max(error + t.budget.sag, target);
    terrain.extras.normals = normals(t, tile);
    return draft;
}

std::string TerrainMaker::encode(TerrainDraft& draft, const ValidTile& tile, Format format) const {
    if (draft.tile.filler) {
        return format == Format::Terrain ? encode_quantized_mesh(draft.tile.mesh, draft.tile.extras)
                                         : encode_terrain_glb(draft.tile);
    }
    const MeshedTile& t = draft.meshed;
    const double target =
        plan_.terrain_budget_at(tile.z(), plan_.terrain_eps_for_zoom(tile.z())).drawn_bound;
    TerrainTile& terrain = draft.tile;
    double drawn = draft.quantized; // what the encoded format draws, at every sample
    if (format == Format::Terrain3d) {
        // 16-bit positions, unless they draw the tile further from the DEM than its bound
        // (or, on a coarser lattice than the pixels, 5 % further than the quantized mesh
        // itself: the lattice's own error dominates there), or the tile is so wide that a
        // 16-bit step of its box moves heights at its far side by metres (the box is level
        // at the tile's centre).
        const LonLatBox b = tile_bounds(options_.scheme, tile.id());
        terrain.exact_positions = b.east - b.west > kExactPositionsDegrees;
        const auto measure = [&] {
            return surface_error(terrain_glb_surface(terrain.mesh, terrain.exact_positions),
                                 t.raster,
                                 t.source_pixels,
                                 nullptr,
                                 t.cells);
        };
        drawn = measure();
        if (!terrain.exact_positions &&
            drawn > std::max(target - t.budget.sag, draft.quantized * 1.05) + 1e-9) {
            terrain.exact_positions = true;
            drawn = measure();
        }
        terrain.glb_error = std::max(drawn + t.budget.sag, target);
    } else {
        terrain.extras.water_mask =
            terrain_water_mask(t.raster, tile_bounds(options_.scheme, tile.id()));
        terrain.extras.metadata = terrain_metadata(terrain_spec(), tile.id(), terrain.error, false);
    }
    if (drawn + t.budget.sag > target + 1e-9) {
        // A zoom meshed on a lattice coarser than the pixels is expected to miss them by
        // more than eps (its bound is what it measures); at the pixels' own zoom only the
        // quantization can.
        const bool pixels = plan_.zoom_source(tile.z()) == ZoomSource::Pixels;
        log::write(pixels ? log::Level::Warn : log::Level::Debug,
                   std::string("terrain tile ") + tile_name(tile.id()) + "." + extension(format) +
                       (pixels ? ": quantization leaves it " : ": it is ") +
                       std::to_string(drawn + t.budget.sag) +
                       " m from the DEM, above the zoom's eps " + std::to_string(target) +
                       " m; the tile itself publishes the larger bound");
        note_over_eps_();
    }
    return format == Format::Terrain ? encode_quantized_mesh(terrain.mesh, terrain.extras)
                                     : encode_terrain_glb(terrain);
}

double TerrainMaker::filler_error(const ValidTile& tile) const {
    const LonLatBox b = tile_bounds(Scheme::Geodetic, tile.id());
    const bool over_data = b.west < plan_.footprint().east && b.east > plan_.footprint().west &&
                           b.south < plan_.footprint().north && b.north > plan_.footprint().south;
    return over_data ? plan_.relief() : 0.0;
}

std::function<double(double, double)> TerrainMaker::carried_corners(const ValidTile& tile) const {
    const int z = tile.z(), n = options_.tile_size;
    LatticeFootprint fp = lattice_footprint(Scheme::Geodetic,
                                            z,
                                            n,
                                            plan_.footprint(),
                                            sampler_or_source(plan_.lattice_sampler(z), source_));
    const double step = lattice_x(Scheme::Geodetic, z, n, 1) - lattice_x(Scheme::Geodetic, z, n, 0);
    return [this, z, n, step, fp = std::move(fp)](double lon, double lat) {
        // A tile corner is a lattice point: its column and row, exactly.
        const auto column = std::llround((lon - lattice_x(Scheme::Geodetic, z, n, 0)) / step);
        const auto row = std::llround((lattice_y(Scheme::Geodetic, z, n, 0) - lat) / step);
        return carried_height(Scheme::Geodetic, z, n, column, row, fp, plan_.datum());
    };
}

std::vector<std::array<double, 3>> TerrainMaker::normals(const MeshedTile& t,
                                                         const ValidTile& tile) const {
    const bool pixels = plan_.zoom_source(tile.z()) == ZoomSource::Pixels;
    return vertex_normals(t.mesh,
                          tile.id(),
                          options_.scheme,
                          options_.tile_size,
                          source_,
                          pixels ? &*plan_.pixels() : nullptr,
                          plan_.lattice_sampler(tile.z()));
}

} // namespace tb::tiler
