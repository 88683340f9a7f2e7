// Tile raster geometry (the global sample lattice of a zoom) and void filling.
#include "tiler/sources/tile_raster.hpp"

#include "core/error.hpp"
#include "tiler/sources/gdal_source.hpp"

#include <algorithm>
#include <cmath>

namespace tb::tiler {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kEarthRadius = 6378137.0;
constexpr double kMercatorHalf = kPi * kEarthRadius;

// Native width of one tile at zoom z.
double tile_width(Scheme scheme, int z) {
    const double tiles = static_cast<double>(std::int64_t{1} << z);
    return scheme == Scheme::Geodetic ? 180.0 / tiles : 2 * kMercatorHalf / tiles;
}

// Search radius of fill step 1 when filling a whole raster (no tile border to agree on).
constexpr int kWholeRadius = 16;

} // namespace

double lattice_x(Scheme scheme, int z, int size, std::int64_t column) {
    const double step = tile_width(scheme, z) / size;
    const double x_min = scheme == Scheme::Geodetic ? -180.0 : -kMercatorHalf;
    return x_min + static_cast<double>(column) * step;
}

double lattice_y(Scheme scheme, int z, int size, std::int64_t row) {
    const double step = tile_width(scheme, z) / size;
    const double y_max = scheme == Scheme::Geodetic ? 90.0 : kMercatorHalf;
    return y_max - static_cast<double>(row) * step;
}

std::int64_t tile_first_column(Scheme, const TileId& id, int size) {
    return id.x * size;
}

std::int64_t tile_first_row(Scheme scheme, const TileId& id, int size) {
    // Geodetic tiles count y from the south (TMS), mercator from the north (XYZ).
    const std::int64_t from_north =
        scheme == Scheme::Geodetic ? tiles_down(scheme, id.z) - 1 - id.y : id.y;
    return from_north * size;
}

LonLat native_to_lonlat(Scheme scheme, double x, double y) {
    if (scheme == Scheme::Geodetic) {
        return {x, y};
    }
    return {x / kMercatorHalf * 180.0, std::atan(std::sinh(y / kEarthRadius)) * 180.0 / kPi};
}

void lonlat_to_native(Scheme scheme, const LonLat& p, double& x, double& y) {
    if (scheme == Scheme::Geodetic) {
        x = p.lon, y = p.lat;
        return;
    }
    x = p.lon / 180.0 * kMercatorHalf;
    y = kEarthRadius * std::log(std::tan(kPi / 4 + p.lat * kPi / 360.0));
}

GridFrame frame_of(const TileRaster& raster) {
    if (raster.frame.dx > 0) {
        return raster.frame;
    }
    GridFrame f;
    f.x0 = lattice_x(raster.scheme,
                     raster.id.z,
                     raster.size,
                     tile_first_column(raster.scheme, raster.id, raster.size));
    f.y0 = lattice_y(raster.scheme,
                     raster.id.z,
                     raster.size,
                     tile_first_row(raster.scheme, raster.id, raster.size));
    f.dx = f.dy = tile_width(raster.scheme, raster.id.z) / raster.size;
    return f;
}

LonLat grid_to_lonlat(const TileRaster& raster, double column, double row) {
    const GridFrame f = frame_of(raster);
    if (f.lonlat) {
        return {f.x0 + column * f.dx, f.y0 - row * f.dy};
    }
    return native_to_lonlat(raster.scheme, f.x0 + column * f.dx, f.y0 - row * f.dy);
}

void lonlat_to_grid(const TileRaster& raster, const LonLat& p, double& column, double& row) {
    const GridFrame f = frame_of(raster);
    double x = p.lon, y = p.lat;
    if (!f.lonlat) {
        lonlat_to_native(raster.scheme, p, x, y);
    }
    column = (x - f.x0) / f.dx;
    row = (f.y0 - y) / f.dy;
}

