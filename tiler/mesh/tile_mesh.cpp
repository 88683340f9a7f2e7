// Tile meshes in native coordinates, and the void rule shared by every way a tile is meshed.
#include "tiler/mesh/tile_mesh.hpp"

#include "core/error.hpp"

#include <algorithm>

namespace tb::tiler {

core::Index TileMesh::add(double vx, double vy, float vz, bool on_border) {
    x.push_back(vx);
    y.push_back(vy);
    z.push_back(vz);
    border.push_back(on_border ? 1 : 0);
    return static_cast<core::Index>(x.size() - 1);
}

bool holds_valid_sample(const core::HeightGrid& grid,
                        core::GridPoint a,
                        core::GridPoint b,
                        core::GridPoint c) {
    if (grid.is_valid(a.x, a.y) || grid.is_valid(b.x, b.y) || grid.is_valid(c.x, c.y)) {
        return true;
    }
    if (grid.valid.empty()) {
        return true;
    }
    // Exact orientation tests on the integer grid: a sample on an edge counts as inside.
    const auto orient = [](core::GridPoint p, core::GridPoint q, std::int64_t x, std::int64_t y) {
        return (std::int64_t{q.x} - p.x) * (y - p.y) - (std::int64_t{q.y} - p.y) * (x - p.x);
    };
    const std::int64_t area = orient(a, b, c.x, c.y);
    const int x0 = std::min({a.x, b.x, c.x}), x1 = std::max({a.x, b.x, c.x});
    const int y0 = std::min({a.y, b.y, c.y}), y1 = std::max({a.y, b.y, c.y});
    for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
            if (!grid.is_valid(x, y)) {
                continue;
            }
            const std::int64_t w0 = orient(b, c, x, y), w1 = orient(c, a, x, y),
                               w2 = orient(a, b, x, y);
            const bool inside =
                area > 0 ? (w0 >= 0 && w1 >= 0 && w2 >= 0) : (w0 <= 0 && w1 <= 0 && w2 <= 0);
            if (inside) {
                return true;
            }
        }
    }
    return false;
}

TileMesh to_tile_mesh(const TileRaster& raster, const core::Mesh& mesh, bool drop_voids) {
    const GridFrame f = frame_of(raster);
    const int w = raster.grid.width, h = raster.grid.height;
    TileMesh out;
    out.x.reserve(mesh.points.size());
    for (std::size_t v = 0; v < mesh.points.size(); ++v) {
        const core::GridPoint p = mesh.points[v];
        const bool border = p.x == 0 || p.y == 0 || p.x == w - 1 || p.y == h - 1;
        out.add(f.x0 + p.x * f.dx, f.y0 - p.y * f.dy, mesh.z[v], border);
    }
    out.triangles.reserve(mesh.triangles.size());
    bool dropped = false;
    for (std::size_t t = 0; t < mesh.triangle_count(); ++t) {
        const core::Index a = mesh.triangles[3 * t], b = mesh.triangles[3 * t + 1],
                          c = mesh.triangles[3 * t + 2];
        if (drop_voids &&
            !holds_valid_sample(raster.grid, mesh.points[a], mesh.points[b], mesh.points[c])) {
            dropped = true;
            continue;
        }
        // Core winds counter-clockwise in (column, row) with rows running south: clockwise seen
        // from above, so two indices swap.
        out.triangles.insert(out.triangles.end(), {a, c, b});
    }
    if (drop_voids) {
        drop_unused_vertices(out);
    }
    if (dropped) {
        // Only dropped triangles can leave a vertex where two fans touch.
        split_nonmanifold_vertices(out);
    }
    return out;
}

