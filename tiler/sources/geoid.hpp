#pragma once
// EGM96 geoid undulation: ellipsoidal height = orthometric (EGM96) height + N.
namespace tb::tiler {

// Path of the EGM96 15' grid this build reads (Debian package proj-data).
inline constexpr const char* kEgm96GridPath = "/usr/share/proj/egm96_15.gtx";

// Geoid undulation N in metres above the WGS84 ellipsoid at (lon, lat) degrees, bilinear in
// the 15' grid, longitude wrapped, latitude clamped to [-90, 90]. The grid is read once, on
// first use (thread-safe). Throws InputError when the grid file is missing or unreadable.
double egm96_undulation(double lon, double lat);

// egm96_undulation split by axis, for rasters whose columns share a longitude and rows a
// latitude: the grid columns and weight of a longitude, the grid rows and weight of a
// latitude, combined per sample by egm96_at. egm96_at(egm96_column(lon), egm96_row(lat)) is
// egm96_undulation(lon, lat), bit for bit (it is how that is computed).
struct Egm96Column {
    int c0 = 0, c1 = 0; // the grid columns west and east of lon (wrapped)
    double fu = 0;      // lon's weight toward c1
};
struct Egm96Row {
    const float* upper = nullptr; // the grid rows north and south of lat
    const float* lower = nullptr;
    double fv = 0; // lat's weight toward lower
};
Egm96Column egm96_column(double lon);
Egm96Row egm96_row(double lat);
inline double egm96_at(const Egm96Column& c, const Egm96Row& r) {
    const double top =
        static_cast<double>(r.upper[c.c0]) * (1 - c.fu) + static_cast<double>(r.upper[c.c1]) * c.fu;
    const double bottom =
        static_cast<double>(r.lower[c.c0]) * (1 - c.fu) + static_cast<double>(r.lower[c.c1]) * c.fu;
    return top * (1 - r.fv) + bottom * r.fv;
}

} // namespace tb::tiler
