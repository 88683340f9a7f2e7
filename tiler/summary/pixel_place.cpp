// Where a summarised source's pixels lie (pixel_place.hpp).
#include "tiler/summary/pixel_place.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <utility>

namespace tb::tiler {

bool summary_serves(const PixelGrid& grid, Scheme scheme) {
    return grid.lonlat == (scheme == Scheme::Geodetic);
}

double pixels_per_step(const PixelGrid& grid, Scheme scheme, int z, int size) {
    const double step = lattice_x(scheme, z, size, 1) - lattice_x(scheme, z, size, 0);
    return step / std::max(grid.dx, grid.dy);
}

PixelPlace::PixelPlace(const DemSource& source, Scheme scheme)
    : source_(&source), grid_(source.pixel_grid(scheme)) {
    TB_ASSERT(source.georeferenced() && source.members().empty());
    serves_ = grid_ && summary_serves(*grid_, scheme);
    width_ = source.info().width;
    height_ = source.info().height;
    const double metres = source.info().resolution_m;
    fine_span_ = metres > 0 ? std::clamp(std::floor(80 / metres), 1.0, 8.0) : 1.0;
}

void PixelPlace::row_to_lonlat(double i0,
                               double di,
                               double j,
                               int n,
                               double span,
                               std::vector<double>& lon,
                               std::vector<double>& lat) const {
    const int s = grid_ ? 1 : std::max(1, static_cast<int>(std::floor(span / di)));
    std::vector<int> at; // the points moved through the CRS
    for (int k = 0; k < n; k += s) {
        at.push_back(k);
    }
    if (at.empty() || at.back() != n - 1) {
        at.push_back(n - 1);
    }
    std::vector<double> x(at.size()), y(at.size(), j);
    for (std::size_t q = 0; q < at.size(); ++q) {
        x[q] = i0 + at[q] * di;
    }
    to_lonlat(x, y);
    if (s == 1) {
        lon = std::move(x), lat = std::move(y);
        return;
    }
    // Across the antimeridian, interpolate the longitude the short way round, then wrap it.
    for (std::size_t q = 1; q < x.size(); ++q) {
        if (x[q] - x[q - 1] > 180) {
            x[q] -= 360;
        } else if (x[q] - x[q - 1] < -180) {
            x[q] += 360;
        }
    }
    lon.resize(static_cast<std::size_t>(n));
    lat.resize(static_cast<std::size_t>(n));
    for (std::size_t q = 0; q + 1 < at.size(); ++q) {
        const int k0 = at[q], k1 = at[q + 1];
        for (int k = k0; k < k1; ++k) {
            const double f = static_cast<double>(k - k0) / (k1 - k0);
            lon[static_cast<std::size_t>(k)] = x[q] + f * (x[q + 1] - x[q]);
            lat[static_cast<std::size_t>(k)] = y[q] + f * (y[q + 1] - y[q]);
        }
    }
    lon.back() = x.back(), lat.back() = y.back();
    for (double& v : lon) {
        v = v > 180 ? v - 360 : v < -180 ? v + 360 : v;
    }
}

double PixelPlace::pixels_per_step(Scheme scheme, int z, int size) const {
    return grid_ && summary_serves(*grid_, scheme) ? tiler::pixels_per_step(*grid_, scheme, z, size)
                                                   : source_->pixels_per_sample(scheme, z, size);
}

LonLatBox PixelPlace::footprint() const {
    return source_->footprint();
}

void PixelPlace::to_lonlat(std::vector<double>& x, std::vector<double>& y) const {
    if (!grid_) {
        source_->pixels_to_lonlat(x, y);
        return;
    }
    const PixelGrid& g = *grid_;
    for (std::size_t k = 0; k < x.size(); ++k) {
        const double gx = g.x0 + (x[k] + 0.5) * g.dx, gy = g.y0 - (y[k] + 0.5) * g.dy;
        if (g.lonlat) {
            x[k] = gx, y[k] = gy;
        } else {
            const LonLat p = native_to_lonlat(Scheme::Mercator, gx, gy);
            x[k] = p.lon, y[k] = p.lat;
        }
    }
}

void PixelPlace::to_pixels(std::vector<double>& x, std::vector<double>& y) const {
    if (!grid_) {
        source_->lonlat_to_pixels(x, y);
        return;
    }
    const PixelGrid& g = *grid_;
    for (std::size_t k = 0; k < x.size(); ++k) {
        double gx = x[k], gy = y[k];
        if (!g.lonlat) {
            lonlat_to_native(Scheme::Mercator, {x[k], y[k]}, gx, gy);
        }
        x[k] = (gx - g.x0) / g.dx - 0.5;
        y[k] = (g.y0 - gy) / g.dy - 0.5;
    }
}

std::string PixelPlace::key() const {
    std::ostringstream key;
    key.precision(17);
    if (grid_) {
        const PixelGrid& g = *grid_;
        key << g.x0 << " " << g.y0 << " " << g.dx << " " << g.dy << " " << g.width << " "
            << g.height << " " << (g.lonlat ? "lonlat" : "mercator");
        return key.str();
    }
    key << "crs";
    for (const double v : source_->info().geotransform) {
        key << " " << v;
    }
    const DemInfo& info = source_->info();
    key << " " << width_ << " " << height_ << " " << info.crs_id << " " << info.crs_name;
    return key.str();
}

} // namespace tb::tiler
