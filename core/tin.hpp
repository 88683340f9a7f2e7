#pragma once
// The working triangulation of the mesher: an index-based half-edge mesh (delaunator layout)
// with a free list of triangles, a vertex -> outgoing half-edge map, and the local operations
// of Lu & Yun §3.3-3.4 (split a triangle, split an edge, swap a diagonal, replace a fan).
#include <array>
#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "core/memory.hpp"
#include "core/mesh.hpp"

namespace tb::core {

struct Tin {
    LargeVector<GridPoint> points;  // vertex v
    LargeVector<Index> triangles;   // half-edge e -> start vertex; kNone for a freed triangle
    LargeVector<Index> halfedges;   // twin of e, or kNone on the border
    LargeVector<Index> vertex_edge; // vertex v -> a half-edge starting at v; kNone if removed
    std::vector<Index> free_triangles;

    // The rectangle [0,w-1] x [0,h-1] as two triangles; vertices 0..3 are its corners.
    static Tin rectangle(int width, int height);

    std::size_t triangle_slots() const { return triangles.size() / 3; }
    bool alive(Index t) const { return triangles[3 * t] != kNone; }
    GridPoint start(Index e) const { return points[triangles[e]]; }

    Index add_point(GridPoint p);

    // Room for `vertices` vertices and twice as many triangles without moving any array
    // (memory.hpp): growth then neither copies nor moves to fresh memory.
    void reserve(std::size_t vertices);

    // Splits triangle t by the new vertex p lying strictly inside it. Writes the three
    // triangles around p (t reused first) to out.
    void split_triangle(Index t, Index p, std::array<Index, 4>& out);

    // Splits the edge e (and its twin's triangle, if any) at the new vertex p lying strictly
    // inside the edge. Writes the 2 or 4 triangles around p to out; returns their count.
    int split_edge(Index e, Index p, std::array<Index, 4>& out);

    // Swaps the diagonal of the quadrilateral formed by e's triangle and its twin's.
    // Contract: e has a twin and the quadrilateral is strictly convex. Afterwards e's triangle
    // is (r, p, s) and the twin's (s, q, r), where e was p -> q with third vertex r and the
    // twin's third vertex was s; returns the half-edge s -> r of the first.
    Index flip(Index e);

    // Removes triangle t (its twins must already be relinked or freed too).
    void free_triangle(Index t);
    Index add_triangle(Index a, Index b, Index c);
    // The same two without the free list, for a caller that keeps its own free slots: clear
    // marks t removed, fill makes the counter-clockwise (a, b, c) of the removed slot t.
    void clear_triangle(Index t);
    void fill_triangle(Index t, Index a, Index b, Index c);
    void link(Index e, Index f) {
        halfedges[e] = f;
        if (f != kNone) {
            halfedges[f] = e;
        }
    }
    // Points vertex_edge of the triangle's three vertices at its half-edges.
    void touch(Index t) {
        for (Index e = 3 * t; e < 3 * t + 3; ++e) {
            vertex_edge[triangles[e]] = e;
        }
    }

    // The outgoing half-edges of v in counter-clockwise order; for a vertex on the border the
    // first one is the border edge leaving v (its twin is kNone).
    void ring(Index v, std::vector<Index>& out) const;
    bool on_border(Index v) const;

    // Renumbers the live vertices and triangles along a Z-order curve (removed ones dropped,
    // free list emptied), so that neighbours in the plane are neighbours in memory. In place:
    // the arrays keep their capacity. swap_also(a, b) is called whenever the triangles in
    // slots a and b trade places, so that a caller's data per triangle can follow them.
    void compact(const std::function<void(Index, Index)>& swap_also = {});

    // The live triangles in order, with vertices renumbered compactly (removed ones dropped).
    Mesh to_mesh(const std::vector<float>& heights, int width) const;
};

// Position of p on the Z-order (Morton) curve: a locality-preserving order for ties.
std::uint64_t z_order_key(GridPoint p);

} // namespace tb::core
