// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <cstdint>
#include <string>

namespace pmsc::app {

/// How much more memory this process may use, and what says so.
struct MemoryLimit {
    std::uint64_t bytes = 0;    ///< 0 = no limit found
    std::string source;         ///< "the cgroup memory limit (/sys/fs/cgroup/...)", for messages
    bool addressSpace = false;  ///< the limit is ulimit -v's: address space, not resident memory
};

/// The tightest limit the environment sets on this process, less what is already used under it:
///  - the address-space limit (`ulimit -v`, RLIMIT_AS) less the address space mapped now;
///  - the memory cgroup it runs in (Slurm's --mem, a container's limit): cgroup v2's memory.max less
///    memory.current, and cgroup v1's memory.limit_in_bytes less memory.usage_in_bytes, for its own
///    cgroup and every ancestor up to the hierarchy's mount point (a parent's limit binds too);
///    the inactive page cache (memory.stat's inactive_file, v1 total_inactive_file) does not count
///    as used, since the kernel reclaims it before it kills.
/// A farm task is held by the cgroup: the kernel kills it past the limit (signal 9) with no error
/// to catch, so what would not fit must be known before it is allocated.
/// @param proc, sys  roots of /proc and of the file system (tests give a made-up tree).
MemoryLimit environmentMemoryLimit(const std::string& proc = "/proc", const std::string& sys = "");

/// What a run's frame buffers (engine::EngineOptions::memoryLimit) may take of `limit`, the memory
/// left once the model and the evaluator are loaded, with `threads` workers about to start (0 =
/// every core, as the engine counts them): half. Decision: the other half is for what the engine
/// does not count, the evaluator's per-call workspace (a gather's paths, a rig's pose), the output
/// writer and the allocator's slack. Under an address-space limit each worker first reserves its
/// stack and a malloc arena (8 + 64 MiB of address space with glibc), so those come off before
/// halving. No limit stays 0; a limit used up gives 1 byte, which the engine refuses with one line.
std::uint64_t frameBufferBudget(const MemoryLimit& limit, int threads);

}  // namespace pmsc::app
