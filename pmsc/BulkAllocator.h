// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <Eigen/Core>

#include <cstddef>
#include <cstdlib>
#include <new>
#include <utility>

namespace pmsc {

/// posix_memalign, then madvise(MADV_HUGEPAGE) when `huge` (a refusal is not an error: the pages
/// are then ordinary ones). Null when the memory is not there.
void* allocateAligned(std::size_t bytes, std::size_t alignment, bool huge) noexcept;

/// The allocator of pmsc's large arrays (frames, the reconstruction's panels, a model file's bytes):
/// aligned as Eigen's own storage, and two choices for arrays of hundreds of megabytes, where the
/// machine's page faults cost more than the values' arithmetic (`perf record bin/pmsc_ict_frames
/// ...`, `perf record bin/pmsc train ...`):
/// - a value-initialising resize leaves the doubles as the memory holds them, so a writer that
///   fills every value writes each page once instead of zeros first;
/// - an allocation of kHugePageBytes or more is aligned to it and asks the kernel for transparent
///   huge pages (madvise MADV_HUGEPAGE, where the kernel leaves them to the program's choice), one
///   fault per 2 MiB instead of one per 4 KiB.
template <class T>
struct BulkAllocator {
    using value_type = T;
    static constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;

    BulkAllocator() = default;
    template <class U>
    BulkAllocator(const BulkAllocator<U>&) noexcept {}

    T* allocate(std::size_t n) {
        const std::size_t bytes = n * sizeof(T);
        const bool huge = bytes >= kHugePageBytes;
        void* p = allocateAligned(bytes, huge ? kHugePageBytes : kAlignment, huge);
        if (p == nullptr) throw std::bad_alloc();
        return static_cast<T*>(p);
    }
    void deallocate(T* p, std::size_t) noexcept { std::free(p); }

    template <class U>
    void construct(U* p) noexcept {
        ::new (static_cast<void*>(p)) U;
    }
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }

    friend bool operator==(const BulkAllocator&, const BulkAllocator&) noexcept { return true; }

private:
    static constexpr std::size_t kAlignment = EIGEN_MAX_ALIGN_BYTES > 16 ? EIGEN_MAX_ALIGN_BYTES : 16;
};

}  // namespace pmsc
