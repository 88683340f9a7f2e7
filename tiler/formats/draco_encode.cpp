// Encoding a meshed tile with Draco: glTF 2.0 binary with KHR_draco_mesh_compression (.glb)
// and raw Draco with geometry metadata (.drc). Draco's Status becomes a tb error here.
//
// Quantization is explicit and level-wide: every position is snapped, in double precision, to
// the lattice s*Z^3 of error_budget(eps), and Draco is told to quantize on exactly that
// lattice (origin a lattice point, range s*(2^bits - 1)). Draco then stores the lattice
// indices and dequantizes them as float(q) * s + origin, which is exact in float32 while
// q < 2^23 (s is a power of two; see kMaxLatticeBits and Snapped). The glb's frame origin
// (node translation) is itself a lattice point, so translation + decoded position is the
// snapped ECEF point, identical in every tile that holds the vertex. Before writing, the tile
// is decoded and checked against every valid sample (snapped_error, then a Draco round trip).
#include "tiler/formats/draco_decode.hpp"
#include "tiler/formats/encode.hpp"
#include "tiler/geodesy.hpp"
#include "tiler/helper_threads.hpp"
#include "tiler/json_number.hpp"
#include "tiler/log.hpp"

#include "core/error.hpp"
#include "core/triangulate.hpp"

#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>
#include <draco/metadata/geometry_metadata.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>

