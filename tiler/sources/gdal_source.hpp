#pragma once
// What a DEM is, as GDAL reads it (band 1). GDAL types stay inside tiler/gdal_*.cpp.
#include "core/mesh.hpp"
#include "tiler/sources/tile_raster.hpp"
#include "tiler/tile_grid.hpp"

#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

class OGRSpatialReference;

namespace tb::tiler {

// Heights outside this range (metres, after scale and offset) are no place on Earth: the
// Challenger Deep lies near -11,000 m and Everest near 8,850 m. Such samples (+-3.4e38 left by
// a conversion of an ASCII grid's inf, a spike of 3e38, undeclared markers out of range) count
// as nodata, and one warning per source says how many and where the first lies.
inline constexpr double kLowestHeight = -12000;
inline constexpr double kHighestHeight = 9000;

// The heights a source may hold (--valid-range MIN,MAX): kLowestHeight..kHighestHeight unless
// changed (another planet, a DEM whose offset puts its heights elsewhere).
struct ValidRange {
    double low = kLowestHeight, high = kHighestHeight;
    bool is_default() const { return low == kLowestHeight && high == kHighestHeight; }
};
// "MIN,MAX" (metres, MIN < MAX, both finite); InputError naming `what` otherwise.
ValidRange parse_valid_range(const std::string& text, const std::string& what);

struct DemInfo {
    std::string path;
    std::vector<std::string> files; // the files read: one, or a mosaic's (empty: not opened)
    std::string driver;             // GDAL short name: GTiff, SRTMHGT, DTED, AAIGrid, ...
    int width = 0, height = 0, bands = 0;
    std::string data_type;   // Int16, UInt16, Int32, Float32, ...
    std::string crs_name;    // "WGS 84", "" when the file has none
    std::string crs_id;      // "EPSG:4326", "" when not identified
    bool geographic = false; // the CRS is lon/lat
    bool has_geotransform = false;
    std::array<double, 6> geotransform{0, 1, 0, 0, 0, 1};
    std::optional<double> nodata;
    // Band 1's scale and offset, times metres_per_unit: every read gives metres.
    double scale = 1.0, offset = 0.0;
    // The unit the file gives its heights in (band 1's unit type, or the vertical CRS's), and
    // metres per unit; "" and 1 when it gives none (metres are assumed).
    std::string height_unit;
    double metres_per_unit = 1.0;
    bool has_data = false;                 // false when every sample is nodata
    double min_height = 0, max_height = 0; // over valid samples, after scale/offset
    bool range_exact = true; // min/max read from every sample, not GDAL's approximate pass
    std::optional<std::array<double, 4>> lonlat_bounds; // west, south, east, north (degrees)
    double resolution_m = 0;   // approximate ground size of one pixel, metres
    bool nodata_given = false; // nodata comes from the caller (--nodata), not from the file
    // A raw value that looks like voids not declared as nodata (see kLikelyNodataShare), the
    // share of valid samples holding it, and the height range of the others.
    std::optional<double> likely_nodata;
    double likely_nodata_share = 0;
    double others_min = 0, others_max = 0;
    // Samples outside kLowestHeight..kHighestHeight (counted as nodata), and the first one
    // found (row by row): its pixel and height. Counted over every sample when range_exact,
    // else over GDAL's approximate pass (a lower bound). A mosaic described from its files'
    // scans counts the pixels under another file too, and its first is the first file's that
    // has one (in the order given), as a pixel of the mosaic.
    ValidRange valid_range; // heights outside it are outliers
    std::int64_t outliers = 0;
    std::int64_t outlier_column = 0, outlier_row = 0;
    double outlier_height = 0;
};

// An extreme value (the minimum or the maximum) of the valid samples is taken for undeclared
// voids when it holds more than this share of them, the other samples (more than one value)
// hold more than this share too, and it lies further than kLikelyNodataGap
// from the nearest other value, and that gap is wider than the spread of all the other values
// for a usual void marker (-32768, -32767, -9999, -999, -99999, 9999, 32767, 65535, the
// float32 limits), or ten times wider for any other value: -32767 or -9999 holes in 0 .. 3000 m
// terrain, say, but not a sea at 0 m next to land at 1 m, nor a flat plateau above hills.
inline constexpr double kLikelyNodataShare = 0.005;
inline constexpr double kLikelyNodataGap = 500;

// The height of a raw sample of band 1, or NaN when it is nodata: NaN, +-Inf, equal to
// `nodata` (compared as float32 too for Float32 bands, whose nodata is often written as a
// double that is not exactly a float), or outside kLowestHeight..kHighestHeight once scale and
// offset are applied. This is the one place that decides which source values are heights.
double to_height(double raw,
                 const std::optional<double>& nodata,
                 bool float32,
                 double scale,
                 double offset,
                 const ValidRange& range = {});
// The same without the range: what the sample says, NaN for nodata only.
double sample_height(
    double raw, const std::optional<double>& nodata, bool float32, double scale, double offset);

// Up to this many samples inspect_dem reads every block for the exact height range (about a
// second per 100 Mpixel of a compressed GeoTIFF here); above it GDAL's approximate pass over
// overviews or a subsample, which can miss the extremes.
inline constexpr double kExactRangeSamples = 1e9;

// Opens `path` read-only and describes band 1 (statistics computed from the data, not from
// metadata; exact up to exact_range_samples samples, else from an overview or a decimated
// read). `nodata`, when given, replaces the file's nodata value. Throws InputError naming the
// path: missing file, a directory, not a raster, a NUL in the path; IoError naming GDAL's
// message when the file cannot be read (permissions, truncated data, a missing VRT source).
DemInfo inspect_dem(const std::string& path,
                    double exact_range_samples = kExactRangeSamples,
                    std::optional<double> nodata = std::nullopt,
                    const ValidRange& range = {});
// The same without reading a sample: size, type, nodata, CRS, georeferencing, lon/lat bounds and
// resolution (has_data false, no height range). For files read through a mosaic, which is
// inspected whole instead: a collection of thousands of files is read once, not twice.
DemInfo inspect_metadata(const std::string& path,
                         std::optional<double> nodata = std::nullopt,
                         const ValidRange& range = {});

// What a pass over band 1 found, in heights (to_height applied). second_min is the smallest
// height above min (infinite when there is none), second_max the largest below max.
struct SampleStats {
    std::int64_t valid = 0;
    double min = INFINITY, max = -INFINITY;
    std::int64_t at_min = 0, at_max = 0;
    double second_min = INFINITY, second_max = -INFINITY;
};

// Every sample that is not nodata (for undeclared voids, which may lie outside the plausible
// range), the heights within it, and the outliers (the first one's pixel and height).
struct BandStats {
    SampleStats all, heights;
    std::int64_t outliers = 0;
    std::int64_t outlier_column = 0, outlier_row = 0;
    double outlier_height = 0;
};

// Two files of one mosaic whose pixels overlap: `first` (given first) wins there. pixels: those
// valid in both that were compared; max_diff: the largest height difference among them (m).
struct FileOverlap {
    std::string first, second;
    std::int64_t pixels = 0;
    double max_diff = 0;
};

// One file of several, opened once: what inspect_metadata says of it, band 1's block size and
// overviews, its CRS (null without one), and, when `scanned`, every sample's statistics, to merge
// into its mosaic's (describe_mosaic). Band 1 is checked to hold heights, as DemSource::open does.
struct FileScan {
    DemInfo info;
    int block_width = 0, block_height = 0;
    std::vector<int> overview_factors; // band 1's overviews: file pixels per overview pixel
    std::shared_ptr<const OGRSpatialReference> srs;
    bool scanned = false;
    BandStats stats;
};
// The value a mosaic reads as void (its nodata), compared with a file's raw samples, or with its
// heights where the mosaic applies the file's scale and offset itself.
struct MosaicFill {
    double value = 0;
    bool heights = false;
};
// Scans the samples when may_scan(the file's description) says so (asked once; it may throw to
// refuse the file). With `fill`, samples the mosaic reads as void are left out as nodata is.
// Thread-safe: the files of a collection are scanned on several threads.
FileScan scan_file(const std::string& path,
                   const std::function<bool(const DemInfo&)>& may_scan,
                   std::optional<double> nodata,
                   const ValidRange& range,
                   std::optional<MosaicFill> fill = std::nullopt);

// A mosaic described from the files it draws (every one scanned): its size, CRS and
// georeferencing from `vrt` (its VRT, no sample read), its height range, outliers and undeclared
// voids from its files' statistics merged. Pixels that another file hides count too, so the
// range may be wider than what the mosaic shows, never narrower.
DemInfo describe_mosaic(const std::string& vrt,
                        const std::vector<const FileScan*>& files,
                        std::optional<double> nodata,
                        const ValidRange& range);

// Registers GDAL drivers once and routes GDAL's error handler to our logger. Idempotent. GDAL's
// block cache starts at kDefaultBlockCacheMb unless GDAL_CACHEMAX is set (GDAL's own default,
// 5 % of the RAM, held 1.2 GB in an idle serve on a 24 GiB machine).
void init_gdal();

inline constexpr std::size_t kDefaultBlockCacheMb = 64;
// GDAL's block cache, MiB: set (serve's memory budget) and read back as GDAL has it.
void set_block_cache_mb(std::size_t mb);
std::size_t block_cache_mb();

// ---- Reading DEMs for tiles (tiler/gdal_reader.cpp) ----

// A rectangular block of the global sample lattice of one zoom (see sample_column/sample_row):
// `width` x `height` samples, row-major from the north-west corner. Heights are the source's
// (scale/offset applied, datum not converted); valid = 0 where the source has nodata or no
// coverage, and the height there is 0.
struct LatticeBlock {
    std::int64_t column0 = 0, row0 = 0;
    int width = 0, height = 0;
    std::vector<double> heights;
    std::vector<std::uint8_t> valid;
};

// What DemSource::sample reads at one zoom: band 1 itself or one of its overviews (internal,
// an external .ovr, or a VRT's implicit ones), then every `step`-th pixel of that band.
struct ReadLevel {
    int overview = -1;         // index among band 1's overviews (GDAL's order); -1 = band 1
    int width = 0, height = 0; // pixels of the band read
    double factor = 1;         // source pixels per pixel of it, larger of x and y; 1 for band 1
    int step = 1;              // a power of two
};

// A source's pixel grid, axis-aligned with a scheme's tiles: pixel (i, j) of band 1 has its
// centre at x = x0 + (i + 0.5) * dx, y = y0 - (j + 0.5) * dy (dx, dy > 0), lon/lat degrees or
// EPSG:3857 metres.
struct PixelGrid {
    double x0 = 0, y0 = 0, dx = 0, dy = 0;
    int width = 0, height = 0;
    bool lonlat = true; // x, y are WGS84 lon/lat degrees; false: EPSG:3857 metres
    double x(std::int64_t i) const { return x0 + (static_cast<double>(i) + 0.5) * dx; }
    double y(std::int64_t j) const { return y0 - (static_cast<double>(j) + 0.5) * dy; }
};

// A valid source pixel centre: where it is and its height as read (scale/offset applied, datum
// not converted).
struct SourcePixel {
    double lon = 0, lat = 0;
    double height = 0;
};

// Which of a set of lon/lat points lie in a valid pixel of a source: in the area of a pixel
// that is not nodata. Made for one box (DemSource::coverage), used by one thread.
class PixelCoverage {
public:
    virtual ~PixelCoverage() = default;
    // Sets covered[k] = 1 where point (lons[k], lats[k]) lies in a valid pixel; leaves the rest.
    virtual void mark(const std::vector<double>& lons,
                      const std::vector<double>& lats,
                      std::vector<std::uint8_t>& covered) const = 0;
};

// How the DEMs of a collection rank where they overlap (--priority).
enum class SourcePriority {
    Finest, // the finer resolution wins; equal resolutions keep the order given
    Listed, // the order given (command line, list file or config): the first wins
};
// "finest" | "listed"; InputError naming `what` otherwise.
SourcePriority parse_source_priority(const std::string& text, const std::string& what);
const char* to_string(SourcePriority priority);

// Band 1 of one DEM or of an in-memory VRT mosaic of several, opened for reading from many
// threads: each call borrows a GDAL handle from a small pool (GDAL handles are not
// thread-safe), so a DemSource is safe to share.
class DemSource {
public:
    // `nodata`, when given, replaces every file's nodata value (--nodata). Throws InputError
    // naming the file and problem: no band, complex or RGB(A) data,
    // likely voids not declared as nodata (DemInfo::likely_nodata) while `nodata` is not given;
    // IoError when a file cannot be read.
    // Files of one CRS and one pixel size read as one VRT mosaic (the first given wins where
    // they overlap); several such groups as a collection (collection_source.hpp), ranked by
    // `priority`.
    static std::shared_ptr<const DemSource> open(const std::vector<std::string>& paths,
                                                 std::optional<double> nodata = std::nullopt,
                                                 const ValidRange& range = {},
                                                 SourcePriority priority = SourcePriority::Finest);
    virtual ~DemSource() = default;

