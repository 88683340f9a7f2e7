#pragma once
// What a DEM is, as GDAL reads it (band 1). GDAL types stay inside tiler/gdal_*.cpp.
#include <array>
#include <optional>
#include <string>

namespace tb::tiler {

struct DemInfo {
    std::string path;
    std::string driver;                 // GDAL short name: GTiff, SRTMHGT, DTED, AAIGrid, ...
    int width = 0, height = 0, bands = 0;
    std::string data_type;              // Int16, UInt16, Int32, Float32, ...
    std::string crs_name;               // "WGS 84", "" when the file has none
    std::string crs_id;                 // "EPSG:4326", "" when not identified
    bool geographic = false;            // the CRS is lon/lat
    bool has_geotransform = false;
    std::array<double, 6> geotransform{0, 1, 0, 0, 0, 1};
    std::optional<double> nodata;
    double scale = 1.0, offset = 0.0;
    bool has_data = false;              // false when every sample is nodata
    double min_height = 0, max_height = 0;  // over valid samples, after scale/offset
    std::optional<std::array<double, 4>> lonlat_bounds;  // west, south, east, north (degrees)
    double resolution_m = 0;            // approximate ground size of one pixel, metres
};

// Opens `path` read-only and describes band 1 (statistics computed from the data, not from
// metadata). Throws InputError naming the path: missing file, a directory, not a raster.
DemInfo inspect_dem(const std::string& path);

// Registers GDAL drivers once and routes GDAL's error handler to our logger. Idempotent.
void init_gdal();

}  // namespace tb::tiler
