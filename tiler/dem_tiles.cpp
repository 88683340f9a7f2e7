// Raster DEM tiles: pixel-centre samples of the layer's DEM in EPSG:3857, voids filled, heights
// on the chosen datum, packed into PNG.
#include "tiler/dem_tiles.hpp"

#include "core/error.hpp"
#include "tiler/formats/dem_png.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/geoid.hpp"
#include "tiler/sources/tile_raster.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace tb::tiler {
namespace {

// EPSG:3857's latitude limit, atan(sinh(pi)).
constexpr double kMercatorLat = 85.05112877980659;

bool in_range(const TileRange& r, const TileId& id) {
    return !r.empty() && id.x >= r.x0 && id.x <= r.x1 && id.y >= r.y0 && id.y <= r.y1;
}

// The pixels of zoom z (P per tile) whose centres lie in `bounds`: columns first..last, rows
// first..last (north to south); a box narrower than a pixel gets the pixel holding its centre.
struct PixelSpan {
    std::int64_t first_column, last_column, first_row, last_row;
};
PixelSpan pixels_in(const LonLatBox& bounds, int z, int p) {
    double west = 0, south = 0, east = 0, north = 0;
    lonlat_to_native(Scheme::Mercator, {bounds.west, bounds.south}, west, south);
    lonlat_to_native(Scheme::Mercator, {bounds.east, bounds.north}, east, north);
    const double x0 = lattice_x(Scheme::Mercator, z, p, 0),
                 y0 = lattice_y(Scheme::Mercator, z, p, 0);
    const double pw = lattice_x(Scheme::Mercator, z, p, 1) - x0;
    const auto span = [](double lo, double hi) {
        auto first = static_cast<std::int64_t>(std::ceil(lo - 0.5));
        auto last = static_cast<std::int64_t>(std::floor(hi - 0.5));
        if (first > last) {
            first = last = static_cast<std::int64_t>(std::floor(0.5 * (lo + hi)));
        }
        return std::pair{first, last};
    };
    const auto [c0, c1] = span((west - x0) / pw, (east - x0) / pw);
    const auto [r0, r1] = span((y0 - north) / pw, (y0 - south) / pw);
    return {c0, c1, r0, r1};
}

// Gives the pixels of the w x w block from pixel (column0, row0) that lie beyond the data's
// footprint the height of the nearest pixel inside it (column and row clamped to the
// footprint's), where that one is valid: MapLibre and deck.gl then draw the DEM's edge carried
// outward, not a cliff down to sea level. A function of the pixel alone, so tiles agree.
void extend_edges(const Layer& layer,
                  const DemTilePlan& plan,
                  int z,
                  std::int64_t column0,
                  std::int64_t row0,
                  int w,
                  std::vector<double>& heights,
                  std::vector<std::uint8_t>& valid) {
    const PixelSpan in = pixels_in(plan.bounds, z, plan.tile_size);
    const auto clamp_column = [&](std::int64_t c) {
        return std::clamp(c, in.first_column, in.last_column);
    };
    const auto clamp_row = [&](std::int64_t r) { return std::clamp(r, in.first_row, in.last_row); };
    const std::int64_t c_lo = clamp_column(column0), c_hi = clamp_column(column0 + w - 1);
    const std::int64_t r_lo = clamp_row(row0), r_hi = clamp_row(row0 + w - 1);
    if (c_lo == column0 && c_hi == column0 + w - 1 && r_lo == row0 && r_hi == row0 + w - 1) {
        return; // the block lies inside the footprint
    }
    // The clamped block, one lattice row per pixel row (pixel centres are the odd points of
    // the (z, 2P) lattice).
    const int lattice = 2 * plan.tile_size;
    const int cols = static_cast<int>(c_hi - c_lo + 1), rows = static_cast<int>(r_hi - r_lo + 1);
    std::vector<LatticeBlock> edge;
    for (int j = 0; j < rows; ++j) {
        edge.push_back(layer.sample(
            Scheme::Mercator, z, lattice, 2 * c_lo + 1, 2 * (r_lo + j) + 1, 2 * cols - 1, 1));
    }
    for (int j = 0; j < w; ++j) {
        for (int i = 0; i < w; ++i) {
            const std::int64_t c = column0 + i, r = row0 + j;
            if (clamp_column(c) == c && clamp_row(r) == r) {
                continue; // inside: its own sample, or a void that fill_voids fills
            }
            const LatticeBlock& row = edge[static_cast<std::size_t>(clamp_row(r) - r_lo)];
            const auto at = static_cast<std::size_t>(2 * (clamp_column(c) - c_lo));
            const std::size_t k = static_cast<std::size_t>(j) * w + i;
            if (row.valid[at] != 0) {
                heights[k] = row.heights[at];
                valid[k] = 1;
            }
        }
    }
}

} // namespace

DemTilePlan dem_tile_plan(const Layer& layer) {
    const LayerOptions& o = layer.options();
    if (o.dem_tile_size != 256 && o.dem_tile_size != 512) {
        throw InputError("layer '" + o.name + "': DEM tile size " +
                         std::to_string(o.dem_tile_size) + " is not supported; use 256 or 512");
    }
    DemTilePlan plan;
    plan.tile_size = o.dem_tile_size;
    plan.bounds = layer.data_bounds();
    plan.bounds.south = std::max(plan.bounds.south, -kMercatorLat);
    plan.bounds.north = std::min(plan.bounds.north, kMercatorLat);
    const DemSource& source = layer.source();
    plan.max_zoom = native_zoom(source, Scheme::Mercator, plan.tile_size);
    // From zoom 0: MapLibre and deck.gl draw no terrain below a raster-dem source's minzoom.
    // Coarse zooms read the layer's summary where it has one (Layer::sample).
    plan.min_zoom = 0;
    return plan;
}