    // Description of the (mosaic) raster, as inspect_dem gives it.
    virtual const DemInfo& info() const = 0;
    // True when the CRS is georeferenced (CRS + geotransform): tiles can be made.
    virtual bool georeferenced() const = 0;
    // Lon/lat box of the pixel-centre hull (densified for projected CRSs). Requires
    // georeferenced().
    virtual LonLatBox footprint() const = 0;
    // True when the CRS states that heights are WGS84 ellipsoidal (a 3D geographic CRS, or a
    // compound CRS whose vertical part is ellipsoidal).
    virtual bool ellipsoidal_heights() const = 0;
    // Source pixels per lattice sample at zoom z (geometric mean, at the footprint's centre).
    virtual double pixels_per_sample(Scheme scheme, int z, int size) const = 0;

    // The band and decimation sample() reads at zoom z, from (scheme, z, size) alone: the
    // coarsest overview whose factor (both ways) is at most pixels_per_sample, else band 1;
    // then step = the largest power of two with factor * step <= pixels_per_sample.
    virtual ReadLevel read_level(Scheme scheme, int z, int size) const = 0;

    // Bilinear samples of the source at the lattice points of (scheme, z, size), reading only
    // the window they need of the level read_level() chooses (every step-th pixel of an
    // overview or of band 1, aligned to that band's pixel grid), so the same lattice point
    // gets the same value, bit for bit, whichever block it is read in. Thread-safe.
    virtual LatticeBlock sample(Scheme scheme,
                                int z,
                                int size,
                                std::int64_t column0,
                                std::int64_t row0,
                                int width,
                                int height) const = 0;

