// quantized-mesh-1.0 encoding (see quantized_mesh.hpp): 15-bit quantization on the tile's
// rectangle, the measured error of the quantized surface, and the tile's bytes.
#include "tiler/formats/quantized_mesh.hpp"

#include "core/error.hpp"
#include "tiler/geodesy.hpp"
#include "tiler/sources/geoid.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>

namespace tb::tiler {
namespace {

constexpr double kWgs84A = 6378137.0;
constexpr double kWgs84B = 6356752.3142451793;

// Little-endian writers.
void put_u8(std::string& out, std::uint8_t v) {
    out.push_back(static_cast<char>(v));
}
void put_u16(std::string& out, std::uint16_t v) {
    put_u8(out, static_cast<std::uint8_t>(v & 0xff));
    put_u8(out, static_cast<std::uint8_t>(v >> 8));
}
void put_u32(std::string& out, std::uint32_t v) {
    for (int k = 0; k < 4; ++k) {
        put_u8(out, static_cast<std::uint8_t>((v >> (8 * k)) & 0xff));
    }
}
void put_f32(std::string& out, float f) {
    std::uint32_t bits = 0;
    std::memcpy(&bits, &f, sizeof bits);
    put_u32(out, bits);
}
void put_f64(std::string& out, double d) {
    std::uint64_t bits = 0;
    std::memcpy(&bits, &d, sizeof bits);
    for (int k = 0; k < 8; ++k) {
        put_u8(out, static_cast<std::uint8_t>((bits >> (8 * k)) & 0xff));
    }
}

std::uint32_t get_u32(std::string_view in, std::size_t pos) {
    if (pos + 4 > in.size()) {
        throw InputError("quantized-mesh tile: truncated at byte " + std::to_string(pos));
    }
    std::uint32_t v = 0;
    for (int k = 0; k < 4; ++k) {
        v |= static_cast<std::uint32_t>(static_cast<unsigned char>(in[pos + k])) << (8 * k);
    }
    return v;
}

std::uint16_t zig_zag(int value) {
    return static_cast<std::uint16_t>((value << 1) ^ (value >> 31));
}

// Quantizes x in [lo, hi] to 0..32767; exactly lo and hi (border lines) map to 0 and 32767 and
// everything else stays strictly inside.
std::uint16_t quantize_coordinate(double x, double lo, double hi) {
    if (x == lo) {
        return 0;
    }
    if (x == hi) {
        return kQuantizedMax;
    }
    const double q = std::round((x - lo) / (hi - lo) * kQuantizedMax);
    return static_cast<std::uint16_t>(std::clamp(q, 1.0, kQuantizedMax - 1.0));
}

// A point the drawn surface is judged at, in continuous u/v units.
struct Probe {
    double u = 0, v = 0, h = 0;
    double lon = 0, lat = 0;
};

// Triangles of a surface mesh bucketed on a square grid over u/v, for point location.
class TriangleBuckets {
public:
    // About two triangles per cell. The cells' lists are laid end to end (a count, then a
    // fill, each triangle in ascending order): one allocation where a list per cell made tens
    // of millions over a globe-terrain build.
    // Everything error_at needs is copied out of q, which need not outlive the buckets.
    explicit TriangleBuckets(const SurfaceMesh& q)
        : cells_per_side_(std::clamp(
              static_cast<int>(std::sqrt(static_cast<double>(q.triangles.size()) / 6)), 16, 1024)) {
        const std::size_t cells = static_cast<std::size_t>(cells_per_side_) * cells_per_side_;
        const std::size_t triangles = q.triangles.size() / 3;
        // Each triangle's corners, heights and area, read once here instead of through the
        // index for every probe, and its box of cells, found once for both passes. A triangle
        // of zero area holds no probe and is left out.
        corners_.resize(triangles);
        std::vector<std::array<int, 4>> box(triangles); // first column, last, first row, last
        for (std::size_t t = 0; t < triangles; ++t) {
            const std::uint32_t a = q.triangles[3 * t], b = q.triangles[3 * t + 1],
                                c = q.triangles[3 * t + 2];
            Corners& k = corners_[t];
            k.ua = q.u[a], k.va = q.v[a], k.ub = q.u[b], k.vb = q.v[b], k.uc = q.u[c],
            k.vc = q.v[c], k.ha = q.h[a], k.hb = q.h[b], k.hc = q.h[c];
            k.area = (k.ub - k.ua) * (k.vc - k.va) - (k.uc - k.ua) * (k.vb - k.va);
            if (k.area == 0) {
                box[t] = {0, -1, 0, -1};
                continue;
            }
            k.u0 = std::min({k.ua, k.ub, k.uc}), k.u1 = std::max({k.ua, k.ub, k.uc});
            k.v0 = std::min({k.va, k.vb, k.vc}), k.v1 = std::max({k.va, k.vb, k.vc});
            box[t] = {cell(k.u0), cell(k.u1), cell(k.v0), cell(k.v1)};
            // A probe the exact test below accepts has weights of at least kTol, so it lies
            // within |kTol| times the triangle's height (at most the tile's diagonal, 46,341
            // units) of it: well inside the box widened by kSlack.
            k.u0 -= kSlack, k.u1 += kSlack, k.v0 -= kSlack, k.v1 += kSlack;
        }
        first_.assign(cells + 1, 0);
        const auto each_cell = [&](std::size_t t, auto&& f) {
            const auto& [cx0, cx1, cy0, cy1] = box[t];
            for (int cy = cy0; cy <= cy1; ++cy) {
                for (int cx = cx0; cx <= cx1; ++cx) {
                    f(static_cast<std::size_t>(cy) * static_cast<std::size_t>(cells_per_side_) +
                      static_cast<std::size_t>(cx));
                }
            }
        };
        for (std::size_t t = 0; t < triangles; ++t) {
            each_cell(t, [&](std::size_t c) { ++first_[c + 1]; });
        }
        for (std::size_t c = 0; c < cells; ++c) {
            first_[c + 1] += first_[c];
        }
        members_.resize(first_[cells]);
        std::vector<std::uint32_t> at(first_.begin(), first_.end() - 1);
        for (std::size_t t = 0; t < triangles; ++t) {
            each_cell(t, [&](std::size_t c) { members_[at[c]++] = static_cast<std::uint32_t>(t); });
        }
    }

