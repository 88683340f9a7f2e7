// Tile rasters from the zoom's lattice (lattice_raster.hpp).
#include "tiler/sources/lattice_raster.hpp"

#include "core/error.hpp"
#include "tiler/sources/geoid.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <tuple>
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

// Unit vectors (on a sphere) of the lattice points of zoom z from (c0, r0), w x h: longitude
// depends on the column alone and latitude on the row alone in both schemes, so the
// trigonometry is done once per column and per row.
class UnitLattice {
public:
    UnitLattice(Scheme scheme, int z, int n, std::int64_t c0, std::int64_t r0, int w, int h)
        : c0_(c0), r0_(r0) {
        constexpr double kRad = 3.14159265358979323846 / 180.0;
        for (int i = 0; i < w; ++i) {
            const double lon = native_to_lonlat(scheme, lattice_x(scheme, z, n, c0 + i), 0).lon;
            cos_lon_.push_back(std::cos(lon * kRad));
            sin_lon_.push_back(std::sin(lon * kRad));
        }
        for (int j = 0; j < h; ++j) {
            const double lat = native_to_lonlat(scheme, 0, lattice_y(scheme, z, n, r0 + j)).lat;
            cos_lat_.push_back(std::cos(lat * kRad));
            sin_lat_.push_back(std::sin(lat * kRad));
        }
    }
    // Metres between two lattice points (the chord on a sphere of the Earth's mean radius).
    double metres(std::int64_t c, std::int64_t r, std::int64_t qc, std::int64_t qr) const {
        const auto u = at(c, r), v = at(qc, qr);
        return 6371008.8 * std::hypot(u[0] - v[0], u[1] - v[1], u[2] - v[2]);
    }

private:
    std::array<double, 3> at(std::int64_t c, std::int64_t r) const {
        const auto i = static_cast<std::size_t>(c - c0_), j = static_cast<std::size_t>(r - r0_);
        return {cos_lat_[j] * cos_lon_[i], cos_lat_[j] * sin_lon_[i], sin_lat_[j]};
    }
    std::int64_t c0_, r0_;
    std::vector<double> cos_lon_, sin_lon_, cos_lat_, sin_lat_;
};

// The orthometric height carried to lattice point (c, r) from the footprint point (qc, qr)
// nearest it, whose height is `edge`. The slope starts one lattice step out: the first ring
// beyond the footprint keeps the edge's height, since the DEM's own pixels may reach up to a
// step past the lattice points inside it.
double carried_ortho(double edge,
                     const UnitLattice& units,
                     std::int64_t c,
                     std::int64_t r,
                     std::int64_t qc,
                     std::int64_t qr) {
    const auto back = [](std::int64_t v, std::int64_t q) { return v - (v > q) + (v < q); };
    const double d = units.metres(back(c, qc), back(r, qr), qc, qr);
    return std::copysign(std::max(0.0, std::abs(edge) - kEdgeGrade * d), edge);
}

LonLat lattice_lonlat(Scheme scheme, int z, int n, std::int64_t c, std::int64_t r) {
    return native_to_lonlat(scheme, lattice_x(scheme, z, n, c), lattice_y(scheme, z, n, r));
}

double undulation_at(Scheme scheme, int z, int n, std::int64_t c, std::int64_t r) {
    const LonLat p = lattice_lonlat(scheme, z, n, c, r);
    return egm96_undulation(p.lon, p.lat);
}

} // namespace

double carried_height(Scheme scheme,
                      int z,
                      int tile_size,
                      std::int64_t column,
                      std::int64_t row,
                      const LatticeFootprint& fp,
                      VerticalDatum datum) {
    TB_ASSERT(fp.first_column <= fp.last_column && fp.first_row <= fp.last_row && fp.sample);
    const std::int64_t qc = std::clamp(column, fp.first_column, fp.last_column);
    const std::int64_t qr = std::clamp(row, fp.first_row, fp.last_row);
    const LatticeBlock b = fp.sample(scheme, z, tile_size, qc, qr, 1, 1);
    if (b.valid.empty() || b.valid[0] == 0) {
        return std::nan("");
    }
    const bool ellipsoid = datum == VerticalDatum::Ellipsoid;
    const double edge =
        b.heights[0] - (ellipsoid ? undulation_at(scheme, z, tile_size, qc, qr) : 0);
    const std::int64_t c0 = std::min(column, qc), r0 = std::min(row, qr);
    const UnitLattice units(scheme,
                            z,
                            tile_size,
                            c0,
                            r0,
                            static_cast<int>(std::max(column, qc) - c0 + 1),
                            static_cast<int>(std::max(row, qr) - r0 + 1));
    return carried_ortho(edge, units, column, row, qc, qr) +
           undulation_at(scheme, z, tile_size, column, row);
}

namespace {

// lattice_tile_raster's first rule (see there): sets `ortho` and `known` at the carried voids of
// the w x w block from lattice point (c0, r0). `ortho` holds the block's orthometric heights.
void carry_edge_outward(Scheme scheme,
                        int z,
                        int n,
                        int w,
                        const LatticeBlock& block,
                        const LatticeFootprint& fp,
                        std::vector<double>& ortho,
                        std::vector<std::uint8_t>& known) {
    TB_ASSERT(fp.first_column <= fp.last_column && fp.first_row <= fp.last_row);
    const std::int64_t c0 = block.column0, r0 = block.row0;
    const auto clamp_c = [&](std::int64_t c) {
        return std::clamp(c, fp.first_column, fp.last_column);
    };
    const auto clamp_r = [&](std::int64_t r) { return std::clamp(r, fp.first_row, fp.last_row); };
    if (clamp_c(c0) == c0 && clamp_c(c0 + w - 1) == c0 + w - 1 && clamp_r(r0) == r0 &&
        clamp_r(r0 + w - 1) == r0 + w - 1) {
        return; // the block lies inside the footprint
    }
    // A tile meets the data, so the footprint points nearest its block's lie in the block.
    TB_ASSERT(clamp_c(c0) < c0 + w && clamp_c(c0 + w - 1) >= c0);
    TB_ASSERT(clamp_r(r0) < r0 + w && clamp_r(r0 + w - 1) >= r0);
    const UnitLattice units(scheme, z, n, c0, r0, w, w);
    const auto at = [&](std::int64_t c, std::int64_t r) {
        return static_cast<std::size_t>((r - r0) * w + (c - c0));
    };
    for (std::int64_t r = r0; r < r0 + w; ++r) {
        for (std::int64_t c = c0; c < c0 + w; ++c) {
            const std::int64_t qc = clamp_c(c), qr = clamp_r(r);
            if ((qc == c && qr == r) || block.valid[at(c, r)] != 0 ||
                block.valid[at(qc, qr)] == 0) {
                continue; // inside, measured, or beyond a void edge (left to fill_voids)
            }
            ortho[at(c, r)] = carried_ortho(ortho[at(qc, qr)], units, c, r, qc, qr);
            known[at(c, r)] = 1;
        }
    }
}

} // namespace

TileRaster lattice_tile_raster(const TileId& id,
                               const LatticeBlock& block,
                               Scheme scheme,
                               int tile_size,
                               VerticalDatum datum,
                               const LatticeFootprint* footprint) {
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
    if (footprint != nullptr) {
        carry_edge_outward(scheme, id.z, n, w, block, *footprint, ortho, known);
    }
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
