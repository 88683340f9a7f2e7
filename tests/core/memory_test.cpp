// The mesher's large arrays (memory.hpp).
#include <doctest/doctest.h>

#include <cstdint>

#include "core/memory.hpp"

TEST_CASE("within a HugePages scope, arrays of 2 MiB and more start on a 2 MiB boundary") {
    constexpr std::size_t kHuge = std::size_t{1} << 21;
    const auto aligned = [&](const void* p) {
        return reinterpret_cast<std::uintptr_t>(p) % kHuge == 0;
    };
    {
        const tb::core::HugePages on(true);
        auto big = tb::core::large_vector<std::uint32_t>(3 * kHuge / 4 + 5, 7u); // 1.5 MiB + 20 B
        auto bigger = tb::core::large_vector<std::uint64_t>(kHuge / 4, 1u);      // 4 MiB
        CHECK(aligned(bigger.data()));
        // The contents are those of any vector, growth included.
        bigger.resize(bigger.size() * 3, 2u);
        CHECK(aligned(bigger.data()));
        CHECK(bigger.front() == 1u);
        CHECK(bigger.back() == 2u);
        CHECK(big.size() == 3 * kHuge / 4 + 5);
        CHECK(big[12345] == 7u);
        {
            // A nested scope that turns them off ends, and the outer one holds again.
            const tb::core::HugePages off(false);
        }
        const auto again = tb::core::large_vector<char>(kHuge, 'x');
        CHECK(aligned(again.data()));
    }
    // Small arrays come from the ordinary heap and work as any vector.
    const tb::core::HugePages on(true);
    tb::core::LargeVector<int> small(10, 3);
    CHECK(small[9] == 3);
}
