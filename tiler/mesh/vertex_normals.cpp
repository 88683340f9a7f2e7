// Vertex normals from the DEM's slope (vertex_normals.hpp).
#include "tiler/mesh/vertex_normals.hpp"

#include "tiler/sources/tile_raster.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>

namespace tb::tiler {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180;

// Gradient (dh/dx, dh/dy) per vertex, as the height difference across two steps of
// step_x, step_y grid units; `degrees`: those units are degrees, else EPSG:3857 metres.
struct Gradients {
    std::vector<double> gx, gy;
    double step_x = 0, step_y = 0;
    bool degrees = false;
};

// Central differences one pixel either side on the bilinear surface of the source's pixels
// (voids left out of the weights), in the pixel grid's units.
Gradients pixel_gradients(const TileMesh& m,
                          const std::vector<LonLat>& ll,
                          const TileId& id,
                          Scheme scheme,
                          const DemSource& source,
                          const PixelGrid& g) {
    Gradients d{std::vector<double>(m.vertex_count()), std::vector<double>(m.vertex_count())};
    d.degrees = g.lonlat;
    // A vertex in the pixel grid's units: lon/lat, or (mercator scheme) its native metres.
    const auto grid_xy = [&](std::size_t v) {
        return g.lonlat ? std::pair{ll[v].lon, ll[v].lat} : std::pair{m.x[v], m.y[v]};
    };
    const LonLatBox b = tile_bounds(scheme, id);
    double west = b.west, north = b.north, east = b.east, south = b.south;
    if (!g.lonlat) {
        lonlat_to_native(scheme, {b.west, b.north}, west, north);
        lonlat_to_native(scheme, {b.east, b.south}, east, south);
    }
    const auto col = [&g](double x) { return (x - g.x0) / g.dx - 0.5; };
    const auto row = [&g](double y) { return (g.y0 - y) / g.dy - 0.5; };
    // The tile and 3 pixels around it, the part inside the raster only: beyond it every
    // pixel is nodata, which the lookups skip as they skip pixels off the window (a
    // tile at the source's edge would otherwise fill megabytes with NaN).
    const auto first_col = static_cast<std::int64_t>(std::floor(col(west))) - 3;
    const auto first_row = static_cast<std::int64_t>(std::floor(row(north))) - 3;
    const auto end_col = static_cast<std::int64_t>(std::ceil(col(east))) + 4;
    const auto end_row = static_cast<std::int64_t>(std::ceil(row(south))) + 4;
    const std::int64_t c0 = std::max<std::int64_t>(first_col, 0);
    const std::int64_t r0 = std::max<std::int64_t>(first_row, 0);
    const int w =
        static_cast<int>(std::max<std::int64_t>(std::min<std::int64_t>(end_col, g.width) - c0, 0));
    const int h =
        static_cast<int>(std::max<std::int64_t>(std::min<std::int64_t>(end_row, g.height) - r0, 0));
    const std::vector<double> px =
        w > 0 && h > 0 ? source.read_pixels(c0, r0, w, h) : std::vector<double>();
    const auto bilinear = [&](double fc, double fr, double& value) {
        const double ic = std::floor(fc), ir = std::floor(fr);
        const double tc = fc - ic, tr = fr - ir;
        double sum = 0, total = 0;
        for (int k = 0; k < 4; ++k) {
            const std::int64_t c = static_cast<std::int64_t>(ic) + (k & 1) - c0;
            const std::int64_t r = static_cast<std::int64_t>(ir) + (k >> 1) - r0;
            if (c < 0 || r < 0 || c >= w || r >= h) {
                continue;
            }
            const double v = px[static_cast<std::size_t>(r * w + c)];
            const double weight = ((k & 1) ? tc : 1 - tc) * ((k >> 1) ? tr : 1 - tr);
            if (!std::isnan(v) && weight > 0) {
                sum += weight * v, total += weight;
            }
        }
        if (total <= 0) {
            return false;
        }
        value = sum / total;
        return true;
    };
    d.step_x = g.dx, d.step_y = g.dy;
    for (std::size_t v = 0; v < m.vertex_count(); ++v) {
        const auto [x, y] = grid_xy(v);
        const double fc = col(x), fr = row(y);
        double e = 0, wst = 0, n = 0, s = 0;
        d.gx[v] = bilinear(fc + 1, fr, e) && bilinear(fc - 1, fr, wst) ? (e - wst) : 0.0;
        d.gy[v] = bilinear(fc, fr - 1, n) && bilinear(fc, fr + 1, s) ? (n - s) : 0.0;
    }
    return d;
}

// Central differences on the zoom's lattice, in the scheme's native units.
Gradients lattice_gradients(const TileMesh& m,
                            const TileId& id,
                            Scheme scheme,
                            int tile_size,
                            const DemSource& source,
                            const LatticeSampler& lattice) {
    Gradients d{std::vector<double>(m.vertex_count()), std::vector<double>(m.vertex_count())};
    d.degrees = scheme == Scheme::Geodetic;
    const int n = tile_size;
    const std::int64_t c0 = tile_first_column(scheme, id, n) - 1;
    const std::int64_t r0 = tile_first_row(scheme, id, n) - 1;
    const int w = n + 3;
    const LatticeBlock block = lattice ? lattice(scheme, id.z, n, c0, r0, w, w)
                                       : source.sample(scheme, id.z, n, c0, r0, w, w);
    TileRaster raster;
    raster.id = id;
    raster.scheme = scheme;
    raster.size = n;
    const GridFrame f = frame_of(raster); // native units, the zoom's lattice
    d.step_x = f.dx, d.step_y = f.dy;
    const auto at = [&](int i, int j, double& value) {
        if (i < 0 || j < 0 || i >= w || j >= w) {
            return false;
        }
        const std::size_t k = static_cast<std::size_t>(j) * w + static_cast<std::size_t>(i);
        value = block.heights[k];
        return block.valid[k] != 0;
    };
    for (std::size_t v = 0; v < m.vertex_count(); ++v) {
        const int i = static_cast<int>(std::lround((m.x[v] - f.x0) / f.dx)) + 1;
        const int j = static_cast<int>(std::lround((f.y0 - m.y[v]) / f.dy)) + 1;
        double e = 0, wst = 0, nn = 0, s = 0;
        d.gx[v] = at(i + 1, j, e) && at(i - 1, j, wst) ? (e - wst) : 0.0;
        d.gy[v] = at(i, j - 1, nn) && at(i, j + 1, s) ? (nn - s) : 0.0;
    }
    return d;
}

} // namespace