    // The largest |drawn - p.h| over the triangles holding p, and the triangle giving it (with
    // p's smallest barycentric weight in it); false when none holds p.
    bool error_at(const Probe& p,
                  double& error,
                  std::uint32_t* where = nullptr,
                  std::array<double, 3>* weights = nullptr) const {
        bool found = false;
        error = 0;
        const std::size_t at = static_cast<std::size_t>(cell(p.v)) * cells_per_side_ +
                               static_cast<std::size_t>(cell(p.u));
        for (std::uint32_t k = first_[at]; k < first_[at + 1]; ++k) {
            const std::uint32_t t = members_[k];
            const Corners& c = corners_[t];
            if (p.u < c.u0 || p.u > c.u1 || p.v < c.v0 || p.v > c.v1) {
                continue;
            }
            const double na = (c.ub - p.u) * (c.vc - p.v) - (c.uc - p.u) * (c.vb - p.v);
            const double nb = (c.uc - p.u) * (c.va - p.v) - (c.ua - p.u) * (c.vc - p.v);
            // Most triangles of a cell do not hold p: a weight clearly below kTol (twice as far
            // below 0, so that the division could not bring it back) rules one out before the
            // divisions; any other goes through the exact test below.
            const double margin = 2 * kTol * std::abs(c.area);
            if ((c.area > 0 ? na : -na) < margin || (c.area > 0 ? nb : -nb) < margin) {
                continue;
            }
            const double wa = na / c.area;
            const double wb = nb / c.area;
            const double wc = 1 - wa - wb;
            if (wa < kTol || wb < kTol || wc < kTol) {
                continue;
            }
            const double h = wa * c.ha + wb * c.hb + wc * c.hc;
            const double e = std::abs(h - p.h);
            if (!found || e > error) {
                error = e;
                if (where) {
                    *where = t;
                }
                if (weights) {
                    *weights = {wa, wb, wc};
                }
            }
            found = true;
        }
        return found;
    }

private:
    int cell(double w) const {
        return std::clamp(
            static_cast<int>(w * cells_per_side_ / (kQuantizedMax + 1.0)), 0, cells_per_side_ - 1);
    }
    int cells_per_side_;
    static constexpr double kTol = -1e-9; // the least barycentric weight of a point held
    static constexpr double kSlack = 1e-3;
    struct Corners {
        double ua, va, ub, vb, uc, vc, area, ha, hb, hc;
        double u0, u1, v0, v1; // the bounding box, widened by kSlack
    };
    std::vector<Corners> corners_;     // per triangle
    std::vector<std::uint32_t> first_; // cell c's triangles are members_[first_[c], first_[c + 1])
    std::vector<std::uint32_t> members_;
};

} // namespace

double QuantizedMesh::lon(std::size_t i) const {
    return bounds.west + (bounds.east - bounds.west) * (u[i] / double{kQuantizedMax});
}
double QuantizedMesh::lat(std::size_t i) const {
    return bounds.south + (bounds.north - bounds.south) * (v[i] / double{kQuantizedMax});
}
double QuantizedMesh::height(std::size_t i) const {
    const double lo = min_height, hi = max_height;
    return lo + (hi - lo) * (h[i] / double{kQuantizedMax});
}

SurfaceMesh to_surface(const QuantizedMesh& q) {
    SurfaceMesh out;
    out.bounds = q.bounds;
    const std::size_t n = q.u.size();
    out.u.resize(n), out.v.resize(n), out.h.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        out.u[i] = q.u[i], out.v[i] = q.v[i], out.h[i] = q.height(i);
    }
    out.triangles = q.triangles;
    return out;
}

QuantizedMesh quantize_mesh(const TileMesh& mesh, const LonLatBox& bounds) {
    QuantizedMesh q;
    q.bounds = bounds;
    const std::size_t n = mesh.vertex_count();
    q.u.resize(n), q.v.resize(n), q.h.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        q.u[i] = quantize_coordinate(mesh.x[i], bounds.west, bounds.east);
        q.v[i] = quantize_coordinate(mesh.y[i], bounds.south, bounds.north);
    }
    q.triangles.assign(mesh.triangles.begin(), mesh.triangles.end());

    // Moving a vertex moves the surface at the vertex's own place by the slope times the move,
    // which is what breaks eps on steep ground; pixel-tile vertices sit on the samples the
    // mesher fitted. So an interior vertex that quantization moves gets the height that puts the
    // moved surface back through its old place and height (two Gauss-Seidel passes over the
    // vertices, as its neighbours move too). Vertices on the border lines keep their heights, so
    // that both tiles beside a line draw it alike.
    std::vector<double> z(mesh.z.begin(), mesh.z.end());
    const double z_lo = n ? *std::min_element(z.begin(), z.end()) : 0;
    const double z_hi = n ? *std::max_element(z.begin(), z.end()) : 0;
    std::vector<std::uint32_t> start(n + 1, 0), fan(mesh.triangles.size());
    for (core::Index i : mesh.triangles) {
        ++start[i + 1];
    }
    for (std::size_t i = 0; i < n; ++i) {
        start[i + 1] += start[i];
    }
    {
        std::vector<std::uint32_t> at(start.begin(), start.end() - 1);
        for (std::size_t e = 0; e < mesh.triangles.size(); ++e) {
            fan[at[mesh.triangles[e]]++] = static_cast<std::uint32_t>(e);
        }
    }
    const double su = kQuantizedMax / (bounds.east - bounds.west);
    const double sv = kQuantizedMax / (bounds.north - bounds.south);
    for (int pass = 0; pass < 2; ++pass) {
        for (std::size_t i = 0; i < n; ++i) {
            if (q.u[i] == 0 || q.u[i] == kQuantizedMax || q.v[i] == 0 || q.v[i] == kQuantizedMax) {
                continue;
            }
            const double pu = (mesh.x[i] - bounds.west) * su, pv = (mesh.y[i] - bounds.south) * sv;
            for (std::uint32_t k = start[i]; k < start[i + 1]; ++k) {
                // The corner of the triangle at i, then the two others.
                const std::size_t e = fan[k], t = e / 3 * 3;
                const core::Index b = mesh.triangles[t + (e - t + 1) % 3],
                                  c = mesh.triangles[t + (e - t + 2) % 3];
                const double ua = q.u[i], va = q.v[i], ub = q.u[b], vb = q.v[b], uc = q.u[c],
                             vc = q.v[c];
                const double area = (ub - ua) * (vc - va) - (uc - ua) * (vb - va);
                if (area <= 0) {
                    continue;
                }
                const double wa = ((ub - pu) * (vc - pv) - (uc - pu) * (vb - pv)) / area;
                const double wb = ((uc - pu) * (va - pv) - (ua - pu) * (vc - pv)) / area;
                const double wc = 1 - wa - wb;
                if (wa < 0 || wb < 0 || wc < 0) {
                    continue;
                }
                // Only where the vertex carries most of the point (near it, as a half step is),
                // and within the mesh's own heights: on a coarse tile a step is hundreds of
                // metres, and the height that would put the surface back can lie far outside
                // them (7,766 m on a zoom-0 tile of a DEM below 1,900 m), and outside the
                // bounding volumes the tilesets publish. What is left is measured.
                if (wa > 0.5) {
                    z[i] = std::clamp((mesh.z[i] - wb * z[b] - wc * z[c]) / wa, z_lo, z_hi);
                }
                break;
            }
        }
    }
    float lo = std::numeric_limits<float>::infinity(), hi = -lo;
    for (double h : z) {
        lo = std::min(lo, static_cast<float>(h)), hi = std::max(hi, static_cast<float>(h));
    }
    if (n == 0) {
        lo = hi = 0;
    }
    q.min_height = lo, q.max_height = hi;
    const double range = static_cast<double>(hi) - lo;
    for (std::size_t i = 0; i < n; ++i) {
        q.h[i] = range > 0 ? static_cast<std::uint16_t>(std::clamp(
                                 std::round((z[i] - lo) / range * kQuantizedMax), 0.0, 32767.0))
                           : 0;
    }
    return q;
}

