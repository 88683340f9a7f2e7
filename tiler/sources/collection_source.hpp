#pragma once
// A collection of DEMs read as one source, each keeping its own resolution and CRS: a 1 m lidar
// block in UTM over 30 m geographic SRTM, say. Members are ranked; at each point the first
// member with a valid pixel there wins, and the ones below fill its voids.
//
// What a point's "truth" is decides the promise: a member's pixel counts (pixels_in) only where
// no higher member has a valid pixel whose area holds its centre (PixelCoverage). The lattice a
// tile meshes takes, at each point, the first member whose sample there is valid, so it follows
// the same member almost everywhere; where the two rules part (within a pixel of a member's edge
// or void), a tile's published error is measured against the truth pixels, so it stays honest.
//
// Members never form one resampled raster: no pixel grid (pixel_grid() is nullopt) and no
// whole-band access (read_pixels, read_all).
#include "tiler/sources/gdal_source.hpp"

#include <memory>
#include <vector>

namespace tb::tiler {

// `members` in the order given, ranked by `priority` (first wins). At least two, each
// georeferenced, all with the same kind of height (ellipsoidal or not); InputError otherwise.
std::shared_ptr<const DemSource>
make_collection_source(std::vector<std::shared_ptr<const DemSource>> members,
                       SourcePriority priority);

} // namespace tb::tiler
