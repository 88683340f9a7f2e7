#include "tiler/sources/mosaic_overlaps.hpp"

#include "core/error.hpp"

#include <gdal_priv.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <string>

namespace tb::tiler {
namespace {

// A file's pixels as a window of the first file's grid.
struct Window {
    const FileScan* file = nullptr;
    std::int64_t col = 0, row = 0, width = 0, height = 0;
};

Window window_of(const FileScan& f, const std::array<double, 6>& first) {
    const auto& g = f.info.geotransform;
    return Window{&f,
                  std::llround((g[0] - first[0]) / first[1]),
                  std::llround((g[3] - first[3]) / first[5]),
                  f.info.width,
                  f.info.height};
}

// Heights of a window of band 1 of `f` (NaN for nodata), read into a w x h buffer.
std::vector<double> read_heights(
    const FileScan& f, std::int64_t col, std::int64_t row, int cols, int rows, int w, int h) {
    const DemInfo& info = f.info;
    GDALDatasetUniquePtr ds(GDALDataset::Open(
        info.path.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr, nullptr, nullptr));
    if (!ds) {
        throw IoError(info.path + ": cannot be reopened to compare it with the files it overlaps");
    }
    GDALRasterBand* band = ds->GetRasterBand(1);
    std::vector<double> v(static_cast<std::size_t>(w) * h);
    if (band->RasterIO(GF_Read,
                       static_cast<int>(col),
                       static_cast<int>(row),
                       cols,
                       rows,
                       v.data(),
                       w,
                       h,
                       GDT_Float64,
                       0,
                       0,
                       nullptr) != CE_None) {
        throw IoError(info.path + ": cannot read the part it shares with another file");
    }
    const bool float32 = band->GetRasterDataType() == GDT_Float32;
    for (double& x : v) {
        x = to_height(x, info.nodata, float32, info.scale, info.offset, info.valid_range);
    }
    return v;
}

// The pair's overlap, compared (pixels 0 when they only touch or share no valid pixel).
FileOverlap compare(const Window& a, const Window& b) {
    const std::int64_t c0 = std::max(a.col, b.col), c1 = std::min(a.col + a.width, b.col + b.width);
    const std::int64_t r0 = std::max(a.row, b.row),
                       r1 = std::min(a.row + a.height, b.row + b.height);
    FileOverlap out{a.file->info.path, b.file->info.path, 0, 0.0};
    if (c1 <= c0 || r1 <= r0) {
        return out;
    }
    const int cols = static_cast<int>(c1 - c0), rows = static_cast<int>(r1 - r0);
    const double scale = std::min(1.0, std::sqrt(kMaxOverlapPixels / (double(cols) * rows)));
    const int w = std::max(1, static_cast<int>(cols * scale)),
              h = std::max(1, static_cast<int>(rows * scale));
    const std::vector<double> ha = read_heights(*a.file, c0 - a.col, r0 - a.row, cols, rows, w, h);
    const std::vector<double> hb = read_heights(*b.file, c0 - b.col, r0 - b.row, cols, rows, w, h);
    for (std::size_t k = 0; k < ha.size(); ++k) {
        if (std::isfinite(ha[k]) && std::isfinite(hb[k])) {
            ++out.pixels;
            out.max_diff = std::max(out.max_diff, std::abs(ha[k] - hb[k]));
        }
    }
    return out;
}

} // namespace

std::vector<FileOverlap> measure_overlaps(const std::vector<const FileScan*>& files) {
    if (files.size() < 2) {
        return {};
    }
    const std::array<double, 6> first = files.front()->info.geotransform;
    std::vector<Window> by_col;
    for (const FileScan* f : files) {
        by_col.push_back(window_of(*f, first));
    }
    std::vector<std::size_t> order(files.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    std::sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) {
        return by_col[i].col < by_col[j].col || (by_col[i].col == by_col[j].col && i < j);
    });
    std::vector<FileOverlap> out;
    for (std::size_t p = 0; p < order.size(); ++p) {
        const Window& a = by_col[order[p]];
        for (std::size_t q = p + 1; q < order.size(); ++q) {
            const Window& b = by_col[order[q]];
            if (b.col >= a.col + a.width) {
                break;
            }
            if (b.row >= a.row + a.height || a.row >= b.row + b.height) {
                continue;
            }
            // The file given first (the one that wins) first.
            FileOverlap o = order[p] < order[q] ? compare(a, b) : compare(b, a);
            if (o.pixels > 0) {
                out.push_back(std::move(o));
            }
        }
    }
    return out;
}

} // namespace tb::tiler
