#pragma once
// The single entry point of the mesher: Lu & Yun's L-infinity split-merge triangulation.
#include <functional>
#include <string_view>

#include "core/mesh.hpp"

namespace tb::core {

// How hard the mesher works for fewer triangles. Every level keeps every valid sample within
// eps, gives the same locked border vertices (the border fits do not depend on it) and is
// deterministic; the levels differ in the merge agent's work and the interior scan lines.
//   Best:     the paper's split-merge in full (merge passes until none removes a vertex, at
//             most 4; holes of up to 24 vertices).
//   Balanced: one merge pass over the vertices of degree <= 8: 3-11 % more triangles than
//             Best for 15-20 % less work on the bench cases.
//   Fast:     the interior scan lines' greedy chains as anchors (O(samples) each), then one
//             merge pass over the vertices of degree <= 5 only, one dynamic program each.
// The measured curve (triangles against time, against hmm and delatin) is in bench/README.md,
// "Effort levels".
enum class Effort { Fast, Balanced, Best };

// "fast", "balanced" or "best" (exactly, lower case); anything else throws tb::InputError
// naming the value and the three choices.
Effort parse_effort(std::string_view name);
// The name parse_effort reads: "fast", "balanced" or "best".
const char* to_string(Effort effort);

struct TriangulateOptions {
    double eps = 1.0;        // vertical bound, same unit as the heights; > 0 and finite
    bool lock_border = true; // border vertices = optimal 1-D fit of each border (crack-free tiles)
    // Longest edge allowed, Euclidean length in (column, row) units; 0 = no limit. Otherwise at
    // least kMinMaxEdge: every lattice triangle has an edge of length >= sqrt(2), and above 1.5
    // an over-long edge can always be split or swapped away. With lock_border the border
    // vertices are the optimal 1-D fit with segments of at most floor(max_edge) samples, still
    // a pure function of the border's samples, eps and max_edge.
    double max_edge = 0.0;
    // Whether the mesh's error is measured at every sample before it is returned (max_error;
    // over eps throws). The tiling check (check_mesh) runs either way. Off only for callers that
    // measure every valid sample against what they publish themselves: the tiler's encoders
    // judge the drawn, quantized surface, and this pass would only repeat them on the exact one
    // (7 % of the time of a cold server tile). Either way the bound holds by construction: the
    // split agent stops when no sample is over eps, and the merge agent removes a vertex only
    // when full scans of its new triangles find none.
    bool check_error = true;
    // Whether the mesher's arrays of 2 MiB and more take transparent huge pages (memory.hpp):
    // fewer page faults for one large mesh (fuji-513 eps 6: 5-7 % of its time on a virtual
    // machine), but up to 2 MiB unused at the end of each array. Off for many small meshes at
    // once: the tiler's strips, where it raised the peak memory of `build` by a quarter.
    bool huge_pages = true;
    // Best by default: the paper's full merge for a caller that does not say. The tiler chooses
    // the level (its config key `effort`, Balanced by default) and records it with the tiles it
    // publishes.
    Effort effort = Effort::Best;
    // Threads the mesher may use (1 or 2). On a grid of 2^18 samples or more (never a 257 x 257
    // tile) the scan lines' fits, the first error scan and the final error check split their
    // work in two, and each merge pass first works the halves left and right of the middle
    // column apart: on two threads when this is 2, one after the other when 1. The mesh is the
    // same either way, bit for bit.
    int threads = 2;
};

inline constexpr double kMinMaxEdge = 1.5;

// Where one triangulate() call spent its time, phase by phase (wall milliseconds, steady
// clock), and what each phase left: for benchmarks (bench/mesh_bench --phases).
struct TriangulatePhases {
    double anchors_ms = 0.0;    // §3.1: the 1-D fits of the borders and scan lines
    double start_ms = 0.0;      // the anchors' Delaunay triangulation and its renumbering
    double first_scan_ms = 0.0; // the error scan of every start triangle
    double split_ms = 0.0;      // the split agent's first round, from the start mesh
    double resplit_ms = 0.0;    // its rounds after each merge pass
    double renumber_ms = 0.0;   // the renumbering before the merge agent
    double merge_ms = 0.0;      // the merge agent, every pass
    double finish_ms = 0.0;     // the mesh out, its tiling and error checks
    std::size_t anchors = 0;
    std::size_t split_triangles = 0; // when the split agent first ends, before any merge
    std::size_t merge_passes = 0;
    std::size_t removed = 0; // vertices the merge agent removed
    double total_ms() const {
        return anchors_ms + start_ms + first_scan_ms + split_ms + resplit_ms + renumber_ms +
               merge_ms + finish_ms;
    }
};

// Contract: grid is at least 2x2, heights finite wherever valid (and finite everywhere: callers
// fill nodata before meshing), eps > 0 and finite; otherwise throws tb::InputError naming the
// problem. On return every valid sample lies within eps of the mesh (checked exactly unless
// options.check_error is off; a violation throws tb::Error), the triangles tile the rectangle
// exactly once, counter-clockwise, with no T-junction, every edge is at most options.max_edge
// long (when > 0; max_edge finite and 0 or >= kMinMaxEdge, else InputError), and the result is
// deterministic bit for bit.
// When phases is given it is filled; the mesh is the same either way.
Mesh triangulate(const HeightGrid& grid,
                 const TriangulateOptions& options,
                 TriangulatePhases* phases = nullptr);

// Throws tb::InputError naming the problem when triangulate() would refuse grid or options.
void check_input(const HeightGrid& grid, const TriangulateOptions& options);

// The same guarantee, with the grid cut into `strips` vertical strips of nearly equal width
// that share their cut columns, each meshed by triangulate() on its own thread, then stitched.
// A cut column is a locked border of both strips it separates, so both give it the same
// vertices (the optimal 1-D fit of that column), exactly as two neighbouring tiles share a
// border: the stitched mesh is conforming. The strips cost a few triangles along the cuts
// (0.1-0.7 % for two strips of a 257 x 257 tile) and divide the wall time by up to `strips`
// on as many cores. The result depends on grid, options and strips alone, never on thread
// timing. Meshes the grid whole when options.lock_border is off (the cuts must be locked) or
// when strips of at least kMinStripColumns columns do not fit. `threads` (>= 1) caps the threads
// used, the calling one included (1: the strips one after the other, on this thread); 0 gives
// each strip its own. The mesh is the same for any value. The other threads' strips go to
// `run_elsewhere` when given (it must run each job it gets, once, on some other thread: the
// caller's long-lived helpers), else each to a thread of its own (std::async).
using RunElsewhere = std::function<void(std::function<void()>)>;
Mesh triangulate_strips(const HeightGrid& grid,
                        const TriangulateOptions& options,
                        int strips,
                        int threads = 0,
                        const RunElsewhere& run_elsewhere = {});

inline constexpr int kMinStripColumns = 33;

// Largest |mesh - height| over the valid samples, by exact point location (the guarantee check).
// With threads = 2 the triangles are judged in two halves on two threads (the same result).
double max_error(const Mesh& mesh, const HeightGrid& grid, int threads = 1);

// Verifies twin symmetry, CCW orientation, no zero-area triangle, border edges on the grid
// boundary, and that the triangles' total area equals (W-1)(H-1). Throws tb::Error on failure.
void check_mesh(const Mesh& mesh, int width, int height);

// Length of the longest triangle edge, in (column, row) units (0 for an empty mesh).
double longest_edge(const Mesh& mesh);

} // namespace tb::core
