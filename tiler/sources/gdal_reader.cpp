// Reading DEMs for tiles: band 1 of one file or of an in-memory VRT mosaic, sampled bilinearly
// at the global lattice of a zoom, one GDAL handle per concurrent reader.
#include "core/error.hpp"
#include "tiler/cpus.hpp"
#include "tiler/helper_threads.hpp"
#include "tiler/layer.hpp"
#include "tiler/log.hpp"
#include "tiler/sources/collection_source.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/mosaic_overlaps.hpp"
#include "tiler/sources/mosaic_vrt.hpp"
#include "tiler/sources/source_list.hpp"

#include <cpl_conv.h>
#include <cpl_error.h>
#include <cpl_string.h>
#include <cpl_vsi.h>
#include <gdal_priv.h>
#include <ogr_spatialref.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <mutex>
#include <set>
#include <unistd.h>

namespace tb::tiler {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kMetresPerDegree = 6378137.0 * kPi / 180.0;

std::string gdal_message() {
    const char* m = CPLGetLastErrorMsg();
    return m && *m ? m : "unknown GDAL error";
}

struct CslDeleter {
    void operator()(char** list) const { CSLDestroy(list); }
};
using CslPtr = std::unique_ptr<char*, CslDeleter>;

OGRSpatialReference scheme_srs(Scheme scheme) {
    OGRSpatialReference srs;
    srs.importFromEPSG(scheme == Scheme::Geodetic ? 4326 : 3857);
    srs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
    return srs;
}

// Without overviews each coarse zoom reads every block of the source, which is slow for a large
// DEM. Said once per source per process: several layers (and reloads) may open the same DEM.
void suggest_overviews(const DemInfo& info, bool mosaic) {
    static std::mutex mutex;
    static std::set<std::string> told;
    std::lock_guard lock(mutex);
    if (told.insert(info.path).second) {
        log::info(info.path + ": " + std::to_string(info.width) + " x " +
                  std::to_string(info.height) +
                  " pixels and no overviews, so each coarse zoom reads every block of it; run " +
                  (mosaic ? "'gdaladdo -r average FILE' on each file"
                          : "'gdaladdo -r average " + info.path + "'") +
                  " once for fast coarse zooms");
    }
}

// A file in GDAL's memory file system, removed with its last owner. A mosaic's VRT lives in
// one: opened from its XML text instead, GDAL compares that text (a megabyte for a thousand
// files) on every read, which doubles the time of a tile.
class MemoryFile {
public:
    explicit MemoryFile(const std::string& text) {
        static std::atomic<std::uint64_t> serial{0};
        path_ = "/vsimem/terrabound/" + std::to_string(::getpid()) + "_" +
                std::to_string(++serial) + ".vrt";
        auto* bytes = static_cast<GByte*>(CPLMalloc(text.size()));
        std::memcpy(bytes, text.data(), text.size());
        VSILFILE* f = VSIFileFromMemBuffer(path_.c_str(), bytes, text.size(), TRUE);
        if (!f) {
            CPLFree(bytes);
            throw IoError("cannot make the in-memory file " + path_);
        }
        VSIFCloseL(f);
    }
    ~MemoryFile() { VSIUnlink(path_.c_str()); }
    MemoryFile(const MemoryFile&) = delete;
    MemoryFile& operator=(const MemoryFile&) = delete;
    const std::string& path() const { return path_; }

private:
    std::string path_;
};

class GdalDemSource final : public DemSource {
public:
    // `file`, when given, holds open_name (a mosaic's VRT) for as long as the source lives;
    // `file_bounds` are a mosaic's files' lon/lat outlines (footprints_at).
    GdalDemSource(std::string open_name,
                  DemInfo info,
                  std::shared_ptr<const MemoryFile> file = nullptr,
                  std::vector<LonLatBox> file_bounds = {},
                  std::vector<FileOverlap> overlaps = {})
        : file_(std::move(file)), open_name_(std::move(open_name)), info_(std::move(info)),
          file_bounds_(std::move(file_bounds)), overlaps_(std::move(overlaps)) {
        GDALDatasetUniquePtr ds = open_dataset();
        GDALRasterBand* band = ds->GetRasterBand(1);
        data_type_ = band->GetRasterDataType();
        if (const OGRSpatialReference* srs = ds->GetSpatialRef()) {
            srs_ = *srs;
            srs_.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
            has_srs_ = true;
            ellipsoidal_ = srs_.IsGeographic() && srs_.GetAxesCount() == 3;
        }
        georeferenced_ = has_srs_ && info_.has_geotransform;
        if (info_.has_geotransform) {
            if (!GDALInvGeoTransform(info_.geotransform.data(), inverse_.data())) {
                throw InputError(info_.path + ": its geotransform cannot be inverted; fix the "
                                              "georeferencing");
            }
        }
        if (georeferenced_) {
            compute_footprint();
            grids_[0] = find_pixel_grid(Scheme::Geodetic);
            grids_[1] = find_pixel_grid(Scheme::Mercator);
        }
        for (int k = 0; k < band->GetOverviewCount(); ++k) {
            GDALRasterBand* overview = band->GetOverview(k);
            if (overview && overview->GetXSize() > 0 && overview->GetYSize() > 0) {
                overviews_.push_back({k, overview->GetXSize(), overview->GetYSize()});
            }
        }
        if (overviews_.empty() && static_cast<double>(info_.width) * info_.height > 4096.0 * 4096) {
            suggest_overviews(info_, open_name_ != info_.path);
        }
        release(std::make_unique<Handle>(Handle{std::move(ds), {}, {}, {}}));
    }

    const DemInfo& info() const override { return info_; }
    bool georeferenced() const override { return georeferenced_; }
    LonLatBox footprint() const override {
        TB_ASSERT(georeferenced_);
        return footprint_;
    }
    bool ellipsoidal_heights() const override { return ellipsoidal_; }
    std::vector<FileOverlap> overlaps() const override { return overlaps_; }

    // A mosaic's data lies under its files, not over the whole box around them (scattered
    // surveys): each file's outline within the footprint.
    std::vector<LonLatBox> footprints_at(Scheme, int, int) const override {
        TB_ASSERT(georeferenced_);
        std::vector<LonLatBox> out;
        for (const LonLatBox& b : file_bounds_) {
            const LonLatBox in{std::max(b.west, footprint_.west),
                               std::max(b.south, footprint_.south),
                               std::min(b.east, footprint_.east),
                               std::min(b.north, footprint_.north)};
            if (in.west <= in.east && in.south <= in.north) {
                out.push_back(in);
            }
        }
        return out.empty() ? std::vector<LonLatBox>{footprint_} : out;
    }

    double pixels_per_sample(Scheme scheme, int z, int size) const override {
        TB_ASSERT(georeferenced_);
        const double tiles = static_cast<double>(std::int64_t{1} << z);
        const auto& g = info_.geotransform;
        if (scheme == Scheme::Geodetic && info_.geographic) {
            const double step = 180.0 / tiles / size;
            return step / std::sqrt(std::abs(g[1] * g[5] - g[2] * g[4]));
        }
        const double lat = 0.5 * (footprint_.south + footprint_.north) * kPi / 180.0;
        const double spacing_m =
            scheme == Scheme::Geodetic
                ? 180.0 / tiles / size * kMetresPerDegree * std::sqrt(std::cos(lat))
                : 2 * kPi * 6378137.0 / tiles / size * std::cos(lat);
        return spacing_m / info_.resolution_m;
    }

