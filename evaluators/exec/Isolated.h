// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

namespace pmsc::evaluators::exec {

/// Limits for work done in a child process.
struct IsolationLimits {
    std::chrono::milliseconds timeout{600'000};
    /// Address-space limit of the child in bytes (RLIMIT_AS), so an importer asking for tens of GB
    /// fails there instead of taking the machine; 0 = half the machine's memory, at least 2 GiB.
    /// Not applied in sanitizer builds, whose shadow memory needs terabytes of address space.
    std::uint64_t addressSpace = 0;
};

/// Runs `work` in a forked copy of this process and returns the bytes it returned. Everything the
/// work does to memory stays in the child, so a library that crashes, corrupts its heap, hangs or
/// allocates without bound (Assimp on a damaged asset) fails this call, never the caller.
///
/// @param what  how messages start ("skin: PATH: ")
/// @throws pmsc::InputError with `work`'s own message when it threw (any std::exception), or
///         "WHAT the importer crashed (killed by signal 11: Segmentation fault)", "... ran out of
///         memory (limit 12 GiB)", "... did not finish within 600 s".
///
/// Decision: fork without exec. The work needs no program to be found on disk (pmsc is also a
/// Python module and a static library inside other programs), and the child shares the parent's
/// loaded code. After fork only the calling thread exists in the child; glibc's malloc is safe
/// there, and a lock another thread held at the fork would hang the child, which the timeout ends.
std::string runIsolated(const std::function<std::string()>& work, const std::string& what,
                        const IsolationLimits& limits = {});

}  // namespace pmsc::evaluators::exec
