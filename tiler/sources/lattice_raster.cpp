// Tile rasters from the zoom's lattice (lattice_raster.hpp).
#include "tiler/sources/lattice_raster.hpp"

#include "tiler/geodesy.hpp"
#include "tiler/sources/geoid.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace tb::tiler {

LatticeSampler sampler_or_source(LatticeSampler sampler, const DemSource& source) {
    if (sampler) {
        return sampler;
    }
    return [&source](Scheme s, int z, int size, std::int64_t c, std::int64_t r, int w, int h) {
        return source.sample(s, z, size, c, r, w, h);
    };
}

LatticeFootprint lattice_footprint(
    Scheme scheme, int z, int tile_size, const LonLatBox& box, LatticeSampler sample) {
    double west = 0, north = 0, east = 0, south = 0;
    lonlat_to_native(scheme, {box.west, box.north}, west, north);
    lonlat_to_native(scheme, {box.east, box.south}, east, south);
    const double x_min = lattice_x(scheme, z, tile_size, 0);
    const double step = lattice_x(scheme, z, tile_size, 1) - x_min;
    const double y_max = lattice_y(scheme, z, tile_size, 0);
    // The lattice indices from lo to hi (lattice units), or the one nearest their middle.
    const auto span = [](double lo, double hi) {
        auto first = static_cast<std::int64_t>(std::ceil(lo - 1e-9));
        auto last = static_cast<std::int64_t>(std::floor(hi + 1e-9));
        if (first > last) {
            first = last = std::llround(0.5 * (lo + hi));
        }
        return std::pair{first, last};
    };
    LatticeFootprint f;
    std::tie(f.first_column, f.last_column) = span((west - x_min) / step, (east - x_min) / step);
    std::tie(f.first_row, f.last_row) = span((y_max - north) / step, (y_max - south) / step);
    f.sample = std::move(sample);
    return f;
}

namespace {

LonLat lattice_lonlat(Scheme scheme, int z, int n, std::int64_t c, std::int64_t r) {
    return native_to_lonlat(scheme, lattice_x(scheme, z, n, c), lattice_y(scheme, z, n, r));
}

// The orthometric height carried to p from the footprint point q, whose height is `edge`.
double carried_ortho(double edge, const LonLat& p, const LonLat& q) {
    const Ecef a = to_ecef({p.lon, p.lat, 0}), b = to_ecef({q.lon, q.lat, 0});
    const double d = std::hypot(a.x - b.x, a.y - b.y, a.z - b.z);
    return std::copysign(std::max(0.0, std::abs(edge) - kEdgeGrade * d), edge);
}

} // namespace

double carried_height(Scheme scheme,
                      int z,
                      int tile_size,
                      std::int64_t column,
                      std::int64_t row,
                      const LatticeFootprint& fp,
                      VerticalDatum datum) {
    const std::int64_t qc = std::clamp(column, fp.first_column, fp.last_column);
    const std::int64_t qr = std::clamp(row, fp.first_row, fp.last_row);
    const LatticeBlock b = fp.sample(scheme, z, tile_size, qc, qr, 1, 1);
    if (b.valid.empty() || b.valid[0] == 0) {
        return std::nan("");
    }
    const LonLat p = lattice_lonlat(scheme, z, tile_size, column, row);
    const LonLat q = lattice_lonlat(scheme, z, tile_size, qc, qr);
    const double edge =
        b.heights[0] - (datum == VerticalDatum::Ellipsoid ? egm96_undulation(q.lon, q.lat) : 0.0);
    return carried_ortho(edge, p, q) + egm96_undulation(p.lon, p.lat);
}

