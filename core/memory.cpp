#include "core/memory.hpp"

#include <cstdlib>
#include <new>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace tb::core {
namespace {

constexpr std::size_t kHugePage = std::size_t{1} << 21;

thread_local bool huge_pages = false;

} // namespace

HugePages::HugePages(bool on) : previous_(huge_pages) {
    huge_pages = on;
}

HugePages::~HugePages() {
    huge_pages = previous_;
}

void* allocate_large(std::size_t bytes) {
    void* data = nullptr;
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    if (huge_pages && bytes >= kHugePage) {
        const std::size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
        data = std::aligned_alloc(kHugePage, rounded);
        if (data != nullptr) {
            // A hint: without transparent huge pages the pages stay small.
            (void)madvise(data, rounded, MADV_HUGEPAGE);
        }
    }
#endif
    if (data == nullptr) {
        data = std::malloc(bytes);
    }
    if (data == nullptr) {
        throw std::bad_alloc();
    }
    return data;
}

void free_large(void* data) noexcept {
    std::free(data);
}

} // namespace tb::core
