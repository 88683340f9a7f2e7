// terrabound info: what a DEM is.
#include "core/error.hpp"
#include "server/commands.hpp"
#include "tiler/gdal_source.hpp"

#include <cmath>
#include <cstdio>
#include <sstream>

namespace tb::cli {
namespace {

std::string describe(const tiler::DemInfo& d) {
    std::ostringstream out;
    out.precision(10);
    out << d.path << "\n";
    out << "  format:      " << d.driver << "\n";
    out << "  size:        " << d.width << " x " << d.height << " samples, " << d.bands
        << " band(s); band 1 is used\n";
    out << "  data type:   " << d.data_type << "\n";
    out << "  crs:         ";
    if (d.crs_name.empty()) {
        out << "none (no georeferencing)\n";
    } else {
        out << d.crs_name << (d.crs_id.empty() ? " (not identified as an EPSG code)" : "")
            << (d.crs_id.empty() ? "" : " (" + d.crs_id + ")") << "\n";
    }
    out << "  nodata:      ";
    if (d.nodata) {
        out << *d.nodata << "\n";
    } else {
        out << "none\n";
    }
    if (d.scale != 1.0 || d.offset != 0.0) {
        out << "  scale:       " << d.scale << ", offset " << d.offset << "\n";
    }
    out << "  heights:     ";
    if (d.has_data) {
        out << d.min_height << " .. " << d.max_height << "\n";
    } else {
        out << "no valid sample (every sample is nodata)\n";
    }
    if (d.has_geotransform) {
        const auto& g = d.geotransform;
        out << "  pixel size:  " << std::abs(g[1]) << " x " << std::abs(g[5])
            << (d.geographic ? " degrees" : " CRS units");
        if (d.resolution_m > 0) {
            out << " (about " << std::round(d.resolution_m * 10) / 10 << " m)";
        }
        out << "\n";
        out << "  origin:      " << g[0] << ", " << g[3] << "\n";
    } else {
        out << "  pixel size:  unknown (no geotransform)\n";
    }
    if (d.lonlat_bounds) {
        const auto& b = *d.lonlat_bounds;
        out << "  lon/lat:     west " << b[0] << ", south " << b[1] << ", east " << b[2]
            << ", north " << b[3] << "\n";
    }
    return out.str();
}

int run(const Args& args) {
    if (args.positional.empty()) {
        throw InputError("info: name a DEM file; see 'terrabound info --help'");
    }
    for (const auto& path : args.positional) {
        std::fputs(describe(tiler::inspect_dem(path)).c_str(), stdout);
    }
    return 0;
}

}  // namespace

const Command& info_command() {
    static const Command command{
        {"info",
         "DEM...",
         "Describe a DEM: size, CRS, data type, nodata, height range, resolution.",
         {},
         ""},
        run};
    return command;
}

}  // namespace tb::cli
