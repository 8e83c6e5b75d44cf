// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#include "evaluators/exec/ChildProcess.h"

#include "pmsc/Errors.h"

#include <fcntl.h>
#include <poll.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <thread>

extern char** environ;

namespace pmsc::evaluators::exec {

namespace {

std::string systemError(const std::string& what) { return what + ": " + std::strerror(errno); }

/// An unlinked temporary file for the child's standard error, in $TMPDIR or /tmp.
int openErrorLog() {
    const char* dir = std::getenv("TMPDIR");
    const std::string folder = dir && *dir ? dir : "/tmp";
    int fd = ::open(folder.c_str(), O_TMPFILE | O_RDWR | O_APPEND | O_CLOEXEC, 0600);
    if (fd >= 0) return fd;
    // File systems without O_TMPFILE: make a named file and unlink it at once.
    std::string pattern = folder + "/pmsc-exec-XXXXXX";
    fd = ::mkostemp(pattern.data(), O_APPEND | O_CLOEXEC);
    if (fd < 0) throw EvaluatorError(systemError("exec: cannot make a temporary file in " + folder));
    ::unlink(pattern.c_str());
    return fd;
}

/// Waits until `fd` is ready for `events` or the deadline passes. @return false on timeout.
bool waitFor(int fd, short events, ChildProcess::Clock::time_point deadline) {
    for (;;) {
        const auto left =
            std::chrono::duration_cast<std::chrono::milliseconds>(deadline - ChildProcess::Clock::now());
        if (left.count() <= 0) return false;
        pollfd p{fd, events, 0};
        const int timeout = static_cast<int>(std::min<long long>(left.count() + 1, 60'000));
        const int r = ::poll(&p, 1, timeout);
        if (r > 0) return true;
        if (r < 0 && errno != EINTR) throw EvaluatorError(systemError("exec: poll"));
    }
}

}  // namespace

bool writeFully(int fd, const void* bytes, std::size_t size) {
    const auto* p = static_cast<const char*>(bytes);
    while (size > 0) {
        const ssize_t n = ::write(fd, p, size);
        if (n > 0) {
            p += n;
            size -= static_cast<std::size_t>(n);
        } else if (n < 0 && errno != EINTR) {
            return false;
        }
    }
    return true;
}

std::string describeExitStatus(int status) {
    if (WIFEXITED(status)) {
        // The shell reports a command that a signal killed as 128 + the signal.
        const int code = WEXITSTATUS(status);
        std::string text = "exited with code " + std::to_string(code);
        if (code > 128 && code < 128 + 65) {
            const char* name = ::strsignal(code - 128);
            text += " (killed by signal " + std::to_string(code - 128) +
                    (name ? std::string(": ") + name : "") + ")";
        }
        return text;
    }
    if (WIFSIGNALED(status)) {
        const int sig = WTERMSIG(status);
        const char* name = ::strsignal(sig);
        return "was killed by signal " + std::to_string(sig) + (name ? std::string(" (") + name + ")" : "");
    }
    return "ended with status " + std::to_string(status);
}

ChildProcess::ChildProcess(const std::string& command) {
    int pair[2];
    if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, pair) != 0)
        throw EvaluatorError(systemError("exec: socketpair"));
    socket_ = pair[0];
    // Larger buffers let a whole frame of answers (160,000 points x 3 doubles is 3.8 MB) move in
    // few wake-ups. Best effort: the kernel caps them at net.core.wmem_max / rmem_max.
    for (const int fd : pair)
        for (const int option : {SO_SNDBUF, SO_RCVBUF}) {
            const int bytes = 4 << 20;
            ::setsockopt(fd, SOL_SOCKET, option, &bytes, sizeof bytes);
        }
    try {
        errorLog_ = openErrorLog();
    } catch (...) {
        ::close(pair[0]);
        ::close(pair[1]);
        throw;
    }

    // The child's descriptors 0 and 1 are its end of the socket, 2 the error log; dup2 clears
    // close-on-exec on the copies, and every other descriptor of ours is close-on-exec, so children
    // started concurrently from other threads never hold each other's sockets open.
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, pair[1], 0);
    posix_spawn_file_actions_adddup2(&actions, pair[1], 1);
    posix_spawn_file_actions_adddup2(&actions, errorLog_, 2);
    posix_spawnattr_t attr;
    posix_spawnattr_init(&attr);
    sigset_t none, defaults;
    sigemptyset(&none);
    sigemptyset(&defaults);
    sigaddset(&defaults, SIGPIPE);
    sigaddset(&defaults, SIGINT);
    posix_spawnattr_setsigmask(&attr, &none);
    posix_spawnattr_setsigdefault(&attr, &defaults);
    posix_spawnattr_setpgroup(&attr, 0);
    posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF | POSIX_SPAWN_SETPGROUP);

    std::string sh = "sh", dashC = "-c", cmd = command;
    char* argv[] = {sh.data(), dashC.data(), cmd.data(), nullptr};
    const int rc = ::posix_spawn(&pid_, "/bin/sh", &actions, &attr, argv, environ);
    posix_spawn_file_actions_destroy(&actions);
    posix_spawnattr_destroy(&attr);
    ::close(pair[1]);
    if (rc != 0) {
        ::close(socket_);
        ::close(errorLog_);
        errno = rc;
        throw EvaluatorError(systemError("exec '" + command + "': cannot start /bin/sh"));
    }
}

