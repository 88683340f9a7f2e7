// The L-infinity bound first: sweeps over terrains, sizes and eps, each mesh judged by the
// independent exact oracle (linf_oracle.hpp) and by check_mesh.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <tuple>
#include <vector>

#include "core/breakpoints.hpp"
#include "core/error.hpp"
#include "core/predicates.hpp"
#include "core/triangulate.hpp"
#include "tests/core/linf_oracle.hpp"
#include "tests/core/terrains.hpp"

namespace {

using tb::core::HeightGrid;
using tb::core::Mesh;
using tb::core::TriangulateOptions;

// Meshes g, judges it, checks determinism; returns the mesh.
Mesh mesh_and_judge(const HeightGrid& g, double eps, bool lock_border = true) {
    const TriangulateOptions opt{.eps = eps, .lock_border = lock_border};
    const Mesh m = tb::core::triangulate(g, opt);
    CHECK_NOTHROW(tb::core::check_mesh(m, g.width, g.height));
    const oracle::Verdict v = oracle::judge(m, g, eps);
    CHECK_MESSAGE(v.problem.empty(), v.problem);
    CHECK_MESSAGE(v.over_eps == 0, "max error ", static_cast<double>(v.max_error));
    CHECK(tb::core::max_error(m, g) <= eps);
    const Mesh again = tb::core::triangulate(g, opt);
    CHECK(again.points == m.points);
    CHECK(again.z == m.z);
    CHECK(again.triangles == m.triangles);
    CHECK(again.halfedges == m.halfedges);
    return m;
}

const std::vector<std::string> kKinds = {
    "flat", "plane", "saddle", "ridge", "cliff", "spikes", "noise"};

} // namespace

TEST_CASE("a plane and a flat grid become exactly two triangles at any eps") {
    for (const char* kind : {"plane", "flat"}) {
        for (double eps : {0.0009765625, 1.0, 1000.0}) {
            const HeightGrid g = terrain::named(kind, 37, 23, 1);
            INFO(kind, " eps=", eps);
            CHECK(mesh_and_judge(g, eps).triangle_count() == 2);
        }
    }
}

TEST_CASE("every terrain stays within eps at small sizes, eps tiny to huge (seed 7)") {
    const std::vector<std::pair<int, int>> sizes = {
        {2, 2}, {2, 9}, {9, 2}, {3, 3}, {17, 17}, {33, 20}, {20, 41}};
    for (const auto& kind : kKinds) {
        for (const auto& [w, h] : sizes) {
            const HeightGrid g = terrain::named(kind, w, h, 7);
            for (double eps : {0.0009765625, 0.25, 1.5, 10.0, 1000.0}) {
                INFO(kind, " ", w, "x", h, " eps=", eps);
                mesh_and_judge(g, eps);
            }
        }
    }
}

TEST_CASE("every terrain stays within eps on 65x65 with free borders too (seed 11)") {
    for (const auto& kind : kKinds) {
        const HeightGrid g = terrain::named(kind, 65, 65, 11);
        for (double eps : {0.125, 2.0, 16.0}) {
            for (bool lock : {true, false}) {
                INFO(kind, " eps=", eps, " lock_border=", lock);
                mesh_and_judge(g, eps, lock);
            }
        }
    }
}

TEST_CASE("the saddle z = x^2 - y^2 of the paper meshes within eps on 257x257") {
    const HeightGrid g = terrain::named("saddle", 257, 257, 0);
    const Mesh m = mesh_and_judge(g, 0.5);
    MESSAGE("saddle 257x257 eps 0.5: ", m.triangle_count(), " triangles");
    CHECK(m.triangle_count() < 257 * 257 / 4);
}

TEST_CASE("seeded noise on 257x257 and non-square 300x101 stays within eps (seeds 3, 4)") {
    mesh_and_judge(terrain::noise(257, 257, 3, 200.0, 3.0), 2.0);
    mesh_and_judge(terrain::noise(300, 101, 4, 50.0, 1.0), 0.5, false);
}

