#pragma once
// A stable least-significant-digit radix sort on unsigned integer keys, for the mesher's sorts of
// many records by a bounded key (anchors in raster order, vertices along the Z-order curve):
// O(n) per 11-bit digit of the largest key, where std::sort's comparisons cost O(n log n) and
// mispredict on every other branch.
#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>
#include <vector>

namespace tb::core {

// Sorts items by key(item) ascending (key returns std::uint64_t), keeping the input order of
// equal keys. Uses one scratch vector of items' size (the same type as items).
template <typename Vector, typename Key> void radix_sort(Vector& items, const Key& key) {
    constexpr int kDigit = 11;
    constexpr std::size_t kBuckets = std::size_t{1} << kDigit;
    std::uint64_t largest = 0;
    for (const auto& item : items) {
        largest = std::max<std::uint64_t>(largest, key(item));
    }
    const int bits = std::bit_width(largest);
    if (items.size() < 2 || bits == 0) {
        return;
    }
    Vector other(items.size());
    std::array<std::size_t, kBuckets> start{};
    for (int shift = 0; shift < bits; shift += kDigit) {
        start.fill(0);
        for (const auto& item : items) {
            ++start[(key(item) >> shift) & (kBuckets - 1)];
        }
        std::size_t sum = 0;
        for (std::size_t& s : start) {
            const std::size_t count = s;
            s = sum;
            sum += count;
        }
        for (const auto& item : items) {
            other[start[(key(item) >> shift) & (kBuckets - 1)]++] = item;
        }
        items.swap(other);
    }
}

} // namespace tb::core
