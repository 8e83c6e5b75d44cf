// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#include "app/MemoryLimit.h"

#include <sys/resource.h>
#include <tbb/info.h>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

namespace pmsc::app {

namespace {

namespace fs = std::filesystem;

/// The first line of a file as a number of bytes; false when missing, "max" or not a number.
bool readBytes(const fs::path& file, std::uint64_t& value) {
    std::ifstream in(file);
    std::string text;
    if (!(in >> text) || text == "max") return false;
    try {
        std::size_t used = 0;
        value = std::stoull(text, &used);
        return used == text.size();
    } catch (const std::exception&) {
        return false;
    }
}

std::uint64_t addressSpaceInUse(const std::string& proc) {
    std::ifstream status(proc + "/self/status");
    for (std::string line; std::getline(status, line);)
        if (line.rfind("VmSize:", 0) == 0) return std::stoull(line.substr(7)) * 1024;
    return 0;
}

struct Mount {
    fs::path point;
    bool v2 = false;
};

/// The memory controller's mount points: cgroup2, and cgroup (v1) with the memory option.
std::vector<Mount> memoryMounts(const std::string& proc, const std::string& sys) {
    std::vector<Mount> mounts;
    std::ifstream in(proc + "/self/mounts");
    for (std::string line; std::getline(in, line);) {
        std::istringstream fields(line);
        std::string device, point, type, options;
        if (!(fields >> device >> point >> type >> options)) continue;
        if (type == "cgroup2") mounts.push_back({sys + point, true});
        if (type == "cgroup" && ("," + options + ",").find(",memory,") != std::string::npos)
            mounts.push_back({sys + point, false});
    }
    return mounts;
}

/// The cgroup path of this process in the v2 hierarchy ("0::/path") or the v1 memory one.
std::string cgroupPath(const std::string& proc, bool v2) {
    std::ifstream in(proc + "/self/cgroup");
    for (std::string line; std::getline(in, line);) {
        const auto a = line.find(':'), b = line.find(':', a + 1);
        if (a == std::string::npos || b == std::string::npos) continue;
        const std::string controllers = line.substr(a + 1, b - a - 1);
        const bool match = v2 ? line.substr(0, a) == "0" && controllers.empty()
                              : ("," + controllers + ",").find(",memory,") != std::string::npos;
        if (match) return line.substr(b + 1);
    }
    return "";
}

/// A field of a cgroup's memory.stat ("inactive_file 123"), 0 when absent.
std::uint64_t statField(const fs::path& file, const std::string& name) {
    std::ifstream in(file);
    std::string key;
    std::uint64_t value = 0;
    while (in >> key >> value)
        if (key == name) return value;
    return 0;
}

void tighten(MemoryLimit& best, std::uint64_t bytes, const std::string& source, bool addressSpace = false) {
    if (best.bytes == 0 || bytes < best.bytes) best = {bytes == 0 ? 1 : bytes, source, addressSpace};
}

/// The cgroup's own limit and every ancestor's, each less its usage.
void cgroupLimits(const Mount& mount, const std::string& path, MemoryLimit& best) {
    const char* limitFile = mount.v2 ? "memory.max" : "memory.limit_in_bytes";
    const char* usageFile = mount.v2 ? "memory.current" : "memory.usage_in_bytes";
    // v1 reports "no limit" as a page-rounded LLONG_MAX.
    constexpr std::uint64_t kUnlimited = std::uint64_t{1} << 60;
    fs::path dir = mount.point / fs::path(path).relative_path();
    for (;;) {
        std::uint64_t limit = 0, usage = 0;
        if (readBytes(dir / limitFile, limit) && limit < kUnlimited) {
            readBytes(dir / usageFile, usage);
            // Usage counts the page cache; its inactive part (a shot read once) is reclaimed before
            // the kernel kills anything, so it is room, not use.
            const std::uint64_t reclaimable =
                statField(dir / "memory.stat", mount.v2 ? "inactive_file" : "total_inactive_file");
            usage -= std::min(usage, reclaimable);
            tighten(best, limit > usage ? limit - usage : 0,
                    std::string("the cgroup memory limit (") + (dir / limitFile).string() + ")");
        }
        if (dir == mount.point || !dir.has_parent_path() || dir.parent_path() == dir) break;
        dir = dir.parent_path();
    }
}

}  // namespace

MemoryLimit environmentMemoryLimit(const std::string& proc, const std::string& sys) {
    MemoryLimit best;
    rlimit as{};
    if (sys.empty() && ::getrlimit(RLIMIT_AS, &as) == 0 && as.rlim_cur != RLIM_INFINITY) {
        const std::uint64_t used = addressSpaceInUse(proc);
        tighten(best, as.rlim_cur > used ? as.rlim_cur - used : 0,
                "the address-space limit (ulimit -v) less what the program already maps", true);
    }
    for (const Mount& mount : memoryMounts(proc, sys)) {
        const std::string path = cgroupPath(proc, mount.v2);
        if (!path.empty()) cgroupLimits(mount, path, best);
    }
    return best;
}

std::uint64_t frameBufferBudget(const MemoryLimit& limit, int threads) {
    if (limit.bytes == 0) return 0;
    std::uint64_t left = limit.bytes;
    if (limit.addressSpace) {
        const int workers = threads > 0 ? threads : tbb::info::default_concurrency();
        const std::uint64_t reserved =
            (std::uint64_t{72} << 20) * static_cast<std::uint64_t>(std::max(workers, 1));
        left = left > reserved ? left - reserved : 0;
    }
    return std::max<std::uint64_t>(1, left / 2);
}

}  // namespace pmsc::app
