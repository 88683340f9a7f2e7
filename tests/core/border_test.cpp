// Locked borders: the border vertices are exactly the 1-D fit of the border, so neighbouring
// tiles that share a row or column get identical vertices there (no cracks).
#include <doctest/doctest.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "core/breakpoints.hpp"
#include "core/triangulate.hpp"
#include "tests/core/brute_force.hpp"
#include "tests/core/linf_oracle.hpp"
#include "tests/core/terrains.hpp"

namespace {

using tb::core::HeightGrid;

void check_neighbours(const HeightGrid& g, int size, double eps) {
    // Left/right windows share column `size - 1`; top/bottom windows share row `size - 1`.
    const HeightGrid left = brute::window(g, 0, 0, size, size);
    const HeightGrid right = brute::window(g, size - 1, 0, size, size);
    const HeightGrid below = brute::window(g, 0, size - 1, size, size);
    const tb::core::TriangulateOptions opt{.eps = eps, .lock_border = true};
    const auto ml = tb::core::triangulate(left, opt);
    const auto mr = tb::core::triangulate(right, opt);
    const auto mb = tb::core::triangulate(below, opt);
    CHECK(oracle::judge(ml, left, eps).over_eps == 0);
    CHECK(oracle::judge(mr, right, eps).over_eps == 0);
    CHECK(oracle::judge(mb, below, eps).over_eps == 0);
    const auto shared_col = brute::on_column(ml, size - 1);
    CHECK(shared_col == brute::on_column(mr, 0));
    CHECK(shared_col == tb::core::border_breakpoints(left, eps, 3));
    const auto shared_row = brute::on_row(ml, size - 1);
    CHECK(shared_row == brute::on_row(mb, 0));
    CHECK(shared_row == tb::core::border_breakpoints(left, eps, 1));
}

} // namespace

TEST_CASE("neighbouring windows of a heightfield share identical border vertices (seed 21)") {
    const HeightGrid g = terrain::noise(129, 129, 21, 120.0, 3.0);
    for (double eps : {0.5, 4.0}) {
        INFO("eps=", eps);
        check_neighbours(g, 65, eps);
    }
}

TEST_CASE("neighbouring windows of the real DEM N44W072.hgt share border vertices") {
    const std::string path = std::string(TB_SHARED_DATA) + "/N44W072.hgt";
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        MESSAGE("skipped: ", path, " is absent");
        return;
    }
    // SRTM .hgt: 1201 x 1201 big-endian int16, row 0 = north, no header.
    constexpr int kSide = 1201;
    std::vector<unsigned char> raw(static_cast<std::size_t>(kSide) * kSide * 2);
    in.read(reinterpret_cast<char*>(raw.data()), static_cast<std::streamsize>(raw.size()));
    REQUIRE(in);
    HeightGrid g;
    g.width = g.height = kSide;
    g.heights.resize(static_cast<std::size_t>(kSide) * kSide);
    for (std::size_t i = 0; i < g.heights.size(); ++i) {
        const auto v = static_cast<std::int16_t>((raw[2 * i] << 8) | raw[2 * i + 1]);
        g.heights[i] = static_cast<float>(v);
    }
    const HeightGrid part = brute::window(g, 400, 400, 257, 257);
    check_neighbours(part, 129, 10.0);
}
