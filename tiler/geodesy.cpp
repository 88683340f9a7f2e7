// WGS84 geodesy: GeographicLib's Geocentric (exact, not an iterative approximation) for
// geodetic <-> ECEF, plus ENU frames and tile bounding volumes.
#include "tiler/geodesy.hpp"

#include "core/error.hpp"

#include <GeographicLib/Geocentric.hpp>

#include <algorithm>
#include <cmath>

namespace tb::tiler {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

// The boundary of a lon/lat box, sampled: corners, edge points and the centre. Large boxes
// (a hemisphere at z=0) bulge between corners, so each edge is sampled densely.
template <class F> void for_each_box_point(const LonLatBox& box, F&& f) {
    constexpr int kSteps = 16;
    for (int j = 0; j <= kSteps; ++j) {
        for (int i = 0; i <= kSteps; ++i) {
            const bool on_edge = i == 0 || j == 0 || i == kSteps || j == kSteps;
            if (!on_edge && !(i == kSteps / 2 && j == kSteps / 2)) {
                continue;
            }
            f(box.west + (box.east - box.west) * i / kSteps,
              box.south + (box.north - box.south) * j / kSteps);
        }
    }
}

double distance(const Ecef& a, const Ecef& b) {
    return std::hypot(a.x - b.x, a.y - b.y, a.z - b.z);
}

} // namespace

Ecef to_ecef(const Geodetic& p) {
    Ecef out;
    GeographicLib::Geocentric::WGS84().Forward(p.lat, p.lon, p.h, out.x, out.y, out.z);
    return out;
}

Geodetic to_geodetic(const Ecef& p) {
    Geodetic out;
    GeographicLib::Geocentric::WGS84().Reverse(p.x, p.y, p.z, out.lat, out.lon, out.h);
    return out;
}

EnuFrame enu_frame(const Geodetic& origin) {
    EnuFrame frame;
    frame.origin = origin;
    frame.origin_ecef = to_ecef(origin);
    const double sl = std::sin(origin.lon * kDeg), cl = std::cos(origin.lon * kDeg);
    const double sp = std::sin(origin.lat * kDeg), cp = std::cos(origin.lat * kDeg);
    frame.axes[0] = {-sl, cl, 0.0};
    frame.axes[1] = {-sp * cl, -sp * sl, cp};
    frame.axes[2] = {cp * cl, cp * sl, sp};
    return frame;
}

Ecef enu_to_ecef(const EnuFrame& frame, const std::array<double, 3>& enu) {
    const auto& a = frame.axes;
    return {frame.origin_ecef.x + enu[0] * a[0][0] + enu[1] * a[1][0] + enu[2] * a[2][0],
            frame.origin_ecef.y + enu[0] * a[0][1] + enu[1] * a[1][1] + enu[2] * a[2][1],
            frame.origin_ecef.z + enu[0] * a[0][2] + enu[1] * a[1][2] + enu[2] * a[2][2]};
}

std::array<double, 3> ecef_to_enu(const EnuFrame& frame, const Ecef& p) {
    const double dx = p.x - frame.origin_ecef.x;
    const double dy = p.y - frame.origin_ecef.y;
    const double dz = p.z - frame.origin_ecef.z;
    std::array<double, 3> out{};
    for (int k = 0; k < 3; ++k) {
        out[k] = dx * frame.axes[k][0] + dy * frame.axes[k][1] + dz * frame.axes[k][2];
    }
    return out;
}

std::array<double, 16> enu_to_ecef_matrix(const EnuFrame& frame) {
    const auto& a = frame.axes;
    return {a[0][0],
            a[0][1],
            a[0][2],
            0.0, // column 0: east
            a[1][0],
            a[1][1],
            a[1][2],
            0.0, // column 1: north
            a[2][0],
            a[2][1],
            a[2][2],
            0.0, // column 2: up
            frame.origin_ecef.x,
            frame.origin_ecef.y,
            frame.origin_ecef.z,
            1.0};
}

BoundingSphere bounding_sphere(const LonLatBox& box, double min_h, double max_h) {
    TB_ASSERT(box.west <= box.east && box.south <= box.north && min_h <= max_h);
    // Centre: middle of the axis-aligned ECEF box of the sampled points; radius: farthest
    // sampled point plus the chord sag at max_h, which bounds the bulge between samples.
    Ecef lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    for (double h : {min_h, max_h}) {
        for_each_box_point(box, [&](double lon, double lat) {
            const Ecef p = to_ecef({lon, lat, h});
            lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
            hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
        });
    }
    BoundingSphere s;
    s.centre = {(lo.x + hi.x) / 2, (lo.y + hi.y) / 2, (lo.z + hi.z) / 2};
    for (double h : {min_h, max_h}) {
        for_each_box_point(box, [&](double lon, double lat) {
            s.radius = std::max(s.radius, distance(s.centre, to_ecef({lon, lat, h})));
        });
    }
    // Between boundary samples the true boundary bulges outward by at most the sag of the
    // sampling step; a tenth of the box's sag (and a metre) covers the 16-step sampling.
    s.radius += 0.1 * chord_sag(box) + 1.0;
    return s;
}

double chord_sag(const LonLatBox& box) {
    TB_ASSERT(box.west <= box.east && box.south <= box.north);
    // Every vertex lies within chord distance r of the box centre on the ellipsoid. A flat
    // triangle with vertices in a spherical cap of chord radius r sits at least R - sqrt(R^2 -
    // r^2) below the cap (the hull lies above the cap's base plane). The ellipsoid is no more
    // curved than a sphere of radius b^2/a (its smallest radius of curvature, meridional at
    // the equator), so that radius gives an upper bound; 2% covers heights up to ~100 km and
    // the boundary sampling.
    const auto& wgs = GeographicLib::Geocentric::WGS84();
    const double a = wgs.EquatorialRadius();
    const double b = a * (1 - wgs.Flattening());
    const double r_min = b * b / a;
    const Ecef centre = to_ecef({(box.west + box.east) / 2, (box.south + box.north) / 2, 0.0});
    double r = 0;
    for_each_box_point(box, [&](double lon, double lat) {
        r = std::max(r, distance(centre, to_ecef({lon, lat, 0.0})));
    });
    const double sag = r >= r_min ? r_min : r_min - std::sqrt(r_min * r_min - r * r);
    return sag * 1.02;
}

} // namespace tb::tiler