    // The source's own pixel grid, when its rows and columns run along the scheme's tile
    // borders: a north-up geotransform without rotation, and a CRS that is WGS84 lon/lat (or a
    // geographic CRS that PROJ maps onto it unchanged, such as NAD83 without a datum grid), for
    // both schemes (mercator tiles are lon/lat boxes too), or EPSG:3857 for mercator.
    // Requires georeferenced().
    virtual std::optional<PixelGrid> pixel_grid(Scheme scheme) const = 0;

    // Pixel coordinates to WGS84 lon/lat, in place: (x[k], y[k]) = (i, j), pixel (i, j)'s centre
    // at integer i and j, through the geotransform and the CRS, whatever they are (a UTM grid,
    // a rotated one). A point that does not transform becomes NaN. Requires georeferenced();
    // not for a collection (its members have pixels). Thread-safe.
    virtual void pixels_to_lonlat(std::vector<double>& x, std::vector<double>& y) const = 0;
    // The inverse: lon/lat to fractional pixel coordinates, NaN where it fails.
    virtual void lonlat_to_pixels(std::vector<double>& x, std::vector<double>& y) const = 0;

    // Band 1 at full resolution over columns [column0, column0 + width) and rows [row0, row0 +
    // height), row-major; NaN where the source has nodata or the window leaves the raster.
    // Thread-safe.
    virtual std::vector<double>
    read_pixels(std::int64_t column0, std::int64_t row0, int width, int height) const = 0;

