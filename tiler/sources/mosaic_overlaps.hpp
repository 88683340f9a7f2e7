#pragma once
// Where files of one mosaic overlap, how far their heights differ: the first given wins there,
// so a user whose files disagree learns which one the tiles show.
#include "tiler/sources/gdal_source.hpp"

#include <vector>

namespace tb::tiler {

// Every pair of `files` (one grid: one CRS and pixel size, no rotation) whose pixels overlap
// (an area, not an edge), with the largest height difference over the pixels valid in both
// (heights as to_height gives them). An overlap larger than kMaxOverlapPixels is compared on a
// regular subset of its pixels (GDAL's nearest-pixel decimation, the same pixels of both), so
// its difference may be an underestimate. Pairs are found through the files sorted by column,
// so thousands of files that only touch cost no reads. IoError when a file cannot be read.
std::vector<FileOverlap> measure_overlaps(const std::vector<const FileScan*>& files);

inline constexpr double kMaxOverlapPixels = 1024.0 * 1024.0;

} // namespace tb::tiler
