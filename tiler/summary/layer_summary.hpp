#pragma once
// The DEM's summary as a layer uses it: kept on disk between runs (summary_file.hpp), else made.
#include "tiler/layer.hpp"
#include "tiler/sources/gdal_source.hpp"
#include "tiler/summary/dem_summary.hpp"

namespace tb::tiler {

// The summary of a source kept on disk for this source and these settings
// (options.summary_dir, nodata; `files`: the source's files; datum: the layer's, resolved),
// else made, and kept where options.summary_dir allows. Throws like DemSummary::build.
DemSummary load_or_make_summary(const LayerOptions& options,
                                const std::vector<std::string>& files,
                                const DemSource& source,
                                const PixelPlace& place,
                                VerticalDatum datum);

} // namespace tb::tiler
