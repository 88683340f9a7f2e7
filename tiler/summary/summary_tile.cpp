// Coarse tiles from the summary: lattice heights off the blocks' planes, blocks as CheckCells.
#include "tiler/summary/summary_tile.hpp"

#include "tiler/sources/geoid.hpp"
#include "tiler/summary/projected_cells.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <utility>

namespace tb::tiler {
namespace {

// Source pixel coordinates (fractional column, row) of a native point of `scheme`.
void to_pixel(const PixelGrid& g, Scheme scheme, double x, double y, double& i, double& j) {
    if (g.lonlat) {
        const LonLat p = native_to_lonlat(scheme, x, y);
        x = p.lon, y = p.lat;
    }
    i = (x - g.x0) / g.dx - 0.5;
    j = (g.y0 - y) / g.dy - 0.5;
}

// Source pixel coordinates of lattice row `row`'s columns column0 .. column0 + width - 1.
void lattice_row_to_pixels(const PixelPlace& place,
                           Scheme scheme,
                           int z,
                           int size,
                           std::int64_t column0,
                           std::int64_t row,
                           int width,
                           std::vector<double>& is,
                           std::vector<double>& js) {
    is.resize(static_cast<std::size_t>(width));
    js.resize(static_cast<std::size_t>(width));
    const double y = lattice_y(scheme, z, size, row);
    for (int c = 0; c < width; ++c) {
        const double x = lattice_x(scheme, z, size, column0 + c);
        const auto k = static_cast<std::size_t>(c);
        if (place.grid()) {
            to_pixel(*place.grid(), scheme, x, y, is[k], js[k]);
        } else {
            const LonLat p = native_to_lonlat(scheme, x, y);
            is[k] = p.lon, js[k] = p.lat;
        }
    }
    if (!place.grid()) {
        place.to_pixels(is, js);
    }
}

} // namespace

int summary_level(
    const DemSummary& summary, const PixelPlace& place, Scheme scheme, int z, int size) {
    return summary_level(summary, place.pixels_per_step(scheme, z, size));
}

int summary_level(const DemSummary& summary, double pixels_per_step) {
    const int level = static_cast<int>(std::floor(std::log2(pixels_per_step) + 1e-9));
    if (level < kFinestLevel) {
        return -1;
    }
    // A source too large for kFinestLevel keeps coarser blocks only: a zoom finer than them
    // reads them all the same, its bound held by blocks wider than its lattice step.
    return std::clamp(level, summary.finest_level(), summary.coarsest_level());
}

double
zoom_reach(const DemSummary& summary, const PixelPlace& place, Scheme scheme, int z, int size) {
    TileRoughness roughest;
    add_roughness(summary, place, scheme, z, size, roughest);
    return median_roughness(roughest);
}

void add_roughness(const DemSummary& summary,
                   const PixelPlace& place,
                   Scheme scheme,
                   int z,
                   int size,
                   TileRoughness& roughest) {
    const double step = place.pixels_per_step(scheme, z, size);
    const int level = std::max(summary_level(summary, step), summary.finest_level());
    // Scaled to a lattice step, but no further than the whole source: a source narrower than a
    // step (its one coarsest block) has no relief beyond its own.
    const double scale = std::min(step, std::exp2(summary.coarsest_level())) / std::exp2(level);
    // Each block's middle, row by row, through the CRS every 512 pixels (which tile a block
    // falls in is all that is asked: a bend of metres there moves none but a few at tile edges).
    const std::int64_t across = summary.blocks_across(level);
    const std::int64_t side = std::int64_t{1} << level;
    const auto middle = [&](std::int64_t bx) { // of its columns, as in whole pixels
        return static_cast<double>(((bx << level) + summary.last_column(level, bx)) / 2);
    };
    std::vector<double> lons, lats;
    for (std::int64_t by = 0; by < summary.blocks_down(level); ++by) {
        const double j = static_cast<double>(((by << level) + summary.last_row(level, by)) / 2);
        place.row_to_lonlat(middle(0), double(side), j, static_cast<int>(across), 512, lons, lats);
        if (middle(across - 1) != middle(0) + static_cast<double>((across - 1) * side)) {
            std::vector<double> x{middle(across - 1)}, y{j}; // a narrower last block
            place.to_lonlat(x, y);
            lons.back() = x[0], lats.back() = y[0];
        }
        for (std::int64_t bx = 0; bx < across; ++bx) {
            const SummaryBlock* b = summary.block(level, bx, by);
            const double lon = lons[static_cast<std::size_t>(bx)];
            const double lat = lats[static_cast<std::size_t>(bx)];
            if (b->empty() || std::isnan(lon)) {
                continue;
            }
            constexpr double kPoint = 1e-9; // degrees: a box around the point, inside one tile
            const TileRange r =
                tiles_covering(scheme, {lon - kPoint, lat - kPoint, lon + kPoint, lat + kPoint}, z);
            if (!r.empty()) {
                double& rough = roughest[{r.x0, r.y0}];
                rough = std::max(rough, (static_cast<double>(b->high) - b->low) * scale);
            }
        }
    }
}

double median_roughness(const TileRoughness& roughest) {
    if (roughest.empty()) {
        return 0.0;
    }
    std::vector<double> values;
    values.reserve(roughest.size());
    for (const auto& [tile, rough] : roughest) {
        values.push_back(rough);
    }
    const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
    std::nth_element(values.begin(), mid, values.end());
    return *mid;
}

LatticeBlock summary_lattice(const DemSummary& summary,
                             const PixelPlace& place,
                             VerticalDatum datum,
                             Scheme scheme,
                             int z,
                             int size,
                             int level,
                             std::int64_t column0,
                             std::int64_t row0,
                             int width,
                             int height) {
    LatticeBlock out;
    out.column0 = column0, out.row0 = row0, out.width = width, out.height = height;
    const std::size_t count = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
    out.heights.assign(count, 0.0);
    out.valid.assign(count, 0);
    const int W = place.width(), H = place.height();
    std::vector<double> is, js;
    for (int r = 0; r < height; ++r) {
        lattice_row_to_pixels(place, scheme, z, size, column0, row0 + r, width, is, js);
        for (int c = 0; c < width; ++c) {
            const double i = is[static_cast<std::size_t>(c)], j = js[static_cast<std::size_t>(c)];
            if (!(i >= -0.5 && j >= -0.5 && i <= W - 0.5 && j <= H - 0.5)) {
                continue; // NaN too
            }
            const auto col = std::clamp<std::int64_t>(std::llround(i), 0, W - 1);
            const auto row = std::clamp<std::int64_t>(std::llround(j), 0, H - 1);
            const std::int64_t bx = col >> level, by = row >> level;
            const SummaryBlock* b = summary.block(level, bx, by);
            if (b == nullptr || b->empty()) {
                continue;
            }
            // The least-squares plane, not the middle of the block's range: at coarse levels
            // the range spans the block's whole relief, often lopsided, and its middle can lie
            // far above or below every pixel near the point (7,766 m over a DEM below 1,900 m).
            double h = DemSummary::plane(*b, level, bx, by, i, j);
            if (datum == VerticalDatum::Egm96) {
                const LonLat p = native_to_lonlat(scheme,
                                                  lattice_x(scheme, z, size, column0 + c),
                                                  lattice_y(scheme, z, size, row0 + r));
                h -= egm96_undulation(p.lon, p.lat);
            }
            const std::size_t k = static_cast<std::size_t>(r) * width + c;
            out.heights[k] = h;
            out.valid[k] = 1;
        }
    }
    return out;
}

std::vector<CheckCell> summary_cells(const DemSummary& summary,
                                     const PixelPlace& place,
                                     const TileRaster& raster,
                                     int level) {
    if (!place.serves()) {
        return projected_cells(summary, place, raster, level);
    }
    const PixelGrid& grid = *place.grid();
    const GridFrame f = frame_of(raster);
    // The tile's box in pixel coordinates, then the pixel centres inside it (closed).
    double i_west = 0, j_north = 0, i_east = 0, j_south = 0;
    to_pixel(grid, raster.scheme, f.x0, f.y0, i_west, j_north);
    to_pixel(grid,
             raster.scheme,
             f.x0 + f.dx * (raster.grid.width - 1),
             f.y0 - f.dy * (raster.grid.height - 1),
             i_east,
             j_south);
    const auto i0 = std::max<std::int64_t>(static_cast<std::int64_t>(std::ceil(i_west)), 0);
    const auto j0 = std::max<std::int64_t>(static_cast<std::int64_t>(std::ceil(j_north)), 0);
    const auto i1 =
        std::min<std::int64_t>(static_cast<std::int64_t>(std::floor(i_east)), grid.width - 1);
    const auto j1 =
        std::min<std::int64_t>(static_cast<std::int64_t>(std::floor(j_south)), grid.height - 1);
    std::vector<CheckCell> cells;
    if (i0 > i1 || j0 > j1) {
        return cells;
    }
    // Pixel (i, j) in grid coordinates: affine on both axes (summary_serves).
    const double sx = grid.dx / f.dx, sy = grid.dy / f.dy;
    const double gx0 = (grid.x(0) - f.x0) / f.dx, gy0 = (f.y0 - grid.y(0)) / f.dy;
    for (std::int64_t by = j0 >> level; by <= j1 >> level; ++by) {
        for (std::int64_t bx = i0 >> level; bx <= i1 >> level; ++bx) {
            const SummaryBlock* b = summary.block(level, bx, by);
            if (b == nullptr || b->empty()) {
                continue;
            }
            const auto ia = std::max(bx << level, i0),
                       ib = std::min(summary.last_column(level, bx), i1);
            const auto ja = std::max(by << level, j0),
                       jb = std::min(summary.last_row(level, by), j1);
            CheckCell c;
            c.x0 = gx0 + static_cast<double>(ia) * sx, c.x1 = gx0 + static_cast<double>(ib) * sx;
            c.y0 = gy0 + static_cast<double>(ja) * sy, c.y1 = gy0 + static_cast<double>(jb) * sy;
            c.height = DemSummary::plane(*b, level, bx, by, double(ia), double(ja)) +
                       (static_cast<double>(b->low) + b->high) / 2;
            c.per_column = static_cast<double>(b->per_column) / sx;
            c.per_row = static_cast<double>(b->per_row) / sy;
            c.half = (static_cast<double>(b->high) - b->low) / 2 + 1e-6;
            cells.push_back(c);
        }
    }
    return cells;
}

} // namespace tb::tiler
