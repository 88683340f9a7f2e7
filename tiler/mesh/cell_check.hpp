#pragma once
// Judging a drawn tile against blocks of source pixels it does not read one by one.
//
// A coarse tile is meshed from far fewer samples than the source has pixels under it (see
// tiler/summary/dem_summary.hpp). Its published error must still bound the distance from the
// drawn surface to every valid source pixel. A block of pixels is summarised by a reference
// plane R and a half-range: every valid pixel p of the block lies within `half` of R(p). For a
// pixel p in a drawn triangle T,
//     |T(p) - h(p)| <= |T(p) - R(p)| + |R(p) - h(p)| <= |T(p) - R(p)| + half,
// and T - R is linear, so over the part of the block's box that T covers (a convex polygon: the
// box clipped by T) its largest magnitude is reached at a corner of that polygon. Evaluating
// those corners for every (triangle, block) pair that meet bounds every pixel of every block,
// whatever the triangles' shapes, without reading a pixel.
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tb::tiler {

// A block of valid source pixels, in the tile raster's grid coordinates (column, row).
struct CheckCell {
    // The box holding every valid pixel centre of the block: x0 <= x1, y0 <= y1 (a box may be
    // flat, or a single point).
    double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    // The reference height at (x0, y0), ellipsoidal metres, and its slope per column and per row.
    double height = 0, per_column = 0, per_row = 0;
    // Every valid pixel of the block lies within `half` metres of the reference plane.
    double half = 0;
    double reference(double x, double y) const {
        return height + per_column * (x - x0) + per_row * (y - y0);
    }
};

// A drawn surface: vertices as (column, row, height) in the same grid coordinates, triangles as
// vertex index triples (either winding).
struct GridSurface {
    const std::vector<std::array<double, 3>>& vertices;
    const std::vector<std::uint32_t>& triangles;
};

struct CellsVerdict {
    double error = 0; // the largest bound over the blocks, metres (0 with no cell drawn over)
    // Blocks no drawn triangle meets at all (they lie where the tile draws nothing).
    std::size_t outside = 0;
};

// The bound above, over every cell and every triangle meeting it: for each pixel of a cell that
// lies in a drawn triangle, |drawn - pixel| <= verdict.error (in grid-linear interpolation; a
// caller adds the chord sag). Pixels of a cell that no triangle covers are not bounded (a cell
// straddling the edge of the drawn area): `outside` counts only cells no triangle meets.
CellsVerdict cells_error(const GridSurface& surface, const std::vector<CheckCell>& cells);

} // namespace tb::tiler