TileRange dem_tiles_at(const Layer& layer, int z) {
    const DemTilePlan plan = dem_tile_plan(layer);
    if (z < plan.min_zoom || z > plan.max_zoom || plan.bounds.south >= plan.bounds.north) {
        return TileRange{z, 0, 0, -1, -1};
    }
    return tiles_covering(Scheme::Mercator, plan.bounds, z);
}

std::vector<double>
dem_tile_heights(const Layer& layer, const ValidTile& tile, const CancelFn& cancelled) {
    TB_ASSERT(tile.scheme() == Scheme::Mercator);
    const TileId& id = tile.id();
    const auto checkpoint = [&](const char* before) {
        throw_if_cancelled(cancelled, "DEM tile", id, before);
    };
    const LayerOptions& o = layer.options();
    const DemTilePlan plan = dem_tile_plan(layer);
    if (!in_range(dem_tiles_at(layer, id.z), id)) {
        throw NotFound("DEM tile " + tile_name(id) + ": layer '" + o.name +
                       "' has no data there (DEM zooms " + std::to_string(plan.min_zoom) + ".." +
                       std::to_string(plan.max_zoom) + ")");
    }
    // Pixel centres are the odd points of the (mercator, z, 2P) lattice; read them with a
    // margin of m pixels, as the block of lattice points from the first margin pixel's centre.
    const int p = plan.tile_size, m = kDemFillMargin, w = p + 2 * m;
    const int lattice = 2 * p;
    const std::int64_t c0 = id.x * lattice + 1 - 2 * m;
    const std::int64_t r0 = id.y * lattice + 1 - 2 * m;
    // One lattice row per pixel row: the even rows between them are never read.
    std::vector<double> heights(static_cast<std::size_t>(w) * w);
    std::vector<std::uint8_t> valid(heights.size());
    for (int j = 0; j < w; ++j) {
        if (j % 32 == 0) {
            checkpoint(j == 0 ? "reading its heights" : "reading more of its heights");
        }
        const LatticeBlock row =
            layer.sample(Scheme::Mercator, id.z, lattice, c0, r0 + 2 * j, 2 * w - 1, 1);
        for (int i = 0; i < w; ++i) {
            heights[static_cast<std::size_t>(j) * w + i] =
                row.heights[static_cast<std::size_t>(2 * i)];
            valid[static_cast<std::size_t>(j) * w + i] = row.valid[static_cast<std::size_t>(2 * i)];
        }
    }
    extend_edges(layer, plan, id.z, id.x * p - m, id.y * p - m, w, heights, valid);
    const bool all_valid =
        std::all_of(valid.begin(), valid.end(), [](std::uint8_t v) { return v != 0; });

    const bool to_ellipsoid = o.dem_heights == DemHeights::Ellipsoid;
    const bool source_ellipsoidal = layer.source_datum() == VerticalDatum::Ellipsoid;
    std::vector<double> undulation;
    if (to_ellipsoid || source_ellipsoidal) {
        undulation.resize(heights.size());
        for (int j = 0; j < w; ++j) {
            const double y = lattice_y(Scheme::Mercator, id.z, lattice, r0 + 2 * j);
            for (int i = 0; i < w; ++i) {
                const double x = lattice_x(Scheme::Mercator, id.z, lattice, c0 + 2 * i);
                const LonLat q = native_to_lonlat(Scheme::Mercator, x, y);
                undulation[static_cast<std::size_t>(j) * w + i] = egm96_undulation(q.lon, q.lat);
            }
        }
    }
    // An ellipsoidal source served in ellipsoidal heights keeps its own measured heights.
    const std::vector<double> measured =
        source_ellipsoidal && to_ellipsoid ? heights : std::vector<double>();
    // Voids are filled in heights above sea level, so data-free areas lie at sea level.
    if (source_ellipsoidal) {
        for (std::size_t k = 0; k < heights.size(); ++k) {
            heights[k] -= valid[k] ? undulation[k] : 0.0;
        }
    }
    if (!all_valid) {
        fill_voids(heights, valid, w, w, m, 0.0);
    }
    std::vector<double> out(static_cast<std::size_t>(p) * p);
    for (int j = 0; j < p; ++j) {
        for (int i = 0; i < p; ++i) {
            const std::size_t k = static_cast<std::size_t>(j + m) * w + (i + m);
            double h = to_ellipsoid ? heights[k] + undulation[k] : heights[k];
            if (!measured.empty() && valid[k]) {
                h = measured[k];
            }
            out[static_cast<std::size_t>(j) * p + i] = h;
        }
    }
    checkpoint("encoding");
    return out;
}

std::string
make_dem_tile(const Layer& layer, const ValidTile& tile, Format format, const CancelFn& cancelled) {
    TB_ASSERT(is_dem_format(format));
    const std::vector<double> heights = dem_tile_heights(layer, tile, cancelled);
    const int p = layer.options().dem_tile_size;
    return encode_dem_png(heights, p, p, format);
}

DemHeights parse_dem_heights(const std::string& name) {
    if (name == "sea_level") {
        return DemHeights::SeaLevel;
    }
    if (name == "ellipsoid") {
        return DemHeights::Ellipsoid;
    }
    throw InputError("DEM heights '" + name + "': expected 'sea_level' or 'ellipsoid'");
}

const char* to_string(DemHeights heights) {
    return heights == DemHeights::Ellipsoid ? "ellipsoid" : "sea_level";
}

} // namespace tb::tiler