    ReadLevel read_level(Scheme scheme, int z, int size) const override {
        const double pps = pixels_per_sample(scheme, z, size);
        ReadLevel level{-1, info_.width, info_.height, 1.0, 1};
        for (const auto& o : overviews_) {
            const double factor = std::max(static_cast<double>(info_.width) / o.width,
                                           static_cast<double>(info_.height) / o.height);
            if (factor <= pps && factor > level.factor) {
                level = {o.index, o.width, o.height, factor, 1};
            }
        }
        while (level.factor * level.step * 2 <= pps && level.step < (1 << 20)) {
            level.step *= 2;
        }
        return level;
    }

    LatticeBlock sample(Scheme scheme,
                        int z,
                        int size,
                        std::int64_t column0,
                        std::int64_t row0,
                        int width,
                        int height) const override;

    core::HeightGrid read_all() const override;
    // sample's read of every f-th pixel, at view rows j_min..j_max and columns i_min..i_max.
    void read_view_rows(GDALRasterBand& band,
                        int f,
                        int i_min,
                        int i_max,
                        int j_min,
                        int j_max,
                        int W,
                        int H,
                        std::vector<double>& view) const;

    std::optional<PixelGrid> pixel_grid(Scheme scheme) const override {
        return grids_[scheme == Scheme::Geodetic ? 0 : 1];
    }
    void pixels_to_lonlat(std::vector<double>& x, std::vector<double>& y) const override;
    void lonlat_to_pixels(std::vector<double>& x, std::vector<double>& y) const override;
    std::vector<double>
    read_pixels(std::int64_t column0, std::int64_t row0, int width, int height) const override;
    bool
    window_empty(std::int64_t column0, std::int64_t row0, int width, int height) const override;
    void pixels_in(const LonLatBox& box, const PixelVisitor& visit) const override;
    std::size_t window_pixels(const LonLatBox& box) const override {
        const std::optional<Window> w = window_of(box);
        return w ? static_cast<std::size_t>(w->width) * static_cast<std::size_t>(w->height) : 0;
    }
    std::unique_ptr<const PixelCoverage> coverage(const LonLatBox& box) const override;
    double tile_pixels(Scheme scheme, int z, int size) const override {
        const double side = pixels_per_sample(scheme, z, size) * size + 2;
        return std::min<double>(side, info_.width) * std::min<double>(side, info_.height);
    }

private:
    // A window of source pixels: columns [column0, column0 + width), rows likewise.
    struct Window {
        std::int64_t column0 = 0, row0 = 0;
        int width = 0, height = 0;
    };
    // The source pixels whose centres may lie in `box` (its outline densified, with a margin);
    // nullopt when none. Throws InputError above kMaxPixelsPerTile.
    std::optional<Window> window_of(const LonLatBox& box) const;
    // Source CRS coordinates to WGS84 lon/lat in place; `good` flags the points that transformed.
    void to_lonlat(std::vector<double>& x, std::vector<double>& y, std::vector<int>& good) const;

    struct Overview {
        int index = 0, width = 0, height = 0;
    };
    class Coverage;

    struct Handle {
        GDALDatasetUniquePtr ds;
        // Scheme CRS -> source CRS, created on first use; null = identity.
        std::unique_ptr<OGRCoordinateTransformation> transform[2];
        bool transform_ready[2] = {false, false};
        // Source CRS -> WGS84 lon/lat, created on first use.
        std::unique_ptr<OGRCoordinateTransformation> to_lonlat;
    };
    struct HandleReturn {
        const GdalDemSource* owner;
        void operator()(Handle* h) const { owner->release(std::unique_ptr<Handle>(h)); }
    };
    using Lease = std::unique_ptr<Handle, HandleReturn>;

    GDALDatasetUniquePtr open_dataset() const {
        CPLErrorReset();
        GDALDatasetUniquePtr ds(GDALDataset::Open(
            open_name_.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr, nullptr, nullptr));
        if (!ds) {
            throw IoError(info_.path + ": cannot be reopened (" + gdal_message() + ")");
        }
        return ds;
    }

    Lease acquire() const {
        {
            std::lock_guard lock(mutex_);
            if (!idle_.empty()) {
                Handle* h = idle_.back().release();
                idle_.pop_back();
                return Lease(h, HandleReturn{this});
            }
        }
        auto h = std::make_unique<Handle>(Handle{open_dataset(), {}, {}, {}});
        return Lease(h.release(), HandleReturn{this});
    }

    void release(std::unique_ptr<Handle> h) const {
        std::lock_guard lock(mutex_);
        idle_.push_back(std::move(h));
    }

    OGRCoordinateTransformation* transform_for(Handle& h, Scheme scheme) const {
        const int k = scheme == Scheme::Geodetic ? 0 : 1;
        if (!h.transform_ready[k]) {
            OGRSpatialReference from = scheme_srs(scheme);
            const char* options[] = {"IGNORE_DATA_AXIS_TO_SRS_AXIS_MAPPING=YES", nullptr};
            if (!from.IsSame(&srs_, options)) {
                h.transform[k].reset(OGRCreateCoordinateTransformation(&from, &srs_));
                if (!h.transform[k]) {
                    throw InputError(info_.path + ": no transformation from " +
                                     (scheme == Scheme::Geodetic ? "EPSG:4326" : "EPSG:3857") +
                                     " to the DEM's CRS (" + gdal_message() + ")");
                }
            }
            h.transform_ready[k] = true;
        }
        return h.transform[k].get();
    }

    void compute_footprint() {
        OGRSpatialReference wgs84 = scheme_srs(Scheme::Geodetic);
        std::unique_ptr<OGRCoordinateTransformation> ct(
            OGRCreateCoordinateTransformation(&srs_, &wgs84));
        if (!ct) {
            throw InputError(info_.path + ": its CRS cannot be transformed to WGS84 lon/lat (" +
                             gdal_message() + "); tiles need a CRS PROJ understands");
        }
        // The hull of the pixel centres, densified so projected outlines bound the data.
        const auto& g = info_.geotransform;
        double u0 = 0.5, u1 = info_.width - 0.5, v0 = 0.5, v1 = info_.height - 0.5;
        // One column or one row has no area between its centres; take the pixels' own extent
        // then (sample() reads up to half a pixel beyond the centres), so it meets tiles.
        if (info_.width == 1) {
            u0 = 0, u1 = 1;
        }
        if (info_.height == 1) {
            v0 = 0, v1 = 1;
        }
        constexpr int kSteps = 64;
        double west = INFINITY, south = INFINITY, east = -INFINITY, north = -INFINITY;
        for (int i = 0; i <= kSteps; ++i) {
            const double f = static_cast<double>(i) / kSteps;
            const double pts[4][2] = {{u0 + f * (u1 - u0), v0},
                                      {u0 + f * (u1 - u0), v1},
                                      {u0, v0 + f * (v1 - v0)},
                                      {u1, v0 + f * (v1 - v0)}};
            for (const auto& p : pts) {
                double x = g[0] + p[0] * g[1] + p[1] * g[2];
                double y = g[3] + p[0] * g[4] + p[1] * g[5];
                if (ct->Transform(1, &x, &y) && std::isfinite(x) && std::isfinite(y)) {
                    west = std::min(west, x), east = std::max(east, x);
                    south = std::min(south, y), north = std::max(north, y);
                }
            }
        }
        if (!(west <= east && south <= north)) {
            throw InputError(info_.path + ": its extent does not transform to lon/lat; check "
                                          "the CRS and geotransform");
        }
        // A pole inside the pixel-centre hull (a polar stereographic DEM of Antarctica): the
        // outline never reaches it, but the data does, at every longitude.
        std::unique_ptr<OGRCoordinateTransformation> back(
            OGRCreateCoordinateTransformation(&wgs84, &srs_));
        for (const double pole : {-90.0, 90.0}) {
            double x = 0, y = pole;
            if (back && back->Transform(1, &x, &y) && std::isfinite(x) && std::isfinite(y)) {
                const double u = inverse_[0] + x * inverse_[1] + y * inverse_[2];
                const double v = inverse_[3] + x * inverse_[4] + y * inverse_[5];
                if (u >= u0 && u <= u1 && v >= v0 && v <= v1) {
                    west = -180, east = 180;
                    (pole < 0 ? south : north) = pole;
                }
            }
        }
        footprint_ = {std::max(west, -180.0),
                      std::max(south, -90.0),
                      std::min(east, 180.0),
                      std::min(north, 90.0)};
    }

