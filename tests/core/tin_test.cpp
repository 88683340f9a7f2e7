// The working triangulation's renumbering (Tin::compact): in place, along the Z-order curve, with
// a caller's data per triangle following its triangle.
#include <doctest/doctest.h>

#include <array>
#include <vector>

#include "core/breakpoints.hpp"
#include "core/delaunay.hpp"
#include "core/refiner.hpp"
#include "core/tin.hpp"
#include "core/triangulate.hpp"
#include "tests/core/terrains.hpp"

namespace {

using tb::core::GridPoint;
using tb::core::Index;
using tb::core::kNone;

// A triangle's corners by position, in its own order: renumbering must keep them as they are.
std::array<GridPoint, 3> corners(const tb::core::Tin& tin, Index t) {
    return {tin.points[tin.triangles[3 * t]],
            tin.points[tin.triangles[3 * t + 1]],
            tin.points[tin.triangles[3 * t + 2]]};
}

} // namespace

TEST_CASE("compacting renumbers in place along the Z-order curve; data per triangle follows") {
    // A triangulation with removed vertices and freed triangle slots: split, then merge.
    const auto g = terrain::noise(64, 48, 21, 60.0, 2.0);
    tb::core::Refiner r(
        g,
        1.0,
        false,
        0.0,
        tb::core::delaunay_rectangle(g.width, g.height, tb::core::anchor_points(g, 1.0), 4096));
    r.split_until_clean();
    REQUIRE(r.merge_pass() > 0);
    tb::core::Tin tin = r.tin();
    REQUIRE(!tin.free_triangles.empty());

    const std::size_t slots = tin.triangle_slots();
    std::vector<std::array<GridPoint, 3>> before(slots);
    std::size_t live_triangles = 0;
    for (Index t = 0; t < slots; ++t) {
        if (tin.alive(t)) {
            before[t] = corners(tin, t);
            ++live_triangles;
        }
    }
    std::size_t live_vertices = 0;
    for (Index v = 0; v < tin.points.size(); ++v) {
        live_vertices += tin.vertex_edge[v] != kNone ? 1 : 0;
    }
    const Index* storage = tin.triangles.data();
    const auto mesh_before = tin.to_mesh(g.heights, g.width);

    // Each slot's old index rides along with its triangle.
    std::vector<Index> old_slot(slots);
    for (Index t = 0; t < slots; ++t) {
        old_slot[t] = t;
    }
    tin.compact([&](Index a, Index b) { std::swap(old_slot[a], old_slot[b]); });

    CHECK(tin.free_triangles.empty());
    CHECK(tin.triangle_slots() == live_triangles);
    CHECK(tin.points.size() == live_vertices);
    CHECK(tin.triangles.data() == storage); // in place: the same array, its room kept
    // Vertices strictly along the Z-order curve.
    for (Index v = 1; v < tin.points.size(); ++v) {
        CHECK(tb::core::z_order_key(tin.points[v - 1]) < tb::core::z_order_key(tin.points[v]));
    }
    Index previous_lowest = 0;
    for (Index t = 0; t < tin.triangle_slots(); ++t) {
        REQUIRE(old_slot[t] < slots);
        // The same triangle, corners in the same order, as the one in its old slot.
        CHECK(tin.alive(t));
        CHECK(corners(tin, t) == before[old_slot[t]]);
        // Triangles by their lowest vertex; those with the same one in their old order.
        const Index lowest =
            std::min({tin.triangles[3 * t], tin.triangles[3 * t + 1], tin.triangles[3 * t + 2]});
        CHECK(lowest >= previous_lowest);
        if (t > 0 && lowest == previous_lowest) {
            CHECK(old_slot[t - 1] < old_slot[t]);
        }
        previous_lowest = lowest;
        for (Index e = 3 * t; e < 3 * t + 3; ++e) {
            const Index twin = tin.halfedges[e];
            if (twin != kNone) {
                CHECK(tin.halfedges[twin] == e);
                CHECK(tin.triangles[twin] == tin.triangles[tb::core::next_edge(e)]);
            }
        }
    }
    for (Index v = 0; v < tin.points.size(); ++v) {
        REQUIRE(tin.vertex_edge[v] != kNone);
        CHECK(tin.triangles[tin.vertex_edge[v]] == v);
    }
    const auto mesh_after = tin.to_mesh(g.heights, g.width);
    CHECK_NOTHROW(tb::core::check_mesh(mesh_after, g.width, g.height));
    CHECK(mesh_after.triangle_count() == mesh_before.triangle_count());
    CHECK(tb::core::max_error(mesh_after, g) == tb::core::max_error(mesh_before, g));
}