void drop_unused_vertices(TileMesh& mesh) {
    std::vector<core::Index> to(mesh.vertex_count(), core::kNone);
    for (core::Index v : mesh.triangles) {
        to[v] = 0;
    }
    core::Index next = 0;
    for (std::size_t v = 0; v < to.size(); ++v) {
        if (to[v] == core::kNone) {
            continue;
        }
        to[v] = next;
        mesh.x[next] = mesh.x[v];
        mesh.y[next] = mesh.y[v];
        mesh.z[next] = mesh.z[v];
        mesh.border[next] = mesh.border[v];
        ++next;
    }
    mesh.x.resize(next);
    mesh.y.resize(next);
    mesh.z.resize(next);
    mesh.border.resize(next);
    for (core::Index& v : mesh.triangles) {
        v = to[v];
    }
}

void split_nonmanifold_vertices(TileMesh& mesh) {
    const std::size_t n = mesh.vertex_count();
    // Triangles around each vertex (CSR).
    std::vector<std::uint32_t> start(n + 1, 0);
    for (core::Index v : mesh.triangles) {
        ++start[v + 1];
    }
    for (std::size_t v = 0; v < n; ++v) {
        start[v + 1] += start[v];
    }
    std::vector<std::uint32_t> around(mesh.triangles.size());
    {
        std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
        for (std::size_t e = 0; e < mesh.triangles.size(); ++e) {
            around[fill[mesh.triangles[e]]++] = static_cast<std::uint32_t>(e / 3);
        }
    }
    std::vector<std::uint32_t> group;
    for (std::size_t v = 0; v < n; ++v) {
        const std::uint32_t b = start[v], e = start[v + 1];
        if (e - b < 2) {
            continue;
        }
        // Union the triangles at v that share an edge (v, w): a small union-find over the fan.
        const std::size_t k = e - b;
        group.resize(k);
        for (std::size_t i = 0; i < k; ++i) {
            group[i] = static_cast<std::uint32_t>(i);
        }
        const auto find = [&](std::uint32_t i) {
            while (group[i] != i) {
                i = group[i] = group[group[i]];
            }
            return i;
        };
        const auto others = [&](std::uint32_t t, core::Index& a, core::Index& c) {
            const core::Index* tri = &mesh.triangles[3 * static_cast<std::size_t>(t)];
            const int at = tri[0] == v ? 0 : tri[1] == v ? 1 : 2;
            a = tri[(at + 1) % 3];
            c = tri[(at + 2) % 3];
        };
        for (std::size_t i = 0; i < k; ++i) {
            core::Index a1 = 0, c1 = 0;
            others(around[b + i], a1, c1);
            for (std::size_t j = i + 1; j < k; ++j) {
                core::Index a2 = 0, c2 = 0;
                others(around[b + j], a2, c2);
                if (a1 == a2 || a1 == c2 || c1 == a2 || c1 == c2) {
                    group[find(static_cast<std::uint32_t>(i))] =
                        find(static_cast<std::uint32_t>(j));
                }
            }
        }
        // Every fan but the first one's gets a copy of v.
        std::vector<std::pair<std::uint32_t, core::Index>> copy_of; // root -> new vertex
        const std::uint32_t first = find(0);
        for (std::size_t i = 0; i < k; ++i) {
            const std::uint32_t root = find(static_cast<std::uint32_t>(i));
            if (root == first) {
                continue;
            }
            core::Index to = core::kNone;
            for (const auto& [r, w] : copy_of) {
                if (r == root) {
                    to = w;
                }
            }
            if (to == core::kNone) {
                to = mesh.add(mesh.x[v], mesh.y[v], mesh.z[v], mesh.border[v] != 0);
                copy_of.push_back({root, to});
            }
            core::Index* tri = &mesh.triangles[3 * static_cast<std::size_t>(around[b + i])];
            for (int q = 0; q < 3; ++q) {
                if (tri[q] == v) {
                    tri[q] = to;
                }
            }
        }
    }
}

void vertex_grid_position(
    const TileRaster& raster, const TileMesh& mesh, std::size_t v, double& column, double& row) {
    lonlat_to_grid(raster, native_to_lonlat(raster.scheme, mesh.x[v], mesh.y[v]), column, row);
}

} // namespace tb::tiler