    // The pixel grid in the scheme's CRS (see DemSource::pixel_grid): the same CRS, or a
    // geographic one whose transformation to WGS84 moves no pixel centre (checked at the corners
    // and the centre of the pixel-centre hull to 1e-9 degrees, about 0.1 mm).
    std::optional<PixelGrid> find_pixel_grid(Scheme scheme) const {
        const auto& g = info_.geotransform;
        if (g[2] != 0 || g[4] != 0 || !(g[1] > 0) || !(g[5] < 0)) {
            return std::nullopt;
        }
        const char* options[] = {"IGNORE_DATA_AXIS_TO_SRS_AXIS_MAPPING=YES", nullptr};
        const OGRSpatialReference mercator = scheme_srs(Scheme::Mercator);
        if (scheme == Scheme::Mercator && mercator.IsSame(&srs_, options)) {
            return PixelGrid{g[0], g[3], g[1], -g[5], info_.width, info_.height, false};
        }
        OGRSpatialReference target = scheme_srs(Scheme::Geodetic);
        if (!target.IsSame(&srs_, options)) {
            if (!srs_.IsGeographic()) {
                return std::nullopt;
            }
            std::unique_ptr<OGRCoordinateTransformation> ct(
                OGRCreateCoordinateTransformation(&srs_, &target));
            if (!ct) {
                return std::nullopt;
            }
            const double u[3] = {0.5, info_.width / 2.0, info_.width - 0.5};
            const double v[3] = {0.5, info_.height / 2.0, info_.height - 0.5};
            for (int a = 0; a < 3; ++a) {
                for (int b = 0; b < 3; ++b) {
                    const double x0 = g[0] + u[a] * g[1], y0 = g[3] + v[b] * g[5];
                    double x = x0, y = y0;
                    if (!ct->Transform(1, &x, &y) || !(std::abs(x - x0) <= 1e-9) ||
                        !(std::abs(y - y0) <= 1e-9)) {
                        return std::nullopt;
                    }
                }
            }
        }
        return PixelGrid{g[0], g[3], g[1], -g[5], info_.width, info_.height, true};
    }

    // Height of a raw sample, or NaN for nodata (tiler::to_height decides).
    double to_height(double raw) const {
        return tiler::to_height(raw,
                                info_.nodata,
                                data_type_ == GDT_Float32,
                                info_.scale,
                                info_.offset,
                                info_.valid_range);
    }

