// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <utility>
#include <vector>

namespace pmsc {

/// Signed index type used throughout (matches Eigen::Index).
using Index = Eigen::Index;

/// posix_memalign, then madvise(MADV_HUGEPAGE) when `huge` (a refusal is not an error: the pages
/// are then ordinary ones). Null when the memory is not there.
void* allocateAligned(std::size_t bytes, std::size_t alignment, bool huge) noexcept;

/// The frames' allocator: aligned as Eigen's own storage, and two choices for frames of hundreds of
/// megabytes, where the machine's page faults cost more than the values' arithmetic (`perf record
/// bin/pmsc_ict_frames ...`, `perf record bin/pmsc train ...`):
/// - a value-initialising resize leaves the doubles as the memory holds them, so a reader that
///   fills every value writes each page once instead of zeros first;
/// - an allocation of kHugePageBytes or more is aligned to it and asks the kernel for transparent
///   huge pages (madvise MADV_HUGEPAGE, where the kernel leaves them to the program's choice), one
///   fault per 2 MiB instead of one per 4 KiB.
template <class T>
struct FrameAllocator {
    using value_type = T;
    static constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;

    FrameAllocator() = default;
    template <class U>
    FrameAllocator(const FrameAllocator<U>&) noexcept {}

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

    friend bool operator==(const FrameAllocator&, const FrameAllocator&) noexcept { return true; }

private:
    static constexpr std::size_t kAlignment = EIGEN_MAX_ALIGN_BYTES > 16 ? EIGEN_MAX_ALIGN_BYTES : 16;
};

/// F frames of N points with C channels (3 for positions or RGB, 1 allowed).
///
/// Storage is exactly the C-order layout of a NumPy array of shape (F, N, C):
/// value(f, p, c) = values[(f * N + p) * C + c]. Seen as a column-major
/// (N*C) x F matrix this is the paper's training matrix Q (section 3), rows
/// indexed by x = p*C + c ("space"), columns by t = f ("time").
struct FrameSet {
    Index frames = 0;
    Index points = 0;
    Index channels = 0;
    /// Aligned as an Eigen matrix's own storage (EIGEN_MAX_ALIGN_BYTES), so the training matrix can
    /// be centred and trained where the frames lie (MatrixBlocks(FrameSet&&)) and computes to the
    /// bit what it computes on a copy.
    std::vector<double, FrameAllocator<double>> values;

    /// Tag of the constructor whose values are left for the caller to fill.
    struct Uninitialised {};

    FrameSet() = default;
    /// Allocates F*N*C zeros. @throws std::invalid_argument on a non-positive size.
    FrameSet(Index frameCount, Index pointCount, Index channelCount);
    /// Allocates F*N*C values the caller must write, every one, before reading any (a file
    /// reader, a calculation of every point). @throws std::invalid_argument on a non-positive size.
    FrameSet(Index frameCount, Index pointCount, Index channelCount, Uninitialised);

    Index rows() const { return points * channels; }

    /// The (N*C) x F training matrix, a view on `values`.
    Eigen::Map<const Eigen::MatrixXd> matrix() const { return {values.data(), rows(), frames}; }
    Eigen::Map<Eigen::MatrixXd> matrix() { return {values.data(), rows(), frames}; }

    /// One frame's N*C values (point-major, channel-minor).
    const double* frame(Index f) const { return values.data() + f * rows(); }
    double* frame(Index f) { return values.data() + f * rows(); }
};

}  // namespace pmsc
