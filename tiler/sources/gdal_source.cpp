#include "tiler/sources/gdal_source.hpp"

#include "core/error.hpp"
#include "tiler/log.hpp"

#include <cpl_conv.h>
#include <cpl_error.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fcntl.h>
#include <filesystem>
#include <mutex>
#include <unistd.h>
#include <utility>
#include <vector>

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

// Shows a path in an error message without letting control bytes into the log.
std::string printable(const std::string& s) {
    std::string out;
    for (unsigned char c : s) {
        if (c < 0x20 || c == 0x7f) {
            static const char* hex = "0123456789abcdef";
            out += "\\x";
            out += hex[c >> 4];
            out += hex[c & 15];
        } else {
            out += static_cast<char>(c);
        }
    }
    return out;
}

void add_sample(SampleStats& s, double h) {
    ++s.valid;
    if (h < s.min) {
        s.second_min = s.min;
        s.min = h, s.at_min = 1;
    } else if (h == s.min) {
        ++s.at_min;
    } else if (h < s.second_min) {
        s.second_min = h;
    }
    if (h > s.max) {
        s.second_max = s.max;
        s.max = h, s.at_max = 1;
    } else if (h == s.max) {
        ++s.at_max;
    } else if (h > s.second_max) {
        s.second_max = h;
    }
}

// Whether a sample (raw, and its height) is what its mosaic reads as void.
bool is_fill(double raw, double height, const MosaicFill& fill, bool float32) {
    return fill.heights ? height == fill.value
                        : std::isnan(sample_height(raw, fill.value, float32, 1.0, 0.0));
}

// Reads band 1 (or, with `approx`, GDAL's sample overview of it, decimated to at most 16
// Mpixel) strip by strip through to_height. A failed read is an IoError with GDAL's message:
// truncated data, a missing VRT source, a file larger on paper than on disk.
BandStats scan_band(const DemInfo& info,
                    GDALRasterBand& band,
                    bool approx,
                    const std::optional<MosaicFill>& fill = std::nullopt) {
    constexpr double kApproxSamples = 4096.0 * 4096;
    GDALRasterBand* src = &band;
    if (approx) {
        src = band.GetRasterSampleOverview(static_cast<GUIntBig>(kApproxSamples));
        if (!src) {
            src = &band;
        }
    }
    const int W = src->GetXSize(), H = src->GetYSize();
    int out_w = W, out_h = H;
    const double pixels = static_cast<double>(W) * H;
    if (approx && pixels > kApproxSamples) {
        const double f = std::sqrt(pixels / kApproxSamples);
        out_w = std::max(1, static_cast<int>(W / f));
        out_h = std::max(1, static_cast<int>(H / f));
    }
    const bool float32 = band.GetRasterDataType() == GDT_Float32;
    const int rows = std::max(1, static_cast<int>(std::min<double>(out_h, (1 << 22) / out_w)));
    std::vector<double> buffer(static_cast<std::size_t>(out_w) * rows);
    BandStats stats;
    for (int y0 = 0; y0 < out_h; y0 += rows) {
        const int n = std::min(rows, out_h - y0);
        const int wy0 = static_cast<int>(static_cast<std::int64_t>(y0) * H / out_h);
        const int wy1 = static_cast<int>(static_cast<std::int64_t>(y0 + n) * H / out_h);
        CPLErrorReset();
        if (src->RasterIO(GF_Read,
                          0,
                          wy0,
                          W,
                          std::max(1, wy1 - wy0),
                          buffer.data(),
                          out_w,
                          n,
                          GDT_Float64,
                          0,
                          0,
                          nullptr) != CE_None) {
            throw IoError(info.path + ": read failed (" + last_gdal_error() +
                          "); the file, or one it refers to, is damaged, truncated or missing");
        }
        for (std::size_t k = 0; k < static_cast<std::size_t>(out_w) * n; ++k) {
            const double h =
                sample_height(buffer[k], info.nodata, float32, info.scale, info.offset);
            if (std::isnan(h) || (fill && is_fill(buffer[k], h, *fill, float32))) {
                continue;
            }
            add_sample(stats.all, h);
            if (h >= info.valid_range.low && h <= info.valid_range.high) {
                add_sample(stats.heights, h);
            } else if (stats.outliers++ == 0) {
                const auto i = static_cast<std::int64_t>(k % static_cast<std::size_t>(out_w));
                const auto j = y0 + static_cast<std::int64_t>(k / static_cast<std::size_t>(out_w));
                stats.outlier_column = i * W / out_w;
                stats.outlier_row = j * H / out_h;
                stats.outlier_height = h;
            }
        }
    }
    return stats;
}