namespace {

// The valid samples of raster.grid and the check points, in the tile's u/v units, made one at
// a time instead of kept in a list: a coarse globe-terrain tile holds millions of samples, and
// the list (40 bytes a probe) took about 200 MB on each build thread at once.
class Probes {
public:
    Probes(const LonLatBox& b, const TileRaster& raster, const std::vector<CheckPoint>& points)
        : b_(b), raster_(raster), points_(points) {
        const core::HeightGrid& g = raster.grid;
        lon_.resize(static_cast<std::size_t>(g.width));
        lat_.resize(static_cast<std::size_t>(g.height));
        for (int i = 0; i < g.width; ++i) {
            lon_[static_cast<std::size_t>(i)] = grid_to_lonlat(raster, i, 0).lon;
        }
        for (int j = 0; j < g.height; ++j) {
            lat_[static_cast<std::size_t>(j)] = grid_to_lonlat(raster, 0, j).lat;
        }
    }

    // Calls f(handle, probe) for every probe, samples in raster order, then the check points;
    // at(handle) makes that probe again.
    template <typename F> void for_each(F&& f) const {
        const core::HeightGrid& g = raster_.grid;
        const auto w = static_cast<std::size_t>(g.width);
        for (int j = 0; j < g.height; ++j) {
            for (int i = 0; i < g.width; ++i) {
                if (g.is_valid(i, j)) {
                    const std::size_t handle =
                        static_cast<std::size_t>(j) * w + static_cast<std::size_t>(i);
                    f(handle, sample(i, j));
                }
            }
        }
        const std::size_t first = w * static_cast<std::size_t>(g.height);
        for (std::size_t c = 0; c < points_.size(); ++c) {
            f(first + c, check_point(c));
        }
    }

    // The handle of the first check point (samples come before).
    std::size_t first_point() const {
        return static_cast<std::size_t>(raster_.grid.width) *
               static_cast<std::size_t>(raster_.grid.height);
    }

    Probe at(std::size_t handle) const {
        const auto w = static_cast<std::size_t>(raster_.grid.width);
        const std::size_t first = w * static_cast<std::size_t>(raster_.grid.height);
        if (handle >= first) {
            return check_point(handle - first);
        }
        return sample(static_cast<int>(handle % w), static_cast<int>(handle / w));
    }

private:
    Probe make(const LonLat& p, double h) const {
        return Probe{(p.lon - b_.west) / (b_.east - b_.west) * kQuantizedMax,
                     (p.lat - b_.south) / (b_.north - b_.south) * kQuantizedMax,
                     h,
                     p.lon,
                     p.lat};
    }
    Probe sample(int i, int j) const {
        return make({lon_[static_cast<std::size_t>(i)], lat_[static_cast<std::size_t>(j)]},
                    raster_.grid.at(i, j));
    }
    Probe check_point(std::size_t c) const {
        const CheckPoint& p = points_[c];
        return make(grid_to_lonlat(raster_, p.column, p.row), p.height);
    }

    const LonLatBox& b_;
    const TileRaster& raster_;
    const std::vector<CheckPoint>& points_;
    std::vector<double> lon_, lat_;
};

// The cells' bound (cell_check.hpp) on a surface mesh, its vertices taken to raster's grid.
CellsVerdict surface_cells_error(const SurfaceMesh& q,
                                 const TileRaster& raster,
                                 const std::vector<CheckCell>& cells) {
    if (cells.empty()) {
        return {};
    }
    const LonLatBox& b = q.bounds;
    std::vector<std::array<double, 3>> grid(q.u.size());
    for (std::size_t i = 0; i < q.u.size(); ++i) {
        const LonLat p{b.west + q.u[i] / kQuantizedMax * (b.east - b.west),
                       b.south + q.v[i] / kQuantizedMax * (b.north - b.south)};
        lonlat_to_grid(raster, p, grid[i][0], grid[i][1]);
        grid[i][2] = q.h[i];
    }
    return cells_error(GridSurface{grid, q.triangles}, cells);
}

double worst_error(const SurfaceMesh& q, const Probes& probes, std::size_t* missed) {
    const TriangleBuckets buckets(q);
    double worst = 0;
    std::size_t outside = 0;
    probes.for_each([&](std::size_t, const Probe& p) {
        double e = 0;
        if (buckets.error_at(p, e)) {
            worst = std::max(worst, e);
        } else {
            ++outside;
        }
    });
    if (missed) {
        *missed = outside;
    }
    return worst;
}

} // namespace

double quantized_error(const QuantizedMesh& q,
                       const TileRaster& raster,
                       const std::vector<CheckPoint>& points,
                       std::size_t* uncovered,
                       const std::vector<CheckCell>& cells) {
    return surface_error(to_surface(q), raster, points, uncovered, cells);
}