    // True when GDAL knows, without reading, that every pixel of the window reads as the
    // source's own nodata (unwritten blocks of a sparse GeoTIFF, VRT areas no source covers).
    // False when it does not know, or such pixels would read as a height (no nodata, or a
    // --nodata override). Thread-safe.
    virtual bool
    window_empty(std::int64_t column0, std::int64_t row0, int width, int height) const = 0;

    // Calls `visit` with every valid full-resolution pixel whose centre lies in `box` (closed),
    // its centre transformed to WGS84 lon/lat, row by row; the source holds only a strip of rows
    // at a time. Throws InputError when the window it needs exceeds kMaxPixelsPerTile. Requires
    // georeferenced(). Thread-safe.
    using PixelVisitor = std::function<void(const SourcePixel&)>;
    virtual void pixels_in(const LonLatBox& box, const PixelVisitor& visit) const = 0;
    // At most how many pixels pixels_in(box) visits: the size of the window it reads. Throws
    // as pixels_in does.
    virtual std::size_t window_pixels(const LonLatBox& box) const = 0;
    // Which points of `box` lie in a valid pixel of the source (the full-resolution pixels of
    // pixels_in's window). Throws as pixels_in does. Thread-safe.
    virtual std::unique_ptr<const PixelCoverage> coverage(const LonLatBox& box) const = 0;
    // About how many full-resolution pixels a tile of zoom z reads at most (pixels_in's window):
    // its side in pixels, clipped to the raster. Requires georeferenced().
    virtual double tile_pixels(Scheme scheme, int z, int size) const = 0;
    // Where data as fine as zoom z's lattice or finer lies: the footprint, a mosaic's files'
    // footprints, or for a collection those of the members that go that deep, each file on its
    // own (the pyramid goes as deep as the finest source under each region, and no deeper
    // elsewhere: not over the land between two surveys). Requires georeferenced().
    virtual std::vector<LonLatBox> footprints_at(Scheme, int /*z*/, int /*size*/) const {
        return {footprint()};
    }
    // Overlapping files of a mosaic and how far they differ (measure_overlaps); none for one
    // file. A collection's are its members'.
    virtual std::vector<FileOverlap> overlaps() const { return {}; }
    // The DEMs it reads: itself, or each member of a collection (collection_source.hpp).
    virtual std::vector<const DemInfo*> parts() const { return {&info()}; }
    // A collection's members, ranked (the first wins where they overlap); empty for one DEM or
    // one mosaic.
    virtual std::vector<std::shared_ptr<const DemSource>> members() const { return {}; }