TEST_CASE("tiny eps forces a near-full mesh that is still exact (seed 5)") {
    // Pure white noise: almost every sample must become a vertex.
    terrain::Lcg r(5);
    const HeightGrid g = terrain::make(24, 19, [&](int, int) { return 100.0 * r.next(); });
    const Mesh m = mesh_and_judge(g, 0.0009765625);
    CHECK(m.points.size() > 24 * 19 * 9 / 10);
}

TEST_CASE("nodata holes constrain nothing and vertices on them take their height (seed 9)") {
    HeightGrid g = terrain::noise(80, 60, 9, 40.0, 2.0);
    g.valid.assign(g.heights.size(), 1);
    for (int y = 10; y < 30; ++y) {
        for (int x = 20; x < 50; ++x) {
            const std::size_t i = static_cast<std::size_t>(y) * 80 + x;
            g.valid[i] = 0;
            g.heights[i] = 4000.0f; // a filled void far from the terrain
        }
    }
    for (int x = 0; x < 80; ++x) { // invalid samples on the border too
        g.valid[static_cast<std::size_t>(x)] = x % 3 == 0 ? 0 : 1;
    }
    for (bool lock : {true, false}) {
        INFO("lock_border=", lock);
        const Mesh m = mesh_and_judge(g, 1.0, lock);
        HeightGrid all_valid = g;
        all_valid.valid.clear();
        // With the mask ignored the huge void would be far out of eps: the mask mattered.
        CHECK(tb::core::max_error(m, all_valid) > 1.0);
    }
    HeightGrid none = g;
    std::fill(none.valid.begin(), none.valid.end(), std::uint8_t{0});
    CHECK(mesh_and_judge(none, 0.5).triangle_count() == 2);
}

TEST_CASE("a cliff one sample wide is resolved within eps on both sides (seed 0)") {
    // Regression guard for edges crossing a step: a sample just beside the step must not be
    // interpolated from the other side.
    const HeightGrid g = terrain::make(12, 12, [](int x, int) { return x < 6 ? 0.0 : 500.0; });
    const Mesh m = mesh_and_judge(g, 0.5);
    CHECK(m.triangle_count() <= 10);
}

TEST_CASE("max_error equals the oracle's largest error where the heights moved (seeds 1-40)") {
    // The mesh of one grid judged against another: errors land inside triangles, on their
    // edges, on the rows of horizontal edges and at vertices, with and without a mask, so
    // every path of the guarantee check (span ends, span insides) is compared with the oracle.
    for (std::uint64_t seed = 1; seed <= 40; ++seed) {
        const HeightGrid g = terrain::named(kKinds[seed % kKinds.size()], 47, 33, seed);
        const Mesh m = tb::core::triangulate(g, TriangulateOptions{.eps = 2.0});
        HeightGrid moved = g;
        std::vector<std::uint8_t> vertex(g.heights.size(), 0); // vertices keep their heights
        for (const tb::core::GridPoint& p : m.points) {
            vertex[static_cast<std::size_t>(p.y) * g.width + p.x] = 1;
        }
        terrain::Lcg r(seed);
        for (std::size_t i = 0; i < moved.heights.size(); ++i) {
            const double shift = r.next() < 0.2 ? 64.0 * r.next() - 32.0 : 0.0;
            if (vertex[i] == 0) {
                moved.heights[i] = terrain::quantize(moved.heights[i] + shift);
            }
        }
        if (seed % 2 == 0) {
            moved.valid.assign(moved.heights.size(), 1);
            for (std::uint8_t& ok : moved.valid) {
                ok = r.next() < 0.3 ? 0 : 1;
            }
        }
        INFO("seed ", seed);
        const oracle::Verdict v = oracle::judge(m, moved, 1.0e6);
        REQUIRE_MESSAGE(v.problem.empty(), v.problem);
        CHECK(tb::core::max_error(m, moved) ==
              doctest::Approx(static_cast<double>(v.max_error)).epsilon(1e-12));
    }
}

