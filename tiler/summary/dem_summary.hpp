#pragma once
// The multi-resolution summary of a DEM: what a coarse tile reads instead of the full-resolution
// pixels under it. Its blocks are the source's own pixels, in whatever CRS (pixel_place.hpp).
//
// Level k cuts the source into blocks of 2^k x 2^k pixels (block (bx, by) holds pixel columns
// bx 2^k .. bx 2^k + 2^k - 1, rows likewise, clipped to the raster). Each block keeps a plane
// through its pixels' ellipsoidal heights and the exact range of their residuals against it:
// every valid pixel (i, j) of the block has height in
//     plane(i, j) + [low, high],  plane(i, j) = height + per_column (i - ci) + per_row (j - cj)
// with (ci, cj) the block's first pixel plus (2^k - 1) / 2 both ways, evaluated in double from
// the stored floats. That is the whole promise a coarse tile needs: the lattice it meshes is
// read off the planes, and the drawn tile is judged against each block as a CheckCell
// (tiler/mesh/cell_check.hpp), so its published error holds at every valid pixel.
//
// Level kFinestLevel is fitted to the pixels (least squares, then the exact residual range);
// each coarser level is fitted to its four children's planes, and its range is made from
// theirs: child plane minus parent plane is linear over the child's box, so its extremes at the
// box's corners plus the child's range bound every pixel of the child. The ranges are rounded
// outward to float. Made in one pass over the source, a window of rows and columns at a time
// (windows GDAL reports empty, as in sparse files, are not read).
#include "tiler/layer.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/sources/geoid.hpp"
#include "tiler/summary/pixel_place.hpp"

#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace tb::tiler {

struct SummaryBlock {
    float height = 0, per_column = 0, per_row = 0; // the plane at the block's centre
    float low = 0, high = 0;                       // residual range; low > high: no valid pixel
    bool empty() const { return !(low <= high); }
};

// The finest level kept: 8 x 8 pixel blocks, 20 bytes per 64 pixels (65 MB for 207 Mpixel).
// Coarser zooms than that read the summary; finer ones read the pixels themselves.
inline constexpr int kFinestLevel = 3;
// Sources whose finest level would hold more blocks than this (over 537 Mpixel) start at a
// coarser level instead, so that the summary's memory stays under about 220 MB whatever the
// source's size (a 100000^2 raster: level 6, 2.4 M blocks).
inline constexpr std::int64_t kMaxFinestBlocks = std::int64_t{1} << 23;

// The finest level of a width x height source's summary: kFinestLevel, or the first coarser one
// within kMaxFinestBlocks.
int summary_finest_level(std::int64_t width, std::int64_t height);

class DemSummary {
public:
    // Reads every pixel of `source` once, in strips, converting heights to the WGS84 ellipsoid
    // (`datum`: Egm96 adds the EGM96 undulation at each pixel centre, `place` saying where that
    // is), and logs its progress.
    static DemSummary build(const DemSource& source, const PixelPlace& place, VerticalDatum datum);

    int width() const { return width_; } // the source's pixels
    int height() const { return height_; }
    int finest_level() const { return finest_; }
    int coarsest_level() const { return finest_ + static_cast<int>(levels_.size()) - 1; }
    std::int64_t blocks_across(int level) const;
    std::int64_t blocks_down(int level) const;
    // The block, or nullptr outside the raster; level in finest_level()..coarsest_level().
    const SummaryBlock* block(int level, std::int64_t bx, std::int64_t by) const;
    // The block's centre (ci, cj) in pixel coordinates, and its pixel range (inclusive).
    static double centre(int level, std::int64_t b) {
        return static_cast<double>(b) * std::exp2(level) + (std::exp2(level) - 1) / 2;
    }
    std::int64_t last_column(int level, std::int64_t bx) const;
    std::int64_t last_row(int level, std::int64_t by) const;

    // The plane of a block at pixel coordinates (i, j), as the ranges were computed.
    static double
    plane(const SummaryBlock& b, int level, std::int64_t bx, std::int64_t by, double i, double j) {
        return static_cast<double>(b.height) +
               static_cast<double>(b.per_column) * (i - centre(level, bx)) +
               static_cast<double>(b.per_row) * (j - centre(level, by));
    }

    std::size_t bytes() const; // memory held

    // Every level's blocks, finest first, each row-major (what summary_file.hpp stores).
    const std::vector<std::vector<SummaryBlock>>& levels() const { return levels_; }
    // A summary of a width x height source from stored levels; nullopt unless they have the
    // shape build() gives: levels from the finest up to the first of one block, each
    // blocks_across x blocks_down blocks.
    static std::optional<DemSummary>
    from_levels(int width, int height, std::vector<std::vector<SummaryBlock>> levels);

    // Reads the window of the source's columns column0.. (width of them) and rows row0..
    // (height) and fits the finest level's blocks in it (both a multiple of the blocks' side
    // away from 0); skipped when GDAL knows the window holds no data (sparse files).
    void fit_window(const DemSource& source,
                    const PixelPlace& place,
                    const std::vector<Egm96Column>& undulation_columns,
                    VerticalDatum datum,
                    std::int64_t column0,
                    std::int64_t row0,
                    int width,
                    int height);

private:
    SummaryBlock fit_children(int level, std::int64_t bx, std::int64_t by) const;

    int width_ = 0, height_ = 0;
    int finest_ = kFinestLevel;
    std::vector<std::vector<SummaryBlock>> levels_; // levels_[k - finest_], row-major
};

} // namespace tb::tiler