double surface_error(const SurfaceMesh& mesh,
                     const TileRaster& raster,
                     const std::vector<CheckPoint>& points,
                     std::size_t* uncovered,
                     const std::vector<CheckCell>& cells) {
    const double error = worst_error(mesh, Probes(mesh.bounds, raster, points), uncovered);
    return std::max(error, surface_cells_error(mesh, raster, cells).error);
}

QuantizedMesh quantize_within(TileMesh& mesh,
                              const LonLatBox& bounds,
                              const TileRaster& raster,
                              const std::vector<CheckPoint>& points,
                              double allowed,
                              double& error,
                              std::size_t* uncovered,
                              const std::vector<CheckCell>& cells) {
    const Probes probes(bounds, raster, points);
    constexpr int kRounds = 8;
    constexpr double kClear = 1e-3; // a weight below this puts the sample on an edge
    constexpr std::uint32_t kNoTriangle = ~std::uint32_t{0};
    for (int round = 0;; ++round) {
        QuantizedMesh q = quantize_mesh(mesh, bounds);
        // Per triangle, its worst sample past `allowed` off the border lines (a vertex there
        // would be missing in the tile beside) and off the triangle's corners.
        const TriangleBuckets buckets(to_surface(q));
        struct Worst {
            double error = 0;
            std::size_t probe = 0;
            std::array<double, 3> w{};
        };
        std::vector<Worst> worst(mesh.triangle_count());
        error = 0;
        std::size_t outside = 0;
        probes.for_each([&](std::size_t k, const Probe& p) {
            double e = 0;
            std::uint32_t t = 0;
            std::array<double, 3> w{};
            if (!buckets.error_at(p, e, &t, &w)) {
                ++outside;
                return;
            }
            error = std::max(error, e);
            const int on_edges = (w[0] < kClear) + (w[1] < kClear) + (w[2] < kClear);
            // Check points (source pixels off the lattice) are measured, never made vertices:
            // a lattice coarser than the pixels misses them by its own coarseness, which
            // inserting pixel after pixel cannot mend (a zoom-7 tile grew to 384,409 triangles).
            const bool movable = k < probes.first_point() && p.lon != bounds.west &&
                                 p.lon != bounds.east && p.lat != bounds.south &&
                                 p.lat != bounds.north && on_edges < 2;
            if (e > allowed && e > worst[t].error && movable) {
                worst[t] = {e, k, w};
            }
        });
        if (uncovered) {
            *uncovered = outside;
        }
        std::vector<std::uint32_t> order;
        for (std::uint32_t t = 0; t < worst.size(); ++t) {
            if (worst[t].error > 0) {
                order.push_back(t);
            }
        }
        if (error <= allowed || round + 1 == kRounds || order.empty()) {
            // The cells add no vertex (no single pixel stands for them): measured once, here.
            error = std::max(error, surface_cells_error(to_surface(q), raster, cells).error);
            return q;
        }
        std::sort(order.begin(), order.end(), [&worst](std::uint32_t a, std::uint32_t b) {
            return std::pair(worst[a].error, b) > std::pair(worst[b].error, a);
        });
        // The triangles beside the edges samples lie on: the twins of those edges, found in one
        // pass over the triangles (directed edge (b, a) of the twin of (a, b)).
        std::vector<std::pair<std::pair<core::Index, core::Index>, std::uint32_t>> twins;
        for (std::uint32_t t : order) {
            for (std::uint32_t k = 0; k < 3; ++k) {
                if (worst[t].w[k] < kClear) {
                    const core::Index a = mesh.triangles[3 * t + (k + 1) % 3],
                                      b = mesh.triangles[3 * t + (k + 2) % 3];
                    twins.push_back({{b, a}, kNoTriangle});
                }
            }
        }
        std::sort(twins.begin(), twins.end());
        for (std::uint32_t t = 0; t < mesh.triangle_count() && !twins.empty(); ++t) {
            for (std::uint32_t k = 0; k < 3; ++k) {
                const std::pair<core::Index, core::Index> e{mesh.triangles[3 * t + k],
                                                            mesh.triangles[3 * t + (k + 1) % 3]};
                const auto it =
                    std::lower_bound(twins.begin(), twins.end(), std::pair(e, std::uint32_t{0}));
                if (it != twins.end() && it->first == e) {
                    it->second = t;
                }
            }
        }
        const auto twin_of = [&twins](core::Index a, core::Index b) {
            const std::pair<core::Index, core::Index> e{b, a};
            const auto it =
                std::lower_bound(twins.begin(), twins.end(), std::pair(e, std::uint32_t{0}));
            return it != twins.end() && it->first == e ? it->second : kNoTriangle;
        };
        std::vector<std::uint8_t> touched(mesh.triangle_count(), 0);
        for (std::uint32_t t : order) {
            if (touched[t]) {
                continue;
            }
            const Probe p = probes.at(worst[t].probe);
            const auto& w = worst[t].w;
            const core::Index tri[3] = {
                mesh.triangles[3 * t], mesh.triangles[3 * t + 1], mesh.triangles[3 * t + 2]};
            int edge = -1; // the corner opposite the edge the sample lies on
            for (int k = 0; k < 3; ++k) {
                if (w[static_cast<std::size_t>(k)] < kClear) {
                    edge = k;
                }
            }
            if (edge < 0) {
                // Inside: three triangles around the sample.
                const core::Index v = mesh.add(p.lon, p.lat, static_cast<float>(p.h), false);
                mesh.triangles[3 * t + 2] = v;
                mesh.triangles.insert(mesh.triangles.end(), {tri[1], tri[2], v, tri[2], tri[0], v});
                touched[t] = 1;
                continue;
            }
            // On the edge (a, b) opposite corner r: (a, b, r) and its twin (b, a, s) become
            // (a, v, r), (v, b, r), (b, v, s), (v, a, s).
            const core::Index r = tri[edge], a = tri[(edge + 1) % 3], b = tri[(edge + 2) % 3];
            const std::uint32_t t2 = twin_of(a, b);
            if (t2 == kNoTriangle || touched[t2]) {
                continue;
            }
            core::Index s2 = 0;
            for (std::uint32_t k = 0; k < 3; ++k) {
                const core::Index c = mesh.triangles[3 * t2 + k];
                if (c != a && c != b) {
                    s2 = c;
                }
            }
            const core::Index v = mesh.add(p.lon, p.lat, static_cast<float>(p.h), false);
            mesh.triangles[3 * t] = a;
            mesh.triangles[3 * t + 1] = v;
            mesh.triangles[3 * t + 2] = r;
            mesh.triangles[3 * t2] = b;
            mesh.triangles[3 * t2 + 1] = v;
            mesh.triangles[3 * t2 + 2] = s2;
            mesh.triangles.insert(mesh.triangles.end(), {v, b, r, v, a, s2});
            touched[t] = touched[t2] = 1;
        }
    }
}