// Fills DemInfo::likely_nodata when the minimum or the maximum looks like undeclared voids.
void find_likely_nodata(DemInfo& info, const SampleStats& s) {
    const auto suspect = [&](double value, std::int64_t count, double nearest, double other_end) {
        if (info.likely_nodata || !std::isfinite(nearest)) {
            return;
        }
        const double share = static_cast<double>(count) / static_cast<double>(s.valid);
        const double others = 1 - share;
        const double gap = std::abs(nearest - value);
        const double spread = std::abs(other_end - nearest);
        const double raw = (value - info.offset) / info.scale;
        constexpr double kFloatMax = 3.4028234663852886e38;
        const bool marker = raw == -32768 || raw == -32767 || raw == -9999 || raw == -999 ||
                            raw == -99999 || raw == 9999 || raw == 32767 || raw == 65535 ||
                            std::abs(raw) == kFloatMax;
        if (share > kLikelyNodataShare && others > kLikelyNodataShare && spread > 0 &&
            gap > kLikelyNodataGap && gap > (marker ? 1.0 : 10.0) * spread) {
            info.likely_nodata = raw;
            info.likely_nodata_share = share;
            info.others_min = std::min(nearest, other_end);
            info.others_max = std::max(nearest, other_end);
        }
    };
    suspect(s.min, s.at_min, s.second_min, s.max);
    suspect(s.max, s.at_max, s.second_max, s.min);
}

} // namespace

void init_gdal() {
    static std::once_flag once;
    std::call_once(once, [] {
        GDALAllRegister();
        CPLSetErrorHandler(quiet_error_handler);
        // Statistics must come from the data: never write .aux.xml next to a user's DEM.
        CPLSetConfigOption("GDAL_PAM_ENABLED", "NO");
        // GDAL lists a file's whole directory on every open, to find sidecars: in a directory
        // of 10,000 DEMs that is 10,000 listings of 10,000 names, half the time to open them.
        // TRUE looks for each sidecar (.ovr) by name instead.
        if (CPLGetConfigOption("GDAL_DISABLE_READDIR_ON_OPEN", nullptr) == nullptr) {
            CPLSetConfigOption("GDAL_DISABLE_READDIR_ON_OPEN", "TRUE");
        }
        if (CPLGetConfigOption("GDAL_CACHEMAX", nullptr) == nullptr) {
            GDALSetCacheMax64(static_cast<GIntBig>(kDefaultBlockCacheMb) << 20);
        }
    });
}

void set_block_cache_mb(std::size_t mb) {
    init_gdal();
    GDALSetCacheMax64(static_cast<GIntBig>(mb) << 20);
}

std::size_t block_cache_mb() {
    init_gdal();
    return static_cast<std::size_t>(GDALGetCacheMax64() >> 20);
}

namespace {

// Refuses a path before any driver sees it: a NUL byte, a missing file, a directory, a file that
// cannot be read (some drivers, SRTMHGT, recognize a file by its name and crash on one they
// cannot read). Virtual paths (/vsi..., a VRT's XML text) are left to GDAL.
void check_path(const std::string& path) {
    namespace fs = std::filesystem;
    if (path.find('\0') != std::string::npos) {
        throw InputError(printable(path) + ": the path holds a NUL byte; name the file without it");
    }
    if (path.rfind("/vsi", 0) == 0 || path.find('<') != std::string::npos) {
        return;
    }
    std::error_code ec;
    const auto status = fs::status(path, ec);
    if (!fs::exists(status)) {
        throw InputError(path + ": no such file; check the path");
    }
    if (fs::is_directory(status)) {
        throw InputError(path + ": is a directory, not a raster; name a DEM file");
    }
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) {
        const int err = errno;
        throw IoError(path + ": cannot be read (" + std::strerror(err) + ")" +
                      (err == EACCES || err == EPERM
                           ? "; fix its permissions (chmod a+r) or run as its owner"
                           : "; check the file"));
    }
    ::close(fd);
}

