#pragma once
// Lu & Yun §3.3-3.4: the split agent and the merge agent working on one triangulation. The
// class guards the invariant that stats_[t] is the error scan of every live triangle t and that
// every live triangle with error points has a current entry in the split queue.
#include <cstdint>
#include <queue>
#include <utility>
#include <vector>

#include "core/error_scan.hpp"
#include "core/polygon_dp.hpp"
#include "core/split_queue.hpp"
#include "core/tin.hpp"
#include "core/triangulate.hpp"

namespace tb::core {

// How much the merge agent tries per vertex (triangulate() picks it by TriangulateOptions::effort).
struct MergeLimits {
    // Holes with more vertices are left alone: the dynamic program is cubic in the hole's size.
    // A hole around an interior vertex has as many vertices as the vertex has neighbours.
    std::size_t max_hole = 24;
    // Runs of the dynamic program per vertex: each re-run follows a chosen triangle that failed
    // its full scan (the program works on estimates, see merge.cpp).
    int max_attempts = 6;
    // Threads a pass may use on a big grid (1 or 2; see merge_pass). The mesh is the same
    // for either value.
    int threads = 2;
};

class Refiner {
public:
    // Room reserved for the split agent's vertices, as a multiple of the start's. The split
    // agent ends with 1.6-2.6 times the anchors on bench/mesh_bench.sh's cases; beyond the
    // room the arrays grow as vectors do.
    static constexpr std::size_t kGrowth = 4;

    // Takes the initial triangulation (§3.1) and scans every triangle. grid must outlive the
    // refiner (it is kept by reference); eps > 0; max_edge 0 (no limit) or >= kMinMaxEdge,
    // and with lock_border the border edges of tin already within max_edge. threads (1 or 2):
    // on a grid of kTwoThreadSamples or more, the scan of the start's triangles is split in
    // two halves on two threads (the same stats either way).
    Refiner(const HeightGrid& grid,
            double eps,
            bool lock_border,
            double max_edge,
            Tin tin,
            int threads = 1);

    // The split agent (split.cpp): while some valid sample is over eps, insert the worst sample
    // of the triangle with the most error points and swap diagonals around it. When none is,
    // the globally longest edge over max_edge is split at the lattice sample nearest its
    // midpoint (or swapped away when no sample is left near it). On return error_points() == 0
    // and no edge is longer than max_edge. Swaps never create an edge over max_edge.
    void split_until_clean();

    // One pass of the merge agent (merge.cpp) over the vertices, along the Z-order curve (fewer
    // error points around first, when there are any): a vertex is removed when the optimal
    // re-triangulation of its hole has no more error points than its neighbourhood had.
    // Vertices already tried whose neighbourhood has not changed since are skipped, and so are
    // those whose hole is over limits.max_hole. On a grid of kTwoThreadSamples or more, with
    // no error points, the pass first works the two halves left and right of the middle column
    // apart (on two threads when limits.threads is 2): each visits, in the same order, the
    // vertices whose neighbourhood lies wholly on its side, which no removal on the other side
    // can touch; the vertices left over follow. Returns the number of vertices removed.
    std::size_t merge_pass(const MergeLimits& limits = {});

    // Renumbers vertices and triangles along a Z-order curve (Tin::compact) so that the merge
    // agent's walks stay in cache; caches and queue follow. Vertex indices change.
    void compact();

    std::int64_t error_points() const { return error_points_; }
    const Tin& tin() const { return tin_; }

private:
    TriangleStats scan(Index a, Index b, Index c, std::int64_t stop_at = INT64_MAX) const;
    TriangleStats scan(Index t) const;
    void set_stats(Index t, const TriangleStats& st); // also (re)queues t
    void release(Index t);                            // forgets t's stats, frees it
    void swap_around(Index p, std::vector<Index>& stack);
    // Working memory of try_remove, kept to save allocations: one per thread of the merge agent.
    struct MergeWorker {
        std::vector<Index> ring;
        std::vector<Index> poly;
        std::vector<GridPoint> pts;
        std::vector<std::uint8_t> state;
        std::vector<TriangleCost> estimate;
        std::vector<std::pair<std::size_t, TriangleStats>> exact;
        std::vector<std::int64_t> toward_v;
        std::vector<Index> outer;
        std::vector<Index> diagonal;
        PolygonDpScratch dp;
        // With `local` the worker frees triangles into `slots` and takes new ones from there,
        // never from the tin's free list (another worker may be using it): a removal frees more
        // triangles than it adds, so a worker never runs short.
        bool local = false;
        std::vector<Index> slots;
        // Indices into the visit list of the vertices this worker left for later.
        std::vector<std::size_t> deferred;
        std::size_t removed = 0;
    };
    bool try_remove(Index v, MergeWorker& w, const MergeLimits& limits);
    // The vertices merge_pass visits, in its order.
    LargeVector<Index> merge_visit_list();
    // Visits, in order, the vertices of `visit` strictly on one side (side 0: x < cut, 1:
    // x > cut) whose every triangle lies strictly on that side; the others of that side (and,
    // for side 0, those on the cut) go to w.deferred.
    void merge_region(const LargeVector<Index>& visit,
                      int side,
                      int cut,
                      MergeWorker& w,
                      const MergeLimits& limits);
    // Visits visit[i] for every i of `order` (ascending) with the tin's free list.
    void merge_serial(const LargeVector<Index>& visit,
                      const std::vector<std::size_t>* order,
                      MergeWorker& w,
                      const MergeLimits& limits);
    void release(Index t, MergeWorker& w);
    Index add_triangle(Index a, Index b, Index c, MergeWorker& w);
    // Squared length of t's longest edge and that edge (first of equals).
    std::int64_t longest_edge2(Index t, Index& edge) const;
    bool too_long(GridPoint a, GridPoint b) const { // inline: the merge agent asks per triangle
        const std::int64_t dx = b.x - a.x, dy = b.y - a.y;
        return dx * dx + dy * dy > max_edge2_floor_;
    }
    // Removes the over-long edge e (the globally longest edge): see split_until_clean.
    void shorten(Index e, std::vector<Index>& stack);
    void insert_at(Index t, GridPoint q, std::vector<Index>& stack);

    const HeightGrid& grid_;
    double eps_;
    bool lock_border_;
    double max_edge_;
    std::int64_t max_edge2_floor_; // the largest integer squared length <= max_edge^2
    Tin tin_;
    LargeVector<TriangleStats> stats_;
    SplitQueue queue_; // every live triangle with error points
    // Triangles that may have an edge over max_edge: (squared longest edge, -t), longest first.
    // Entries go stale when t changes; a changed triangle is always pushed again.
    std::priority_queue<std::pair<std::int64_t, std::int64_t>> long_queue_;
    std::int64_t error_points_ = 0;
    // Vertex v's neighbourhood changed since the merge agent last failed to remove it.
    LargeVector<std::uint8_t> dirty_;
    MergeWorker workers_[2];
};

} // namespace tb::core