namespace tb::tiler {
namespace {

// The drawn-surface check splits its rows between two threads from this many rows on.
constexpr int kMinRowsToSplit = 64;
constexpr int kDracoSpeed = 5; // Draco's default trade-off; fixed for determinism
// Draco quantizes with floor(v / s + 0.5f) in float32, exact only while v / s < 2^23 (above it
// the + 0.5 rounds to even); float32 positions are exact below 2^24 steps.
constexpr int kMaxLatticeBits = 23;
constexpr std::uint32_t kGlbMagic = 0x46546C67; // "glTF"
constexpr std::uint32_t kChunkJson = 0x4E4F534A;
constexpr std::uint32_t kChunkBin = 0x004E4942;
// The one material of a non-empty glb: matte (no metal, full roughness) in a light grey-brown,
// so clients light the relief instead of drawing it unshaded. Linear RGB, as glTF wants.
constexpr const char* kGlbMaterials =
    R"("materials":[{"name":"terrain","pbrMetallicRoughness":{"baseColorFactor":)"
    R"([0.5,0.46,0.4,1],"metallicFactor":0,"roughnessFactor":1}}],)";

void check(const draco::Status& status, const char* what, const TileId& id) {
    if (!status.ok()) {
        throw Error("tile " + tile_name(id) + ": Draco " + what + " failed: " +
                    status.error_msg_string() + "; this is a bug, please report it with the tile");
    }
}

// Shortest round-trip decimal form of a double (JSON numbers keep every bit).
std::string number(double v) {
    return json_number(v, "a glTF number");
}

void put_u32(std::string& out, std::uint32_t v) {
    for (int k = 0; k < 4; ++k) {
        out.push_back(static_cast<char>((v >> (8 * k)) & 0xFF));
    }
}

// Vertices snapped to the lattice: q[v] are integer lattice coordinates (units of `step`) in
// the output frame; Draco quantizes them on [origin, origin + (2^bits - 1)] * step.
//
// Draco 1.5 passes the explicit origin and range to its encoder as text through std::to_string
// (6 decimals), then parses them back. A float survives that exactly when it is an integer
// multiple of 2^-6 or at least 16 in magnitude (its spacing then exceeds the 1e-6 rounding).
// So the origin is rounded down to a multiple of max(16 m, s) and the range made >= 16 m;
// without this, small tiles at fine steps decoded a few 1e-7 m off the lattice.
struct Snapped {
    std::vector<std::array<std::int64_t, 3>> q;
    std::array<std::int64_t, 3> lo{}, hi{}, origin{};
    int bits = 1;
};

Snapped finish_lattice(const std::vector<std::array<std::int64_t, 3>>& q,
                       double step,
                       const TileRaster& raster,
                       const ErrorBudget& budget) {
    Snapped out;
    out.q = q;
    out.lo.fill(std::numeric_limits<std::int64_t>::max());
    out.hi.fill(std::numeric_limits<std::int64_t>::min());
    for (const auto& p : out.q) {
        for (int k = 0; k < 3; ++k) {
            out.lo[k] = std::min(out.lo[k], p[k]);
            out.hi[k] = std::max(out.hi[k], p[k]);
        }
    }
    constexpr double kTextSafe = 16.0; // metres; see above
    const std::int64_t unit = std::max<std::int64_t>(1, std::llround(kTextSafe / step));
    const std::int64_t min_range = unit; // (2^bits - 1) >= 16 m / step
    std::int64_t extent = min_range;
    std::int64_t magnitude = 0;
    for (int k = 0; k < 3; ++k) {
        // Floor division: the origin is at or below the smallest coordinate.
        out.origin[k] =
            (out.lo[k] >= 0 ? out.lo[k] / unit : -((-out.lo[k] + unit - 1) / unit)) * unit;
        extent = std::max(extent, out.hi[k] - out.origin[k]);
        magnitude = std::max({magnitude, -out.origin[k], out.hi[k]});
    }
    while (out.bits < 62 && (std::int64_t{1} << out.bits) - 1 < extent) {
        ++out.bits;
    }
    if (out.bits > kMaxLatticeBits || magnitude >= (std::int64_t{1} << kMaxLatticeBits)) {
        throw InputError("tile " + tile_name(raster.id) + ": eps " + number(budget.eps) +
                         " m gives a quantization step of " + number(step) +
                         " m, too fine for a tile this large (more than 2^23 steps across); "
                         "use a larger eps for this zoom");
    }
    return out;
}

// Largest |snapped surface - sample| over the tile's valid samples, evaluated as a client
// sees the decoded tile: each snapped vertex back to lon/lat/h and tile grid coordinates, the
// surface interpolated linearly in (column, row) at each sample's exact position. A sample held
// by several triangles (on an edge) takes the worst; one held by none (a border vertex snapped
// a hair inward) is evaluated on the nearest triangle's plane.
struct Verdict {
    double max_error = 0;
    int column = -1, row = -1;
};

// Snapped vertices as clients decode them, back in raster's grid coordinates and height.
using GridVertices = std::vector<std::array<double, 3>>;
GridVertices to_grid(const TileRaster& raster, const std::vector<Ecef>& world) {
    GridVertices g(world.size());
    for (std::size_t v = 0; v < world.size(); ++v) {
        const Geodetic p = to_geodetic(world[v]);
        lonlat_to_grid(raster, {p.lon, p.lat}, g[v][0], g[v][1]);
        g[v][2] = p.h;
    }
    return g;
}

// Triangle t of the snapped mesh in grid coordinates (column, row, height), with twice its
// signed area; det 0 when it has collapsed (all of a pole row): its samples are then covered by
// its neighbours.
struct SnappedTriangle {
    const std::array<double, 3>& a;
    const std::array<double, 3>& b;
    const std::array<double, 3>& c;
    double det;
};
SnappedTriangle snapped_triangle(const TileMesh& mesh, const GridVertices& g, std::size_t t) {
    const auto& a = g[mesh.triangles[3 * t]];
    const auto& b = g[mesh.triangles[3 * t + 1]];
    const auto& c = g[mesh.triangles[3 * t + 2]];
    return {a, b, c, (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])};
}

Verdict
snapped_error(const TileRaster& raster, const TileMesh& mesh, const GridVertices& g, int threads) {
    const core::HeightGrid& grid = raster.grid;
    const int width = grid.width, height = grid.height;
    const std::size_t count = static_cast<std::size_t>(width) * height;
    constexpr double kEdge = -1e-9; // barycentric slack: on an edge counts as inside
    const auto lo3 = [](double u, double v, double w) { return std::min({u, v, w}); };
    const auto hi3 = [](double u, double v, double w) { return std::max({u, v, w}); };
    // The worst sample so far: the largest error, the first sample (row-major) on a tie, as a
    // row-major scan of every sample's own error finds it.
    struct Worst {
        double error = 0;
        std::size_t k = 0;
        void take(double e, std::size_t at) {
            if (e > error || (e == error && e > 0 && at < k)) {
                error = e;
                k = at;
            }
        }
    };
    // Sample (x, y) against triangle (a, b, c): its error, and how far outside (0: inside,
    // within the slack).
    const auto measure = [&](const std::array<double, 3>& a,
                             const std::array<double, 3>& b,
                             const std::array<double, 3>& c,
                             double det,
                             int x,
                             int y,
                             double& out) {
        const double la = ((b[0] - x) * (c[1] - y) - (c[0] - x) * (b[1] - y)) / det;
        const double lb = ((c[0] - x) * (a[1] - y) - (a[0] - x) * (c[1] - y)) / det;
        const double lc = 1 - la - lb;
        out = std::max(0.0, -lo3(la, lb, lc) + kEdge);
        return std::abs(la * a[2] + lb * b[2] + lc * c[2] - grid.at(x, y));
    };
    // Pass 1, every sample a triangle holds (its error is the worst of the triangles holding
    // it, so only the worst of all is kept, and a byte per sample saying it is held): row by
    // row, over the x-extent of the triangle within a band of +-band around the row, widened by
    // band. A sample within the slack of a triangle lies at most 1e-9 of the triangle's height
    // outside it (a few 1e-9 of its extent), so a band of 1e-3 pixels plus 1e-8 of the extent
    // finds it, however far a vertex lies (a snapped pole can sit far outside the tile). Rows
    // [first, last] only; the worst of two row ranges is the worst of one pass.
    std::vector<std::uint8_t> held(count, 0);
    const auto pass1 = [&](int first, int last, Worst& worst) {
        for (std::size_t t = 0; t < mesh.triangle_count(); ++t) {
            const auto [a, b, c, det] = snapped_triangle(mesh, g, t);
            if (det == 0) {
                continue;
            }
            const std::array<double, 3>* corner[3] = {&a, &b, &c};
            const double extent = std::max(hi3(a[0], b[0], c[0]) - lo3(a[0], b[0], c[0]),
                                           hi3(a[1], b[1], c[1]) - lo3(a[1], b[1], c[1]));
            const double band = 1e-3 + 1e-8 * extent;
            const int y0 =
                std::max(first, static_cast<int>(std::ceil(lo3(a[1], b[1], c[1]) - band)));
            const int y1 =
                std::min(last, static_cast<int>(std::floor(hi3(a[1], b[1], c[1]) + band)));
            for (int y = y0; y <= y1; ++y) {
                const double band_lo = y - band, band_hi = y + band;
                double x_lo = std::numeric_limits<double>::infinity(), x_hi = -x_lo;
                for (int i = 0; i < 3; ++i) {
                    const auto& p = *corner[i];
                    const auto& q = *corner[(i + 1) % 3];
                    if (p[1] >= band_lo && p[1] <= band_hi) {
                        x_lo = std::min(x_lo, p[0]);
                        x_hi = std::max(x_hi, p[0]);
                    }
                    for (const double yb : {band_lo, band_hi}) {
                        if ((p[1] < yb && yb < q[1]) || (q[1] < yb && yb < p[1])) {
                            const double x = p[0] + (yb - p[1]) * (q[0] - p[0]) / (q[1] - p[1]);
                            x_lo = std::min(x_lo, x);
                            x_hi = std::max(x_hi, x);
                        }
                    }
                }
                if (!(x_lo <= x_hi)) {
                    continue;
                }
                const int x0 = std::max(0, static_cast<int>(std::ceil(x_lo - band)));
                const int x1 = std::min(width - 1, static_cast<int>(std::floor(x_hi + band)));
                for (int x = x0; x <= x1; ++x) {
                    if (!grid.is_valid(x, y)) {
                        continue;
                    }
                    double out = 0;
                    const double e = measure(a, b, c, det, x, y, out);
                    if (out == 0) {
                        const std::size_t k = static_cast<std::size_t>(y) * width + x;
                        held[k] = 1;
                        worst.take(e, k);
                    }
                }
            }
        }
    };
    Worst worst;
    // Two row halves on two threads for a tile worth it (a cold tile in the server).
    if (threads >= 2 && height >= kMinRowsToSplit) {
        const int mid = height / 2;
        Worst lower_worst;
        Beside<void> lower =
            beside([&pass1, &lower_worst, mid, height] { pass1(mid, height - 1, lower_worst); });
        pass1(0, mid - 1, worst);
        lower.get();
        worst.take(lower_worst.error, lower_worst.k);
    } else {
        pass1(0, height - 1, worst);
    }
    // Pass 2, the valid samples pass 1 found in no triangle (border samples a snapped vertex
    // moved a hair away from), few: each against every triangle within a pixel of it, in
    // triangle order, exactly as one loop over every triangle's widened bounding box would:
    // the nearest one deciding, or the worst of those holding it after all. They are listed by
    // row (row_start), so a triangle finds those in its box by a binary search per row.
    std::vector<std::uint32_t> row_start(static_cast<std::size_t>(height) + 1, 0);
    std::vector<int> open_x;
    for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
            if (grid.is_valid(x, y) && held[static_cast<std::size_t>(y) * width + x] == 0) {
                open_x.push_back(x);
            }
        }
        row_start[static_cast<std::size_t>(y) + 1] = static_cast<std::uint32_t>(open_x.size());
    }
    std::vector<double> outside(open_x.size(), std::numeric_limits<double>::infinity());
    std::vector<double> error(open_x.size(), 0.0);
    for (std::size_t t = 0; !open_x.empty() && t < mesh.triangle_count(); ++t) {
        const auto [a, b, c, det] = snapped_triangle(mesh, g, t);
        if (det == 0) {
            continue;
        }
        const int x0 = std::max(0, int(std::floor(lo3(a[0], b[0], c[0]))) - 1);
        const int x1 = std::min(width - 1, int(std::ceil(hi3(a[0], b[0], c[0]))) + 1);
        const int y0 = std::max(0, int(std::floor(lo3(a[1], b[1], c[1]))) - 1);
        const int y1 = std::min(height - 1, int(std::ceil(hi3(a[1], b[1], c[1]))) + 1);
        for (int y = y0; y <= y1; ++y) {
            const auto row_begin = open_x.begin() + row_start[static_cast<std::size_t>(y)];
            const auto row_end = open_x.begin() + row_start[static_cast<std::size_t>(y) + 1];
            for (auto it = std::lower_bound(row_begin, row_end, x0); it != row_end && *it <= x1;
                 ++it) {
                const std::size_t i = static_cast<std::size_t>(it - open_x.begin());
                double out = 0;
                const double e = measure(a, b, c, det, *it, y, out);
                if (out == 0) {
                    error[i] = outside[i] == 0 ? std::max(error[i], e) : e;
                    outside[i] = 0;
                } else if (out < outside[i]) {
                    outside[i] = out;
                    error[i] = e;
                }
            }
        }
    }
    for (int y = 0; y < height; ++y) {
        for (std::uint32_t i = row_start[static_cast<std::size_t>(y)];
             i < row_start[static_cast<std::size_t>(y) + 1];
             ++i) {
            worst.take(error[i], static_cast<std::size_t>(y) * width + open_x[i]);
        }
    }
    Verdict verdict;
    if (worst.error > 0) {
        verdict.max_error = worst.error;
        verdict.column = static_cast<int>(worst.k % width);
        verdict.row = static_cast<int>(worst.k / width);
    }
    return verdict;
}

