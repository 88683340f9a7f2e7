// The mesher's large arrays (memory.hpp).
#include <doctest/doctest.h>

#include <cstdint>

#include "core/memory.hpp"

namespace {

constexpr std::size_t kHuge = std::size_t{1} << 21;

bool aligned(const void* p) {
    return reinterpret_cast<std::uintptr_t>(p) % kHuge == 0;
}

} // namespace

#if defined(__linux__) && defined(__GLIBC__)
TEST_CASE("within a HugePages scope, arrays of 2 MiB and more start on a 2 MiB boundary") {
    // glibc puts a large block 16 bytes past a page boundary, so without the scope an array is
    // never 2 MiB aligned: the test tells the two apart.
    const tb::core::LargeVector<std::uint64_t> outside(kHuge / 4, 1u); // 4 MiB
    CHECK(!aligned(outside.data()));
    {
        const tb::core::HugePages on(true);
        tb::core::LargeVector<std::uint64_t> bigger(kHuge / 4, 1u);
        CHECK(aligned(bigger.data()));
        // The contents are those of any vector, growth included.
        bigger.resize(bigger.size() * 3, 2u);
        CHECK(aligned(bigger.data()));
        CHECK(bigger.front() == 1u);
        CHECK(bigger.back() == 2u);
        {
            const tb::core::HugePages off(false);
            const tb::core::LargeVector<char> plain(kHuge, 'x');
            CHECK(!aligned(plain.data()));
            CHECK(plain.back() == 'x');
        }
        // The inner scope ended: the outer one holds again.
        const tb::core::LargeVector<char> again(kHuge, 'x');
        CHECK(aligned(again.data()));
    }
    const tb::core::LargeVector<char> after(kHuge, 'y');
    CHECK(!aligned(after.data()));
}
#else
TEST_CASE("huge pages are a Linux (glibc) hint" * doctest::skip()) {
    MESSAGE("skipped: the huge-page path is Linux-only; elsewhere arrays come from malloc");
}
#endif