void fill_voids(std::vector<double>& heights,
                const std::vector<std::uint8_t>& valid,
                int width,
                int height,
                int margin,
                double fallback) {
    TB_ASSERT(width > 0 && height > 0);
    TB_ASSERT(heights.size() == static_cast<std::size_t>(width) * height);
    TB_ASSERT(valid.size() == heights.size());
    TB_ASSERT(margin >= 0 && 2 * margin < width && 2 * margin < height);
    const bool tile_mode = margin > 0;
    const int radius = tile_mode ? margin : kWholeRadius;
    const auto at = [width](int x, int y) { return static_cast<std::size_t>(y) * width + x; };
    // The region whose samples are filled: the tile inside the margin, or everything.
    const int x0 = margin, y0 = margin, x1 = width - 1 - margin, y1 = height - 1 - margin;

    std::vector<std::uint8_t> filled(valid);
    bool any_void = false;
    for (int y = y0; y <= y1 && !any_void; ++y) {
        for (int x = x0; x <= x1; ++x) {
            if (!valid[at(x, y)]) {
                any_void = true;
                break;
            }
        }
    }
    if (!any_void) {
        return;
    }

    // Step 1. Chessboard distance to the nearest valid sample, by breadth-first search over the
    // whole block (margin included) up to `radius`; a void at distance d then averages the
    // valid samples of its ring d (inverse-square weights), which are the nearest ones.
    constexpr int kFar = 1 << 30;
    std::vector<int> distance(heights.size(), kFar);
    std::vector<std::size_t> frontier;
    for (std::size_t i = 0; i < heights.size(); ++i) {
        if (valid[i]) {
            distance[i] = 0;
            frontier.push_back(i);
        }
    }
    for (int d = 1; d <= radius && !frontier.empty(); ++d) {
        std::vector<std::size_t> next;
        for (std::size_t i : frontier) {
            const int x = static_cast<int>(i % width), y = static_cast<int>(i / width);
            for (int dy = -1; dy <= 1; ++dy) {
                for (int dx = -1; dx <= 1; ++dx) {
                    const int nx = x + dx, ny = y + dy;
                    if (nx < 0 || ny < 0 || nx >= width || ny >= height) {
                        continue;
                    }
                    if (distance[at(nx, ny)] == kFar) {
                        distance[at(nx, ny)] = d;
                        next.push_back(at(nx, ny));
                    }
                }
            }
        }
        frontier.swap(next);
    }
    for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
            const int d = distance[at(x, y)];
            if (d == 0 || d == kFar) {
                continue;
            }
            double sum = 0, weights = 0;
            for (int dy = -d; dy <= d; ++dy) {
                for (int dx = -d; dx <= d; ++dx) {
                    if (std::max(std::abs(dx), std::abs(dy)) != d) {
                        continue;
                    }
                    const int nx = x + dx, ny = y + dy;
                    if (nx < 0 || ny < 0 || nx >= width || ny >= height || !valid[at(nx, ny)]) {
                        continue;
                    }
                    const double w = 1.0 / (dx * dx + dy * dy);
                    sum += w * heights[at(nx, ny)];
                    weights += w;
                }
            }
            TB_ASSERT(weights > 0);
            heights[at(x, y)] = sum / weights;
            filled[at(x, y)] = 1;
        }
    }

    if (tile_mode) {
        // Step 2: corners far from any data (typically open sea, where voids are largest).
        for (const auto& [cx, cy] : {std::pair{x0, y0}, {x1, y0}, {x0, y1}, {x1, y1}}) {
            if (!filled[at(cx, cy)]) {
                heights[at(cx, cy)] = fallback;
                filled[at(cx, cy)] = 1;
            }
        }
        // Step 3: each border line on its own, so the neighbour sharing it agrees.
        const auto fill_line = [&](int ax, int ay, int bx, int by) {
            const int n = std::max(std::abs(bx - ax), std::abs(by - ay));
            const int sx = (bx > ax) - (bx < ax), sy = (by > ay) - (by < ay);
            int last = 0; // index along the line of the last filled sample (the start corner)
            for (int k = 1; k <= n; ++k) {
                const std::size_t i = at(ax + k * sx, ay + k * sy);
                if (!filled[i]) {
                    continue;
                }
                const double h0 = heights[at(ax + last * sx, ay + last * sy)];
                const double h1 = heights[i];
                for (int m = last + 1; m < k; ++m) {
                    const double t = static_cast<double>(m - last) / (k - last);
                    heights[at(ax + m * sx, ay + m * sy)] = h0 + t * (h1 - h0);
                    filled[at(ax + m * sx, ay + m * sy)] = 1;
                }
                last = k;
            }
        };
        fill_line(x0, y0, x1, y0);
        fill_line(x0, y1, x1, y1);
        fill_line(x0, y0, x0, y1);
        fill_line(x1, y0, x1, y1);
    }

    // Step 4: the rest, layer by layer from what is filled: each void takes the mean of its
    // filled 8-neighbours of earlier layers. Linear in the number of samples.
    std::vector<std::size_t> layer;
    std::vector<std::uint8_t> queued(heights.size(), 0);
    const auto in_region = [&](int x, int y) { return x >= x0 && x <= x1 && y >= y0 && y <= y1; };
    bool any_filled = false;
    for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
            any_filled = any_filled || filled[at(x, y)];
        }
    }
    if (!any_filled) {
        for (int y = y0; y <= y1; ++y) {
            for (int x = x0; x <= x1; ++x) {
                heights[at(x, y)] = fallback;
            }
        }
        return;
    }
    for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
            if (filled[at(x, y)]) {
                continue;
            }
            bool touches = false;
            for (int dy = -1; dy <= 1 && !touches; ++dy) {
                for (int dx = -1; dx <= 1; ++dx) {
                    if (in_region(x + dx, y + dy) && filled[at(x + dx, y + dy)]) {
                        touches = true;
                        break;
                    }
                }
            }
            if (touches) {
                layer.push_back(at(x, y));
                queued[at(x, y)] = 1;
            }
        }
    }
    while (!layer.empty()) {
        std::vector<double> values(layer.size());
        for (std::size_t k = 0; k < layer.size(); ++k) {
            const int x = static_cast<int>(layer[k] % width),
                      y = static_cast<int>(layer[k] / width);
            double sum = 0;
            int count = 0;
            for (int dy = -1; dy <= 1; ++dy) {
                for (int dx = -1; dx <= 1; ++dx) {
                    if (in_region(x + dx, y + dy) && filled[at(x + dx, y + dy)]) {
                        sum += heights[at(x + dx, y + dy)];
                        ++count;
                    }
                }
            }
            TB_ASSERT(count > 0);
            values[k] = sum / count;
        }
        std::vector<std::size_t> next;
        for (std::size_t k = 0; k < layer.size(); ++k) {
            heights[layer[k]] = values[k];
            filled[layer[k]] = 1;
        }
        for (std::size_t i : layer) {
            const int x = static_cast<int>(i % width), y = static_cast<int>(i / width);
            for (int dy = -1; dy <= 1; ++dy) {
                for (int dx = -1; dx <= 1; ++dx) {
                    const int nx = x + dx, ny = y + dy;
                    if (in_region(nx, ny) && !filled[at(nx, ny)] && !queued[at(nx, ny)]) {
                        queued[at(nx, ny)] = 1;
                        next.push_back(at(nx, ny));
                    }
                }
            }
        }
        std::sort(next.begin(), next.end()); // deterministic order (does not change values)
        layer.swap(next);
    }
}

} // namespace tb::tiler
