#pragma once
// Lu & Yun §3.2 "Error Scan": the samples a triangle answers for, and their errors.
#include <cstdint>

#include "core/mesh.hpp"
#include "core/triangulate.hpp"

namespace tb::core {

// What one triangle knows about its samples (valid samples only; vertices excluded, their
// error is exactly 0).
struct TriangleStats {
    std::int64_t error_points = 0;  // samples with |mesh - height| > eps
    std::int64_t samples = 0;       // valid samples owned
    double total_error = 0.0;       // sum of |mesh - height|
    double worst_error = 0.0;       // largest |mesh - height|
    std::int64_t worst_sample = -1; // its index y * width + x (lowest index on ties), or -1
};

// The one ownership rule: a sample on an edge a -> b of a triangle belongs to that triangle
// when the edge lies on the grid boundary or when a comes before b in raster order; its twin
// (b -> a) then excludes it, so every non-vertex sample has exactly one owner. Vertices belong
// to no triangle. Both neighbours compute the same error for an edge sample anyway (lerp_edge).
bool owns_edge_samples(GridPoint a, GridPoint b, int width, int height);

// Scans the counter-clockwise triangle (a, b, c) with heights za, zb, zc over the samples it
// owns. Stops early, with partial stats, once error_points reaches stop_at. With stride > 1
// only the samples with x and y multiples of stride are visited (a cheap estimate whose error
// points are still real error points). Cost O(samples visited + rows spanned).
TriangleStats scan_triangle(const HeightGrid& grid,
                            double eps,
                            GridPoint a,
                            GridPoint b,
                            GridPoint c,
                            std::int64_t stop_at = INT64_MAX,
                            int stride = 1);

} // namespace tb::core
