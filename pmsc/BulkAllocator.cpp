#include "pmsc/BulkAllocator.h"

#include <sys/mman.h>

namespace pmsc {

void* allocateAligned(std::size_t bytes, std::size_t alignment, bool huge) noexcept {
    void* p = nullptr;
    if (::posix_memalign(&p, alignment, bytes == 0 ? alignment : bytes) != 0) return nullptr;
    if (huge) ::madvise(p, bytes, MADV_HUGEPAGE);
    return p;
}

}  // namespace pmsc
