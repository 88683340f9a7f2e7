// Raster DEM tiles: pixel-centre samples of the layer's DEM in EPSG:3857, voids filled, heights
// on the chosen datum, packed into PNG.
#include "tiler/dem_tiles.hpp"

#include "core/error.hpp"
#include "tiler/formats/dem_png.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/geoid.hpp"

#include <algorithm>
#include <cmath>

namespace tb::tiler {
namespace {

// EPSG:3857's latitude limit, atan(sinh(pi)).
constexpr double kMercatorLat = 85.05112877980659;

std::string tile_name(const TileId& id) {
    return std::to_string(id.z) + "/" + std::to_string(id.x) + "/" + std::to_string(id.y);
}

bool in_range(const TileRange& r, const TileId& id) {
    return !r.empty() && id.x >= r.x0 && id.x <= r.x1 && id.y >= r.y0 && id.y <= r.y1;
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
    plan.max_zoom = kMaxZoom;
    for (int z = 0; z <= kMaxZoom; ++z) {
        if (source.pixels_per_sample(Scheme::Mercator, z, plan.tile_size) <= 1.0 + 1e-9) {
            plan.max_zoom = z;
            break;
        }
    }
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

std::vector<double> dem_tile_heights(const Layer& layer, const TileId& id) {
    const LayerOptions& o = layer.options();
    if (!is_valid(Scheme::Mercator, id)) {
        throw InputError("DEM tile " + tile_name(id) + ": outside EPSG:3857 XYZ (z 0.." +
                         std::to_string(kMaxZoom) + ", x and y below 2^z)");
    }
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
        const LatticeBlock row =
            layer.sample(Scheme::Mercator, id.z, lattice, c0, r0 + 2 * j, 2 * w - 1, 1);
        for (int i = 0; i < w; ++i) {
            heights[static_cast<std::size_t>(j) * w + i] =
                row.heights[static_cast<std::size_t>(2 * i)];
            valid[static_cast<std::size_t>(j) * w + i] = row.valid[static_cast<std::size_t>(2 * i)];
        }
    }
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
    return out;
}

std::string make_dem_tile(const Layer& layer, const TileId& id, Format format) {
    TB_ASSERT(is_dem_format(format));
    const std::vector<double> heights = dem_tile_heights(layer, id);
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
