#pragma once
// The multi-resolution summary of a DEM whose pixels lie on a tiling scheme's grid: what a
// coarse tile reads instead of the full-resolution pixels under it.
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
// outward to float. Made in one pass over the source, a strip of 2^kFinestLevel rows at a time.
#include "tiler/layer.hpp"
#include "tiler/sources/gdal_source.hpp"

#include <cmath>
#include <cstdint>
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

class DemSummary {
public:
    // Reads every pixel of `source` once, in strips, converting heights to the WGS84 ellipsoid
    // (`datum`: Egm96 adds the EGM96 undulation at each pixel centre), and logs its progress.
    static DemSummary build(const DemSource& source, const PixelGrid& grid, VerticalDatum datum);

    int width() const { return width_; } // the source's pixels
    int height() const { return height_; }
    int finest_level() const { return kFinestLevel; }
    int coarsest_level() const { return kFinestLevel + static_cast<int>(levels_.size()) - 1; }
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

private:
    SummaryBlock fit_children(int level, std::int64_t bx, std::int64_t by) const;
    static double lon_of(const PixelGrid& grid, std::int64_t i, std::int64_t j);
    static double lat_of(const PixelGrid& grid, std::int64_t i, std::int64_t j);

    int width_ = 0, height_ = 0;
    std::vector<std::vector<SummaryBlock>> levels_; // levels_[k - kFinestLevel], row-major
};

} // namespace tb::tiler
