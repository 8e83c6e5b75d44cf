#include "pmsc/Parallel.h"

#include <algorithm>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace pmsc {

void runOnEveryCore(const std::function<void()>& work, Index jobs) {
    const Index threads =
        std::clamp<Index>(Index(std::thread::hardware_concurrency()), 1, std::max<Index>(1, jobs));
    std::exception_ptr failed;
    std::mutex failedLock;
    auto guarded = [&] {
        try {
            work();
        } catch (...) {
            const std::lock_guard<std::mutex> hold(failedLock);
            if (!failed) failed = std::current_exception();
        }
    };
    std::vector<std::thread> pool;
    for (Index t = 1; t < threads; ++t) pool.emplace_back(guarded);
    guarded();
    for (std::thread& t : pool) t.join();
    if (failed) std::rethrow_exception(failed);
}

}  // namespace pmsc
