#pragma once
// EGM96 geoid undulation: ellipsoidal height = orthometric (EGM96) height + N.
namespace tb::tiler {

// Path of the EGM96 15' grid this build reads (Debian package proj-data).
inline constexpr const char* kEgm96GridPath = "/usr/share/proj/egm96_15.gtx";

// Geoid undulation N in metres above the WGS84 ellipsoid at (lon, lat) degrees, bilinear in
// the 15' grid, longitude wrapped, latitude clamped to [-90, 90]. The grid is read once, on
// first use (thread-safe). Throws InputError when the grid file is missing or unreadable.
double egm96_undulation(double lon, double lat);

} // namespace tb::tiler