    std::shared_ptr<const MemoryFile> file_; // first: outlives the handles reading it
    std::string open_name_;
    DemInfo info_;
    std::vector<LonLatBox> file_bounds_;
    std::vector<FileOverlap> overlaps_;
    GDALDataType data_type_ = GDT_Unknown;
    OGRSpatialReference srs_;
    bool has_srs_ = false, georeferenced_ = false, ellipsoidal_ = false;
    std::array<double, 6> inverse_{};
    LonLatBox footprint_;
    // Band 1's overviews as found at open; read_level() chooses from these alone, so the level
    // of a zoom is the same for every handle and every block.
    std::vector<Overview> overviews_;
    std::optional<PixelGrid> grids_[2]; // geodetic, mercator
    mutable std::mutex mutex_;
    mutable std::vector<std::unique_ptr<Handle>> idle_;
};

// The rows j_min..j_max of a decimated view (view pixel (i, j) is band pixel (pick(i, W),
// pick(j, H))), columns i_min..i_max, into `view`. A file's rows are read one RasterIO per view
// row; a VRT's (a mosaic) in strips of about a megapixel, every row of them: it walks its files
// on every read, and 257 reads a tile cost a 10,000-file collection 100 ms. (Strips would cost a
// file more than they save: f times the rows, for reads that are cheap there.)
void GdalDemSource::read_view_rows(GDALRasterBand& band,
                                   int f,
                                   int i_min,
                                   int i_max,
                                   int j_min,
                                   int j_max,
                                   int W,
                                   int H,
                                   std::vector<double>& view) const {
    const int strip_pixels = info_.driver == "VRT" ? 1 << 20 : 1;
    const auto pick = [f](int i, int limit) { return std::min(i * f + f / 2, limit - 1); };
    const int c0 = pick(i_min, W), cw = pick(i_max, W) - c0 + 1, ww = i_max - i_min + 1;
    const int strip_rows = std::max(1, strip_pixels / cw);
    std::vector<double> strip;
    for (int j = j_min; j <= j_max;) {
        const int r0 = pick(j, H);
        int j_end = j;
        while (j_end < j_max && pick(j_end + 1, H) - r0 < strip_rows) {
            ++j_end;
        }
        const int rows = pick(j_end, H) - r0 + 1;
        strip.resize(static_cast<std::size_t>(cw) * rows);
        if (band.RasterIO(
                GF_Read, c0, r0, cw, rows, strip.data(), cw, rows, GDT_Float64, 0, 0, nullptr) !=
            CE_None) {
            throw IoError(info_.path + ": read failed (" + gdal_message() + ")");
        }
        for (; j <= j_end; ++j) {
            const double* row = strip.data() + static_cast<std::size_t>(pick(j, H) - r0) * cw;
            for (int i = i_min; i <= i_max; ++i) {
                view[static_cast<std::size_t>(j - j_min) * ww + (i - i_min)] = row[pick(i, W) - c0];
            }
        }
    }
}

LatticeBlock GdalDemSource::sample(Scheme scheme,
                                   int z,
                                   int size,
                                   std::int64_t column0,
                                   std::int64_t row0,
                                   int width,
                                   int height) const {
    TB_ASSERT(georeferenced_ && width > 0 && height > 0);
    LatticeBlock out;
    out.column0 = column0, out.row0 = row0, out.width = width, out.height = height;
    const std::size_t n = static_cast<std::size_t>(width) * height;
    out.heights.assign(n, 0.0);
    out.valid.assign(n, 0);

    Lease h = acquire();
    // Lattice points in the scheme's CRS, then in the source's.
    std::vector<double> xs(n), ys(n);
    std::vector<int> ok(n, 1);
    for (int j = 0; j < height; ++j) {
        const double y = lattice_y(scheme, z, size, row0 + j);
        for (int i = 0; i < width; ++i) {
            xs[static_cast<std::size_t>(j) * width + i] = lattice_x(scheme, z, size, column0 + i);
            ys[static_cast<std::size_t>(j) * width + i] = y;
        }
    }
    if (OGRCoordinateTransformation* ct = transform_for(*h, scheme)) {
        ct->Transform(static_cast<int>(n), xs.data(), ys.data(), nullptr, ok.data());
    }

    // The band read at this zoom and its view: every f-th pixel of it, view pixel I being the
    // band's pixel P(I) = min(I f + f/2, W - 1). The level depends on the zoom only, so every
    // tile of the zoom interpolates the same values.
    const ReadLevel level = read_level(scheme, z, size);
    const int f = level.step, W = level.width, H = level.height;
    const int wr = (W + f - 1) / f, hr = (H + f - 1) / f;
    const auto pick = [f](int i, int limit) { return std::min(i * f + f / 2, limit - 1); };

    // Pixel-centre coordinates (u, v) of each point in the band read, and the window of the
    // view they need.
    std::vector<double> us(n), vs(n);
    int i_min = wr, i_max = -1, j_min = hr, j_max = -1;
    const auto cell = [f](double u, int count) {
        if (count < 2) {
            return 0;
        }
        const int i = static_cast<int>(std::floor((u - f / 2) / f));
        return std::clamp(i, 0, count - 2);
    };
    const auto& t = inverse_;
    for (std::size_t k = 0; k < n; ++k) {
        if (!ok[k] || !std::isfinite(xs[k]) || !std::isfinite(ys[k])) {
            ok[k] = 0;
            continue;
        }
        double u = t[0] + xs[k] * t[1] + ys[k] * t[2] - 0.5;
        double v = t[3] + xs[k] * t[4] + ys[k] * t[5] - 0.5;
        // Inside the pixel-area extent of the source (half a pixel beyond the outer centres).
        if (!(u >= -0.5 && u <= info_.width - 0.5 && v >= -0.5 && v <= info_.height - 0.5)) {
            ok[k] = 0;
            continue;
        }
        if (level.overview >= 0) {
            // An overview spans the source's extent with fewer, larger pixels.
            u = (u + 0.5) * W / info_.width - 0.5;
            v = (v + 0.5) * H / info_.height - 0.5;
        }
        us[k] = u, vs[k] = v;
        const int i = cell(u, wr), j = cell(v, hr);
        i_min = std::min(i_min, i), i_max = std::max(i_max, std::min(i + 1, wr - 1));
        j_min = std::min(j_min, j), j_max = std::max(j_max, std::min(j + 1, hr - 1));
    }
    if (i_max < 0) {
        return out; // no lattice point inside the source
    }

    // Read the window of the view: one RasterIO at the band's resolution, or one per view row.
    const int ww = i_max - i_min + 1, wh = j_max - j_min + 1;
    std::vector<double> view(static_cast<std::size_t>(ww) * wh);
    GDALRasterBand* band = h->ds->GetRasterBand(1);
    if (level.overview >= 0) {
        band = band->GetOverview(level.overview);
        if (!band || band->GetXSize() != W || band->GetYSize() != H) {
            throw IoError(info_.path + ": overview " + std::to_string(level.overview + 1) +
                          " of band 1 changed since the DEM was opened; restart so it is "
                          "opened afresh");
        }
    }
    CPLErrorReset();
    if (f == 1) {
        if (band->RasterIO(
                GF_Read, i_min, j_min, ww, wh, view.data(), ww, wh, GDT_Float64, 0, 0, nullptr) !=
            CE_None) {
            throw IoError(info_.path + ": read failed (" + gdal_message() + ")");
        }
    } else {
        read_view_rows(*band, f, i_min, i_max, j_min, j_max, W, H, view);
    }
    for (double& value : view) {
        value = to_height(value);
    }

    // Bilinear interpolation. A sample is void when the pixel nearest to it is nodata (so a
    // void keeps the footprint of its nodata pixels); otherwise nodata neighbours drop out and
    // the weights are renormalized, as GDAL's warper does.
    for (std::size_t k = 0; k < n; ++k) {
        if (!ok[k]) {
            continue;
        }
        const int i = cell(us[k], wr), j = cell(vs[k], hr);
        const int i1 = std::min(i + 1, wr - 1), j1 = std::min(j + 1, hr - 1);
        const double cu0 = pick(i, W), cu1 = pick(i1, W), cv0 = pick(j, H), cv1 = pick(j1, H);
        const double a = cu1 > cu0 ? std::clamp((us[k] - cu0) / (cu1 - cu0), 0.0, 1.0) : 0.0;
        const double b = cv1 > cv0 ? std::clamp((vs[k] - cv0) / (cv1 - cv0), 0.0, 1.0) : 0.0;
        const int ci[4] = {i, i1, i, i1}, cj[4] = {j, j, j1, j1};
        const double w[4] = {(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b};
        const int nearest = (a < 0.5 ? 0 : 1) + (b < 0.5 ? 0 : 2);
        if (std::isnan(
                view[static_cast<std::size_t>(cj[nearest] - j_min) * ww + (ci[nearest] - i_min)])) {
            continue;
        }
        double sum = 0, weights = 0;
        for (int q = 0; q < 4; ++q) {
            if (w[q] <= 0) {
                continue;
            }
            const double value =
                view[static_cast<std::size_t>(cj[q] - j_min) * ww + (ci[q] - i_min)];
            if (std::isnan(value)) {
                continue;
            }
            sum += w[q] * value;
            weights += w[q];
        }
        if (weights > 0) {
            out.heights[k] = sum / weights;
            out.valid[k] = 1;
        }
    }
    return out;
}

std::vector<double>
GdalDemSource::read_pixels(std::int64_t column0, std::int64_t row0, int width, int height) const {
    TB_ASSERT(width > 0 && height > 0);
    std::vector<double> out(static_cast<std::size_t>(width) * height, NAN);
    const std::int64_t c0 = std::max<std::int64_t>(column0, 0);
    const std::int64_t r0 = std::max<std::int64_t>(row0, 0);
    const std::int64_t c1 = std::min<std::int64_t>(column0 + width, info_.width);
    const std::int64_t r1 = std::min<std::int64_t>(row0 + height, info_.height);
    if (c0 >= c1 || r0 >= r1) {
        return out;
    }
    const int ww = static_cast<int>(c1 - c0), wh = static_cast<int>(r1 - r0);
    // The part inside the raster is read straight into its place in the result (GDAL's line
    // spacing skips the rest of each row) and converted there: a second buffer of a coarse
    // tile's size would cost more in first-touch page faults than the reading.
    double* const first = out.data() + static_cast<std::size_t>(r0 - row0) * width + (c0 - column0);
    const auto row_bytes = static_cast<GSpacing>(sizeof(double)) * width;
    Lease h = acquire();
    CPLErrorReset();
    if (h->ds->GetRasterBand(1)->RasterIO(GF_Read,
                                          static_cast<int>(c0),
                                          static_cast<int>(r0),
                                          ww,
                                          wh,
                                          first,
                                          ww,
                                          wh,
                                          GDT_Float64,
                                          sizeof(double),
                                          row_bytes,
                                          nullptr) != CE_None) {
        throw IoError(info_.path + ": read failed (" + gdal_message() + ")");
    }
    for (int j = 0; j < wh; ++j) {
        double* const row = first + static_cast<std::size_t>(j) * width;
        for (int i = 0; i < ww; ++i) {
            row[i] = to_height(row[i]);
        }
    }
    return out;
}

bool GdalDemSource::window_empty(std::int64_t column0,
                                 std::int64_t row0,
                                 int width,
                                 int height) const {
    // Unwritten blocks read as the file's nodata value (0 without one): only then are they voids.
    if (!info_.nodata || info_.nodata_given || column0 < 0 || row0 < 0 ||
        column0 + width > info_.width || row0 + height > info_.height) {
        return false;
    }
    Lease h = acquire();
    const int status = h->ds->GetRasterBand(1)->GetDataCoverageStatus(
        static_cast<int>(column0), static_cast<int>(row0), width, height);
    return status == GDAL_DATA_COVERAGE_STATUS_EMPTY;
}

std::optional<GdalDemSource::Window> GdalDemSource::window_of(const LonLatBox& box) const {
    Lease h = acquire();
    // The window: the box outline, densified, in source pixel coordinates.
    constexpr int kSteps = 32;
    std::vector<double> xs, ys;
    for (int k = 0; k <= kSteps; ++k) {
        const double f = static_cast<double>(k) / kSteps;
        const double lon = box.west + f * (box.east - box.west);
        const double lat = box.south + f * (box.north - box.south);
        xs.insert(xs.end(), {lon, lon, box.west, box.east});
        ys.insert(ys.end(), {box.south, box.north, lat, lat});
    }
    std::vector<int> ok(xs.size(), 1);
    if (OGRCoordinateTransformation* ct = transform_for(*h, Scheme::Geodetic)) {
        ct->Transform(static_cast<int>(xs.size()), xs.data(), ys.data(), nullptr, ok.data());
    }
    double u_lo = INFINITY, u_hi = -INFINITY, v_lo = INFINITY, v_hi = -INFINITY;
    const auto& t = inverse_;
    for (std::size_t k = 0; k < xs.size(); ++k) {
        if (!ok[k] || !std::isfinite(xs[k]) || !std::isfinite(ys[k])) {
            continue;
        }
        const double u = t[0] + xs[k] * t[1] + ys[k] * t[2];
        const double v = t[3] + xs[k] * t[4] + ys[k] * t[5];
        u_lo = std::min(u_lo, u), u_hi = std::max(u_hi, u);
        v_lo = std::min(v_lo, v), v_hi = std::max(v_hi, v);
    }
    if (!(u_lo <= u_hi && v_lo <= v_hi)) {
        return std::nullopt;
    }
    // A margin of a few pixels covers the curvature of the box's edges between the probes.
    const std::int64_t c0 = std::max<std::int64_t>(0, std::int64_t(std::floor(u_lo)) - 4);
    const std::int64_t r0 = std::max<std::int64_t>(0, std::int64_t(std::floor(v_lo)) - 4);
    const std::int64_t c1 = std::min<std::int64_t>(info_.width, std::int64_t(std::ceil(u_hi)) + 4);
    const std::int64_t r1 = std::min<std::int64_t>(info_.height, std::int64_t(std::ceil(v_hi)) + 4);
    if (c0 >= c1 || r0 >= r1) {
        return std::nullopt;
    }
    const double count = static_cast<double>(c1 - c0) * static_cast<double>(r1 - r0);
    if (count > kMaxPixelsPerTile) {
        throw InputError(info_.path + ": a tile at this zoom covers " +
                         std::to_string(std::llround(count)) + " source pixels, more than the " +
                         std::to_string(std::llround(kMaxPixelsPerTile)) +
                         " one tile may read; use a finer min zoom");
    }
    return Window{c0, r0, static_cast<int>(c1 - c0), static_cast<int>(r1 - r0)};
}

void GdalDemSource::pixels_in(const LonLatBox& box, const PixelVisitor& visit) const {
    TB_ASSERT(georeferenced_);
    const std::optional<Window> w = window_of(box);
    if (!w) {
        return;
    }
    // Strips of about 64k pixels: the memory a tile's check needs is its own list of pixels,
    // not several full-window copies of them.
    const int strip = std::max(1, 65536 / w->width);
    std::vector<double> px, py, hs;
    std::vector<int> good;
    for (int j0 = 0; j0 < w->height; j0 += strip) {
        const int rows = std::min(strip, w->height - j0);
        const std::vector<double> heights = read_pixels(w->column0, w->row0 + j0, w->width, rows);
        px.clear(), py.clear(), hs.clear();
        const auto& g = info_.geotransform;
        for (int j = 0; j < rows; ++j) {
            for (int i = 0; i < w->width; ++i) {
                const double value = heights[static_cast<std::size_t>(j) * w->width + i];
                if (std::isnan(value)) {
                    continue;
                }
                const double u = static_cast<double>(w->column0 + i) + 0.5;
                const double v = static_cast<double>(w->row0 + j0 + j) + 0.5;
                px.push_back(g[0] + u * g[1] + v * g[2]);
                py.push_back(g[3] + u * g[4] + v * g[5]);
                hs.push_back(value);
            }
        }
        if (px.empty()) {
            continue;
        }
        good.assign(px.size(), 1);
        to_lonlat(px, py, good);
        for (std::size_t k = 0; k < px.size(); ++k) {
            if (good[k] && px[k] >= box.west && px[k] <= box.east && py[k] >= box.south &&
                py[k] <= box.north) {
                visit({px[k], py[k], hs[k]});
            }
        }
    }
}

// The validity of coverage()'s window, and a borrowed handle for its lon/lat -> source CRS
// transformation.
class GdalDemSource::Coverage final : public PixelCoverage {
public:
    Coverage(const GdalDemSource& owner, Window w, std::vector<std::uint8_t> valid)
        : owner_(owner), lease_(owner.acquire()), w_(w), valid_(std::move(valid)) {}

    void mark(const std::vector<double>& lons,
              const std::vector<double>& lats,
              std::vector<std::uint8_t>& covered) const override {
        TB_ASSERT(lons.size() == lats.size() && covered.size() == lons.size());
        std::vector<double> xs = lons, ys = lats;
        std::vector<int> ok(xs.size(), 1);
        if (OGRCoordinateTransformation* ct = owner_.transform_for(*lease_, Scheme::Geodetic)) {
            ct->Transform(static_cast<int>(xs.size()), xs.data(), ys.data(), nullptr, ok.data());
        }
        const auto& t = owner_.inverse_;
        for (std::size_t k = 0; k < xs.size(); ++k) {
            if (covered[k] || !ok[k]) {
                continue;
            }
            // Pixel (i, j) covers [i, i + 1) x [j, j + 1) in pixel coordinates.
            const double u = std::floor(t[0] + xs[k] * t[1] + ys[k] * t[2]) - w_.column0;
            const double v = std::floor(t[3] + xs[k] * t[4] + ys[k] * t[5]) - w_.row0;
            if (u >= 0 && v >= 0 && u < w_.width && v < w_.height &&
                valid_[static_cast<std::size_t>(v) * w_.width + static_cast<std::size_t>(u)]) {
                covered[k] = 1;
            }
        }
    }

private:
    const GdalDemSource& owner_;
    Lease lease_;
    Window w_;
    std::vector<std::uint8_t> valid_; // row-major over w_
};

std::unique_ptr<const PixelCoverage> GdalDemSource::coverage(const LonLatBox& box) const {
    TB_ASSERT(georeferenced_);
    const std::optional<Window> w = window_of(box);
    if (!w) {
        return std::make_unique<Coverage>(*this, Window{}, std::vector<std::uint8_t>());
    }
    // A byte per pixel, read in strips as pixels_in reads (a window of doubles would be 8).
    std::vector<std::uint8_t> valid(static_cast<std::size_t>(w->width) * w->height);
    const int strip = std::max(1, 65536 / w->width);
    for (int j0 = 0; j0 < w->height; j0 += strip) {
        const int rows = std::min(strip, w->height - j0);
        const std::vector<double> heights = read_pixels(w->column0, w->row0 + j0, w->width, rows);
        std::uint8_t* out = valid.data() + static_cast<std::size_t>(j0) * w->width;
        for (std::size_t k = 0; k < heights.size(); ++k) {
            out[k] = std::isnan(heights[k]) ? 0 : 1;
        }
    }
    return std::make_unique<Coverage>(*this, *w, std::move(valid));
}

void GdalDemSource::to_lonlat(std::vector<double>& x,
                              std::vector<double>& y,
                              std::vector<int>& good) const {
    Lease h = acquire();
    if (!h->to_lonlat) {
        OGRSpatialReference wgs84 = scheme_srs(Scheme::Geodetic);
        h->to_lonlat.reset(OGRCreateCoordinateTransformation(&srs_, &wgs84));
        if (!h->to_lonlat) {
            throw InputError(info_.path + ": its CRS cannot be transformed to WGS84 lon/lat (" +
                             gdal_message() + ")");
        }
    }
    h->to_lonlat->Transform(static_cast<int>(x.size()), x.data(), y.data(), nullptr, good.data());
}

void GdalDemSource::pixels_to_lonlat(std::vector<double>& x, std::vector<double>& y) const {
    TB_ASSERT(georeferenced_ && x.size() == y.size());
    const auto& g = info_.geotransform;
    for (std::size_t k = 0; k < x.size(); ++k) {
        const double u = x[k] + 0.5, v = y[k] + 0.5;
        x[k] = g[0] + u * g[1] + v * g[2];
        y[k] = g[3] + u * g[4] + v * g[5];
    }
    std::vector<int> good(x.size(), 0);
    to_lonlat(x, y, good);
    for (std::size_t k = 0; k < x.size(); ++k) {
        if (!good[k] || !std::isfinite(x[k]) || !std::isfinite(y[k])) {
            x[k] = y[k] = NAN;
        }
    }
}

void GdalDemSource::lonlat_to_pixels(std::vector<double>& x, std::vector<double>& y) const {
    TB_ASSERT(georeferenced_ && x.size() == y.size());
    std::vector<int> good(x.size(), 1);
    {
        Lease h = acquire();
        if (OGRCoordinateTransformation* ct = transform_for(*h, Scheme::Geodetic)) {
            ct->Transform(static_cast<int>(x.size()), x.data(), y.data(), nullptr, good.data());
        }
    }
    const auto& t = inverse_;
    for (std::size_t k = 0; k < x.size(); ++k) {
        if (!good[k] || !std::isfinite(x[k]) || !std::isfinite(y[k])) {
            x[k] = y[k] = NAN;
            continue;
        }
        const double u = t[0] + x[k] * t[1] + y[k] * t[2] - 0.5;
        y[k] = t[3] + x[k] * t[4] + y[k] * t[5] - 0.5;
        x[k] = u;
    }
}

core::HeightGrid GdalDemSource::read_all() const {
    const int W = info_.width, H = info_.height;
    if (static_cast<double>(W) * H > 400e6) {
        throw InputError(info_.path + ": " + std::to_string(W) + " x " + std::to_string(H) +
                         " samples is too large to mesh whole; cut it into tiles (terrabound "
                         "tile/build)");
    }
    Lease h = acquire();
    const std::size_t n = static_cast<std::size_t>(W) * H;
    std::vector<double> raw(n);
    CPLErrorReset();
    if (h->ds->GetRasterBand(1)->RasterIO(
            GF_Read, 0, 0, W, H, raw.data(), W, H, GDT_Float64, 0, 0, nullptr) != CE_None) {
        throw IoError(info_.path + ": read failed (" + gdal_message() + ")");
    }
    std::vector<std::uint8_t> valid(n, 0);
    bool any = false;
    for (std::size_t k = 0; k < n; ++k) {
        const double value = to_height(raw[k]);
        if (std::isnan(value)) {
            raw[k] = 0;
        } else {
            raw[k] = value;
            valid[k] = 1;
            any = true;
        }
    }
    if (!any) {
        throw InputError(info_.path + ": every sample of band 1 is nodata; nothing to mesh");
    }
    fill_voids(raw, valid, W, H, 0, 0.0);
    core::HeightGrid grid;
    grid.width = W, grid.height = H;
    grid.heights.assign(raw.begin(), raw.end());
    bool all_valid = std::all_of(valid.begin(), valid.end(), [](std::uint8_t v) { return v != 0; });
    if (!all_valid) {
        grid.valid = std::move(valid);
    }
    return grid;
}

// Refuses a DEM whose extreme value looks like undeclared voids, naming the fix.
// One warning per source holding samples outside kLowestHeight..kHighestHeight: how many, and
// where the first one lies (pixel, and its place in the DEM's CRS).
void warn_outliers(const DemInfo& info) {
    if (info.outliers == 0) {
        return;
    }
    const auto& g = info.geotransform;
    const double px = static_cast<double>(info.outlier_column) + 0.5;
    const double py = static_cast<double>(info.outlier_row) + 0.5;
    char text[512];
    std::snprintf(text,
                  sizeof text,
                  ": %s%lld sample(s) outside the plausible range of heights (%g .. %g m; "
                  "--valid-range MIN,MAX to change it) count as nodata; the first, %.7g m, is "
                  "pixel (%lld, %lld)",
                  info.range_exact ? "" : "at least ",
                  static_cast<long long>(info.outliers),
                  info.valid_range.low,
                  info.valid_range.high,
                  info.outlier_height,
                  static_cast<long long>(info.outlier_column),
                  static_cast<long long>(info.outlier_row));
    std::string where;
    if (info.has_geotransform) {
        char at[160];
        std::snprintf(at,
                      sizeof at,
                      info.geographic ? " at lon %.6f, lat %.6f" : " at x %.2f, y %.2f (%s)",
                      g[0] + px * g[1] + py * g[2],
                      g[3] + px * g[4] + py * g[5],
                      info.crs_id.c_str());
        where = at;
    }
    log::warn(info.path + text + where);
}

void check_likely_nodata(const DemInfo& info) {
    if (!info.likely_nodata || info.nodata_given) {
        return;
    }
    char text[512];
    std::snprintf(text,
                  sizeof text,
                  ": %.3g%% of band 1's samples are %.17g, far from all the others (%.10g .. "
                  "%.10g m), which looks like voids not declared as nodata; pass --nodata %.17g "
                  "(config: \"nodata\": %.17g), or --nodata with a value the file does not "
                  "hold to keep them as heights",
                  100 * info.likely_nodata_share,
                  *info.likely_nodata,
                  info.others_min,
                  info.others_max,
                  *info.likely_nodata,
                  *info.likely_nodata);
    throw InputError(info.path + text);
}

} // namespace

double to_height(double raw,
                 const std::optional<double>& nodata,
                 bool float32,
                 double scale,
                 double offset,
                 const ValidRange& range) {
    const double h = sample_height(raw, nodata, float32, scale, offset);
    return h >= range.low && h <= range.high ? h : NAN;
}

ValidRange parse_valid_range(const std::string& text, const std::string& what) {
    const auto comma = text.find(',');
    ValidRange r;
    char* end = nullptr;
    bool ok = comma != std::string::npos;
    if (ok) {
        const std::string low = text.substr(0, comma), high = text.substr(comma + 1);
        r.low = std::strtod(low.c_str(), &end);
        ok = !low.empty() && *end == '\0';
        r.high = std::strtod(high.c_str(), &end);
        ok = ok && !high.empty() && *end == '\0';
    }
    if (!ok || !std::isfinite(r.low) || !std::isfinite(r.high) || !(r.low < r.high)) {
        throw InputError(what + " '" + text +
                         "': expected MIN,MAX in metres with MIN < MAX, such as -12000,9000");
    }
    return r;
}

double sample_height(
    double raw, const std::optional<double>& nodata, bool float32, double scale, double offset) {
    if (!std::isfinite(raw)) {
        return NAN;
    }
    if (nodata) {
        const double nd = *nodata;
        if (raw == nd) {
            return NAN;
        }
        if (float32 && static_cast<float>(raw) == static_cast<float>(nd)) {
            return NAN;
        }
    }
    return raw * scale + offset;
}

namespace {

// What a mosaic reads where no file lies: --nodata, else the first file's nodata, else NaN.
// (Left unset, the gaps between files would read as 0 m of data where the first has none.)
double mosaic_nodata(const std::vector<const FileScan*>& files, std::optional<double> nodata) {
    if (nodata) {
        return *nodata;
    }
    for (const FileScan* f : files) {
        if (f->info.nodata) {
            return *f->info.nodata;
        }
    }
    return NAN;
}

// The mosaic's description from its files' scans. A sample equal to the mosaic's nodata value
// is a void in the mosaic whatever its file declares, so a file whose nodata is another (or
// none) is scanned again, leaving those out as well as its own.
DemInfo describe_from_scans(const std::string& vrt,
                            const std::vector<const FileScan*>& files,
                            double fill,
                            std::optional<double> nodata,
                            const ValidRange& range) {
    const MosaicFill mosaic_fill{fill, !shares_scale(files)};
    std::vector<FileScan> again;
    again.reserve(files.size());
    std::vector<const FileScan*> scans;
    for (const FileScan* f : files) {
        if (std::isfinite(fill) && f->info.nodata != fill) {
            const auto always = [](const DemInfo&) { return true; };
            again.push_back(scan_file(f->info.path, always, nodata, range, mosaic_fill));
            scans.push_back(&again.back());
        } else {
            scans.push_back(f);
        }
    }
    return describe_mosaic(vrt, scans, nodata, range);
}

// One in-memory VRT mosaic of files that share a CRS and a pixel size; the first given wins
// where they overlap. Its heights' range comes from the files' scans when every file was
// scanned, else from reading the mosaic (exact up to kExactRangeSamples).
std::shared_ptr<const DemSource> open_mosaic(const std::vector<const FileScan*>& files,
                                             std::optional<double> nodata,
                                             const ValidRange& range) {
    std::vector<std::string> paths;
    bool use_scans = true;
    for (const FileScan* f : files) {
        paths.push_back(f->info.path);
        use_scans = use_scans && f->scanned;
    }
    const double fill = mosaic_nodata(files, nodata);
    auto file = std::make_shared<const MemoryFile>(mosaic_vrt_xml(files, fill));
    DemInfo info = use_scans ? describe_from_scans(file->path(), files, fill, nodata, range)
                             : inspect_dem(file->path(), kExactRangeSamples, nodata, range);
    info.path = inputs_text(paths);
    info.files = paths;
    check_likely_nodata(info);
    warn_outliers(info);
    std::vector<LonLatBox> bounds;
    for (const FileScan* f : files) {
        if (const auto& b = f->info.lonlat_bounds) {
            // Its pixel edges, brought in by half a pixel: through its outer pixel centres, as a
            // single file's footprint is.
            const double dx = ((*b)[2] - (*b)[0]) / std::max(1, f->info.width) / 2;
            const double dy = ((*b)[3] - (*b)[1]) / std::max(1, f->info.height) / 2;
            bounds.push_back({(*b)[0] + dx, (*b)[1] + dy, (*b)[2] - dx, (*b)[3] - dy});
        } else {
            bounds.clear(); // one file of unknown extent: the mosaic's box stands for all
            break;
        }
    }
    return std::make_shared<GdalDemSource>(
        file->path(), std::move(info), std::move(file), std::move(bounds), measure_overlaps(files));
}

// One group of group_by_grid, its files' heights read once: a file alone (the same from its
// scan or read again), or their mosaic.
std::shared_ptr<const DemSource> group_source(const std::vector<const FileScan*>& files,
                                              std::optional<double> nodata,
                                              const ValidRange& range) {
    if (files.size() > 1) {
        return open_mosaic(files, nodata, range);
    }
    const FileScan& f = *files.front();
    DemInfo info = f.scanned ? f.info : inspect_dem(f.info.path, kExactRangeSamples, nodata, range);
    info.files = {f.info.path};
    check_likely_nodata(info);
    warn_outliers(info);
    return std::make_shared<GdalDemSource>(f.info.path, std::move(info));
}

// The files in groups that one VRT can hold: one CRS, one pixel size, no rotation. Groups keep
// the order of their first file, and files keep theirs within a group.
std::vector<std::vector<const FileScan*>> group_by_grid(const std::vector<FileScan>& scans) {
    const auto same_grid = [&](const FileScan& a, const FileScan& b) {
        const auto& g = a.info.geotransform;
        const auto& h = b.info.geotransform;
        // Pixel sizes that differ by a rounding (a re-export) drift less than 1 % of a pixel
        // across either file.
        const double span = std::max({a.info.width, a.info.height, b.info.width, b.info.height, 1});
        const auto close = [span](double x, double y) {
            return std::abs(x - y) * span <= 0.01 * std::max(std::abs(x), std::abs(y));
        };
        const char* options[] = {"IGNORE_DATA_AXIS_TO_SRS_AXIS_MAPPING=YES", nullptr};
        return g[2] == 0 && g[4] == 0 && h[2] == 0 && h[4] == 0 && close(g[1], h[1]) &&
               close(g[5], h[5]) && a.srs && b.srs && a.srs->IsSame(b.srs.get(), options);
    };
    std::vector<std::vector<const FileScan*>> groups;
    for (const FileScan& scan : scans) {
        auto g = std::find_if(groups.begin(), groups.end(), [&](const auto& group) {
            return same_grid(*group.front(), scan);
        });
        if (g == groups.end()) {
            groups.push_back({&scan});
        } else {
            g->push_back(&scan);
        }
    }
    return groups;
}

// One file, opened once when its samples are few enough to read for the exact range.
std::shared_ptr<const DemSource>
open_one(const std::string& path, std::optional<double> nodata, const ValidRange& range) {
    const auto few_enough = [](const DemInfo& info) {
        return static_cast<double>(info.width) * info.height <= kExactRangeSamples;
    };
    FileScan scan = scan_file(path, few_enough, nodata, range);
    DemInfo info =
        scan.scanned ? std::move(scan.info) : inspect_dem(path, kExactRangeSamples, nodata, range);
    info.files = {path};
    check_likely_nodata(info);
    warn_outliers(info);
    return std::make_shared<GdalDemSource>(path, std::move(info));
}

// Which files' samples are read while a collection opens: file k's when the files 0..k, in the
// order given, hold at most kExactRangeSamples samples, as if they were opened one after another,
// whichever thread opens which. A thread asking for file k waits until the files before it are
// open (a file that failed counts as none), so the answer never depends on timing.
class ScanBudget {
public:
    explicit ScanBudget(std::size_t files) : samples_(files, -1.0) {}

