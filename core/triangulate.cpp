// Lu & Yun, "Optimizing Triangular Mesh Generation from Range Images": the split-merge
// algorithm end to end (§3): anchor points by 1-D optimal fits (§3.1), their Delaunay
// triangulation, then the split agent (§3.3) and the merge agent (§3.4) alternate until no
// valid sample is over eps and no vertex can be removed (Effort::Best; the other levels bound
// the merge agent's work). Ends with the exact guarantee check.
#include "core/triangulate.hpp"

#include <chrono>
#include <cmath>
#include <sstream>
#include <string>
#include <utility>

#include "core/breakpoints.hpp"
#include "core/delaunay.hpp"
#include "core/error.hpp"
#include "core/memory.hpp"
#include "core/refiner.hpp"
#include "core/two_threads.hpp"

namespace tb::core {
namespace {

// What each effort level runs after the anchors' triangulation (see Effort; the figures are
// from bench/mesh_bench.sh and valgrind instruction counts of triangulate(), 2026-12-04).
struct Plan {
    // Merge passes after the first clean split (at least 1: the split agent's mesh alone is
    // over hmm's triangles at coarse eps); each later pass finds fewer removable vertices.
    int merge_rounds;
    MergeLimits merge;
    // anchor_points' greedy_lines: the interior scan lines' greedy chains, O(samples) each.
    bool greedy_lines = false;
};

Plan plan_for(Effort effort) {
    switch (effort) {
    case Effort::Fast:
        // The interior scan lines' greedy chains (the optimal fits cost O(samples * reach): a
        // fifth of the instructions at fuji-513 eps 50; the greedy start even ends with fewer
        // triangles, bench/README.md 2026-12-05). One pass over the vertices of degree <= 5
        // with one dynamic program each: it removes most of what a full pass removes at a
        // fraction of its cost, and takes every bench case under hmm's triangles.
        return {1, MergeLimits{.max_hole = 5, .max_attempts = 1}, true};
    case Effort::Balanced:
        // One merge pass over the vertices of degree <= 8. The knee of the curve: in
        // instructions per triangle removed (fuji-513 eps 6), degree 6 after Fast's pass costs
        // 15 k, degrees 7-8 41 k, the larger holes of the same pass 137 k and Best's later passes
        // 107 k. 3-11 % more triangles than Best for 15-20 % fewer instructions.
        return {1, MergeLimits{.max_hole = 8, .max_attempts = 6}};
    case Effort::Best:
        break;
    }
    return {4, MergeLimits{}};
}

using Clock = std::chrono::steady_clock;

std::string number(double v) {
    std::ostringstream s;
    s.precision(17);
    s << v;
    return s.str();
}

} // namespace

Effort parse_effort(std::string_view name) {
    for (const Effort effort : {Effort::Fast, Effort::Balanced, Effort::Best}) {
        if (name == to_string(effort)) {
            return effort;
        }
    }
    throw InputError("effort \"" + std::string(name) +
                     "\" is not a level: expected fast, balanced or best");
}

const char* to_string(Effort effort) {
    switch (effort) {
    case Effort::Fast:
        return "fast";
    case Effort::Balanced:
        return "balanced";
    case Effort::Best:
        return "best";
    }
    TB_ASSERT(false);
    return "best";
}

void check_input(const HeightGrid& grid, const TriangulateOptions& options) {
    if (grid.width < 2 || grid.height < 2) {
        throw InputError("grid is " + std::to_string(grid.width) + "x" +
                         std::to_string(grid.height) + ": needs at least 2x2 samples");
    }
    if (grid.width > (1 << 20) || grid.height > (1 << 20)) {
        throw InputError("grid is " + std::to_string(grid.width) + "x" +
                         std::to_string(grid.height) + ": at most 1048576 samples per side");
    }
    const std::size_t n = static_cast<std::size_t>(grid.width) * grid.height;
    if (grid.heights.size() != n) {
        throw InputError("grid is " + std::to_string(grid.width) + "x" +
                         std::to_string(grid.height) + " but has " +
                         std::to_string(grid.heights.size()) + " heights, expected " +
                         std::to_string(n));
    }
    if (!grid.valid.empty() && grid.valid.size() != n) {
        throw InputError("validity mask has " + std::to_string(grid.valid.size()) +
                         " entries, expected " + std::to_string(n) + " (or none)");
    }
    for (std::size_t i = 0; i < n; ++i) {
        if (!std::isfinite(grid.heights[i])) {
            const bool valid = grid.valid.empty() || grid.valid[i] != 0;
            throw InputError(
                std::string("height is not finite at ") + (valid ? "valid" : "nodata") +
                " sample x=" + std::to_string(i % static_cast<std::size_t>(grid.width)) +
                " y=" + std::to_string(i / static_cast<std::size_t>(grid.width)) +
                (valid ? "; mark it nodata and fill it before meshing"
                       : "; fill nodata samples with finite heights before meshing"));
        }
    }
    if (!std::isfinite(options.eps) || options.eps <= 0.0) {
        throw InputError("eps must be finite and > 0, got " + number(options.eps));
    }
    if (options.effort != Effort::Fast && options.effort != Effort::Balanced &&
        options.effort != Effort::Best) {
        throw InputError("effort " + std::to_string(static_cast<int>(options.effort)) +
                         " is not a level: expected fast, balanced or best");
    }
    if (options.threads != 1 && options.threads != 2) {
        throw InputError("threads must be 1 or 2, got " + std::to_string(options.threads));
    }
    if (!std::isfinite(options.max_edge) || options.max_edge < 0.0 ||
        (options.max_edge > 0.0 && options.max_edge < kMinMaxEdge)) {
        throw InputError("max_edge must be 0 (no limit) or a finite length of at least " +
                         number(kMinMaxEdge) + " samples, got " + number(options.max_edge) +
                         " (a grid triangle's diagonal is sqrt(2) samples long)");
    }
}

Mesh triangulate(const HeightGrid& grid,
                 const TriangulateOptions& options,
                 TriangulatePhases* phases) {
    check_input(grid, options);
    // With phases (reset here): the time since the last mark goes to *into.
    if (phases != nullptr) {
        *phases = TriangulatePhases{};
    }
    auto last = phases != nullptr ? Clock::now() : Clock::time_point{};
    const auto mark = [&](double TriangulatePhases::*into) {
        if (phases != nullptr) {
            const auto now = Clock::now();
            phases->*into += std::chrono::duration<double, std::milli>(now - last).count();
            last = now;
        }
    };
    const HugePages huge_pages(options.huge_pages);
    const double eps = options.eps;
    const int max_step = max_step_for(options.max_edge);
    Plan plan = plan_for(options.effort);
    // Big grids split the phases that allow it in two (TriangulateOptions::threads).
    const bool big = static_cast<std::size_t>(grid.width) * static_cast<std::size_t>(grid.height) >=
                     kTwoThreadSamples;
    const int threads = big ? options.threads : 1;
    plan.merge.threads = threads;
    const std::vector<GridPoint> anchors =
        anchor_points(grid, eps, max_step, plan.greedy_lines, threads);
    mark(&TriangulatePhases::anchors_ms);
    // With room for the split agent's vertices (Refiner::kGrowth), which compact() keeps.
    Tin start = delaunay_rectangle(
        grid.width, grid.height, anchors, Refiner::kGrowth * (anchors.size() + 4));
    start.compact(); // triangles in Z-order, so the split agent's rescans stay local
    mark(&TriangulatePhases::start_ms);
    Refiner refiner(grid, eps, options.lock_border, options.max_edge, std::move(start), threads);
    mark(&TriangulatePhases::first_scan_ms);
    refiner.split_until_clean();
    mark(&TriangulatePhases::split_ms);
    if (phases != nullptr) {
        phases->anchors = anchors.size();
        const Tin& tin = refiner.tin();
        phases->split_triangles = tin.triangle_slots() - tin.free_triangles.size();
    }
    refiner.compact(); // the merge agent walks the whole mesh: give it locality first
    mark(&TriangulatePhases::renumber_ms);
    for (int round = 0; round < plan.merge_rounds; ++round) {
        const std::size_t removed = refiner.merge_pass(plan.merge);
        mark(&TriangulatePhases::merge_ms);
        if (phases != nullptr) {
            ++phases->merge_passes;
            phases->removed += removed;
        }
        if (removed == 0) {
            break;
        }
        refiner.split_until_clean();
        mark(&TriangulatePhases::resplit_ms);
    }
    Mesh mesh = refiner.tin().to_mesh(grid.heights, grid.width);
    // The guarantee, checked in every build: O(triangles + samples), a few percent of the run.
    check_mesh(mesh, grid.width, grid.height);
    if (options.check_error) {
        const double err = max_error(mesh, grid, threads);
        if (!(err <= eps)) {
            throw Error("triangulate: internal error: mesh misses a sample by " + number(err) +
                        " > eps " + number(eps));
        }
    }
    if (options.max_edge > 0.0) {
        const double longest = longest_edge(mesh);
        if (!(longest <= options.max_edge)) {
            throw Error("triangulate: internal error: an edge is " + number(longest) +
                        " samples long > max_edge " + number(options.max_edge));
        }
    }
    mark(&TriangulatePhases::finish_ms);
    return mesh;
}

} // namespace tb::core
