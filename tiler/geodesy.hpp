#pragma once
// WGS84 geodesy for placing tiles on the globe: geodetic <-> ECEF (GeographicLib's exact
// Geocentric WGS84), local east-north-up frames, and the bounding volumes 3D Tiles wants.
// Angles are degrees unless a name says radians; lengths and heights are metres, heights above
// the WGS84 ellipsoid. GeographicLib stays inside geodesy.cpp.
#include "tiler/tile_grid.hpp"

#include <array>

namespace tb::tiler {

struct Ecef {
    double x = 0, y = 0, z = 0;
};

struct Geodetic {
    double lon = 0, lat = 0, h = 0; // degrees, degrees, metres
};

Ecef to_ecef(const Geodetic& p);
Geodetic to_geodetic(const Ecef& p);

// A local tangent frame at `origin`: x east, y north, z up (the ellipsoid normal).
struct EnuFrame {
    Geodetic origin;
    Ecef origin_ecef;
    // Rows are the east, north and up unit vectors expressed in ECEF.
    std::array<std::array<double, 3>, 3> axes{};
};
EnuFrame enu_frame(const Geodetic& origin);
Ecef enu_to_ecef(const EnuFrame& frame, const std::array<double, 3>& enu);
std::array<double, 3> ecef_to_enu(const EnuFrame& frame, const Ecef& p);
// The 4x4 ENU -> ECEF transform, column-major (glTF / 3D Tiles `transform` order).
std::array<double, 16> enu_to_ecef_matrix(const EnuFrame& frame);

// 3D Tiles `region`: west, south, east, north in radians, then min and max height in metres.
struct Region {
    double west = 0, south = 0, east = 0, north = 0, min_h = 0, max_h = 0;
};

struct BoundingSphere {
    Ecef centre;
    double radius = 0;
};
// A sphere containing every point of the lon/lat box between heights min_h and max_h.
BoundingSphere bounding_sphere(const LonLatBox& box, double min_h, double max_h);

// An upper bound, in metres, on how far a flat triangle whose vertices lie in `box` (at heights
// in [min_h, max_h]) can dip below the ellipsoid-following surface through its vertices: the
// chord sag of straight ECEF triangles. Renderers draw those straight triangles, so this is
// part of the honest error of a tile. Grows with the square of the box size (~d^2 / 8R).
double chord_sag(const LonLatBox& box);

} // namespace tb::tiler
