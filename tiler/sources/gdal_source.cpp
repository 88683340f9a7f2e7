#include "tiler/sources/gdal_source.hpp"

#include "core/error.hpp"
#include "tiler/log.hpp"

#include <cpl_conv.h>
#include <cpl_error.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <cmath>
#include <filesystem>
#include <mutex>

namespace tb::tiler {
namespace {

void quiet_error_handler(CPLErr level, CPLErrorNum, const char* message) {
    // GDAL's errors reach users through our exceptions (CPLGetLastErrorMsg); warnings are
    // logged at debug level so they do not clutter normal runs.
    if (level == CE_Warning) {
        log::debug(std::string("gdal: ") + message);
    }
}

std::string last_gdal_error() {
    const char* message = CPLGetLastErrorMsg();
    return message && *message ? message : "unknown GDAL error";
}

} // namespace

void init_gdal() {
    static std::once_flag once;
    std::call_once(once, [] {
        GDALAllRegister();
        CPLSetErrorHandler(quiet_error_handler);
        // Statistics must come from the data: never write .aux.xml next to a user's DEM.
        CPLSetConfigOption("GDAL_PAM_ENABLED", "NO");
    });
}

DemInfo inspect_dem(const std::string& path, double exact_range_samples) {
    init_gdal();
    namespace fs = std::filesystem;
    const bool vrt_xml = path.find('<') != std::string::npos; // a mosaic's VRT description
    const bool virtual_path = path.rfind("/vsi", 0) == 0 || vrt_xml;
    if (!virtual_path) {
        std::error_code ec;
        const auto status = fs::status(path, ec);
        if (!fs::exists(status)) {
            throw InputError(path + ": no such file; check the path");
        }
        if (fs::is_directory(status)) {
            throw InputError(path + ": is a directory, not a raster; name a DEM file");
        }
    }
    CPLErrorReset();
    GDALDatasetUniquePtr ds(GDALDataset::Open(
        path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY | GDAL_OF_VERBOSE_ERROR, nullptr, nullptr));
    if (!ds) {
        throw InputError(path + ": not a raster GDAL can read (" + last_gdal_error() + ")");
    }
    if (ds->GetRasterCount() < 1) {
        throw InputError(path + ": has no raster band");
    }
    DemInfo info;
    info.path = path;
    info.driver = ds->GetDriver() ? ds->GetDriver()->GetDescription() : "";
    info.width = ds->GetRasterXSize();
    info.height = ds->GetRasterYSize();
    info.bands = ds->GetRasterCount();
    GDALRasterBand* band = ds->GetRasterBand(1);
    info.data_type = GDALGetDataTypeName(band->GetRasterDataType());
    int has = 0;
    double nodata = band->GetNoDataValue(&has);
    if (has) {
        info.nodata = nodata;
    }
    info.scale = band->GetScale(&has);
    if (!has) {
        info.scale = 1.0;
    }
    info.offset = band->GetOffset(&has);
    if (!has) {
        info.offset = 0.0;
    }
    info.has_geotransform = ds->GetGeoTransform(info.geotransform.data()) == CE_None;

    if (const OGRSpatialReference* srs = ds->GetSpatialRef()) {
        info.crs_name = srs->GetName() ? srs->GetName() : "";
        info.geographic = srs->IsGeographic();
        OGRSpatialReference copy(*srs);
        if (copy.AutoIdentifyEPSG() == OGRERR_NONE || copy.GetAuthorityCode(nullptr)) {
            const char* auth = copy.GetAuthorityName(nullptr);
            const char* code = copy.GetAuthorityCode(nullptr);
            if (auth && code) {
                info.crs_id = std::string(auth) + ":" + code;
            }
        }
        if (info.has_geotransform) {
            OGRSpatialReference wgs84;
            wgs84.SetWellKnownGeogCS("WGS84");
            wgs84.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
            OGRSpatialReference source(*srs);
            source.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
            std::unique_ptr<OGRCoordinateTransformation> ct(
                OGRCreateCoordinateTransformation(&source, &wgs84));
            if (ct) {
                const auto& g = info.geotransform;
                // Densified outline of the raster, so projected sources get honest bounds.
                double west = INFINITY, south = INFINITY, east = -INFINITY, north = -INFINITY;
                constexpr int kSteps = 16;
                for (int i = 0; i <= kSteps; ++i) {
                    for (int side = 0; side < 4; ++side) {
                        double px = 0, py = 0;
                        const double f = static_cast<double>(i) / kSteps;
                        switch (side) {
                        case 0:
                            px = f * info.width, py = 0;
                            break;
                        case 1:
                            px = f * info.width, py = info.height;
                            break;
                        case 2:
                            px = 0, py = f * info.height;
                            break;
                        default:
                            px = info.width, py = f * info.height;
                            break;
                        }
                        double x = g[0] + px * g[1] + py * g[2];
                        double y = g[3] + px * g[4] + py * g[5];
                        if (ct->Transform(1, &x, &y)) {
                            west = std::min(west, x), east = std::max(east, x);
                            south = std::min(south, y), north = std::max(north, y);
                        }
                    }
                }
                if (std::isfinite(west) && std::isfinite(south)) {
                    info.lonlat_bounds = std::array<double, 4>{west, south, east, north};
                }
            }
        }
    }
    if (info.has_geotransform) {
        const auto& g = info.geotransform;
        double dx = std::hypot(g[1], g[4]);
        double dy = std::hypot(g[2], g[5]);
        double size = std::sqrt(dx * dy);
        if (info.geographic && info.lonlat_bounds) {
            const auto& b = *info.lonlat_bounds;
            const double lat = 0.5 * (b[1] + b[3]) * M_PI / 180.0;
            constexpr double kMetresPerDegree = 6378137.0 * M_PI / 180.0;
            size = std::sqrt(dx * std::cos(lat) * dy) * kMetresPerDegree;
        } else if (const OGRSpatialReference* srs = ds->GetSpatialRef()) {
            size *= srs->GetLinearUnits();
        }
        info.resolution_m = size;
    }

    // Exact min/max over valid samples (metadata statistics are not trusted: some files carry
    // stale ones). Tileset bounding volumes are built from it, so an approximate range is only
    // taken where reading everything would hold up every start for long.
    double minmax[2] = {0, 0};
    const double samples = static_cast<double>(info.width) * info.height;
    const bool approx = samples > exact_range_samples;
    info.range_exact = !approx;
    if (!approx && samples > 64e6) {
        log::info((vrt_xml ? std::string("the mosaic") : path) + ": reading all " +
                  std::to_string(std::llround(samples / 1e6)) +
                  " Mpixel once for the exact height range");
    }
    CPLErrorReset();
    if (band->ComputeRasterMinMax(approx, minmax) == CE_None) {
        info.has_data = true;
        const double a = minmax[0] * info.scale + info.offset;
        const double b = minmax[1] * info.scale + info.offset;
        info.min_height = std::min(a, b);
        info.max_height = std::max(a, b);
    } else {
        info.has_data = false;
    }
    return info;
}

} // namespace tb::tiler