// The lon/lat bounds of the raster's densified outline, so projected sources get honest ones.
std::optional<std::array<double, 4>> lonlat_outline(const DemInfo& info,
                                                    const OGRSpatialReference& srs) {
    OGRSpatialReference wgs84;
    wgs84.SetWellKnownGeogCS("WGS84");
    wgs84.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    OGRSpatialReference source(srs);
    source.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    std::unique_ptr<OGRCoordinateTransformation> ct(
        OGRCreateCoordinateTransformation(&source, &wgs84));
    if (!ct) {
        return std::nullopt;
    }
    const auto& g = info.geotransform;
    double west = INFINITY, south = INFINITY, east = -INFINITY, north = -INFINITY;
    constexpr int kSteps = 16;
    for (int i = 0; i <= kSteps; ++i) {
        const double f = static_cast<double>(i) / kSteps;
        const double px[4] = {f * info.width, f * info.width, 0.0, double(info.width)};
        const double py[4] = {0.0, double(info.height), f * info.height, f * info.height};
        for (int side = 0; side < 4; ++side) {
            double x = g[0] + px[side] * g[1] + py[side] * g[2];
            double y = g[3] + px[side] * g[4] + py[side] * g[5];
            if (ct->Transform(1, &x, &y)) {
                west = std::min(west, x), east = std::max(east, x);
                south = std::min(south, y), north = std::max(north, y);
            }
        }
    }
    if (!std::isfinite(west) || !std::isfinite(south)) {
        return std::nullopt;
    }
    return std::array<double, 4>{west, south, east, north};
}

// The CRS's names and the lon/lat bounds.
void describe_crs(DemInfo& info, const OGRSpatialReference& srs) {
    info.crs_name = srs.GetName() ? srs.GetName() : "";
    info.geographic = srs.IsGeographic();
    OGRSpatialReference copy(srs);
    if (copy.AutoIdentifyEPSG() == OGRERR_NONE || copy.GetAuthorityCode(nullptr)) {
        const char* auth = copy.GetAuthorityName(nullptr);
        const char* code = copy.GetAuthorityCode(nullptr);
        if (auth && code) {
            info.crs_id = std::string(auth) + ":" + code;
        }
    }
    if (info.has_geotransform) {
        info.lonlat_bounds = lonlat_outline(info, srs);
    }
}

// The approximate ground size of one pixel, metres.
double pixel_size_m(const DemInfo& info, const OGRSpatialReference* srs) {
    const auto& g = info.geotransform;
    const double dx = std::hypot(g[1], g[4]);
    const double dy = std::hypot(g[2], g[5]);
    double size = std::sqrt(dx * dy);
    if (info.geographic && info.lonlat_bounds) {
        const auto& b = *info.lonlat_bounds;
        const double lat = 0.5 * (b[1] + b[3]) * M_PI / 180.0;
        constexpr double kMetresPerDegree = 6378137.0 * M_PI / 180.0;
        size = std::sqrt(dx * std::cos(lat) * dy) * kMetresPerDegree;
    } else if (srs) {
        size *= srs->GetLinearUnits();
    }
    return size;
}

struct Described {
    GDALDatasetUniquePtr ds;
    DemInfo info;
};

// Metres per unit of a length named as GDAL and its drivers name them, or 0 when it names none.
double metres_per(std::string unit) {
    std::transform(unit.begin(), unit.end(), unit.begin(), [](unsigned char c) {
        return c == '_' || c == '-' ? ' ' : static_cast<char>(std::tolower(c));
    });
    static const std::pair<const char*, double> kUnits[] = {
        {"m", 1},
        {"metre", 1},
        {"meter", 1},
        {"metres", 1},
        {"meters", 1},
        {"ft", 0.3048},
        {"foot", 0.3048},
        {"feet", 0.3048},
        {"international foot", 0.3048},
        {"us ft", 1200.0 / 3937},
        {"ftus", 1200.0 / 3937},
        {"us survey foot", 1200.0 / 3937},
        {"us survey feet", 1200.0 / 3937},
        {"foot us", 1200.0 / 3937},
        {"us foot", 1200.0 / 3937},
        {"cm", 0.01},
        {"centimetre", 0.01},
        {"centimeter", 0.01},
        {"mm", 0.001},
        {"millimetre", 0.001},
        {"millimeter", 0.001},
    };
    for (const auto& [name, metres] : kUnits) {
        if (unit == name) {
            return metres;
        }
    }
    return 0;
}