bool horizon_occlusion_point(const std::array<double, 3>& direction,
                             const std::vector<std::array<double, 3>>& points,
                             double min_height,
                             std::array<double, 3>& out) {
    double ra = kWgs84A, rb = kWgs84B;
    if (min_height < 0 && kWgs84B > -min_height) {
        ra += min_height, rb += min_height;
    }
    const std::array<double, 3> radii{ra, ra, rb};
    std::array<double, 3> d{};
    double len = 0;
    for (int k = 0; k < 3; ++k) {
        d[k] = direction[k] / radii[k];
        len += d[k] * d[k];
    }
    len = std::sqrt(len);
    for (double& c : d) {
        c /= len;
    }
    double best = 0;
    for (const auto& p : points) {
        std::array<double, 3> s{};
        double mag2 = 0;
        for (int k = 0; k < 3; ++k) {
            s[k] = p[k] / radii[k];
            mag2 += s[k] * s[k];
        }
        double mag = std::sqrt(mag2);
        for (double& c : s) {
            c /= mag;
        }
        // Points below the ellipsoid count as on it.
        mag2 = std::max(1.0, mag2);
        mag = std::max(1.0, mag);
        const double cos_alpha = s[0] * d[0] + s[1] * d[1] + s[2] * d[2];
        const double cx = s[1] * d[2] - s[2] * d[1], cy = s[2] * d[0] - s[0] * d[2],
                     cz = s[0] * d[1] - s[1] * d[0];
        const double sin_alpha = std::sqrt(cx * cx + cy * cy + cz * cz);
        const double cos_beta = 1.0 / mag;
        const double sin_beta = std::sqrt(mag2 - 1.0) * cos_beta;
        const double candidate = 1.0 / (cos_alpha * cos_beta - sin_alpha * sin_beta);
        if (candidate < 0) {
            return false;
        }
        best = std::max(best, candidate);
    }
    out = {d[0] * best, d[1] * best, d[2] * best};
    return true;
}

std::array<std::uint8_t, 2> oct_encode(const std::array<double, 3>& n) {
    const double l1 = std::abs(n[0]) + std::abs(n[1]) + std::abs(n[2]);
    double x = n[0] / l1, y = n[1] / l1;
    if (n[2] < 0) {
        const double ox = x, oy = y;
        x = (1 - std::abs(oy)) * (ox < 0 ? -1.0 : 1.0);
        y = (1 - std::abs(ox)) * (oy < 0 ? -1.0 : 1.0);
    }
    const auto snorm = [](double w) {
        return static_cast<std::uint8_t>(
            std::floor((std::clamp(w, -1.0, 1.0) * 0.5 + 0.5) * 255 + 0.5));
    };
    return {snorm(x), snorm(y)};
}

std::array<double, 3> tile_horizon_point(const std::array<double, 3>& centre,
                                         const std::vector<std::array<double, 3>>& points,
                                         double min_height) {
    std::array<double, 3> horizon{};
    if (!horizon_occlusion_point(centre, points, min_height, horizon)) {
        // Some vertex lies beyond 90 degrees of the centre's direction (a zoom 0 tile): no finite
        // point is hidden exactly when the whole tile is. A point far out along the direction is
        // hidden only from cameras in the ellipsoid's shadow cylinder behind it, from where such
        // a tile shows at most its rim.
        constexpr double kFar = 1e6;
        double len = 0;
        const double r[3] = {kWgs84A, kWgs84A, kWgs84B};
        for (int k = 0; k < 3; ++k) {
            horizon[k] = centre[k] / r[k];
            len += horizon[k] * horizon[k];
        }
        for (double& c : horizon) {
            c *= kFar / std::sqrt(len);
        }
    }
    return horizon;
}

VertexOrder first_use_order(const QuantizedMesh& q) {
    const std::size_t n = q.u.size();
    constexpr std::uint32_t kUnset = ~std::uint32_t{0};
    VertexOrder out;
    out.order.assign(n, kUnset);
    out.old_of.reserve(n);
    const auto visit = [&out](std::uint32_t i) {
        if (out.order[i] == kUnset) {
            out.order[i] = static_cast<std::uint32_t>(out.old_of.size());
            out.old_of.push_back(i);
        }
    };
    for (std::uint32_t i : q.triangles) {
        visit(i);
    }
    for (std::uint32_t i = 0; i < n; ++i) {
        visit(i);
    }
    return out;
}

std::array<std::vector<std::uint32_t>, 4> edge_lists(const QuantizedMesh& q,
                                                     const std::vector<std::uint32_t>& old_of) {
    std::array<std::vector<std::uint32_t>, 4> edges; // west, south, east, north
    for (std::uint32_t k = 0; k < old_of.size(); ++k) {
        const std::uint32_t i = old_of[k];
        if (q.u[i] == 0) {
            edges[0].push_back(k);
        }
        if (q.v[i] == 0) {
            edges[1].push_back(k);
        }
        if (q.u[i] == kQuantizedMax) {
            edges[2].push_back(k);
        }
        if (q.v[i] == kQuantizedMax) {
            edges[3].push_back(k);
        }
    }
    for (int s = 0; s < 4; ++s) {
        auto& list = edges[static_cast<std::size_t>(s)];
        const bool along_v = s == 0 || s == 2;
        std::sort(list.begin(), list.end(), [&](std::uint32_t a, std::uint32_t b) {
            const std::uint32_t ia = old_of[a], ib = old_of[b];
            return along_v ? std::pair(q.v[ia], a) < std::pair(q.v[ib], b)
                           : std::pair(q.u[ia], a) < std::pair(q.u[ib], b);
        });
    }
    return edges;
}

