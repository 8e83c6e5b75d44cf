// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <sys/types.h>
#include <chrono>
#include <cstddef>
#include <stdexcept>
#include <string>

namespace pmsc::evaluators::exec {

/// A read or write on a child's socket whose deadline passed.
struct TimedOut : std::runtime_error {
    TimedOut() : std::runtime_error("timed out") {}
};

/// Writes all of `bytes` to a descriptor, retrying short writes and EINTR. @return false on an
/// error (errno says which), for example the reader gone.
bool writeFully(int fd, const void* bytes, std::size_t size);

/// How a child ended, from waitpid's status: "exited with code 1", "was killed by signal 11
/// (Segmentation fault)"; a shell's 128 + N is named as signal N too.
std::string describeExitStatus(int status);

/// A command run by `/bin/sh -c`, talking to its parent over one Unix stream socket that is both
/// its standard input and its standard output. Its standard error goes to an unlinked temporary
/// file, so a child's traceback never mixes with pmsc's one-line errors; lastErrorLine() reads
/// the last line of it for the error message.
///
/// Why a socket and not two pipes: writing to a child that died raises SIGPIPE on a pipe, which
/// would kill the whole program; send(MSG_NOSIGNAL) on a socket returns EPIPE instead, and a
/// library has no business changing the process's signal dispositions.
///
/// The child runs in a process group of its own, so kill() also reaches what the shell started
/// (a wrapper script's renderer). Not thread-safe: one thread uses a child at a time.
class ChildProcess {
public:
    using Clock = std::chrono::steady_clock;

    /// Starts the command. @throws pmsc::EvaluatorError when the socket, the temporary file or
    /// the process cannot be made.
    explicit ChildProcess(const std::string& command);
    ~ChildProcess();  ///< closes the socket, waits briefly for the child to exit, then kills it
    ChildProcess(const ChildProcess&) = delete;
    ChildProcess& operator=(const ChildProcess&) = delete;

    /// Writes all of `bytes`. @return false when the child closed its end (it exited).
    /// @throws TimedOut when the deadline passes first.
    bool writeAll(const void* bytes, std::size_t size, Clock::time_point deadline);
    /// Reads exactly `size` bytes. @return false on end of file first (the child exited or closed
    /// its output). @throws TimedOut when the deadline passes first.
    bool readAll(void* bytes, std::size_t size, Clock::time_point deadline);

    /// Kills the process group (SIGKILL) and reaps the child. Idempotent.
    void kill();
    /// Waits up to `grace` for the child to exit on its own, then kills it.
    /// @return how it ended: "exited with code 1", "was killed by signal 11 (Segmentation fault)".
    std::string reap(std::chrono::milliseconds grace);
    /// The last non-empty line the child wrote to its standard error (at most 200 characters),
    /// or "" if it wrote none.
    std::string lastErrorLine() const;
    /// Empties the captured standard error, so a long-lived chatty child does not fill /tmp.
    void trimErrorLog(std::size_t keepBelow);

    pid_t pid() const { return pid_; }

private:
    int socket_ = -1;    ///< our end of the socket pair
    int errorLog_ = -1;  ///< the child's standard error (unlinked temporary file, O_APPEND)
    pid_t pid_ = -1;
    bool reaped_ = false;
    std::string ended_;  ///< how it ended, once reaped
};

}  // namespace pmsc::evaluators::exec
