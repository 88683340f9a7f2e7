// Where a summarised source's pixels lie (pixel_place.hpp).
#include "tiler/summary/pixel_place.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

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
    key << " " << width_ << " " << height_;
    return key.str();
}

} // namespace tb::tiler
