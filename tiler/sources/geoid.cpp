// EGM96 undulation from PROJ's egm96_15.gtx (721 x 1440 Float32, 0.25 degree cells whose
// centres lie on multiples of 0.25 degree), read once with GDAL and interpolated bilinearly.
#include "tiler/sources/geoid.hpp"

#include "core/error.hpp"
#include "tiler/sources/gdal_source.hpp"

#include <algorithm>
#include <cmath>
#include <mutex>

namespace tb::tiler {
namespace {

const FloatGrid& egm96_grid() {
    static std::once_flag once;
    static FloatGrid grid;
    std::call_once(once, [] {
        FloatGrid g = read_float_grid(kEgm96GridPath);
        const auto& t = g.geotransform;
        // The interpolation below relies on a global north-up grid with whole columns.
        if (t[2] != 0 || t[4] != 0 || t[1] <= 0 || t[5] >= 0 ||
            std::abs(t[1] * g.width - 360.0) > 1e-9) {
            throw InputError(std::string(kEgm96GridPath) +
                             ": not a global north-up geoid grid; reinstall proj-data");
        }
        grid = std::move(g);
    });
    return grid;
}

} // namespace

Egm96Column egm96_column(double lon) {
    const FloatGrid& g = egm96_grid();
    const auto& t = g.geotransform;
    // Cell-centre coordinates: column c sits at lon t0 + (c + 0.5) t1.
    double u = (lon - t[0]) / t[1] - 0.5;
    // Wrapped into [0, width): fmod is slow and, for a u already there, returns it unchanged.
    if (!(u >= 0 && u < static_cast<double>(g.width))) {
        u = std::fmod(u, static_cast<double>(g.width));
        if (u < 0) {
            u += g.width;
        }
    }
    Egm96Column c;
    c.c0 = std::min(static_cast<int>(u), g.width - 1);
    c.c1 = (c.c0 + 1) % g.width; // longitude wraps
    c.fu = u - c.c0;
    return c;
}

Egm96Row egm96_row(double lat) {
    const FloatGrid& g = egm96_grid();
    const auto& t = g.geotransform;
    double v = (std::clamp(lat, -90.0, 90.0) - t[3]) / t[5] - 0.5;
    v = std::clamp(v, 0.0, static_cast<double>(g.height - 1));
    const int r0 = std::min(static_cast<int>(v), g.height - 2);
    Egm96Row r;
    r.upper = g.values.data() + static_cast<std::size_t>(r0) * g.width;
    r.lower = r.upper + g.width;
    r.fv = v - r0;
    return r;
}

double egm96_undulation(double lon, double lat) {
    return egm96_at(egm96_column(lon), egm96_row(lat));
}

} // namespace tb::tiler
