// Bad input throws tb::InputError with a message naming the problem.
#include <doctest/doctest.h>

#include <cmath>
#include <limits>
#include <string>

#include "core/error.hpp"
#include "core/triangulate.hpp"

namespace {

tb::core::HeightGrid grid(int w, int h) {
    tb::core::HeightGrid g;
    g.width = w;
    g.height = h;
    g.heights.assign(static_cast<std::size_t>(std::max(w, 0)) * std::max(h, 0), 1.0f);
    return g;
}

std::string message_of(const tb::core::HeightGrid& g, double eps) {
    try {
        tb::core::triangulate(g, {.eps = eps, .lock_border = true});
    } catch (const tb::InputError& e) {
        return e.what();
    }
    return "(no InputError)";
}

} // namespace

TEST_CASE("a grid smaller than 2x2 is rejected with its size in the message") {
    CHECK(message_of(grid(1, 5), 1.0) == "grid is 1x5: needs at least 2x2 samples");
    CHECK(message_of(grid(5, 1), 1.0) == "grid is 5x1: needs at least 2x2 samples");
    CHECK(message_of(grid(0, 0), 1.0) == "grid is 0x0: needs at least 2x2 samples");
}

TEST_CASE("a heights vector of the wrong size is rejected with both counts") {
    auto g = grid(4, 4);
    g.heights.pop_back();
    CHECK(message_of(g, 1.0) == "grid is 4x4 but has 15 heights, expected 16");
    auto m = grid(4, 4);
    m.valid.assign(3, 1);
    CHECK(message_of(m, 1.0).find("validity mask has 3 entries, expected 16") == 0);
}

TEST_CASE("a non-finite height is rejected naming x and y, valid or nodata") {
    auto g = grid(4, 3);
    g.heights[2 * 4 + 1] = std::numeric_limits<float>::quiet_NaN();
    CHECK(message_of(g, 1.0).find("height is not finite at valid sample x=1 y=2") == 0);
    g.valid.assign(12, 1);
    g.valid[2 * 4 + 1] = 0;
    g.heights[2 * 4 + 1] = std::numeric_limits<float>::infinity();
    CHECK(message_of(g, 1.0).find("height is not finite at nodata sample x=1 y=2") == 0);
}

TEST_CASE("eps that is zero, negative or not finite is rejected naming the value") {
    const auto g = grid(3, 3);
    CHECK(message_of(g, 0.0) == "eps must be finite and > 0, got 0");
    CHECK(message_of(g, -2.5) == "eps must be finite and > 0, got -2.5");
    CHECK(message_of(g, std::numeric_limits<double>::infinity()) ==
          "eps must be finite and > 0, got inf");
    CHECK(message_of(g, std::numeric_limits<double>::quiet_NaN()) ==
          "eps must be finite and > 0, got nan");
}

TEST_CASE("input errors belong to the tb::Error family") {
    CHECK_THROWS_AS(tb::core::triangulate(grid(1, 1), {}), tb::Error);
}
