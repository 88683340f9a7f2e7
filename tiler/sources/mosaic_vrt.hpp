#pragma once
// The VRT that mosaics several DEM files of one grid, written from what one opening of each told
// (FileScan), so that no file is opened again to make it.
#include "tiler/sources/gdal_source.hpp"

#include <string>
#include <vector>

namespace tb::tiler {

// The VRT text of band 1 of `files` (one CRS, pixel sizes within a rounding of each other, no
// rotation): the union of their extents at their mean pixel size (their own when all are equal),
// the first file drawn on top where they overlap, `nodata` (a number or NaN) where none lies.
// A file with a nodata value (its own or --nodata, in its DemInfo) lets the files under it show
// through its voids. Overviews at the factors every file has are read from the files' own. The
// files are opened only when a read needs them.
std::string mosaic_vrt_xml(const std::vector<const FileScan*>& files, double nodata);

// Whether the files share one scale and offset, which the mosaic's band then carries. Otherwise
// the mosaic applies each file's own and holds heights (Float64).
bool shares_scale(const std::vector<const FileScan*>& files);

} // namespace tb::tiler