    bool admit(std::size_t k, double samples) {
        std::unique_lock lock(mutex_);
        publish(k, samples);
        known_.wait(lock, [&] { return prefix_.size() > k; });
        return prefix_[k] <= kExactRangeSamples;
    }
    void failed(std::size_t k) {
        std::lock_guard lock(mutex_);
        publish(k, 0);
    }

private:
    void publish(std::size_t k, double samples) {
        if (samples_[k] >= 0) {
            return;
        }
        samples_[k] = samples;
        while (prefix_.size() < samples_.size() && samples_[prefix_.size()] >= 0) {
            prefix_.push_back((prefix_.empty() ? 0 : prefix_.back()) + samples_[prefix_.size()]);
        }
        known_.notify_all();
    }

    std::mutex mutex_;
    std::condition_variable known_;
    std::vector<double> samples_; // per file, -1 until it is open
    std::vector<double> prefix_;  // samples of files 0..k, for the files known so far
};

// Every file opened once, on each usable CPU: described, checked (a mosaic needs georeferencing),
// and its samples read while ScanBudget admits them. The error thrown is the first file's in
// the order given.
std::vector<FileScan> scan_files(const std::vector<std::string>& paths,
                                 std::optional<double> nodata,
                                 const ValidRange& range) {
    if (paths.size() >= 1000) {
        log::info("reading " + std::to_string(paths.size()) + " DEM files for their footprints " +
                  "and height ranges");
    }
    std::vector<FileScan> scans(paths.size());
    std::vector<std::exception_ptr> errors(paths.size());
    ScanBudget budget(paths.size());
    std::atomic<std::size_t> next{0};
    const auto work = [&] {
        for (std::size_t k; (k = next++) < paths.size();) {
            const auto may_scan = [&](const DemInfo& info) {
                if (!info.has_geotransform || info.crs_name.empty()) {
                    throw InputError(info.path + ": has no georeferencing; a mosaic of several "
                                                 "DEMs needs a CRS and geotransform in each");
                }
                return budget.admit(k, static_cast<double>(info.width) * info.height);
            };
            try {
                scans[k] = scan_file(paths[k], may_scan, nodata, range);
            } catch (...) {
                errors[k] = std::current_exception();
                budget.failed(k);
            }
        }
    };
    std::vector<Beside<void>> helpers;
    const auto threads =
        std::min<std::size_t>(static_cast<std::size_t>(usable_cpus()), paths.size());
    for (std::size_t t = 1; t < threads; ++t) {
        helpers.push_back(beside(work));
    }
    work();
    for (auto& helper : helpers) {
        helper.get();
    }
    for (const auto& error : errors) {
        if (error) {
            std::rethrow_exception(error);
        }
    }
    return scans;
}

} // namespace

std::shared_ptr<const DemSource> DemSource::open(const std::vector<std::string>& paths,
                                                 std::optional<double> nodata,
                                                 const ValidRange& range,
                                                 SourcePriority priority) {
    init_gdal();
    if (paths.empty()) {
        throw InputError("no DEM given; name at least one raster file");
    }
    if (nodata && !std::isfinite(*nodata)) {
        throw InputError("--nodata: expected a finite number (NaN and infinite samples are "
                         "always nodata)");
    }
    if (paths.size() == 1) {
        return open_one(paths[0], nodata, range);
    }
    const std::vector<FileScan> scans = scan_files(paths, nodata, range);
    std::vector<std::shared_ptr<const DemSource>> members;
    for (const auto& group : group_by_grid(scans)) {
        members.push_back(group_source(group, nodata, range));
    }
    if (members.size() == 1) {
        return members.front();
    }
    return make_collection_source(std::move(members), priority);
}

void write_tile_raster_tiff(const TileRaster& raster, const std::string& path) {
    init_gdal();
    const int w = raster.grid.width, hgt = raster.grid.height;
    TB_ASSERT(w >= 1 && hgt >= 1 && raster.grid.heights.size() == std::size_t(w) * hgt);
    GDALDriver* driver = GetGDALDriverManager()->GetDriverByName("GTiff");
    if (!driver) {
        throw IoError(path + ": GDAL has no GTiff driver");
    }
    const std::string temp = path + ".tmp" + std::to_string(::getpid());
    CslPtr create_options(CSLSetNameValue(nullptr, "COMPRESS", "DEFLATE"));
    CPLErrorReset();
    GDALDatasetUniquePtr ds(
        driver->Create(temp.c_str(), w, hgt, 1, GDT_Float32, create_options.get()));
    if (!ds) {
        throw IoError(path + ": cannot create (" + gdal_message() + ")");
    }
    const auto fail = [&](const std::string& what) {
        ds.reset();
        std::remove(temp.c_str());
        throw IoError(path + ": " + what + " (" + gdal_message() + ")");
    };
    // Sample (i, j) is the centre of pixel (i, j).
    const GridFrame f = frame_of(raster);
    double gt[6] = {f.x0 - f.dx / 2, f.dx, 0, f.y0 + f.dy / 2, 0, -f.dy};
    OGRSpatialReference srs = scheme_srs(raster.scheme);
    std::vector<float> heights = raster.grid.heights;
    GDALRasterBand* band = ds->GetRasterBand(1);
    if (ds->SetGeoTransform(gt) != CE_None || ds->SetSpatialRef(&srs) != CE_None) {
        fail("cannot set georeferencing");
    }
    if (band->RasterIO(
            GF_Write, 0, 0, w, hgt, heights.data(), w, hgt, GDT_Float32, 0, 0, nullptr) !=
        CE_None) {
        fail("write failed");
    }
    if (!raster.grid.valid.empty()) {
        // Inside the TIFF, not as a .msk sidecar the rename below would leave behind.
        CPLSetThreadLocalConfigOption("GDAL_TIFF_INTERNAL_MASK", "YES");
        const CPLErr masked = ds->CreateMaskBand(GMF_PER_DATASET);
        CPLSetThreadLocalConfigOption("GDAL_TIFF_INTERNAL_MASK", nullptr);
        if (masked != CE_None) {
            fail("cannot create the void mask");
        }
        std::vector<std::uint8_t> mask(raster.grid.valid.size());
        for (std::size_t k = 0; k < mask.size(); ++k) {
            mask[k] = raster.grid.valid[k] ? 255 : 0;
        }
        if (band->GetMaskBand()->RasterIO(
                GF_Write, 0, 0, w, hgt, mask.data(), w, hgt, GDT_Byte, 0, 0, nullptr) != CE_None) {
            fail("cannot write the void mask");
        }
    }
    CPLErrorReset();
    ds.reset(); // flushes and closes; GDAL reports failures through the error state
    if (CPLGetLastErrorType() == CE_Failure || CPLGetLastErrorType() == CE_Fatal) {
        std::remove(temp.c_str());
        throw IoError(path + ": write failed (" + gdal_message() + ")");
    }
    move_into_place(temp, path);
}

FloatGrid read_float_grid(const std::string& path) {
    init_gdal();
    CPLErrorReset();
    GDALDatasetUniquePtr ds(GDALDataset::Open(
        path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr, nullptr, nullptr));
    if (!ds) {
        throw InputError(path + ": cannot read the grid (" + gdal_message() +
                         "); install it (Debian package proj-data)");
    }
    FloatGrid g;
    g.width = ds->GetRasterXSize();
    g.height = ds->GetRasterYSize();
    if (ds->GetGeoTransform(g.geotransform.data()) != CE_None) {
        throw InputError(path + ": the grid has no geotransform");
    }
    g.values.resize(static_cast<std::size_t>(g.width) * g.height);
    if (ds->GetRasterBand(1)->RasterIO(GF_Read,
                                       0,
                                       0,
                                       g.width,
                                       g.height,
                                       g.values.data(),
                                       g.width,
                                       g.height,
                                       GDT_Float32,
                                       0,
                                       0,
                                       nullptr) != CE_None) {
        throw IoError(path + ": read failed (" + gdal_message() + ")");
    }
    return g;
}

} // namespace tb::tiler
