#pragma once
// Lu & Yun §3.1: the Delaunay triangulation of the anchor points, with exact predicates.
#include <vector>

#include "core/tin.hpp"

namespace tb::core {

// Where a point lies relative to the triangulation.
struct Location {
    enum Kind { kInside, kOnEdge, kVertex } kind;
    Index where; // triangle (kInside), half-edge (kOnEdge) or vertex (kVertex)
};

// Walks from triangle `start` to the triangle containing p (which must lie in the rectangle).
// Exact; terminates on Delaunay triangulations (the visibility walk).
Location locate(const Tin& tin, GridPoint p, Index start);

// Delaunay triangulation of the rectangle [0,w-1] x [0,h-1] with the given grid points as
// vertices (the four corners are added if missing; duplicates are ignored). Built by
// incremental insertion from the two-triangle rectangle: a point on an edge splits that edge
// (and its neighbour), then Lawson flips restore the empty-circle property. Cocircular points
// keep whatever diagonal they have, so the result is one of the Delaunay triangulations and is
// deterministic for a given input order. Every triangle has positive area; the border is
// exactly the rectangle. The result's arrays have room for `room` vertices (Tin::reserve), at
// least for its own.
Tin delaunay_rectangle(int width,
                       int height,
                       const std::vector<GridPoint>& points,
                       std::size_t room = 0);

} // namespace tb::core
