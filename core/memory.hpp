#pragma once
// Memory for the mesher's large arrays. On a virtual machine a fresh 4 KiB page can cost 10 us
// when it is first touched, and a mesh of a few MB spends a good part of its time there. The
// arrays that grow (the working triangulation, its stats, the split queue) reserve their room
// once and are compacted in place (Tin::compact), and within a HugePages scope the arrays of
// 2 MiB and more are aligned to 2 MiB and backed by transparent huge pages where the kernel
// offers them: one fault per 2 MiB instead of 512.
#include <cstddef>
#include <vector>

namespace tb::core {

// Memory for `bytes` bytes (> 0), as LargeAllocator hands it out; throws std::bad_alloc.
void* allocate_large(std::size_t bytes);
void free_large(void* data) noexcept;

// While a HugePages scope with `on` lives on a thread, allocate_large backs the arrays of 2 MiB
// and more made on that thread with huge pages (Linux madvise MADV_HUGEPAGE; elsewhere nothing).
// Outside any scope it does not. A huge page is committed whole once touched, so an array wastes
// up to 2 MiB at its end: worth it for one large mesh, not for many small ones at once. (The
// hint stays on the address range after the array is freed, for whatever the heap puts there
// next.)
class HugePages {
public:
    explicit HugePages(bool on);
    ~HugePages();
    HugePages(const HugePages&) = delete;
    HugePages& operator=(const HugePages&) = delete;

private:
    bool previous_;
};

// std::allocator's contract, with allocate_large's memory.
template <typename T> struct LargeAllocator {
    using value_type = T;
    LargeAllocator() = default;
    template <typename U> LargeAllocator(const LargeAllocator<U>&) noexcept {}
    T* allocate(std::size_t n) { return static_cast<T*>(allocate_large(n * sizeof(T))); }
    void deallocate(T* data, std::size_t) noexcept { free_large(data); }
    template <typename U>
    friend bool operator==(const LargeAllocator&, const LargeAllocator<U>&) noexcept {
        return true;
    }
};

template <typename T> using LargeVector = std::vector<T, LargeAllocator<T>>;

} // namespace tb::core