std::string encode_quantized_mesh(const QuantizedMesh& q, const QuantizedMeshExtras& extras) {
    const std::size_t n = q.u.size();
    TB_ASSERT(!q.triangles.empty());
    TB_ASSERT(extras.normals.empty() || extras.normals.size() == n);
    // Vertices in order of first use, so that high-water-mark codes stay small.
    const VertexOrder vo = first_use_order(q);
    const std::vector<std::uint32_t>&order = vo.order, &old_of = vo.old_of;

    // Header, from the positions a client decodes.
    std::vector<std::array<double, 3>> ecef(n);
    std::array<double, 3> lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    for (std::size_t i = 0; i < n; ++i) {
        const Ecef e = to_ecef({q.lon(i), q.lat(i), q.height(i)});
        ecef[i] = {e.x, e.y, e.z};
        for (int k = 0; k < 3; ++k) {
            lo[k] = std::min(lo[k], ecef[i][k]), hi[k] = std::max(hi[k], ecef[i][k]);
        }
    }
    const std::array<double, 3> centre{
        0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])};
    double radius = 0;
    for (const auto& p : ecef) {
        const double dx = p[0] - centre[0], dy = p[1] - centre[1], dz = p[2] - centre[2];
        radius = std::max(radius, std::sqrt(dx * dx + dy * dy + dz * dz));
    }
    const std::array<double, 3> horizon = tile_horizon_point(centre, ecef, q.min_height);
    // A header clients trust for culling and level selection: never a non-finite number (the
    // sources' outliers are nodata, see kLowestHeight).
    TB_ASSERT(std::isfinite(q.min_height) && std::isfinite(q.max_height) && std::isfinite(radius) &&
              std::isfinite(centre[0] + centre[1] + centre[2]) &&
              std::isfinite(horizon[0] + horizon[1] + horizon[2]));

    std::string out;
    const bool wide = n > 65536;
    out.reserve(88 + 4 + 6 * n + 4 + q.triangles.size() * (wide ? 4 : 2) + 2 * n + 66000);
    for (double c : centre) {
        put_f64(out, c);
    }
    put_f32(out, q.min_height);
    put_f32(out, q.max_height);
    for (double c : centre) {
        put_f64(out, c);
    }
    put_f64(out, radius);
    for (double c : horizon) {
        put_f64(out, c);
    }
    put_u32(out, static_cast<std::uint32_t>(n));
    for (const std::vector<std::uint16_t>* values : {&q.u, &q.v, &q.h}) {
        int previous = 0;
        for (std::uint32_t k = 0; k < n; ++k) {
            const int value = (*values)[old_of[k]];
            put_u16(out, zig_zag(value - previous));
            previous = value;
        }
    }
    const auto put_index = [&out, wide](std::uint32_t i) {
        if (wide) {
            put_u32(out, i);
        } else {
            put_u16(out, static_cast<std::uint16_t>(i));
        }
    };
    if (wide) {
        while (out.size() % 4 != 0) {
            put_u8(out, 0);
        }
    }
    put_u32(out, static_cast<std::uint32_t>(q.triangles.size() / 3));
    std::uint32_t highest = 0;
    for (std::uint32_t i : q.triangles) {
        const std::uint32_t k = order[i];
        put_index(highest - k);
        if (k == highest) {
            ++highest;
        }
    }
    // Edge lists: west and east along v, south and north along u.
    for (const auto& list : edge_lists(q, old_of)) {
        put_u32(out, static_cast<std::uint32_t>(list.size()));
        for (std::uint32_t k : list) {
            put_index(k);
        }
    }

    if (!extras.normals.empty()) {
        put_u8(out, kOctVertexNormals);
        put_u32(out, static_cast<std::uint32_t>(2 * n));
        for (std::uint32_t k = 0; k < n; ++k) {
            const auto oct = oct_encode(extras.normals[old_of[k]]);
            put_u8(out, oct[0]);
            put_u8(out, oct[1]);
        }
    }
    if (!extras.water_mask.empty()) {
        TB_ASSERT(extras.water_mask.size() == 1 || extras.water_mask.size() == 256 * 256);
        put_u8(out, kWaterMask);
        put_u32(out, static_cast<std::uint32_t>(extras.water_mask.size()));
        out.append(reinterpret_cast<const char*>(extras.water_mask.data()),
                   extras.water_mask.size());
    }
    if (!extras.metadata.empty()) {
        put_u8(out, kMetadata);
        put_u32(out, static_cast<std::uint32_t>(4 + extras.metadata.size()));
        put_u32(out, static_cast<std::uint32_t>(extras.metadata.size()));
        out += extras.metadata;
    }
    return out;
}

namespace {

struct ExtensionName {
    QuantizedMeshExtension id;
    const char* name;
};
constexpr ExtensionName kExtensionNames[] = {
    {kOctVertexNormals, "octvertexnormals"}, {kWaterMask, "watermask"}, {kMetadata, "metadata"}};

} // namespace

unsigned parse_terrain_extensions(std::string_view list) {
    if (list == "all") {
        return kAllQuantizedMeshExtensions;
    }
    if (list == "none") {
        return 0;
    }
    unsigned mask = 0;
    for (std::size_t start = 0; start <= list.size();) {
        const std::size_t comma = std::min(list.find(',', start), list.size());
        const std::string_view name = list.substr(start, comma - start);
        const auto known = std::find_if(std::begin(kExtensionNames),
                                        std::end(kExtensionNames),
                                        [&](const ExtensionName& e) { return name == e.name; });
        if (known == std::end(kExtensionNames)) {
            throw InputError("terrain extensions: unknown name '" + std::string(name) +
                             "'; name octvertexnormals, watermask or metadata, separated by "
                             "commas, or all or none");
        }
        mask |= known->id;
        start = comma + 1;
    }
    return mask;
}

std::string terrain_extensions_json(unsigned mask) {
    std::string out = "[";
    for (const ExtensionName& e : kExtensionNames) {
        if ((mask & e.id) != 0) {
            out += std::string(out.size() > 1 ? "," : "") + "\"" + e.name + "\"";
        }
    }
    return out + "]";
}