// The check points against the snapped surface, located by bucketing them into grid cells and
// walking each triangle's bounding cells.
EncodeReport
points_error(const TileMesh& mesh, const GridVertices& g, const std::vector<CheckPoint>& points) {
    EncodeReport report;
    if (points.empty()) {
        return report;
    }
    double c_lo = INFINITY, c_hi = -INFINITY, r_lo = INFINITY, r_hi = -INFINITY;
    for (const auto& v : g) {
        c_lo = std::min(c_lo, v[0]), c_hi = std::max(c_hi, v[0]);
        r_lo = std::min(r_lo, v[1]), r_hi = std::max(r_hi, v[1]);
    }
    const double c0 = std::floor(c_lo) - 1, r0 = std::floor(r_lo) - 1;
    const int cells_x = static_cast<int>(std::ceil(c_hi) - c0) + 2;
    const int cells_y = static_cast<int>(std::ceil(r_hi) - r0) + 2;
    const auto cell_of = [&](double c, double r, int& i, int& j) {
        i = std::clamp(static_cast<int>(std::floor(c - c0)), 0, cells_x - 1);
        j = std::clamp(static_cast<int>(std::floor(r - r0)), 0, cells_y - 1);
    };
    // The points in cell order (a counting sort): 4 bytes a point beside the points themselves,
    // which at coarse zooms are millions of source pixels.
    std::vector<std::uint32_t> start(static_cast<std::size_t>(cells_x) * cells_y + 1, 0);
    const auto cell_index = [&](const CheckPoint& p) {
        int i = 0, j = 0;
        cell_of(p.column, p.row, i, j);
        return static_cast<std::size_t>(j) * cells_x + i;
    };
    for (const CheckPoint& p : points) {
        ++start[cell_index(p) + 1];
    }
    for (std::size_t k = 1; k < start.size(); ++k) {
        start[k] += start[k - 1];
    }
    std::vector<std::uint32_t> order(points.size());
    {
        std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
        for (std::size_t k = 0; k < points.size(); ++k) {
            order[fill[cell_index(points[k])]++] = static_cast<std::uint32_t>(k);
        }
    }
    // The largest error over every (triangle, point it holds) pair is the largest over points of
    // their worst holding triangle; a point no triangle holds is outside.
    constexpr double kEdge = -1e-9;
    std::vector<bool> held(points.size(), false);
    for (std::size_t t = 0; t < mesh.triangle_count(); ++t) {
        const auto [a, b, c, det] = snapped_triangle(mesh, g, t);
        if (det == 0) {
            continue;
        }
        int i0 = 0, j0 = 0, i1 = 0, j1 = 0;
        cell_of(std::min({a[0], b[0], c[0]}), std::min({a[1], b[1], c[1]}), i0, j0);
        cell_of(std::max({a[0], b[0], c[0]}), std::max({a[1], b[1], c[1]}), i1, j1);
        for (int j = j0; j <= j1; ++j) {
            for (int i = i0; i <= i1; ++i) {
                const std::size_t q = static_cast<std::size_t>(j) * cells_x + i;
                for (std::uint32_t o = start[q]; o < start[q + 1]; ++o) {
                    const CheckPoint& p = points[order[o]];
                    const double x = p.column, y = p.row;
                    const double la = ((b[0] - x) * (c[1] - y) - (c[0] - x) * (b[1] - y)) / det;
                    const double lb = ((c[0] - x) * (a[1] - y) - (a[0] - x) * (c[1] - y)) / det;
                    const double lc = 1 - la - lb;
                    if (std::min({la, lb, lc}) < kEdge) {
                        continue;
                    }
                    const double e = std::abs(la * a[2] + lb * b[2] + lc * c[2] - p.height);
                    report.points_error = std::max(report.points_error, e);
                    held[order[o]] = true;
                }
            }
        }
    }
    report.points_outside = static_cast<std::size_t>(std::count(held.begin(), held.end(), false));
    return report;
}