namespace {

// lattice_tile_raster's first rule (see there): sets `ortho` and `known` at the carried voids of
// the w x w block from lattice point (c0, r0). `ortho` holds the block's orthometric heights.
void carry_edge_outward(Scheme scheme,
                        int z,
                        int n,
                        int w,
                        const LatticeBlock& block,
                        VerticalDatum datum,
                        const LatticeFootprint& fp,
                        std::vector<double>& ortho,
                        std::vector<std::uint8_t>& known) {
    const std::int64_t c0 = block.column0, r0 = block.row0;
    const auto clamp_c = [&](std::int64_t c) {
        return std::clamp(c, fp.first_column, fp.last_column);
    };
    const auto clamp_r = [&](std::int64_t r) { return std::clamp(r, fp.first_row, fp.last_row); };
    const std::int64_t ca = clamp_c(c0), cb = clamp_c(c0 + w - 1);
    const std::int64_t ra = clamp_r(r0), rb = clamp_r(r0 + w - 1);
    if (ca == c0 && cb == c0 + w - 1 && ra == r0 && rb == r0 + w - 1) {
        return; // the block lies inside the footprint
    }
    const auto lonlat = [&](std::int64_t c, std::int64_t r) {
        return lattice_lonlat(scheme, z, n, c, r);
    };
    // The clamped points lie in the block unless the block misses the footprint: then read them.
    const bool own = ca >= c0 && cb < c0 + w && ra >= r0 && rb < r0 + w;
    const auto read_width = static_cast<int>(cb - ca + 1);
    LatticeBlock read;
    if (!own) {
        read = fp.sample(scheme, z, n, ca, ra, read_width, static_cast<int>(rb - ra + 1));
    }
    const auto edge_height = [&](std::int64_t c, std::int64_t r, double& h) {
        if (own) {
            const auto k = static_cast<std::size_t>((r - r0) * w + (c - c0));
            h = ortho[k];
            return block.valid[k] != 0;
        }
        const auto k = static_cast<std::size_t>((r - ra) * read_width + (c - ca));
        h = read.heights[k];
        if (read.valid[k] != 0 && datum == VerticalDatum::Ellipsoid) {
            const LonLat p = lonlat(c, r);
            h -= egm96_undulation(p.lon, p.lat);
        }
        return read.valid[k] != 0;
    };
    for (int j = 0; j < w; ++j) {
        for (int i = 0; i < w; ++i) {
            const std::int64_t c = c0 + i, r = r0 + j;
            const auto k = static_cast<std::size_t>(j) * w + i;
            double h = 0;
            if ((clamp_c(c) == c && clamp_r(r) == r) || block.valid[k] != 0 ||
                !edge_height(clamp_c(c), clamp_r(r), h)) {
                continue; // inside, measured, or beyond a void edge (left to fill_voids)
            }
            ortho[k] = carried_ortho(h, lonlat(c, r), lonlat(clamp_c(c), clamp_r(r)));
            known[k] = 1;
        }
    }
}

} // namespace

TileRaster lattice_tile_raster(const TileId& id,
                               const LatticeBlock& block,
                               Scheme scheme,
                               int tile_size,
                               VerticalDatum datum,
                               const LatticeFootprint& footprint) {
    const int n = tile_size;
    const int m = kLatticeFillMargin;
    const int w = n + 1 + 2 * m;
    const std::int64_t c0 = block.column0, r0 = block.row0;

    // Undulation of every lattice point (the same for a point in every tile that holds it).
    std::vector<double> undulation(block.heights.size());
    for (int j = 0; j < w; ++j) {
        const double y = lattice_y(scheme, id.z, n, r0 + j);
        for (int i = 0; i < w; ++i) {
            const LonLat p = native_to_lonlat(scheme, lattice_x(scheme, id.z, n, c0 + i), y);
            undulation[static_cast<std::size_t>(j) * w + i] = egm96_undulation(p.lon, p.lat);
        }
    }
    // Fill voids in orthometric heights, so data-free areas sit on the geoid (sea level).
    std::vector<double> ortho = block.heights;
    if (datum == VerticalDatum::Ellipsoid) {
        for (std::size_t k = 0; k < ortho.size(); ++k) {
            ortho[k] -= block.valid[k] ? undulation[k] : 0.0;
        }
    }
    std::vector<std::uint8_t> known = block.valid;
    carry_edge_outward(scheme, id.z, n, w, block, datum, footprint, ortho, known);
    fill_voids(ortho, known, w, w, m, 0.0);

    TileRaster raster;
    raster.id = id;
    raster.scheme = scheme;
    raster.bounds = tile_bounds(scheme, id);
    raster.size = n;
    raster.grid.width = n + 1;
    raster.grid.height = n + 1;
    raster.grid.heights.resize(static_cast<std::size_t>(n + 1) * (n + 1));
    std::vector<std::uint8_t> valid(raster.grid.heights.size());
    bool all_valid = true;
    for (int j = 0; j <= n; ++j) {
        for (int i = 0; i <= n; ++i) {
            const std::size_t k = static_cast<std::size_t>(j + m) * w + (i + m);
            const std::size_t t = static_cast<std::size_t>(j) * (n + 1) + i;
            const bool measured = block.valid[k] != 0;
            double h = ortho[k] + undulation[k];
            if (datum == VerticalDatum::Ellipsoid && measured) {
                h = block.heights[k]; // the source's own ellipsoidal height, untouched
            }
            raster.grid.heights[t] = static_cast<float>(h);
            valid[t] = measured ? 1 : 0;
            all_valid = all_valid && measured;
        }
    }
    if (!all_valid) {
        raster.grid.valid = std::move(valid);
    }
    return raster;
}

} // namespace tb::tiler
