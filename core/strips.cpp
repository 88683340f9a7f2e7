// Meshing a grid as vertical strips on several threads (triangulate_strips): the tile border
// rule of Lu & Yun's initial triangulation (a locked border is the optimal 1-D fit of its
// samples) applied to cuts inside one grid, so the strips mesh independently and still meet
// without a T-junction.
#include <algorithm>
#include <cstdint>
#include <exception>
#include <future>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/error.hpp"
#include "core/triangulate.hpp"

namespace tb::core {
namespace {

// Columns [first, last] of grid, heights and validity.
HeightGrid columns(const HeightGrid& grid, int first, int last) {
    HeightGrid part;
    part.width = last - first + 1;
    part.height = grid.height;
    const std::size_t w = static_cast<std::size_t>(part.width);
    part.heights.resize(w * static_cast<std::size_t>(grid.height));
    if (!grid.valid.empty()) {
        part.valid.resize(part.heights.size());
    }
    for (int y = 0; y < grid.height; ++y) {
        const std::size_t from = static_cast<std::size_t>(y) * grid.width + first;
        std::copy_n(grid.heights.begin() + static_cast<std::ptrdiff_t>(from),
                    w,
                    part.heights.begin() + static_cast<std::ptrdiff_t>(y * w));
        if (!grid.valid.empty()) {
            std::copy_n(grid.valid.begin() + static_cast<std::ptrdiff_t>(from),
                        w,
                        part.valid.begin() + static_cast<std::ptrdiff_t>(y * w));
        }
    }
    return part;
}

[[noreturn]] void stitch_failure(const std::string& what) {
    throw Error("triangulate_strips: internal error: " + what);
}

// Appends the strips' meshes side by side: the vertices of a cut column are taken once (from
// the strip on its left, matched by row in the strip on its right), and the border half-edges
// along each cut are linked to their twins across it.
Mesh stitch(const std::vector<Mesh>& meshes, const std::vector<int>& cut, int height) {
    Mesh out;
    std::vector<Index> on_cut(static_cast<std::size_t>(height), kNone); // row -> vertex
    std::vector<std::uint8_t> cut_column(static_cast<std::size_t>(cut.back()) + 1, 0);
    for (std::size_t k = 1; k + 1 < cut.size(); ++k) {
        cut_column[static_cast<std::size_t>(cut[k])] = 1;
    }
    for (std::size_t k = 0; k < meshes.size(); ++k) {
        const Mesh& m = meshes[k];
        const int right = cut[k + 1] - cut[k]; // this strip's last column, in its own frame
        std::vector<Index> to_out(m.points.size());
        std::vector<Index> next_cut(static_cast<std::size_t>(height), kNone);
        std::size_t matched = 0;
        for (std::size_t v = 0; v < m.points.size(); ++v) {
            const GridPoint p = m.points[v];
            const std::size_t row = static_cast<std::size_t>(p.y);
            if (k > 0 && p.x == 0) {
                if (on_cut[row] == kNone) {
                    stitch_failure("column " + std::to_string(cut[k]) + " has a vertex at row " +
                                   std::to_string(p.y) + " on its right side only");
                }
                to_out[v] = on_cut[row];
                ++matched;
            } else {
                to_out[v] = static_cast<Index>(out.points.size());
                out.points.push_back({p.x + cut[k], p.y});
                out.z.push_back(m.z[v]);
            }
            if (p.x == right) {
                next_cut[row] = to_out[v];
            }
        }
        if (k > 0 &&
            matched != static_cast<std::size_t>(std::count_if(
                           on_cut.begin(), on_cut.end(), [](Index i) { return i != kNone; }))) {
            stitch_failure("column " + std::to_string(cut[k]) +
                           " has a vertex on its left side only");
        }
        const Index base = static_cast<Index>(out.triangles.size());
        for (std::size_t e = 0; e < m.triangles.size(); ++e) {
            out.triangles.push_back(to_out[m.triangles[e]]);
            out.halfedges.push_back(m.halfedges[e] == kNone ? kNone : base + m.halfedges[e]);
        }
        on_cut = std::move(next_cut);
    }
    // Half-edges still without a twin that run along a cut column meet their twins there.
    std::unordered_map<std::uint64_t, Index> open;
    const auto key = [](Index from, Index to) { return std::uint64_t{from} << 32 | to; };
    for (Index e = 0; e < out.triangles.size(); ++e) {
        if (out.halfedges[e] != kNone) {
            continue;
        }
        const Index from = out.triangles[e], to = out.triangles[next_edge(e)];
        const GridPoint a = out.points[from], b = out.points[to];
        if (a.x != b.x || !cut_column[static_cast<std::size_t>(a.x)]) {
            continue;
        }
        const auto twin = open.find(key(to, from));
        if (twin == open.end()) {
            open.emplace(key(from, to), e);
            continue;
        }
        out.halfedges[e] = twin->second;
        out.halfedges[twin->second] = e;
        open.erase(twin);
    }
    if (!open.empty()) {
        const GridPoint a = out.points[out.triangles[open.begin()->second]];
        stitch_failure("an edge along column " + std::to_string(a.x) + " at row " +
                       std::to_string(a.y) + " has no twin across the cut");
    }
    return out;
}

} // namespace

Mesh triangulate_strips(const HeightGrid& grid,
                        const TriangulateOptions& options,
                        int strips,
                        int threads,
                        const RunElsewhere& run_elsewhere) {
    check_input(grid, options);
    strips = std::min(strips, (grid.width - 1) / (kMinStripColumns - 1));
    if (strips <= 1 || !options.lock_border) {
        return triangulate(grid, options);
    }
    // Cut k at column floor(k (W - 1) / strips): strip k spans columns cut[k] .. cut[k + 1].
    std::vector<int> cut(static_cast<std::size_t>(strips) + 1);
    for (int k = 0; k <= strips; ++k) {
        cut[static_cast<std::size_t>(k)] =
            static_cast<int>(std::int64_t{grid.width - 1} * k / strips);
    }
    std::vector<HeightGrid> parts;
    for (int k = 0; k < strips; ++k) {
        parts.push_back(
            columns(grid, cut[static_cast<std::size_t>(k)], cut[static_cast<std::size_t>(k) + 1]));
    }
    // Strip k on thread k % threads, thread 0 being this one; get() rethrows a strip's exception.
    const std::size_t lanes =
        threads <= 0 ? parts.size() : std::min(parts.size(), static_cast<std::size_t>(threads));
    const auto lane = [&parts, &options, lanes](std::size_t first) {
        std::vector<Mesh> out;
        for (std::size_t k = first; k < parts.size(); k += lanes) {
            out.push_back(triangulate(parts[k], options));
        }
        return out;
    };
    std::vector<std::future<std::vector<Mesh>>> others;
    for (std::size_t l = 1; l < lanes; ++l) {
        if (run_elsewhere) {
            auto task = std::make_shared<std::packaged_task<std::vector<Mesh>()>>(
                [&lane, l] { return lane(l); });
            others.push_back(task->get_future());
            run_elsewhere([task] { (*task)(); });
        } else {
            others.push_back(std::async(std::launch::async, lane, l));
        }
    }
    // Every lane has finished before this returns or throws: they read parts.
    const auto wait_all = [&others] {
        for (auto& f : others) {
            f.wait();
        }
    };
    std::vector<std::vector<Mesh>> by_lane;
    try {
        by_lane.push_back(lane(0));
    } catch (...) {
        wait_all();
        throw;
    }
    wait_all();
    for (auto& f : others) {
        by_lane.push_back(f.get());
    }
    std::vector<Mesh> meshes;
    for (std::size_t k = 0; k < parts.size(); ++k) {
        meshes.push_back(std::move(by_lane[k % lanes][k / lanes]));
    }
    Mesh mesh = stitch(meshes, cut, grid.height);
    // Each strip passed triangulate()'s checks (its error at every sample, unless
    // options.check_error is off), and stitching moves no vertex: what remains to prove is that
    // the pieces tile the rectangle as one mesh.
    check_mesh(mesh, grid.width, grid.height);
    return mesh;
}

} // namespace tb::core