std::string glb_json(const std::array<double, 3>& translation,
                     const std::array<double, 3>& min,
                     const std::array<double, 3>& max,
                     std::size_t vertex_count,
                     std::size_t index_count,
                     std::uint32_t position_id,
                     const std::uint32_t* normal_id,
                     std::size_t draco_bytes) {
    const auto vec = [](const std::array<double, 3>& v) {
        std::string out(1, '['); // built up, not "[" + ...: GCC 12 -O3 warns (-Wrestrict) on that
        for (std::size_t k = 0; k < 3; ++k) {
            out += number(v[k]);
            out += k < 2 ? ',' : ']';
        }
        return out;
    };
    const int index_type = vertex_count > 65535 ? 5125 : 5123;
    std::string j;
    j += R"({"asset":{"version":"2.0","generator":"Terrabound"},)";
    j += R"("extensionsUsed":["KHR_draco_mesh_compression"],)";
    j += R"("extensionsRequired":["KHR_draco_mesh_compression"],)";
    j += R"("scene":0,"scenes":[{"nodes":[0]}],)";
    j += R"("nodes":[{"mesh":0,"translation":)" + vec(translation) + "}],";
    // Accessors: 0 POSITION, 1 indices, 2 NORMAL (when present); material 0 for every mesh.
    j += R"("meshes":[{"primitives":[{"attributes":{"POSITION":0)";
    j += normal_id ? R"(,"NORMAL":2)" : "";
    j += R"(},"indices":1,"material":0,"mode":4,)";
    j += R"("extensions":{"KHR_draco_mesh_compression":{"bufferView":0,"attributes":{"POSITION":)" +
         std::to_string(position_id);
    j += normal_id ? R"(,"NORMAL":)" + std::to_string(*normal_id) : "";
    j += "}}}}]}],";
    j += kGlbMaterials;
    j += R"("accessors":[{"componentType":5126,"count":)" + std::to_string(vertex_count) +
         R"(,"type":"VEC3","min":)" + vec(min) + R"(,"max":)" + vec(max) + "},";
    j += R"({"componentType":)" + std::to_string(index_type) + R"(,"count":)" +
         std::to_string(index_count) + R"(,"type":"SCALAR"})";
    j += normal_id ? R"(,{"componentType":5126,"count":)" + std::to_string(vertex_count) +
                         R"(,"type":"VEC3"})"
                   : "";
    j += "],";
    j += R"("bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":)" +
         std::to_string(draco_bytes) + "}],";
    j += R"("buffers":[{"byteLength":)" + std::to_string(draco_bytes) + "}]}";
    return j;
}