// The unit of band 1's heights: the band's unit type, else the length unit of the CRS's
// vertical part, else metres (DemInfo::height_unit). A unit that is not a length is a warning,
// and metres are assumed.
void find_height_unit(DemInfo& info, GDALRasterBand& band, const OGRSpatialReference* srs) {
    const std::string given = band.GetUnitType() ? band.GetUnitType() : "";
    if (!given.empty()) {
        const double metres = metres_per(given);
        if (metres > 0) {
            info.height_unit = given, info.metres_per_unit = metres;
        } else {
            log::warn(info.path + ": band 1's unit '" + given +
                      "' is not a length Terrabound knows; its heights are taken as metres");
        }
        return;
    }
    if (srs && (srs->IsCompound() || srs->IsVertical())) {
        const char* name = nullptr;
        const double metres = srs->GetTargetLinearUnits("VERT_CS", &name);
        if (metres > 0) {
            info.height_unit = name ? name : "";
            info.metres_per_unit = metres;
        }
    }
}

// Opens `path` and describes band 1 without reading a sample (inspect_metadata).
Described open_described(const std::string& path,
                         std::optional<double> nodata_override,
                         const ValidRange& range) {
    init_gdal();
    check_path(path);
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
    info.valid_range = range;
    info.driver = ds->GetDriver() ? ds->GetDriver()->GetDescription() : "";
    info.width = ds->GetRasterXSize();
    info.height = ds->GetRasterYSize();
    info.bands = ds->GetRasterCount();
    GDALRasterBand* band = ds->GetRasterBand(1);
    info.data_type = GDALGetDataTypeName(band->GetRasterDataType());
    int has = 0;
    const double nodata = band->GetNoDataValue(&has);
    if (nodata_override) {
        info.nodata = nodata_override;
        info.nodata_given = true;
    } else if (has) {
        info.nodata = nodata;
    }
    info.scale = band->GetScale(&has);
    info.scale = has ? info.scale : 1.0;
    info.offset = band->GetOffset(&has);
    info.offset = has ? info.offset : 0.0;
    info.has_geotransform = ds->GetGeoTransform(info.geotransform.data()) == CE_None;
    const OGRSpatialReference* srs = ds->GetSpatialRef();
    if (srs) {
        describe_crs(info, *srs);
    }
    // Heights in feet (US lidar) become metres through the scale and offset every read applies.
    find_height_unit(info, *band, srs);
    info.scale *= info.metres_per_unit;
    info.offset *= info.metres_per_unit;
    if (info.has_geotransform) {
        info.resolution_m = pixel_size_m(info, srs);
    }
    return {std::move(ds), std::move(info)};
}

// What a scan found, into the description.
void take_stats(DemInfo& info, const BandStats& stats) {
    if (stats.all.valid > 0) {
        find_likely_nodata(info, stats.all);
    }
    if (stats.heights.valid > 0) {
        info.has_data = true;
        info.min_height = stats.heights.min;
        info.max_height = stats.heights.max;
    }
    info.outliers = stats.outliers;
    info.outlier_column = stats.outlier_column;
    info.outlier_row = stats.outlier_row;
    info.outlier_height = stats.outlier_height;
}

// Exact min/max over valid samples (metadata statistics are not trusted: some files carry
// stale ones). Tileset bounding volumes are built from it, so an approximate range is only
// taken where reading everything would hold up every start for long.
BandStats scan_for_range(DemInfo& info,
                         GDALRasterBand& band,
                         double exact_range_samples,
                         const std::optional<MosaicFill>& fill = std::nullopt) {
    const double samples = static_cast<double>(info.width) * info.height;
    const bool approx = samples > exact_range_samples;
    info.range_exact = !approx;
    if (!approx && samples > 64e6) {
        const bool mosaic = info.path.rfind("/vsimem/", 0) == 0;
        log::info((mosaic ? std::string("the mosaic") : info.path) + ": reading all " +
                  std::to_string(std::llround(samples / 1e6)) +
                  " Mpixel once for the exact height range");
    }
    return scan_band(info, band, approx, fill);
}

// One end of two scans' statistics merged: `beyond` is < for the minimum, > for the maximum.
template <typename Beyond>
void merge_end(double& end,
               std::int64_t& at,
               double& next,
               double other_end,
               std::int64_t other_at,
               double other_next,
               Beyond beyond) {
    if (beyond(other_end, end)) {
        next = beyond(end, other_next) ? end : other_next;
        end = other_end, at = other_at;
    } else if (other_end == end) {
        at += other_at;
        next = beyond(next, other_next) ? next : other_next;
    } else {
        next = beyond(next, other_end) ? next : other_end;
    }
}

void merge_stats(SampleStats& a, const SampleStats& b) {
    if (b.valid == 0) {
        return;
    }
    if (a.valid == 0) {
        a = b;
        return;
    }
    a.valid += b.valid;
    merge_end(a.min, a.at_min, a.second_min, b.min, b.at_min, b.second_min, std::less<>());
    merge_end(a.max, a.at_max, a.second_max, b.max, b.at_max, b.second_max, std::greater<>());
}

