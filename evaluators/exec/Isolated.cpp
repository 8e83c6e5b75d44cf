// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#include "evaluators/exec/Isolated.h"

#include "evaluators/exec/ChildProcess.h"
#include "pmsc/Errors.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <exception>
#include <new>

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define PMSC_ISOLATED_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#define PMSC_ISOLATED_SANITIZER 1
#endif
#endif

#ifdef PMSC_ISOLATED_SANITIZER
extern "C" void __sanitizer_set_death_callback(void (*callback)());
#endif

namespace pmsc::evaluators::exec {

namespace {

using Clock = std::chrono::steady_clock;

std::uint64_t defaultAddressSpace() {
    const long pages = ::sysconf(_SC_PHYS_PAGES), size = ::sysconf(_SC_PAGESIZE);
    const std::uint64_t half =
        pages > 0 && size > 0 ? static_cast<std::uint64_t>(pages) * static_cast<std::uint64_t>(size) / 2 : 0;
    return std::max<std::uint64_t>(half, std::uint64_t{2} << 30);
}

std::string gib(std::uint64_t bytes) {
    char text[32];
    std::snprintf(text, sizeof text, "%.1f GiB", static_cast<double>(bytes) / double(1 << 30));
    return text;
}

void writeAll(int fd, const void* bytes, std::size_t size) {
    if (!writeFully(fd, bytes, size)) ::_exit(3);  // the parent went away: nobody to tell
}

/// The child's side: run the work, send [u8 ok][u64 length][bytes], leave without running the
/// parent's exit handlers or flushing its stdio buffers.
[[noreturn]] void childMain(int out, const std::function<std::string()>& work, std::uint64_t addressSpace) {
#ifndef PMSC_ISOLATED_SANITIZER
    rlimit limit{};
    if (::getrlimit(RLIMIT_AS, &limit) == 0) {
        const rlim_t want = static_cast<rlim_t>(addressSpace);
        if (limit.rlim_cur == RLIM_INFINITY || limit.rlim_cur > want) limit.rlim_cur = want;
        ::setrlimit(RLIMIT_AS, &limit);
    }
#else
    (void)addressSpace;
    // A fuzzer's crash handlers belong to the parent: the child just dies, and the parent reports it.
    __sanitizer_set_death_callback(nullptr);
    for (const int sig : {SIGSEGV, SIGBUS, SIGABRT, SIGILL, SIGFPE}) std::signal(sig, SIG_DFL);
#endif
    std::uint8_t ok = 0;
    std::string bytes;
    try {
        bytes = work();
        ok = 1;
    } catch (const std::bad_alloc&) {
        bytes = "\x01";  // marker: out of memory
    } catch (const std::exception& e) {
        bytes = e.what();
    } catch (...) {
        bytes = "an unknown exception";
    }
    const std::uint64_t length = bytes.size();
    writeAll(out, &ok, 1);
    writeAll(out, &length, sizeof length);
    writeAll(out, bytes.data(), bytes.size());
    ::_exit(0);
}

/// Reads everything the child sends until end of file or the deadline. @return false on timeout.
bool readUntilEnd(int fd, std::string& into, Clock::time_point deadline) {
    char buffer[1 << 16];
    for (;;) {
        const auto left =
            std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
        if (left <= 0) return false;
        pollfd p{fd, POLLIN, 0};
        const int r = ::poll(&p, 1, static_cast<int>(std::min<long long>(left + 1, 60'000)));
        if (r < 0 && errno != EINTR) return true;
        if (r <= 0) continue;
        const ssize_t n = ::read(fd, buffer, sizeof buffer);
        if (n > 0)
            into.append(buffer, static_cast<std::size_t>(n));
        else if (n == 0 || errno != EINTR)
            return true;
    }
}

}  // namespace

std::string runIsolated(const std::function<std::string()>& work, const std::string& what,
                        const IsolationLimits& limits) {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0) throw InputError(what + "cannot make a pipe: " + std::strerror(errno));
    const std::uint64_t addressSpace = limits.addressSpace > 0 ? limits.addressSpace : defaultAddressSpace();
    const pid_t pid = ::fork();
    if (pid < 0) {
        ::close(fds[0]);
        ::close(fds[1]);
        throw InputError(what + "cannot fork: " + std::strerror(errno));
    }
    if (pid == 0) {
        ::close(fds[0]);
        childMain(fds[1], work, addressSpace);
    }
    ::close(fds[1]);
    std::string got;
    const bool finished = readUntilEnd(fds[0], got, Clock::now() + limits.timeout);
    ::close(fds[0]);
    if (!finished) ::kill(pid, SIGKILL);
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    if (!finished) {
        char seconds[32];
        std::snprintf(seconds, sizeof seconds, "%g s", static_cast<double>(limits.timeout.count()) / 1000.0);
        throw InputError(what + "the importer did not finish within " + seconds);
    }
    std::uint64_t length = 0;
    if (got.size() >= 9) std::memcpy(&length, got.data() + 1, sizeof length);
    if (got.size() < 9 || got.size() - 9 != length) {
        if (WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL)
            throw InputError(what + "the importer was killed (out of memory? limit " + gib(addressSpace) +
                             ")");
        throw InputError(what + "the importer crashed (it " + describeExitStatus(status) + ")");
    }
    std::string bytes = got.substr(9);
    if (got[0] == 1) return bytes;
    if (bytes == "\x01")
        throw InputError(what + "the importer ran out of memory (limit " + gib(addressSpace) + ")");
    throw InputError(bytes);
}

}  // namespace pmsc::evaluators::exec