// A tile whose data are all voids: a glb with an empty scene (no buffer, no BIN chunk); a raw
// Draco tile has no such form, so there is no .drc of it.
std::string empty_tile(const TileRaster& raster, Format format, const ErrorBudget& budget) {
    if (format == Format::Drc) {
        throw NotFound("tile " + tile_name(raster.id) +
                       ": holds only voids, so there is no mesh to send as .drc");
    }
    (void)budget;
    std::string json =
        R"({"asset":{"version":"2.0","generator":"Terrabound"},"scene":0,"scenes":[{"nodes":[]}]})";
    while (json.size() % 4 != 0) {
        json.push_back(' ');
    }
    std::string out;
    put_u32(out, kGlbMagic);
    put_u32(out, 2);
    put_u32(out, static_cast<std::uint32_t>(12 + 8 + json.size()));
    put_u32(out, static_cast<std::uint32_t>(json.size()));
    put_u32(out, kChunkJson);
    return out + json;
}

// Refuses a lattice step of more than a quarter of the ground distance between neighbouring
// samples (east-west at the tile's middle latitude, the smaller one): snapping would then move
// vertices across their neighbours, and clients would draw the tile sheared, folded or as a
// sliver (a tile only metres wide near a pole, asked for at a large eps).
void check_lattice_fits(const TileRaster& raster, const ErrorBudget& budget) {
    constexpr double kPi = 3.14159265358979323846;
    const double middle = (raster.bounds.south + raster.bounds.north) / 2;
    const double shrink = std::min(1.0, std::cos(middle * kPi / 180));
    // Lattice tiles: the zoom's sample spacing; pixel tiles: the pixels' own.
    const GridFrame f = frame_of(raster);
    const bool degrees = f.lonlat || raster.scheme == Scheme::Geodetic;
    const double spacing = raster.frame.dx > 0
                               ? (degrees ? std::min(f.dx * shrink, f.dy) * kPi / 180 * 6378137.0
                                          : std::min(f.dx, f.dy) * shrink)
                               : sample_spacing_m(raster.scheme, raster.id.z, raster.size) * shrink;
    if (budget.quant_step > spacing / 4) {
        throw InputError("tile " + tile_name(raster.id) + ": eps " + number(budget.eps) +
                         " m gives a quantization step of " + number(budget.quant_step) +
                         " m, more than a quarter of the tile's sample spacing (" +
                         number(spacing) + " m here); use a smaller eps for this tile");
    }
}

} // namespace

std::string glb_container(std::string json, std::string_view bin) {
    while (json.size() % 4 != 0) {
        json.push_back(' ');
    }
    const std::size_t bin_padded = (bin.size() + 3) / 4 * 4;
    const std::size_t total = 12 + 8 + json.size() + 8 + bin_padded;
    TB_ASSERT(total <= std::numeric_limits<std::uint32_t>::max());
    std::string out;
    out.reserve(total);
    put_u32(out, kGlbMagic);
    put_u32(out, 2);
    put_u32(out, static_cast<std::uint32_t>(total));
    put_u32(out, static_cast<std::uint32_t>(json.size()));
    put_u32(out, kChunkJson);
    out += json;
    put_u32(out, static_cast<std::uint32_t>(bin_padded));
    put_u32(out, kChunkBin);
    out += bin;
    out.append(bin_padded - bin.size(), '\0');
    return out;
}

// Where a tile's positions are written from: the frame origin (lon/lat at the tile centre, a
// lattice height), its ENU axes, and the glb node translation; and the tile's height range.
struct TileFrame {
    Geodetic centre;
    EnuFrame enu;
    std::array<double, 3> translation{};
    float z_min = 0, z_max = 0;
};

