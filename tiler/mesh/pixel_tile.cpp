// Pixel tiles: the source's own pixel centres as the mesher's samples, and the border strips
// that carry the mesh out to the tile's border lines (see pixel_tile.hpp).
#include "tiler/mesh/pixel_tile.hpp"

#include "core/breakpoints.hpp"
#include "core/error.hpp"
#include "core/triangulate.hpp"
#include "tiler/helper_threads.hpp"
#include "tiler/sources/geoid.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <utility>

namespace tb::tiler {
namespace {

// Pixels read around the block, so that void filling near its border sees beyond it (the fill
// radius of fill_voids) and the border profiles see the pixels across the border.
constexpr int kFillMargin = 16;

// The shortest longest-edge a pixel tile allows: the core mesh's edges are kept to
// sqrt(max_edge^2 - 1) so that a strip triangle, which joins two lines less than a pixel apart
// along segments no longer than that, stays within max_edge; core needs at least kMinMaxEdge.
const double kMinPixelEdge = std::sqrt(core::kMinMaxEdge * core::kMinMaxEdge + 1);

// First index whose coordinate is at or past `edge` going the grid's way (x grows with i, y
// shrinks with j), by exact comparison with the coordinate each pixel centre has everywhere.
template <class Coord, class Past>
std::int64_t first_index(std::int64_t guess, std::int64_t count, Coord coord, Past past) {
    std::int64_t i = std::clamp<std::int64_t>(guess, 0, count);
    while (i < count && !past(coord(i))) {
        ++i;
    }
    while (i > 0 && past(coord(i - 1))) {
        --i;
    }
    return i;
}

// Heights of the window around the block, as read and as used for filling.
struct Window {
    std::int64_t column0 = 0, row0 = 0;
    int width = 0, height = 0;
    // As read, NaN for nodata: kept apart from ortho only for an ellipsoidal source, whose
    // valid pixels ortho moves to the geoid. Otherwise ortho holds the source's own heights at
    // every valid pixel, and this is empty (a coarse tile's window is megabytes, and each
    // fresh page costs a page fault).
    std::vector<double> source;
    std::vector<double> ortho; // orthometric (or source) heights, voids filled
    std::vector<std::uint8_t> valid;
    // The source's height at valid pixels.
    const std::vector<double>& measured() const { return source.empty() ? ortho : source; }
    double at(const std::vector<double>& v, std::int64_t i, std::int64_t j) const {
        return v[static_cast<std::size_t>(j - row0) * width +
                 static_cast<std::size_t>(i - column0)];
    }
    bool is_valid(std::int64_t i, std::int64_t j) const {
        return valid[static_cast<std::size_t>(j - row0) * width +
                     static_cast<std::size_t>(i - column0)] != 0;
    }
};

struct Value {
    float height = 0;
    bool valid = false;
};

// The height at a point between pixels: the weighted mean of the pixels with data among
// `pixels` (listed in the source's row-major order, so every tile that shares the point sums
// them the same way), in source heights; the undulation at the point itself is added for EGM96
// sources. With no data beside it, the point lies on the geoid.
template <std::size_t N>
Value between(const Window& w,
              const std::array<std::pair<std::int64_t, std::int64_t>, N>& pixels,
              const std::array<double, N>& weights,
              double undulation,
              VerticalDatum datum) {
    double sum = 0, total = 0;
    for (std::size_t k = 0; k < N; ++k) {
        if (w.is_valid(pixels[k].first, pixels[k].second)) {
            sum += weights[k] * w.at(w.measured(), pixels[k].first, pixels[k].second);
            total += weights[k];
        }
    }
    if (total <= 0) {
        return {static_cast<float>(undulation), false};
    }
    const double h = sum / total + (datum == VerticalDatum::Egm96 ? undulation : 0.0);
    return {static_cast<float>(h), true};
}

} // namespace

ErrorBudget
pixel_error_budget(double eps, Scheme scheme, const PixelGrid& pixels, double sag_share) {
    constexpr double kA = 6378137.0, kF = 1 / 298.257223563, kB = kA * (1 - kF);
    constexpr double kPi = 3.14159265358979323846;
    // Ground metres per pixel step, an upper bound in every direction: geodetic, degrees times
    // the largest radius of curvature (a^2/b); mercator, EPSG:3857 metres (never shorter than
    // ground metres).
    (void)scheme;
    const double unit = pixels.lonlat ? kPi / 180 * kA * kA / kB : 1.0;
    return spacing_error_budget(
        eps, std::max(pixels.dx, pixels.dy) * unit, kMinPixelEdge, sag_share);
}

PixelTile make_pixel_tile(const DemSource& source,
                          const PixelGrid& g,
                          Scheme scheme,
                          const TileId& id,
                          VerticalDatum datum) {
    TB_ASSERT(datum != VerticalDatum::Auto);
    PixelTile t;
    t.pixels = g;
    // The border lines in the grid's coordinates, each from one expression of its global edge
    // index, so both tiles beside a line get the same value.
    double xw = 0, xe = 0, yn = 0, ys = 0;
    if (g.lonlat) {
        const LonLatBox b = tile_bounds(scheme, id);
        xw = b.west, xe = b.east, yn = b.north, ys = b.south;
    } else {
        const std::int64_t top = tile_first_row(scheme, id, 1);
        xw = lattice_x(scheme, id.z, 1, id.x), xe = lattice_x(scheme, id.z, 1, id.x + 1);
        yn = lattice_y(scheme, id.z, 1, top), ys = lattice_y(scheme, id.z, 1, top + 1);
    }
    t.edge = {xw, xe, yn, ys};

    const auto x_of = [&g](std::int64_t i) { return g.x(i); };
    const auto y_of = [&g](std::int64_t j) { return g.y(j); };
    const auto guess_i = [&g](double x) {
        const double u = (x - g.x0) / g.dx - 0.5;
        return std::isfinite(u) ? static_cast<std::int64_t>(std::clamp(u, -1.0, 1e15)) : 0;
    };
    const auto guess_j = [&g](double y) {
        const double v = (g.y0 - y) / g.dy - 0.5;
        return std::isfinite(v) ? static_cast<std::int64_t>(std::clamp(v, -1.0, 1e15)) : 0;
    };
    const std::int64_t W = g.width, H = g.height;
    const std::int64_t i0 = first_index(guess_i(xw), W, x_of, [xw](double x) { return x >= xw; });
    const std::int64_t i1 =
        first_index(guess_i(xe), W, x_of, [xe](double x) { return x > xe; }) - 1;
    const std::int64_t j0 = first_index(guess_j(yn), H, y_of, [yn](double y) { return y <= yn; });
    const std::int64_t j1 =
        first_index(guess_j(ys), H, y_of, [ys](double y) { return y < ys; }) - 1;
    if (i0 > i1 || j0 > j1) {
        throw NotFound("tile " + tile_name(id) + ": no pixel centre of " + source.info().path +
                       " lies in it");
    }
    const std::int64_t w = i1 - i0 + 1, h = j1 - j0 + 1;
    if (static_cast<double>(w) * static_cast<double>(h) > kMaxPixelsPerTile) {
        throw InputError("tile " + tile_name(id) + ": holds " + std::to_string(w) + " x " +
                         std::to_string(h) + " source pixels, more than one tile may read (" +
                         std::to_string(std::llround(kMaxPixelsPerTile)) +
                         "); use a finer min zoom");
    }
    t.column0 = i0, t.row0 = j0;
    t.sides[kWest].present = g.x(i0) > xw && i0 > 0;
    t.sides[kEast].present = g.x(i1) < xe && i1 + 1 < W;
    t.sides[kNorth].present = g.y(j0) < yn && j0 > 0;
    t.sides[kSouth].present = g.y(j1) > ys && j1 + 1 < H;

    // The window: the block and a margin, read once.
    const int m = kFillMargin;
    Window win;
    win.column0 = i0 - m, win.row0 = j0 - m;
    win.width = static_cast<int>(w) + 2 * m, win.height = static_cast<int>(h) + 2 * m;
    const bool ellipsoidal = datum == VerticalDatum::Ellipsoid;
    win.ortho = source.read_pixels(win.column0, win.row0, win.width, win.height);
    if (ellipsoidal) {
        win.source = win.ortho;
    }
    win.valid.resize(win.ortho.size());
    const auto lonlat = [&](double x, double y) {
        return g.lonlat ? LonLat{x, y} : native_to_lonlat(scheme, x, y);
    };
    const auto undulation = [&](double x, double y) {
        const LonLat p = lonlat(x, y);
        return egm96_undulation(p.lon, p.lat);
    };
    // The geoid by window column and row (longitude depends on x alone and latitude on y
    // alone, in both schemes): egm96_at gives egm96_undulation's value, for a product instead
    // of a projection and two divisions per pixel.
    std::vector<Egm96Column> geoid_column(static_cast<std::size_t>(win.width));
    std::vector<Egm96Row> geoid_row(static_cast<std::size_t>(win.height));
    for (int i = 0; i < win.width; ++i) {
        geoid_column[static_cast<std::size_t>(i)] =
            egm96_column(lonlat(g.x(win.column0 + i), g.y(win.row0)).lon);
    }
    for (int j = 0; j < win.height; ++j) {
        geoid_row[static_cast<std::size_t>(j)] =
            egm96_row(lonlat(g.x(win.column0), g.y(win.row0 + j)).lat);
    }
    for (int j = 0; j < win.height; ++j) {
        for (int i = 0; i < win.width; ++i) {
            const std::size_t k = static_cast<std::size_t>(j) * win.width + i;
            const double v = win.ortho[k];
            win.valid[k] = std::isnan(v) ? 0 : 1;
            win.ortho[k] = std::isnan(v) ? 0.0 : v;
            if (!std::isnan(v) && ellipsoidal) {
                // Voids are filled in orthometric heights, so data-free areas lie on the geoid.
                win.ortho[k] -= egm96_at(geoid_column[static_cast<std::size_t>(i)],
                                         geoid_row[static_cast<std::size_t>(j)]);
            }
        }
    }
    fill_voids(win.ortho, win.valid, win.width, win.height, m, 0.0);

    TileRaster& r = t.raster;
    r.id = id;
    r.scheme = scheme;
    r.bounds = tile_bounds(scheme, id);
    r.size = static_cast<int>(std::max(w, h));
    r.frame = {g.x(i0), g.y(j0), g.dx, g.dy, g.lonlat};
    r.grid.width = static_cast<int>(w);
    r.grid.height = static_cast<int>(h);
    r.grid.heights.resize(static_cast<std::size_t>(w * h));
    std::vector<std::uint8_t> valid(r.grid.heights.size());
    bool all_valid = true;
    for (std::int64_t j = 0; j < h; ++j) {
        const Egm96Row& geoid_j = geoid_row[static_cast<std::size_t>(j + m)];
        for (std::int64_t i = 0; i < w; ++i) {
            const std::int64_t gi = i0 + i, gj = j0 + j;
            const bool measured = win.is_valid(gi, gj);
            double z;
            if (measured && ellipsoidal) {
                z = win.at(win.source, gi, gj); // the source's own ellipsoidal height
            } else {
                z = win.at(win.ortho, gi, gj) +
                    egm96_at(geoid_column[static_cast<std::size_t>(i + m)], geoid_j);
            }
            const std::size_t k = static_cast<std::size_t>(j * w + i);
            r.grid.heights[k] = static_cast<float>(z);
            valid[k] = measured ? 1 : 0;
            all_valid = all_valid && measured;
        }
    }
    if (!all_valid) {
        r.grid.valid = std::move(valid);
    }

    // Border profiles: linear between the pixels either side of the line.
    const auto column_profile = [&](BorderProfile& p, std::int64_t west_pixel, double x) {
        const double t_x = (x - g.x(west_pixel)) / (g.x(west_pixel + 1) - g.x(west_pixel));
        for (std::int64_t j = 0; j < h; ++j) {
            const std::int64_t gj = j0 + j;
            const Value v = between<2>(win,
                                       {{{west_pixel, gj}, {west_pixel + 1, gj}}},
                                       {1 - t_x, t_x},
                                       undulation(x, g.y(gj)),
                                       datum);
            p.heights.push_back(v.height);
            p.valid.push_back(v.valid ? 1 : 0);
        }
    };
    const auto row_profile = [&](BorderProfile& p, std::int64_t north_pixel, double y) {
        const double t_y = (g.y(north_pixel) - y) / (g.y(north_pixel) - g.y(north_pixel + 1));
        for (std::int64_t i = 0; i < w; ++i) {
            const std::int64_t gi = i0 + i;
            const Value v = between<2>(win,
                                       {{{gi, north_pixel}, {gi, north_pixel + 1}}},
                                       {1 - t_y, t_y},
                                       undulation(g.x(gi), y),
                                       datum);
            p.heights.push_back(v.height);
            p.valid.push_back(v.valid ? 1 : 0);
        }
    };
    if (t.sides[kWest].present) {
        column_profile(t.sides[kWest], i0 - 1, xw);
    }
    if (t.sides[kEast].present) {
        column_profile(t.sides[kEast], i1, xe);
    }
    if (t.sides[kNorth].present) {
        row_profile(t.sides[kNorth], j0 - 1, yn);
    }
    if (t.sides[kSouth].present) {
        row_profile(t.sides[kSouth], j1, ys);
    }
    // Corners where two strips meet: bilinear between the four pixels around the corner.
    const auto corner =
        [&](int k, std::int64_t west_pixel, std::int64_t north_pixel, double x, double y) {
            const double tx = (x - g.x(west_pixel)) / (g.x(west_pixel + 1) - g.x(west_pixel));
            const double ty = (g.y(north_pixel) - y) / (g.y(north_pixel) - g.y(north_pixel + 1));
            const Value v = between<4>(win,
                                       {{{west_pixel, north_pixel},
                                         {west_pixel + 1, north_pixel},
                                         {west_pixel, north_pixel + 1},
                                         {west_pixel + 1, north_pixel + 1}}},
                                       {(1 - tx) * (1 - ty), tx * (1 - ty), (1 - tx) * ty, tx * ty},
                                       undulation(x, y),
                                       datum);
            t.corner[static_cast<std::size_t>(k)] = v.height;
            t.corner_valid[static_cast<std::size_t>(k)] = v.valid ? 1 : 0;
        };
    const bool W_ = t.sides[kWest].present, E_ = t.sides[kEast].present;
    const bool N_ = t.sides[kNorth].present, S_ = t.sides[kSouth].present;
    if (W_ && N_) {
        corner(0, i0 - 1, j0 - 1, xw, yn);
    }
    if (E_ && N_) {
        corner(1, i1, j0 - 1, xe, yn);
    }
    if (W_ && S_) {
        corner(2, i0 - 1, j1, xw, ys);
    }
    if (E_ && S_) {
        corner(3, i1, j1, xe, ys);
    }
    return t;
}

TileMesh mesh_pixel_tile(const PixelTile& t,
                         const ErrorBudget& budget,
                         bool drop_voids,
                         int threads,
                         bool check_error,
                         core::Effort effort) {
    const core::HeightGrid& grid = t.raster.grid;
    const int w = grid.width, h = grid.height;
    TB_ASSERT(budget.max_edge == 0 || budget.max_edge >= kMinPixelEdge - 1e-12);
    const double core_edge =
        budget.max_edge > 0
            ? std::max(core::kMinMaxEdge, std::sqrt(budget.max_edge * budget.max_edge - 1))
            : 0.0;
    const int max_step = core::max_step_for(core_edge);
    const bool present[4] = {t.sides[kWest].present,
                             t.sides[kEast].present,
                             t.sides[kNorth].present,
                             t.sides[kSouth].present};

    // Vertices by key (column, row) in the block: -1 and w are the west and east border lines,
    // -1 and h the north and south ones.
    TileMesh out;
    bool dropped = false; // a triangle was left out (voids, or a strip of no width)
    // Vertices by key (column + 1, row + 1): a hash map, as a tile has thousands of them.
    std::unordered_map<std::uint64_t, core::Index> index;
    const auto key = [](int c, int r) {
        return std::uint64_t{static_cast<std::uint32_t>(c + 1)} << 32 |
               static_cast<std::uint32_t>(r + 1);
    };
    const auto is_line = [w, h](int c, int r) { return c < 0 || c >= w || r < 0 || r >= h; };
    const auto value_of = [&](int c, int r) -> Value {
        if (!is_line(c, r)) {
            return {grid.at(c, r), grid.is_valid(c, r)};
        }
        if (is_line(c, 0) && is_line(0, r)) { // a corner
            const int k = (c < 0 ? 0 : 1) + (r < 0 ? 0 : 2);
            return {t.corner[static_cast<std::size_t>(k)],
                    t.corner_valid[static_cast<std::size_t>(k)] != 0};
        }
        const BorderProfile& p = c < 0    ? t.sides[kWest]
                                 : c >= w ? t.sides[kEast]
                                 : r < 0  ? t.sides[kNorth]
                                          : t.sides[kSouth];
        const std::size_t along = static_cast<std::size_t>(c < 0 || c >= w ? r : c);
        return {p.heights[along], p.valid[along] != 0};
    };
    const auto vertex = [&](int c, int r) {
        const auto [it, fresh] = index.try_emplace(key(c, r), core::kNone);
        if (fresh) {
            const double x = c < 0    ? t.edge[kWest]
                             : c >= w ? t.edge[kEast]
                                      : t.pixels.x(t.column0 + c);
            const double y = r < 0    ? t.edge[kNorth]
                             : r >= h ? t.edge[kSouth]
                                      : t.pixels.y(t.row0 + r);
            // On a line shared with a neighbour: a border line, or the block's own edge where no
            // strip lies beyond it (a pixel line on the tile border, or the source's edge).
            const bool shared = is_line(c, r) || (c == 0 && !present[kWest]) ||
                                (c == w - 1 && !present[kEast]) || (r == 0 && !present[kNorth]) ||
                                (r == h - 1 && !present[kSouth]);
            double nx = x, ny = y;
            if (t.pixels.lonlat) {
                lonlat_to_native(t.raster.scheme, {x, y}, nx, ny);
            }
            it->second = out.add(nx, ny, value_of(c, r).height, shared);
        }
        return it->second;
    };
    const auto triangle = [&](core::Index a, core::Index b, core::Index c) {
        const double area = (out.x[b] - out.x[a]) * (out.y[c] - out.y[a]) -
                            (out.x[c] - out.x[a]) * (out.y[b] - out.y[a]);
        if (area == 0) {
            // A strip whose width rounds away in native coordinates (a pixel centre a hair from
            // the border line) covers nothing: left out, it leaves no visible gap.
            dropped = true;
            return;
        }
        if (area > 0) {
            out.triangles.insert(out.triangles.end(), {a, b, c});
        } else {
            out.triangles.insert(out.triangles.end(), {a, c, b});
        }
    };

    // The block: core's mesh, or for a block one pixel thin the optimal fit of its one line.
    std::vector<int> inner[4]; // positions along each side of the block, increasing
    if (w >= 2 && h >= 2) {
        // Small pages: many tiles are meshed at once (core::TriangulateOptions::huge_pages).
        const core::Mesh mesh =
            core::triangulate_strips(grid,
                                     core::TriangulateOptions{.eps = budget.mesh_eps,
                                                              .lock_border = true,
                                                              .max_edge = core_edge,
                                                              .check_error = check_error,
                                                              .huge_pages = false,
                                                              .effort = effort},
                                     2,
                                     threads,
                                     run_on_helper);
        // The block's vertices, and room for those the border lines add.
        index.reserve(mesh.points.size() + static_cast<std::size_t>(w + h) / 2);
        std::vector<core::Index> id(mesh.points.size());
        for (std::size_t v = 0; v < mesh.points.size(); ++v) {
            const core::GridPoint p = mesh.points[v];
            id[v] = vertex(p.x, p.y);
            if (p.x == 0) {
                inner[kWest].push_back(p.y);
            }
            if (p.x == w - 1) {
                inner[kEast].push_back(p.y);
            }
            if (p.y == 0) {
                inner[kNorth].push_back(p.x);
            }
            if (p.y == h - 1) {
                inner[kSouth].push_back(p.x);
            }
        }
        for (std::size_t tr = 0; tr < mesh.triangle_count(); ++tr) {
            const core::Index a = mesh.triangles[3 * tr], b = mesh.triangles[3 * tr + 1],
                              c = mesh.triangles[3 * tr + 2];
            if (!drop_voids ||
                holds_valid_sample(grid, mesh.points[a], mesh.points[b], mesh.points[c])) {
                triangle(id[a], id[b], id[c]);
            } else {
                dropped = true;
            }
        }
        for (auto& side : inner) {
            std::sort(side.begin(), side.end());
        }
    } else {
        const bool column = w == 1;
        const int n = column ? h : w;
        std::vector<int> line{0};
        if (n >= 2) {
            std::vector<float> z(static_cast<std::size_t>(n));
            std::vector<std::uint8_t> valid(static_cast<std::size_t>(n));
            for (int k = 0; k < n; ++k) {
                z[static_cast<std::size_t>(k)] = column ? grid.at(0, k) : grid.at(k, 0);
                valid[static_cast<std::size_t>(k)] =
                    (column ? grid.is_valid(0, k) : grid.is_valid(k, 0)) ? 1 : 0;
            }
            line = core::fit_breakpoints(z, valid, budget.mesh_eps, max_step);
        }
        const std::vector<int> ends{0};
        inner[kWest] = inner[kEast] = column ? line : ends;
        inner[kNorth] = inner[kSouth] = column ? ends : line;
        for (int k : line) {
            vertex(column ? 0 : k, column ? k : 0);
        }
    }

    // Strips: between the block's side (inner) and the border line (outer), each triangle with
    // two vertices on one line and one on the other, in order along the lines.
    const std::size_t first_strip_triangle = out.triangles.size();
    for (int s = 0; s < 4; ++s) {
        if (!present[s]) {
            continue;
        }
        const BorderProfile& p = t.sides[static_cast<std::size_t>(s)];
        const std::vector<int> outer =
            p.heights.size() >= 2
                ? core::fit_breakpoints(p.heights, p.valid, budget.mesh_eps, max_step)
                : std::vector<int>{0};
        const bool vertical = s == kWest || s == kEast;
        const int fixed_inner = s == kWest ? 0 : s == kEast ? w - 1 : s == kNorth ? 0 : h - 1;
        const int fixed_outer = s == kWest ? -1 : s == kEast ? w : s == kNorth ? -1 : h;
        const auto at = [vertical, &vertex](int along, int fixed) {
            return vertical ? vertex(fixed, along) : vertex(along, fixed);
        };
        const std::vector<int>& in = inner[s];
        std::size_t a = 0, b = 0;
        while (a + 1 < in.size() || b + 1 < outer.size()) {
            const bool step_inner =
                b + 1 >= outer.size() || (a + 1 < in.size() && in[a + 1] <= outer[b + 1]);
            if (step_inner) {
                triangle(
                    at(in[a], fixed_inner), at(in[a + 1], fixed_inner), at(outer[b], fixed_outer));
                ++a;
            } else {
                triangle(at(in[a], fixed_inner),
                         at(outer[b], fixed_outer),
                         at(outer[b + 1], fixed_outer));
                ++b;
            }
        }
    }
    // Corners where two strips meet: the square between the block's corner pixel, the corner of
    // the tile and the two border lines' ends.
    const int cw[4] = {-1, w, -1, w}, ch[4] = {-1, -1, h, h};
    const int pc[4] = {0, w - 1, 0, w - 1}, pr[4] = {0, 0, h - 1, h - 1};
    const Side xs[4] = {kWest, kEast, kWest, kEast}, ys[4] = {kNorth, kNorth, kSouth, kSouth};
    for (int k = 0; k < 4; ++k) {
        if (!present[xs[k]] || !present[ys[k]]) {
            continue;
        }
        const core::Index c = vertex(cw[k], ch[k]), p = vertex(pc[k], pr[k]);
        triangle(c, vertex(pc[k], ch[k]), p);
        triangle(c, p, vertex(cw[k], pr[k]));
    }
    // Strip and corner triangles touching a border vertex with no data beside it are dropped:
    // the neighbour decides the same for the vertices both share.
    std::vector<core::Index> kept(out.triangles.begin(),
                                  out.triangles.begin() +
                                      static_cast<std::ptrdiff_t>(first_strip_triangle));
    std::vector<std::pair<int, int>> key_of(out.vertex_count());
    for (const auto& [k, v] : index) {
        key_of[v] = {static_cast<int>(k >> 32) - 1, static_cast<int>(k & 0xFFFFFFFFu) - 1};
    }
    for (std::size_t e = first_strip_triangle; e < out.triangles.size(); e += 3) {
        bool keep = true;
        for (int q = 0; q < 3; ++q) {
            const auto [c, r] = key_of[out.triangles[e + static_cast<std::size_t>(q)]];
            keep = keep && (!drop_voids || !is_line(c, r) || value_of(c, r).valid);
        }
        if (keep) {
            kept.insert(kept.end(),
                        out.triangles.begin() + static_cast<std::ptrdiff_t>(e),
                        out.triangles.begin() + static_cast<std::ptrdiff_t>(e + 3));
        } else {
            dropped = true;
        }
    }
    out.triangles = std::move(kept);
    drop_unused_vertices(out);
    // The block's triangulation zipped to the border lines is a disk; only dropped triangles
    // can leave a vertex where two fans touch.
    if (dropped) {
        split_nonmanifold_vertices(out);
    }
    return out;
}

} // namespace tb::tiler