ChildProcess::~ChildProcess() {
    if (socket_ >= 0) ::close(socket_);  // the child reads end of file and should exit
    socket_ = -1;
    reap(std::chrono::milliseconds(2000));
    if (errorLog_ >= 0) ::close(errorLog_);
}

bool ChildProcess::writeAll(const void* bytes, std::size_t size, Clock::time_point deadline) {
    const auto* p = static_cast<const char*>(bytes);
    while (size > 0) {
        const ssize_t n = ::send(socket_, p, size, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (n > 0) {
            p += n;
            size -= static_cast<std::size_t>(n);
            continue;
        }
        if (n < 0 && errno == EINTR) continue;
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
            if (!waitFor(socket_, POLLOUT, deadline)) throw TimedOut();
            continue;
        }
        if (n < 0 && (errno == EPIPE || errno == ECONNRESET)) return false;
        throw EvaluatorError(systemError("exec: send"));
    }
    return true;
}

bool ChildProcess::readAll(void* bytes, std::size_t size, Clock::time_point deadline) {
    auto* p = static_cast<char*>(bytes);
    while (size > 0) {
        const ssize_t n = ::recv(socket_, p, size, MSG_DONTWAIT);
        if (n > 0) {
            p += n;
            size -= static_cast<std::size_t>(n);
            continue;
        }
        if (n == 0) return false;
        if (errno == EINTR) continue;
        if (errno == EAGAIN || errno == EWOULDBLOCK) {
            if (!waitFor(socket_, POLLIN, deadline)) throw TimedOut();
            continue;
        }
        if (errno == ECONNRESET) return false;
        throw EvaluatorError(systemError("exec: recv"));
    }
    return true;
}

void ChildProcess::kill() {
    if (reaped_ || pid_ <= 0) return;
    ::kill(-pid_, SIGKILL);
    ::kill(pid_, SIGKILL);
    int status = 0;
    while (::waitpid(pid_, &status, 0) < 0 && errno == EINTR) {
    }
    reaped_ = true;
    ended_ = describeExitStatus(status);
}

std::string ChildProcess::reap(std::chrono::milliseconds grace) {
    if (reaped_ || pid_ <= 0) return ended_;
    const auto deadline = Clock::now() + grace;
    for (auto pause = std::chrono::microseconds(100);;
         pause = std::min(pause * 2, std::chrono::microseconds(20'000))) {
        int status = 0;
        const pid_t r = ::waitpid(pid_, &status, WNOHANG);
        if (r == pid_) {
            reaped_ = true;
            ended_ = describeExitStatus(status);
            ::kill(-pid_, SIGKILL);  // whatever it left behind in its group
            return ended_;
        }
        if (r < 0 && errno != EINTR) {
            reaped_ = true;
            ended_ = "ended (its status is unknown)";
            return ended_;
        }
        if (Clock::now() >= deadline) break;
        std::this_thread::sleep_for(pause);
    }
    kill();
    ended_ = "did not exit and was killed";
    return ended_;
}

std::string ChildProcess::lastErrorLine() const {
    struct stat st {};
    if (errorLog_ < 0 || ::fstat(errorLog_, &st) != 0 || st.st_size <= 0) return "";
    const off_t size = st.st_size;
    const off_t start = std::max<off_t>(0, size - 4096);
    std::string tail(static_cast<std::size_t>(size - start), '\0');
    const ssize_t n = ::pread(errorLog_, tail.data(), tail.size(), start);
    if (n <= 0) return "";
    tail.resize(static_cast<std::size_t>(n));
    while (!tail.empty() && (tail.back() == '\n' || tail.back() == '\r' || tail.back() == ' '))
        tail.pop_back();
    const auto nl = tail.find_last_of('\n');
    std::string line = nl == std::string::npos ? tail : tail.substr(nl + 1);
    for (char& c : line)
        if (static_cast<unsigned char>(c) < 0x20) c = ' ';
    if (line.size() > 200) line = line.substr(0, 197) + "...";
    return line;
}

void ChildProcess::trimErrorLog(std::size_t keepBelow) {
    struct stat st {};
    if (errorLog_ >= 0 && ::fstat(errorLog_, &st) == 0 && static_cast<std::size_t>(st.st_size) > keepBelow)
        if (::ftruncate(errorLog_, 0) != 0) {
            // A log that cannot be emptied only costs disk; the calculation goes on.
        }
}

}  // namespace pmsc::evaluators::exec