// The tile's bytes from its snapped lattice (snap, at `step` metres): the Draco mesh, encoded,
// then decoded again and checked, as clients will decode it. `published` is the .drc's eps_m.
std::string draco_tile(const TileRaster& raster,
                       const TileMesh& mesh,
                       Format format,
                       const ErrorBudget& budget,
                       const TileFrame& frame,
                       const Snapped& snap,
                       double step,
                       double published,
                       const std::vector<std::array<double, 3>>* normals) {
    const std::size_t n = mesh.vertex_count();
    const EnuFrame& enu = frame.enu;
    const Geodetic& centre = frame.centre;
    // The Draco mesh: lattice points as float32 (exact), triangles counter-clockwise seen from
    // above as given.
    draco::Mesh dm;
    dm.set_num_points(static_cast<draco::PointIndex::ValueType>(n));
    draco::GeometryAttribute ga;
    ga.Init(draco::GeometryAttribute::POSITION,
            nullptr,
            3,
            draco::DT_FLOAT32,
            false,
            sizeof(float) * 3,
            0);
    const int att_id = dm.AddAttribute(ga, true, static_cast<std::uint32_t>(n));
    draco::PointAttribute* att = dm.attribute(att_id);
    for (std::size_t v = 0; v < n; ++v) {
        const float p[3] = {static_cast<float>(double(snap.q[v][0]) * step),
                            static_cast<float>(double(snap.q[v][1]) * step),
                            static_cast<float>(double(snap.q[v][2]) * step)};
        att->SetAttributeValue(draco::AttributeValueIndex(static_cast<std::uint32_t>(v)), p);
    }
    // Normals in the positions' axes: glb (x, z, -y) of ECEF, drc the ENU frame's axes.
    draco::PointAttribute* normal_att = nullptr;
    if (normals) {
        draco::GeometryAttribute gn;
        gn.Init(draco::GeometryAttribute::NORMAL,
                nullptr,
                3,
                draco::DT_FLOAT32,
                false,
                sizeof(float) * 3,
                0);
        normal_att = dm.attribute(dm.AddAttribute(gn, true, static_cast<std::uint32_t>(n)));
        for (std::size_t v = 0; v < n; ++v) {
            const std::array<double, 3>& e = (*normals)[v];
            std::array<double, 3> out{};
            if (format == Format::Glb) {
                out = {e[0], e[2], -e[1]};
            } else {
                for (int a = 0; a < 3; ++a) {
                    out[a] = enu.axes[a][0] * e[0] + enu.axes[a][1] * e[1] + enu.axes[a][2] * e[2];
                }
            }
            const float f[3] = {
                static_cast<float>(out[0]), static_cast<float>(out[1]), static_cast<float>(out[2])};
            normal_att->SetAttributeValue(draco::AttributeValueIndex(static_cast<std::uint32_t>(v)),
                                          f);
        }
    }
    for (std::size_t t = 0; t < mesh.triangle_count(); ++t) {
        dm.AddFace({draco::PointIndex(mesh.triangles[3 * t]),
                    draco::PointIndex(mesh.triangles[3 * t + 1]),
                    draco::PointIndex(mesh.triangles[3 * t + 2])});
    }
    if (format == Format::Drc) {
        auto md = std::make_unique<draco::GeometryMetadata>();
        md->AddEntryString("schema", kDrcSchema);
        md->AddEntryString("crs", "EPSG:4979");
        md->AddEntryString("frame", "ENU");
        md->AddEntryString("up_axis", "Z");
        md->AddEntryString("scheme", to_string(raster.scheme));
        md->AddEntryDouble("origin_lon_deg", centre.lon);
        md->AddEntryDouble("origin_lat_deg", centre.lat);
        md->AddEntryDouble("origin_h_m", centre.h);
        md->AddEntryDouble("west_deg", raster.bounds.west);
        md->AddEntryDouble("south_deg", raster.bounds.south);
        md->AddEntryDouble("east_deg", raster.bounds.east);
        md->AddEntryDouble("north_deg", raster.bounds.north);
        md->AddEntryDouble("min_h_m", frame.z_min);
        md->AddEntryDouble("max_h_m", frame.z_max);
        md->AddEntryDouble("eps_m", published);
        md->AddEntryString("eps_meaning",
                           "metres: every valid source DEM pixel centre under the tile is within "
                           "eps_m, vertically, of the decoded surface");
        md->AddEntryDouble("quant_step_m", step);
        md->AddEntryDouble("quant_error_m", budget.quant_error);
        md->AddEntryInt("level", raster.id.z);
        md->AddEntryInt("x", static_cast<std::int32_t>(raster.id.x));
        md->AddEntryInt("y", static_cast<std::int32_t>(raster.id.y));
        dm.AddMetadata(std::move(md));
    }

    draco::Encoder encoder;
    encoder.SetSpeedOptions(kDracoSpeed, kDracoSpeed);
    encoder.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
    // One connectivity for every attribute: a tile's normals are one per vertex, so they have
    // no seams, and Draco would otherwise build, encode and decode a connectivity of their own
    // (about a fifth of its time on a tile). Clients decode the same triangles, corners and
    // normals; only the order of the decoded vertices differs, and the file is a little smaller.
    encoder.options().SetGlobalBool("split_mesh_on_seams", true);
    const float origin[3] = {static_cast<float>(double(snap.origin[0]) * step),
                             static_cast<float>(double(snap.origin[1]) * step),
                             static_cast<float>(double(snap.origin[2]) * step)};
    const float range = static_cast<float>(double((std::int64_t{1} << snap.bits) - 1) * step);
    encoder.SetAttributeExplicitQuantization(
        draco::GeometryAttribute::POSITION, snap.bits, 3, origin, range);
    if (normals) {
        encoder.SetAttributeQuantization(draco::GeometryAttribute::NORMAL, kNormalBits);
    }
    draco::EncoderBuffer buffer;
    check(encoder.EncodeMeshToBuffer(dm, &buffer), "encoding", raster.id);
    std::string draco_bytes(buffer.data(), buffer.size());

    // Self-check on the decoded data (what clients see): counts kept, every coordinate on the
    // lattice point it was snapped to; glTF min/max are taken from it.
    const DecodedTile decoded = decode_drc(draco_bytes);
    if (decoded.positions.size() != n || decoded.indices.size() != mesh.triangles.size() ||
        decoded.normals.size() != (normals ? n : 0)) {
        throw Error("tile " + tile_name(raster.id) + ": Draco changed the mesh (" +
                    std::to_string(n) + " vertices -> " + std::to_string(decoded.positions.size()) +
                    "); this is a bug, please report it with the tile");
    }
    std::array<double, 3> min{}, max{};
    for (int k = 0; k < 3; ++k) {
        min[k] = max[k] = decoded.positions[0][k];
    }
    for (const auto& p : decoded.positions) {
        for (int k = 0; k < 3; ++k) {
            const double steps = p[k] / step;
            if (steps != std::round(steps) || p[k] < double(snap.lo[k]) * step ||
                p[k] > double(snap.hi[k]) * step) {
                throw Error("tile " + tile_name(raster.id) + ": Draco decoded coordinate " +
                            number(p[k]) + " off the " + number(step) +
                            " m lattice; this is a bug, please report it with the tile");
            }
            min[k] = std::min(min[k], p[k]);
            max[k] = std::max(max[k], p[k]);
        }
    }
    if (format == Format::Drc) {
        return draco_bytes;
    }
    const std::uint32_t normal_id = normal_att ? normal_att->unique_id() : 0;
    const std::string json = glb_json(frame.translation,
                                      min,
                                      max,
                                      n,
                                      mesh.triangles.size(),
                                      att->unique_id(),
                                      normal_att ? &normal_id : nullptr,
                                      draco_bytes.size());
    return glb_container(json, draco_bytes);
}