TEST_CASE("max_error is bit for bit the largest interpolate() error over each closed triangle") {
    // The guarantee check walks spans with stepped weights; this walks every sample of each
    // triangle's bounding box with weights from orient2d, through the one shared interpolate(),
    // on grids whose heights moved away from the mesh. The largest error must be exactly the
    // same (==), over all samples and over single samples (a mask of one valid sample).
    for (std::uint64_t seed = 41; seed <= 52; ++seed) {
        const HeightGrid g = terrain::named(kKinds[seed % kKinds.size()], 131, 67, seed);
        const Mesh m = tb::core::triangulate(g, TriangulateOptions{.eps = 1.5});
        HeightGrid moved = g;
        terrain::Lcg r(seed);
        for (float& h : moved.heights) {
            h = terrain::quantize(h + (r.next() < 0.3 ? 40.0 * r.next() - 20.0 : 0.0));
        }
        // Each sample's error: the worst of the closed triangles that hold it.
        std::vector<double> error(moved.heights.size(), -1.0);
        for (std::size_t t = 0; t < m.triangle_count(); ++t) {
            const tb::core::Index ia = m.triangles[3 * t], ib = m.triangles[3 * t + 1],
                                  ic = m.triangles[3 * t + 2];
            const tb::core::GridPoint a = m.points[ia], b = m.points[ib], c = m.points[ic];
            const double inv_area = tb::core::inverse_area(a, b, c);
            for (int y = std::min({a.y, b.y, c.y}); y <= std::max({a.y, b.y, c.y}); ++y) {
                for (int x = std::min({a.x, b.x, c.x}); x <= std::max({a.x, b.x, c.x}); ++x) {
                    const tb::core::GridPoint p{x, y};
                    const std::int64_t wa = tb::core::orient2d(b, c, p);
                    const std::int64_t wb = tb::core::orient2d(c, a, p);
                    const std::int64_t wc = tb::core::orient2d(a, b, p);
                    if (wa < 0 || wb < 0 || wc < 0) {
                        continue;
                    }
                    const double z = tb::core::interpolate(
                        a, m.z[ia], b, m.z[ib], c, m.z[ic], wa, wb, wc, inv_area, p);
                    double& e = error[static_cast<std::size_t>(y) * moved.width + x];
                    e = std::max(e, std::abs(z - static_cast<double>(moved.at(x, y))));
                }
            }
        }
        INFO("seed ", seed);
        const double worst = *std::max_element(error.begin(), error.end());
        CHECK(worst > 1.5);
        CHECK(tb::core::max_error(m, moved) == worst);
        moved.valid.assign(moved.heights.size(), 0);
        int differ = 0;
        for (int k = 0; k < 300; ++k) {
            const auto i = static_cast<std::size_t>(r.next() * static_cast<double>(error.size()));
            moved.valid[i] = 1;
            differ += tb::core::max_error(m, moved) == error[i] ? 0 : 1;
            moved.valid[i] = 0;
        }
        CHECK(differ == 0);
    }
}

TEST_CASE("without its own error pass the mesh is the same and still within eps (seeds 12, 13)") {
    // check_error off skips triangulate()'s last measure (callers that measure what they draw
    // turn it off); the bound must then hold by construction, and nothing else may change.
    for (const auto& kind : kKinds) {
        for (const auto& [w, h, seed] : {std::tuple{65, 65, 12}, std::tuple{130, 47, 13}}) {
            const HeightGrid g = terrain::named(kind, w, h, seed);
            for (double eps : {0.125, 2.0}) {
                INFO(kind, " ", w, "x", h, " eps=", eps);
                TriangulateOptions checked{.eps = eps, .max_edge = 12.0};
                TriangulateOptions unchecked = checked;
                unchecked.check_error = false;
                for (int strips : {1, 2}) {
                    INFO("strips=", strips);
                    const Mesh a = tb::core::triangulate_strips(g, checked, strips);
                    const Mesh b = tb::core::triangulate_strips(g, unchecked, strips);
                    CHECK(b.points == a.points);
                    CHECK(b.triangles == a.triangles);
                    CHECK(b.halfedges == a.halfedges);
                    const oracle::Verdict v = oracle::judge(b, g, eps);
                    CHECK_MESSAGE(v.problem.empty(), v.problem);
                    CHECK_MESSAGE(v.over_eps == 0, "max error ", static_cast<double>(v.max_error));
                }
            }
        }
    }
}

