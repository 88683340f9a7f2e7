#pragma once
// Lu & Yun §3.1: optimal 1-D piecewise-linear fits (OPLA) and the anchor points of the
// initial triangulation.
#include <cstdint>
#include <span>
#include <vector>

#include "core/mesh.hpp"

namespace tb::core {

// Optimal piecewise-linear fit of one scan line.
// Inputs: z[0..n) heights (n >= 2) at unit steps; valid is empty or has n entries (0 = the
// sample constrains nothing); eps > 0 in the heights' unit.
// Returns the breakpoint indices, increasing, first 0 and last n-1: the fewest breakpoints such
// that every valid sample k is within eps of the chain, with the chain evaluated exactly as the
// mesh evaluates an edge (lerp_steps from the lower index). The result is a pure function of
// (z, valid, eps): two tiles reading the same border in the same direction get the same points.
// Ties between optimal chains are broken deterministically (each breakpoint is reached from the
// lowest-index predecessor at the same hop count). O(n * reach).
// max_step >= 1 additionally limits every segment to at most max_step samples (j - i <=
// max_step); the chain is then the fewest breakpoints under both constraints, still a pure
// function of (z, valid, eps, max_step). max_step = 0: no limit.
std::vector<int> fit_breakpoints(std::span<const float> z,
                                 std::span<const std::uint8_t> valid,
                                 double eps,
                                 int max_step = 0);

// A cheap chain for the interior scan lines of Effort::Fast: from each breakpoint the longest
// segment (at most max_step samples when max_step >= 1) whose slope lies in the eps tunnel of
// every valid sample between, judged in doubles by cross-multiplication (no division). O(n):
// each sample is visited by at most two segments' searches. Not the fewest breakpoints, and the
// tunnel is not the exact edge test (a sample may miss eps in the last bit): the anchors it gives
// only seed the split agent, which scans every triangle exactly. First 0, last n - 1,
// increasing; a pure function of (z, valid, eps, max_step).
std::vector<int> greedy_breakpoints(std::span<const float> z,
                                    std::span<const std::uint8_t> valid,
                                    double eps,
                                    int max_step = 0);

// True when the segment from sample i to sample j (i < j) keeps every valid sample in between
// within eps (the exact test the fit is verified with).
bool segment_fits(
    std::span<const float> z, std::span<const std::uint8_t> valid, double eps, int i, int j);

struct HeightGrid;

// The anchor points of §3.1: the breakpoints of the four borders (rows read left to right,
// columns top to bottom), then the breakpoints of the vertical scan lines through the interior
// breakpoints of the horizontal border with fewer breakpoints, and of the horizontal scan lines
// through those of the vertical border with fewer breakpoints. Beyond the paper, when a
// forecast from the borders puts the anchors within 1% of the samples (coarse eps), the scan
// lines through the other two borders' breakpoints as well. Sorted in raster order, unique, always
// containing the four corners; a pure function of (grid, eps, max_step, greedy_lines). max_step
// as in fit_breakpoints, for every fit. With greedy_lines the interior scan lines take
// greedy_breakpoints' chains, O(samples) each, instead of the optimal fits, O(samples * reach)
// (the borders' fits are the optimal ones either way). threads = 2 fits the scan lines in two
// halves on two threads (the same anchors).
std::vector<GridPoint> anchor_points(const HeightGrid& grid,
                                     double eps,
                                     int max_step = 0,
                                     bool greedy_lines = false,
                                     int threads = 1);

// The breakpoints of one border: side 0 = top row (y = 0), 1 = bottom row, 2 = left column
// (x = 0), 3 = right column; positions along the border.
std::vector<int> border_breakpoints(const HeightGrid& grid, double eps, int side, int max_step = 0);

// The longest 1-D step an edge bound allows: floor(max_edge), at least 1; 0 for no bound
// (max_edge == 0). Along a border or scan line an edge of j - i samples has length j - i.
int max_step_for(double max_edge);

} // namespace tb::core
