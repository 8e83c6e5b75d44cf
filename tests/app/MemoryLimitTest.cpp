// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// environmentMemoryLimit() on made-up /proc and cgroup trees: v2 (memory.max, "max", an ancestor's
// tighter limit), v1 (memory.limit_in_bytes, the "unlimited" value), usage subtracted, no cgroup.
// tests/scaleout/cgroup-train.sh runs `pmsc train` inside a real memory cgroup.
#include "app/MemoryLimit.h"

#include "tests/common/TempDir.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace {

using pmsc::app::environmentMemoryLimit;
using pmsc::test::TempDir;
namespace fs = std::filesystem;

void put(const fs::path& file, const std::string& text) {
    fs::create_directories(file.parent_path());
    std::ofstream(file) << text;
}

TEST(MemoryLimit, CgroupV2TakesTheTightestOfTheCgroupAndItsAncestorsLessUsage) {
    TempDir t;
    const fs::path root = t.path();
    put(root / "proc/self/mounts", "proc /proc proc rw 0 0\ncgroup2 /sys/fs/cgroup cgroup2 rw,nosuid 0 0\n");
    put(root / "proc/self/cgroup", "0::/slurm/job_7/step_0\n");
    put(root / "sys/fs/cgroup/slurm/job_7/step_0/memory.max", "max\n");
    put(root / "sys/fs/cgroup/slurm/job_7/step_0/memory.current", "1000\n");
    put(root / "sys/fs/cgroup/slurm/job_7/memory.max", "524288000\n");
    put(root / "sys/fs/cgroup/slurm/job_7/memory.current", "24288000\n");
    put(root / "sys/fs/cgroup/slurm/memory.max", "8589934592\n");
    const auto limit = environmentMemoryLimit((root / "proc").string(), root.string());
    EXPECT_EQ(limit.bytes, 500000000u);
    EXPECT_NE(limit.source.find("job_7/memory.max"), std::string::npos) << limit.source;
}

TEST(MemoryLimit, CgroupV1ReadsTheMemoryControllersHierarchy) {
    TempDir t;
    const fs::path root = t.path();
    put(root / "proc/self/mounts",
        "cgroup /sys/fs/cgroup/cpu cgroup rw,relatime,cpu 0 0\ncgroup /sys/fs/cgroup/memory cgroup "
        "rw,relatime,memory 0 0\n");
    put(root / "proc/self/cgroup", "5:cpu:/\n4:memory:/farm/task\n0::/\n");
    put(root / "sys/fs/cgroup/memory/farm/task/memory.limit_in_bytes", "1073741824\n");
    put(root / "sys/fs/cgroup/memory/farm/task/memory.usage_in_bytes", "73741824\n");
    put(root / "sys/fs/cgroup/memory/memory.limit_in_bytes", "9223372036854771712\n");
    EXPECT_EQ(environmentMemoryLimit((root / "proc").string(), root.string()).bytes, 1000000000u);
}

TEST(MemoryLimit, NoLimitAnywhereIsZero) {
    TempDir t;
    const fs::path root = t.path();
    put(root / "proc/self/mounts", "cgroup2 /sys/fs/cgroup cgroup2 rw 0 0\n");
    put(root / "proc/self/cgroup", "0::/\n");
    put(root / "sys/fs/cgroup/memory.max", "max\n");
    EXPECT_EQ(environmentMemoryLimit((root / "proc").string(), root.string()).bytes, 0u);
    TempDir empty;
    EXPECT_EQ(environmentMemoryLimit((empty.path() / "proc").string(), empty.path().string()).bytes, 0u);
}

TEST(MemoryLimit, UsageAboveTheLimitLeavesOneByteNotNone) {
    TempDir t;
    const fs::path root = t.path();
    put(root / "proc/self/mounts", "cgroup2 /sys/fs/cgroup cgroup2 rw 0 0\n");
    put(root / "proc/self/cgroup", "0::/full\n");
    put(root / "sys/fs/cgroup/full/memory.max", "1000\n");
    put(root / "sys/fs/cgroup/full/memory.current", "5000\n");
    EXPECT_EQ(environmentMemoryLimit((root / "proc").string(), root.string()).bytes, 1u);
}

TEST(MemoryLimit, InactivePageCacheIsRoomNotUse) {
    TempDir t;
    const fs::path root = t.path();
    put(root / "proc/self/mounts", "cgroup2 /sys/fs/cgroup cgroup2 rw 0 0\n");
    put(root / "proc/self/cgroup", "0::/task\n");
    put(root / "sys/fs/cgroup/task/memory.max", "1000000\n");
    put(root / "sys/fs/cgroup/task/memory.current", "900000\n");
    put(root / "sys/fs/cgroup/task/memory.stat",
        "anon 100000\nfile 800000\nactive_file 200000\ninactive_file 600000\n");
    EXPECT_EQ(environmentMemoryLimit((root / "proc").string(), root.string()).bytes, 700000u);
    // v1 names it total_inactive_file (the cgroup and its children).
    TempDir v1;
    const fs::path r1 = v1.path();
    put(r1 / "proc/self/mounts", "cgroup /sys/fs/cgroup/memory cgroup rw,memory 0 0\n");
    put(r1 / "proc/self/cgroup", "4:memory:/task\n");
    put(r1 / "sys/fs/cgroup/memory/task/memory.limit_in_bytes", "1000000\n");
    put(r1 / "sys/fs/cgroup/memory/task/memory.usage_in_bytes", "900000\n");
    put(r1 / "sys/fs/cgroup/memory/task/memory.stat",
        "cache 800000\ninactive_file 5\ntotal_inactive_file 600000\n");
    EXPECT_EQ(environmentMemoryLimit((r1 / "proc").string(), r1.string()).bytes, 700000u);
}

TEST(MemoryLimit, FrameBuffersGetHalfOfWhatIsLeftLessTheWorkersAddressSpace) {
    using pmsc::app::frameBufferBudget;
    using pmsc::app::MemoryLimit;
    constexpr std::uint64_t MiB = std::uint64_t{1} << 20;
    EXPECT_EQ(frameBufferBudget(MemoryLimit{}, 8), 0u);  // no limit
    EXPECT_EQ(frameBufferBudget(MemoryLimit{1000 * MiB, "cgroup", false}, 8), 500 * MiB);
    // ulimit -v: each of the 8 workers reserves 72 MiB of address space first.
    EXPECT_EQ(frameBufferBudget(MemoryLimit{1000 * MiB, "ulimit -v", true}, 8), (1000 - 576) * MiB / 2);
    EXPECT_EQ(frameBufferBudget(MemoryLimit{500 * MiB, "ulimit -v", true}, 8), 1u);  // used up: refused
    EXPECT_EQ(frameBufferBudget(MemoryLimit{1, "cgroup", false}, 1), 1u);
}

}  // namespace