    // The whole band 1 at full resolution, row 0 = first raster row, nodata marked invalid and
    // filled (fill_voids, margin 0). Needs no georeferencing. Throws InputError when every
    // sample is nodata or above 400 Mpixel.
    virtual core::HeightGrid read_all() const = 0;
};

// The source's own deepest zoom: the first whose lattice (tiles of `size` samples) is as fine as
// its pixels, or kMaxZoom when none is.
int native_zoom(const DemSource& source, Scheme scheme, int size);

// A function giving what DemSource::sample gives (a collection's zoom read through its members'
// summaries, say).
using LatticeSampler = std::function<LatticeBlock(Scheme scheme,
                                                  int z,
                                                  int size,
                                                  std::int64_t column0,
                                                  std::int64_t row0,
                                                  int width,
                                                  int height)>;

// The most source pixels one tile reads at full resolution (2048 x 2048). Every zoom meshes or
// checks the full-resolution pixels under a tile, so zooms whose tiles would hold more are not
// offered (see Layer). A tile's memory grows with its mesh, up to about 200 MB for a 0.7
// Mpixel tile of the Andes at its eps, so this keeps a tile, and a build on two threads, within
// a few hundred MB.
inline constexpr double kMaxPixelsPerTile = 4.0 * 1024 * 1024;

// Writes a tile raster as a georeferenced single-band Float32 GeoTIFF (EPSG:4326 or EPSG:3857
// by scheme), the heights exactly as meshed, voids marked by an internal mask band. Written to
// a temporary file next to `path` and renamed. Throws IoError.
void write_tile_raster_tiff(const TileRaster& raster, const std::string& path);

// A float grid read whole with GDAL (the geoid), north-up geotransform.
struct FloatGrid {
    int width = 0, height = 0;
    std::array<double, 6> geotransform{};
    std::vector<float> values;
};
FloatGrid read_float_grid(const std::string& path); // InputError when it cannot be read

// Fills the voids of a `width` x `height` block of heights in place (valid = 0 entries).
// With `margin` > 0 the block is a tile grid plus `margin` extra samples on every side, and
// the fill of every tile sample depends only on samples within `margin` of it, or on the
// tile border line it lies on, so tiles sharing a border fill it identically:
//   1. a void within `margin` (chessboard distance) of valid samples takes the inverse-square
//      distance mean of the valid samples at that distance;
//   2. a tile corner still void takes `fallback` (sea level);
//   3. border samples still void interpolate linearly along their border between filled ones;
//   4. interior voids take the mean of filled neighbours, ring by ring from the filled ones.
// With margin 0 (a whole raster), steps 2 and 3 are skipped and step 4 covers the border too;
// a block with no valid sample at all is set to `fallback`.
void fill_voids(std::vector<double>& heights,
                const std::vector<std::uint8_t>& valid,
                int width,
                int height,
                int margin,
                double fallback);

} // namespace tb::tiler