std::string select_extensions(std::string_view tile, unsigned mask) {
    constexpr std::size_t kHeader = 88;
    const std::uint32_t n = get_u32(tile, kHeader);
    const std::size_t index_bytes = n > 65536 ? 4 : 2;
    std::size_t pos = kHeader + 4 + std::size_t{6} * n;
    if (index_bytes == 4 && pos % 4 != 0) {
        pos += 4 - pos % 4;
    }
    const std::uint32_t triangles = get_u32(tile, pos);
    pos += 4 + std::size_t{3} * triangles * index_bytes;
    for (int s = 0; s < 4; ++s) {
        pos += 4 + std::size_t{get_u32(tile, pos)} * index_bytes;
    }
    if (pos > tile.size()) {
        throw InputError("quantized-mesh tile: edge lists run past its end");
    }
    std::string out(tile.substr(0, pos));
    while (pos < tile.size()) {
        const auto id = static_cast<unsigned char>(tile[pos]);
        const std::uint32_t length = get_u32(tile, pos + 1);
        const std::size_t end = pos + 5 + length;
        if (end > tile.size()) {
            throw InputError("quantized-mesh tile: extension " + std::to_string(id) +
                             " runs past its end");
        }
        if ((id == kOctVertexNormals || id == kWaterMask || id == kMetadata) && (mask & id) != 0) {
            out.append(tile.substr(pos, end - pos));
        }
        pos = end;
    }
    return out;
}

} // namespace tb::tiler