ErrorBudget error_budget(double eps, double sag_share) {
    if (!std::isfinite(eps) || !(eps > 0)) {
        throw InputError("eps " + std::to_string(eps) + ": expected a finite number of metres > 0");
    }
    // Per unit of s, snapping can move the surface by (1 + slope) * sqrt(3)/2 (see
    // kQuantMaxSlope); Draco's float32 dequantization adds nothing (exact on the lattice).
    const double per_step = (1 + kQuantMaxSlope) * std::sqrt(3.0) / 2;
    double s = std::exp2(std::floor(std::log2(eps / 8 / per_step)));
    while (per_step * s > eps / 8) {
        s /= 2;
    }
    while (per_step * 2 * s <= eps / 8) {
        s *= 2;
    }
    ErrorBudget b;
    b.eps = eps;
    b.quant_step = s;
    b.quant_error = per_step * s;
    b.sag = eps * sag_share;
    b.max_edge_m = std::sqrt(6 * kSagRadius * b.sag / kSagMargin);
    b.mesh_eps = eps - b.quant_error - b.sag;
    b.drawn_bound = eps;
    TB_ASSERT(b.mesh_eps > 0);
    return b;
}

double sample_spacing_m(Scheme scheme, int z, int size) {
    TB_ASSERT(size >= 1 && z >= 0 && z <= kMaxZoom);
    constexpr double kA = 6378137.0;
    constexpr double kPi = 3.14159265358979323846;
    if (scheme == Scheme::Mercator) {
        return 2 * kPi * kA / std::ldexp(1.0, z) / size;
    }
    constexpr double kF = 1 / 298.257223563;
    constexpr double kB = kA * (1 - kF);
    const double tile_deg = 180.0 / std::ldexp(1.0, z); // geodetic tiles are square in degrees
    return kPi / 180 * (kA * kA / kB) * tile_deg / size;
}

ErrorBudget spacing_error_budget(double eps, double spacing_m, double min_edge, double sag_share) {
    TB_ASSERT(spacing_m > 0 && min_edge >= core::kMinMaxEdge);
    ErrorBudget b = error_budget(eps, sag_share);
    b.max_edge = b.max_edge_m / spacing_m;
    if (b.max_edge < min_edge) {
        b.max_edge = min_edge;
        b.max_edge_m = min_edge * spacing_m;
        b.sag = kSagMargin * b.max_edge_m * b.max_edge_m / (6 * kSagRadius);
        b.mesh_eps = eps - b.quant_error - b.sag;
        if (!(b.mesh_eps >= eps / 8)) {
            b.mesh_eps = eps / 8;
            b.drawn_bound = b.quant_error + b.sag + b.mesh_eps;
        }
    }
    return b;
}

ErrorBudget tile_error_budget(double eps, Scheme scheme, int z, int size, double sag_share) {
    return spacing_error_budget(
        eps, sample_spacing_m(scheme, z, size), core::kMinMaxEdge, sag_share);
}

std::string encode_tile(const TileRaster& raster,
                        const core::Mesh& mesh,
                        Format format,
                        const ErrorBudget& budget) {
    return encode_tile(raster, to_tile_mesh(raster, mesh, false), format, budget);
}