// Rejects what is not a height band: complex numbers, colour images (RGB(A), palettes; e.g.
// Terrain-RGB PNGs must be decoded to heights first).
void check_height_band(const std::string& name, GDALDataset& ds) {
    GDALRasterBand* band = ds.GetRasterBand(1);
    const GDALDataType type = band->GetRasterDataType();
    if (GDALDataTypeIsComplex(type)) {
        throw InputError(name + ": band 1 holds complex numbers (" + GDALGetDataTypeName(type) +
                         "), not heights; convert it to a real type");
    }
    const GDALColorInterp colour = band->GetColorInterpretation();
    if (colour == GCI_PaletteIndex || colour == GCI_RedBand ||
        (type == GDT_Byte && ds.GetRasterCount() >= 3)) {
        throw InputError(
            name + ": is a colour image (RGB(A) or palette), not a height raster; decode it "
                   "to heights first (e.g. Terrain-RGB: -10000 + (R*65536 + G*256 + B) * 0.1)");
    }
}

} // namespace

FileScan scan_file(const std::string& path,
                   const std::function<bool(const DemInfo&)>& may_scan,
                   std::optional<double> nodata,
                   const ValidRange& range,
                   std::optional<MosaicFill> fill) {
    Described d = open_described(path, nodata, range);
    check_height_band(path, *d.ds);
    FileScan scan;
    GDALRasterBand* band = d.ds->GetRasterBand(1);
    band->GetBlockSize(&scan.block_width, &scan.block_height);
    for (int k = 0; k < band->GetOverviewCount(); ++k) {
        GDALRasterBand* overview = band->GetOverview(k);
        if (overview && overview->GetXSize() > 0) {
            scan.overview_factors.push_back(static_cast<int>(
                std::lround(static_cast<double>(d.info.width) / overview->GetXSize())));
        }
    }
    if (const OGRSpatialReference* srs = d.ds->GetSpatialRef()) {
        scan.srs = std::make_shared<const OGRSpatialReference>(*srs);
    }
    if (may_scan(d.info)) {
        scan.stats = scan_for_range(d.info, *band, INFINITY, fill);
        take_stats(d.info, scan.stats);
        scan.scanned = true;
    }
    scan.info = std::move(d.info);
    return scan;
}

DemInfo describe_mosaic(const std::string& vrt,
                        const std::vector<const FileScan*>& files,
                        std::optional<double> nodata,
                        const ValidRange& range) {
    DemInfo info = open_described(vrt, nodata, range).info;
    BandStats all;
    const auto& m = info.geotransform;
    for (const FileScan* f : files) {
        TB_ASSERT(f->scanned);
        merge_stats(all.all, f->stats.all);
        merge_stats(all.heights, f->stats.heights);
        if (all.outliers == 0 && f->stats.outliers > 0) {
            // The first outlier, as a pixel of the mosaic.
            const auto& g = f->info.geotransform;
            const double x = g[0] + (static_cast<double>(f->stats.outlier_column) + 0.5) * g[1];
            const double y = g[3] + (static_cast<double>(f->stats.outlier_row) + 0.5) * g[5];
            all.outlier_column = static_cast<std::int64_t>(std::floor((x - m[0]) / m[1]));
            all.outlier_row = static_cast<std::int64_t>(std::floor((y - m[3]) / m[5]));
            all.outlier_height = f->stats.outlier_height;
        }
        all.outliers += f->stats.outliers;
    }
    info.range_exact = true;
    take_stats(info, all);
    return info;
}

DemInfo inspect_dem(const std::string& path,
                    double exact_range_samples,
                    std::optional<double> nodata,
                    const ValidRange& range) {
    Described d = open_described(path, nodata, range);
    const BandStats stats = scan_for_range(d.info, *d.ds->GetRasterBand(1), exact_range_samples);
    take_stats(d.info, stats);
    return std::move(d.info);
}

DemInfo
inspect_metadata(const std::string& path, std::optional<double> nodata, const ValidRange& range) {
    return open_described(path, nodata, range).info;
}

int native_zoom(const DemSource& source, Scheme scheme, int size) {
    for (int z = 0; z <= kMaxZoom; ++z) {
        if (source.pixels_per_sample(scheme, z, size) <= 1.0 + 1e-9) {
            return z;
        }
    }
    return kMaxZoom;
}

} // namespace tb::tiler