std::vector<std::array<double, 3>> vertex_normals(const TileMesh& m,
                                                  const TileId& id,
                                                  Scheme scheme,
                                                  int tile_size,
                                                  const DemSource& source,
                                                  const PixelGrid* pixels,
                                                  const LatticeSampler& lattice) {
    constexpr double kA = 6378137.0, kE2 = 6.69437999014e-3;
    std::vector<std::array<double, 3>> out(m.vertex_count());
    std::vector<LonLat> ll(m.vertex_count());
    for (std::size_t v = 0; v < m.vertex_count(); ++v) {
        ll[v] = native_to_lonlat(scheme, m.x[v], m.y[v]);
    }
    const Gradients d = pixels ? pixel_gradients(m, ll, id, scheme, source, *pixels)
                               : lattice_gradients(m, id, scheme, tile_size, source, lattice);
    for (std::size_t v = 0; v < m.vertex_count(); ++v) {
        const double lon = ll[v].lon * kDeg, lat = ll[v].lat * kDeg;
        const double sl = std::sin(lat), cl = std::cos(lat);
        const double w2 = 1 - kE2 * sl * sl;
        const double radius_lon = kA / std::sqrt(w2) * cl;               // metres per radian
        const double radius_lat = kA * (1 - kE2) / (w2 * std::sqrt(w2)); // metres per radian
        // Ground metres per grid unit: per degree, or per EPSG:3857 metre (x = a lon,
        // y = a ln tan(pi/4 + lat/2), so dlon/dx = 1/a and dlat/dy = cos(lat)/a).
        const double metres_x = d.degrees ? radius_lon * kDeg : radius_lon / kA;
        const double metres_y = d.degrees ? radius_lat * kDeg : radius_lat * cl / kA;
        const double de = d.gx[v] / (2 * d.step_x * std::max(metres_x, 1e-6));
        const double dn = d.gy[v] / (2 * d.step_y * metres_y);
        const std::array<double, 3> east{-std::sin(lon), std::cos(lon), 0};
        const std::array<double, 3> north{-sl * std::cos(lon), -sl * std::sin(lon), cl};
        const std::array<double, 3> up{cl * std::cos(lon), cl * std::sin(lon), sl};
        std::array<double, 3> nv{};
        double len = 0;
        for (int k = 0; k < 3; ++k) {
            nv[k] = up[k] - de * east[k] - dn * north[k];
            len += nv[k] * nv[k];
        }
        for (double& c : nv) {
            c /= std::sqrt(len);
        }
        out[v] = nv;
    }
    return out;
}

} // namespace tb::tiler