TEST_CASE("max_error is infinite exactly when a valid sample lies in no triangle (150x9)") {
    // Rows of 150 samples span several words of the check's coverage map. One of the two
    // triangles of a flat grid is dropped; each sample it alone covered is made valid in turn.
    const HeightGrid g = terrain::make(150, 9, [](int, int) { return 7.0; });
    const Mesh full = tb::core::triangulate(g, TriangulateOptions{.eps = 1.0});
    REQUIRE(full.triangle_count() == 2);
    CHECK(tb::core::max_error(full, g) == 0.0);
    Mesh half = full;
    half.triangles.resize(3);
    half.halfedges.resize(3);
    const tb::core::GridPoint a = half.points[half.triangles[0]];
    const tb::core::GridPoint b = half.points[half.triangles[1]];
    const tb::core::GridPoint c = half.points[half.triangles[2]];
    HeightGrid masked = g;
    masked.valid.assign(g.heights.size(), 0);
    std::vector<std::size_t> uncovered;
    for (int y = 0; y < g.height; ++y) {
        for (int x = 0; x < g.width; ++x) {
            const tb::core::GridPoint p{x, y};
            const bool in = tb::core::orient2d(b, c, p) >= 0 && tb::core::orient2d(c, a, p) >= 0 &&
                            tb::core::orient2d(a, b, p) >= 0;
            const std::size_t i = static_cast<std::size_t>(y) * g.width + x;
            masked.valid[i] = in ? 1 : 0;
            if (!in) {
                uncovered.push_back(i);
            }
        }
    }
    REQUIRE(uncovered.size() > 500);
    CHECK(tb::core::max_error(half, g) == std::numeric_limits<double>::infinity());
    CHECK(tb::core::max_error(half, masked) == 0.0);
    int missed = 0;
    for (std::size_t i : uncovered) {
        masked.valid[i] = 1;
        missed +=
            tb::core::max_error(half, masked) == std::numeric_limits<double>::infinity() ? 0 : 1;
        masked.valid[i] = 0;
    }
    CHECK(missed == 0);
}

TEST_CASE("the phase record changes no mesh and counts what each phase left (seeds 21-24)") {
    std::size_t removed = 0;
    for (std::uint64_t seed = 21; seed <= 24; ++seed) {
        const HeightGrid g = terrain::named(kKinds[seed % kKinds.size()], 90, 70, seed);
        for (double eps : {0.5, 4.0}) {
            INFO("seed ", seed, " eps ", eps);
            const TriangulateOptions opt{.eps = eps, .max_edge = 20.0};
            const Mesh plain = tb::core::triangulate(g, opt);
            tb::core::TriangulatePhases phases;
            const Mesh recorded = tb::core::triangulate(g, opt, &phases);
            CHECK(recorded.points == plain.points);
            CHECK(recorded.z == plain.z);
            CHECK(recorded.triangles == plain.triangles);
            CHECK(recorded.halfedges == plain.halfedges);
            CHECK(phases.anchors ==
                  tb::core::anchor_points(g, eps, tb::core::max_step_for(opt.max_edge)).size());
            CHECK(phases.split_triangles >= 2);
            CHECK(phases.merge_passes >= 1);
            CHECK(phases.merge_passes <= 4);
            removed += phases.removed;
            for (double ms : {phases.anchors_ms,
                              phases.start_ms,
                              phases.first_scan_ms,
                              phases.split_ms,
                              phases.resplit_ms,
                              phases.renumber_ms,
                              phases.merge_ms,
                              phases.finish_ms}) {
                CHECK(ms >= 0.0);
            }
            CHECK(phases.total_ms() > 0.0);
            // The record is reset by each call: a second call into it counts the same again.
            tb::core::TriangulatePhases again = phases;
            tb::core::triangulate(g, opt, &again);
            CHECK(again.anchors == phases.anchors);
            CHECK(again.split_triangles == phases.split_triangles);
            CHECK(again.merge_passes == phases.merge_passes);
            CHECK(again.removed == phases.removed);
        }
    }
    CHECK(removed > 0); // the merge agent ran on some of them
}