std::string encode_tile(const TileRaster& raster,
                        const TileMesh& mesh,
                        Format format,
                        const ErrorBudget& budget,
                        const std::vector<CheckPoint>& points,
                        EncodeReport* report,
                        const std::vector<std::array<double, 3>>* normals,
                        int threads,
                        const NormalsFn& make_normals,
                        const std::vector<CheckCell>& cells) {
    const std::size_t n = mesh.vertex_count();
    TB_ASSERT(normals == nullptr || normals->size() == n);
    TB_ASSERT(mesh.z.size() == n && mesh.y.size() == n && mesh.border.size() == n);
    TB_ASSERT(mesh.triangles.size() % 3 == 0);
    if (mesh.triangles.empty()) {
        if (report) {
            *report = EncodeReport{0, points.size() + cells.size(), budget.drawn_bound};
        }
        return empty_tile(raster, format, budget);
    }
    TB_ASSERT(n >= 3);
    TB_ASSERT(budget.quant_step > 0 && budget.eps > 0);
    check_lattice_fits(raster, budget);
    // Where the Draco encoding runs beside the check (speculate; see below), the normals made
    // on demand, which need the mesh alone, start now, beside the positions and the lattice.
    const bool speculate =
        threads >= 2 && (format == Format::Glb || (points.empty() && cells.empty()));
    Beside<std::vector<std::array<double, 3>>> normals_ahead;
    if (normals == nullptr && make_normals && speculate) {
        normals_ahead = beside([&make_normals] { return make_normals(); });
    }
    const double s = budget.quant_step;

    // Exact positions (double): lon/lat from the tile grid, height from the mesh.
    std::vector<Ecef> ecef(n);
    float z_min = mesh.z[0], z_max = mesh.z[0];
    for (std::size_t v = 0; v < n; ++v) {
        const LonLat ll = native_to_lonlat(raster.scheme, mesh.x[v], mesh.y[v]);
        ecef[v] = to_ecef({ll.lon, ll.lat, double(mesh.z[v])});
        z_min = std::min(z_min, mesh.z[v]);
        z_max = std::max(z_max, mesh.z[v]);
    }
    // The tile centre: the frame origin, on the level lattice.
    const Geodetic centre{(raster.bounds.west + raster.bounds.east) / 2,
                          (raster.bounds.south + raster.bounds.north) / 2,
                          std::round((double(z_min) + z_max) / 2 / s) * s};
    const EnuFrame enu = enu_frame(centre);
    const Ecef c = to_ecef(centre);
    const std::array<double, 3> kc{std::round(c.x / s), std::round(c.y / s), std::round(c.z / s)};
    std::array<double, 3> translation{};
    if (format == Format::Glb) {
        // glTF is y-up: ECEF (x, y, z) is written as (x, z, -y); the rotation keeps winding.
        translation = {kc[0] * s, kc[2] * s, -kc[1] * s};
    }
    std::vector<std::array<double, 3>> enu_exact(n);
    for (std::size_t v = 0; v < n; ++v) {
        enu_exact[v] = ecef_to_enu(enu, ecef[v]);
    }

    // Border vertices always snap to the level lattice s (their neighbour tile snaps them the
    // same way). Interior vertices start on s too; in the rare tile where that breaks eps
    // (a triangle steeper than kQuantMaxSlope next to a sample already near mesh_eps) they are
    // snapped to a finer lattice s/2^k, of which s is a sublattice, so borders still match.
    constexpr int kMaxRefine = 6;
    const TileFrame frame{centre, enu, translation, z_min, z_max};
    // With two threads the Draco encoding of the first lattice runs beside the check of the
    // drawn surface, on the second thread, once the normals made on demand are there: nearly
    // every tile keeps that lattice, and a refined one is encoded again after its check.
    // The published bound must be known before the check for a .drc (its eps_m), so a .drc
    // with check points is encoded after them. The bytes are the same either way.
    std::vector<std::array<double, 3>> made_normals;
    const auto ensure_normals = [&]() -> const std::vector<std::array<double, 3>>* {
        if (normals == nullptr && make_normals) {
            made_normals = normals_ahead.valid() ? normals_ahead.get() : make_normals();
            TB_ASSERT(made_normals.size() == n);
            normals = &made_normals;
        }
        return normals;
    };
    Beside<std::string> early;
    double step = s;
    std::vector<std::array<std::int64_t, 3>> q(n);
    std::vector<Ecef> world(n);
    GridVertices grid_world;
    Snapped snap; // the lattice of the last round: the one kept
    // What the snapped surface may miss a sample by, measured linearly in grid coordinates:
    // the chord sag (at most budget.sag, by the budget's longest edge) comes on top of it.
    const double allowed = budget.drawn_bound - budget.sag;
    for (int refine = 0;; ++refine) {
        step = std::ldexp(s, -refine);
        for (std::size_t v = 0; v < n; ++v) {
            const double unit = mesh.border[v] ? s : step;
            const double ratio = unit / step; // a power of two
            if (format == Format::Glb) {
                const std::array<double, 3> k{std::round(ecef[v].x / unit) * ratio,
                                              std::round(ecef[v].y / unit) * ratio,
                                              std::round(ecef[v].z / unit) * ratio};
                const double fine = s / step;
                q[v] = {std::llround(k[0] - kc[0] * fine),
                        std::llround(k[2] - kc[2] * fine),
                        -std::llround(k[1] - kc[1] * fine)};
                world[v] = {k[0] * step, k[1] * step, k[2] * step};
            } else {
                std::array<double, 3> local{};
                for (int a = 0; a < 3; ++a) {
                    const double k = std::round(enu_exact[v][a] / unit) * ratio;
                    q[v][a] = std::llround(k);
                    local[a] = k * step;
                }
                world[v] = enu_to_ecef(enu, local);
            }
        }
        // Throws when the lattice is too fine for the tile.
        snap = finish_lattice(q, step, raster, budget);
        if (speculate && refine == 0) {
            early = beside([&, lattice = snap, step]() {
                return draco_tile(raster,
                                  mesh,
                                  format,
                                  budget,
                                  frame,
                                  lattice,
                                  step,
                                  budget.drawn_bound,
                                  ensure_normals());
            });
        }
        grid_world = to_grid(raster, world);
        const Verdict verdict =
            snapped_error(raster, mesh, grid_world, early.valid() ? 1 : threads);
        if (early.valid() && !(verdict.max_error <= allowed)) {
            try {
                early.get(); // the lattice is refined: these bytes are not used
            } catch (const std::exception&) {
                // encoded again below, where a real failure throws
            }
        }
        if (verdict.max_error <= allowed) {
            if (refine > 0) {
                log::debug("tile " + tile_name(raster.id) + ": interior lattice refined to " +
                           number(step) + " m to keep eps " + number(budget.drawn_bound) + " m");
            }
            break;
        }
        if (refine == kMaxRefine) {
            throw Error("tile " + tile_name(raster.id) + ": quantizing positions to the " +
                        number(s) + " m lattice moves the surface by up to " +
                        number(verdict.max_error) + " m at sample (" +
                        std::to_string(verdict.column) + ", " + std::to_string(verdict.row) +
                        "), more than the " + number(allowed) + " m that eps " +
                        number(budget.drawn_bound) + " m leaves beside the chord sag (a " +
                        "near-vertical cliff on the tile border); this is a bug, "
                        "please report it with the tile");
        }
    }
    EncodeReport measured = points_error(mesh, grid_world, points);
    if (!cells.empty()) {
        const CellsVerdict judged = cells_error(GridSurface{grid_world, mesh.triangles}, cells);
        measured.points_error = std::max(measured.points_error, judged.error);
        measured.points_outside += judged.outside;
    }
    measured.published = budget.drawn_bound;
    if (!points.empty() || !cells.empty()) {
        // Rounded up, so the number printed is never below what was measured.
        measured.published = std::max(measured.published,
                                      std::nextafter(measured.points_error + budget.sag,
                                                     std::numeric_limits<double>::infinity()));
    }
    if (report) {
        *report = measured;
    }
    if (early.valid()) {
        return early.get(); // the first lattice held
    }
    return draco_tile(
        raster, mesh, format, budget, frame, snap, step, measured.published, ensure_normals());
}

} // namespace tb::tiler
