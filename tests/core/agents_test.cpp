// Per-step invariants of the split and merge agents (§3.3, §3.4).
#include <doctest/doctest.h>

#include "core/breakpoints.hpp"
#include "core/delaunay.hpp"
#include "core/refiner.hpp"
#include "core/triangulate.hpp"
#include "tests/core/linf_oracle.hpp"
#include "tests/core/terrains.hpp"

namespace {

tb::core::Refiner start(const tb::core::HeightGrid& g, double eps, bool lock) {
    return tb::core::Refiner(
        g,
        eps,
        lock,
        0.0,
        tb::core::delaunay_rectangle(g.width, g.height, tb::core::anchor_points(g, eps)));
}

} // namespace

TEST_CASE("a merge pass never raises the error-point count, even before splitting (seed 13)") {
    const auto g = terrain::noise(60, 50, 13, 80.0, 6.0);
    for (bool lock : {true, false}) {
        auto r = start(g, 1.5, lock);
        const auto before = r.error_points();
        r.merge_pass();
        CHECK(r.error_points() <= before);
        r.split_until_clean();
        CHECK(r.error_points() == 0);
        const auto m = r.tin().to_mesh(g.heights, g.width);
        CHECK(oracle::judge(m, g, 1.5).problem.empty());
    }
}

TEST_CASE("merging after a clean split and a compaction removes vertices within eps (seed 14)") {
    const auto g = terrain::noise(70, 70, 14, 50.0, 1.0);
    auto r = start(g, 1.0, true);
    r.split_until_clean();
    const auto vertices_before = r.tin().to_mesh(g.heights, g.width).points.size();
    // Compaction renumbers everything; the mesh itself and the caches must survive it.
    const auto triangles_before = r.tin().to_mesh(g.heights, g.width).triangle_count();
    r.compact();
    CHECK(r.error_points() == 0);
    CHECK(r.tin().to_mesh(g.heights, g.width).triangle_count() == triangles_before);
    CHECK(oracle::judge(r.tin().to_mesh(g.heights, g.width), g, 1.0).problem.empty());
    const auto removed = r.merge_pass();
    CHECK(r.error_points() == 0);
    const auto m = r.tin().to_mesh(g.heights, g.width);
    CHECK(m.points.size() + removed == vertices_before);
    const auto v = oracle::judge(m, g, 1.0);
    CHECK(v.problem.empty());
    CHECK(v.over_eps == 0);
}

TEST_CASE("the split agent ends with no error point and an exact tiling (seed 15)") {
    const auto g = terrain::named("spikes", 50, 40, 15);
    auto r = start(g, 0.5, false);
    r.split_until_clean();
    CHECK(r.error_points() == 0);
    const auto m = r.tin().to_mesh(g.heights, g.width);
    CHECK_NOTHROW(tb::core::check_mesh(m, g.width, g.height));
    CHECK(oracle::judge(m, g, 0.5).over_eps == 0);
}