namespace tb::tiler {
namespace {

std::string number(double v) {
    char text[32];
    std::snprintf(text, sizeof text, "%.10g", v);
    return text;
}

std::string range_json(const TileRange& r) {
    return "{\"startX\":" + std::to_string(r.x0) + ",\"startY\":" + std::to_string(r.y0) +
           ",\"endX\":" + std::to_string(r.x1) + ",\"endY\":" + std::to_string(r.y1) + "}";
}

// The non-empty ranges, comma-separated.
std::string ranges_json(const std::vector<TileRange>& ranges) {
    std::string out;
    for (const TileRange& r : ranges) {
        if (!r.empty()) {
            out += (out.empty() ? "" : ",") + range_json(r);
        }
    }
    return out;
}

// Signed doubled area of (a, b, c) in lon/lat.
double orient(const TileMesh& m, core::Index a, core::Index b, core::Index c) {
    return (m.x[b] - m.x[a]) * (m.y[c] - m.y[a]) - (m.x[c] - m.x[a]) * (m.y[b] - m.y[a]);
}

void add_ccw(TileMesh& m, core::Index a, core::Index b, core::Index c) {
    const double area = orient(m, a, b, c);
    if (area == 0) {
        return;
    }
    m.triangles.insert(m.triangles.end(), {a, area > 0 ? b : c, area > 0 ? c : b});
}

} // namespace

std::vector<TileRange> terrain_available(const TerrainSpec& spec, int z) {
    if (z < 0 || z > spec.max_zoom) {
        return {};
    }
    if (z == 0) {
        return {TileRange{0, 0, 0, 1, 0}};
    }
    if (spec.available_at) {
        return spec.available_at(z).ranges();
    }
    const TileRange r = tiles_in_families(Scheme::Geodetic, spec.data_bounds, spec.data_bounds, z);
    return r.empty() ? std::vector<TileRange>{} : std::vector<TileRange>{r};
}

bool terrain_lists(const TerrainSpec& spec, const TileId& id) {
    if (id.z < 0 || id.z > spec.max_zoom) {
        return false;
    }
    if (id.z == 0) {
        return (id.x == 0 || id.x == 1) && id.y == 0;
    }
    if (spec.available_at) {
        return spec.available_at(id.z).contains(id.x, id.y);
    }
    return tiles_in_families(Scheme::Geodetic, spec.data_bounds, spec.data_bounds, id.z)
        .contains(id.x, id.y);
}

std::string terrain_layer_json(const TerrainSpec& spec) {
    std::string out =
        "{\"tilejson\":\"2.1.0\",\"name\":\"" + spec.name +
        "\",\"description\":\"Terrabound quantized-mesh terrain: meshed from the "
        "DEM at zooms " +
        std::to_string(spec.min_zoom) + ".." + std::to_string(spec.max_zoom) +
        "; coarser tiles, and tiles beside the data, are flat filler at sea "
        "level\",\"version\":\"1.0.0\",\"format\":\"quantized-mesh-1.0\","
        "\"scheme\":\"tms\",\"projection\":\"EPSG:4326\",\"tiles\":[\"{z}/{x}/"
        "{y}.terrain\"],\"minzoom\":0,\"maxzoom\":" +
        std::to_string(spec.max_zoom) + ",\"bounds\":[-180,-90,180,90],\"extensions\":" +
        terrain_extensions_json(kAllQuantizedMeshExtensions) +
        ",\"metadataAvailability\":" + std::to_string(kMetadataLevels) + ",\"available\":[";
    for (int z = 0; z <= spec.max_zoom; ++z) {
        out += std::string(z ? "," : "") + "[" + ranges_json(terrain_available(spec, z)) + "]";
    }
    const LonLatBox& b = spec.data_bounds;
    out += "],\"data\":{\"minzoom\":" + std::to_string(spec.min_zoom) +
           ",\"maxzoom\":" + std::to_string(spec.max_zoom) + ",\"bounds\":[" + number(b.west) +
           "," + number(b.south) + "," + number(b.east) + "," + number(b.north) +
           "],\"eps_by_zoom\":{";
    for (int z = spec.min_zoom; z <= spec.max_zoom; ++z) {
        out += std::string(z == spec.min_zoom ? "" : ",") + "\"" + std::to_string(z) +
               "\":" + number(spec.eps_for_zoom(z));
    }
    out += "}}}\n";
    return out;
}

std::string layer_json_with_extensions(std::string_view layer_json, unsigned mask) {
    const std::string list =
        "\"extensions\":" + terrain_extensions_json(kAllQuantizedMeshExtensions);
    const std::size_t at = layer_json.find(list);
    if (at == std::string_view::npos) {
        throw InputError("layer.json: no extension list to restrict");
    }
    std::string out(layer_json.substr(0, at));
    out += "\"extensions\":" + terrain_extensions_json(mask);
    std::string_view rest = layer_json.substr(at + list.size());
    const std::string availability = ",\"metadataAvailability\":" + std::to_string(kMetadataLevels);
    if ((mask & kMetadata) == 0 && rest.substr(0, availability.size()) == availability) {
        rest.remove_prefix(availability.size());
    }
    return out.append(rest);
}

std::string terrain_metadata(const TerrainSpec& spec, const TileId& id, double error, bool filler) {
    // Always kMetadataLevels levels (those past max_zoom or kMaxZoom empty), so that a pyramid
    // made deeper changes the metadata only of the tiles above its new tiles: build --update
    // remakes those as their ancestors, and no other.
    std::string out = "{\"available\":[";
    for (int k = 1; k <= kMetadataLevels && id.z + k <= kMaxZoom; ++k) {
        const int z = id.z + k;
        const std::int64_t scale = std::int64_t{1} << k;
        const TileRange window{
            z, id.x * scale, id.y * scale, id.x * scale + scale - 1, id.y * scale + scale - 1};
        const std::vector<TileRange> under =
            spec.available_at && z <= spec.max_zoom
                ? spec.available_at(z).ranges_within(window)
                : TileCover(z, terrain_available(spec, z)).ranges_within(window);
        // Listed as the tiles under this one alone make them: data far away, which splits the
        // zoom's rectangles elsewhere, leaves this tile's bytes as they are (build --update).
        out +=
            std::string(k > 1 ? "," : "") + "[" + ranges_json(TileCover(z, under).ranges()) + "]";
    }
    out += "],\"filler\":" + std::string(filler ? "true" : "false") +
           ",\"geometricError\":" + (filler ? std::string("null") : number(error)) + "}";
    return out;
}

TileMesh terrain_filler(const LonLatBox& b) {
    constexpr int kCells = 16;
    TileMesh m;
    for (int j = 0; j <= kCells; ++j) {
        const double y = j == kCells ? b.north : b.south + (b.north - b.south) * j / kCells;
        for (int i = 0; i <= kCells; ++i) {
            const double x = i == kCells ? b.east : b.west + (b.east - b.west) * i / kCells;
            m.add(x,
                  y,
                  static_cast<float>(egm96_undulation(x, y)),
                  i == 0 || j == 0 || i == kCells || j == kCells);
        }
    }
    for (int j = 0; j < kCells; ++j) {
        for (int i = 0; i < kCells; ++i) {
            const core::Index a = static_cast<core::Index>(j * (kCells + 1) + i);
            const core::Index up = kCells + 1;
            m.triangles.insert(m.triangles.end(), {a, a + 1, a + 1 + up, a, a + 1 + up, a + up});
        }
    }
    return m;
}

void cover_rectangle(TileMesh& m,
                     const LonLatBox& b,
                     const std::function<double(double lon, double lat)>& corner_height) {
    if (m.vertex_count() == 0) {
        return;
    }
    const auto [x0, x1] = std::minmax_element(m.x.begin(), m.x.end());
    const auto [y0, y1] = std::minmax_element(m.y.begin(), m.y.end());
    const double ix0 = *x0, ix1 = *x1, iy0 = *y0, iy1 = *y1;
    if (ix0 == b.west && ix1 == b.east && iy0 == b.south && iy1 == b.north) {
        return;
    }
    const auto corner = [&](double x, double y) {
        const double h = corner_height ? corner_height(x, y) : std::nan("");
        return m.add(x, y, static_cast<float>(std::isnan(h) ? egm96_undulation(x, y) : h), true);
    };
    // Outer corners counter-clockwise from south-west, and the inner sides in the same order.
    const core::Index outer[4] = {corner(b.west, b.south),
                                  corner(b.east, b.south),
                                  corner(b.east, b.north),
                                  corner(b.west, b.north)};
    const std::size_t n = m.vertex_count() - 4;
    for (int s = 0; s < 4; ++s) {
        const bool skip = (s == 0 && iy0 == b.south) || (s == 1 && ix1 == b.east) ||
                          (s == 2 && iy1 == b.north) || (s == 3 && ix0 == b.west);
        if (skip) {
            continue;
        }
        // The mesh's vertices on this inner side, in counter-clockwise order.
        std::vector<core::Index> chain;
        for (std::size_t v = 0; v < n; ++v) {
            const bool on = s == 0   ? m.y[v] == iy0
                            : s == 1 ? m.x[v] == ix1
                            : s == 2 ? m.y[v] == iy1
                                     : m.x[v] == ix0;
            if (on) {
                chain.push_back(static_cast<core::Index>(v));
            }
        }
        std::sort(chain.begin(), chain.end(), [&m, s](core::Index a, core::Index c) {
            const double ka = s == 0 ? m.x[a] : s == 1 ? m.y[a] : s == 2 ? -m.x[a] : -m.y[a];
            const double kc = s == 0 ? m.x[c] : s == 1 ? m.y[c] : s == 2 ? -m.x[c] : -m.y[c];
            return std::pair(ka, a) < std::pair(kc, c);
        });
        chain.erase(std::unique(chain.begin(),
                                chain.end(),
                                [&m](core::Index a, core::Index c) {
                                    return m.x[a] == m.x[c] && m.y[a] == m.y[c];
                                }),
                    chain.end());
        if (chain.empty()) {
            continue;
        }
        const core::Index a = outer[s], bb = outer[(s + 1) % 4];
        const std::size_t mid = (chain.size() - 1) / 2;
        for (std::size_t k = 0; k + 1 < chain.size(); ++k) {
            add_ccw(m, chain[k + 1], chain[k], k < mid ? a : bb);
        }
        add_ccw(m, a, bb, chain[mid]);
    }
}

std::vector<std::uint8_t> terrain_water_mask(const TileRaster& raster, const LonLatBox& b) {
    constexpr int kSize = 256;
    std::vector<std::uint8_t> mask(static_cast<std::size_t>(kSize) * kSize);
    const core::HeightGrid& g = raster.grid;
    std::size_t water = 0;
    for (int r = 0; r < kSize; ++r) {
        const double lat = b.north - (b.north - b.south) * (r + 0.5) / kSize;
        for (int c = 0; c < kSize; ++c) {
            const double lon = b.west + (b.east - b.west) * (c + 0.5) / kSize;
            double column = 0, row = 0;
            lonlat_to_grid(raster, {lon, lat}, column, row);
            bool wet = true;
            if (column >= -0.5 && row >= -0.5 && column <= g.width - 0.5 && row <= g.height - 0.5) {
                const int i = std::clamp(static_cast<int>(std::lround(column)), 0, g.width - 1);
                const int j = std::clamp(static_cast<int>(std::lround(row)), 0, g.height - 1);
                wet = !g.is_valid(i, j) || g.at(i, j) - egm96_undulation(lon, lat) <= 0.01;
            }
            mask[static_cast<std::size_t>(r) * kSize + static_cast<std::size_t>(c)] = wet ? 255 : 0;
            water += wet ? 1 : 0;
        }
    }
    if (water == 0 || water == mask.size()) {
        return {static_cast<std::uint8_t>(water ? 255 : 0)};
    }
    return mask;
}

} // namespace tb::tiler
