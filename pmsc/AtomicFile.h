// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace pmsc {

/// An output file that appears whole or not at all.
///
/// Data go to a temporary file in the folder of the final path (same file
/// system, so the rename is atomic); commit() flushes it to disk (fsync),
/// renames it over the final path and syncs the folder. An object destroyed
/// before commit(), or a failed commit(), removes the temporary file, so an
/// interrupted or failed run never leaves a partial output behind (the
/// command line's "no output file left behind" rule).
///
/// Thread safety: writeAt() may be called concurrently for disjoint ranges;
/// everything else from one thread.
class AtomicFile {
public:
    /// Creates the temporary file "<path>.tmp-<pid>@<host>-XXXXXX" (temporaryTag()).
    /// @throws IoError naming `path` and the system's reason.
    explicit AtomicFile(std::string path);
    ~AtomicFile();
    AtomicFile(const AtomicFile&) = delete;
    AtomicFile& operator=(const AtomicFile&) = delete;

    /// Appends bytes at the current end. @throws IoError (disk full, ...).
    void write(const void* data, std::size_t bytes);
    /// Writes bytes at an absolute offset; does not move the append position.
    /// @throws IoError.
    void writeAt(std::uint64_t offset, const void* data, std::size_t bytes);
    /// fsync, rename onto the final path, fsync the folder. @throws IoError
    /// (the temporary file is removed first).
    void commit();
    /// Removes the temporary file; idempotent, never throws.
    void abandon() noexcept;

    const std::string& path() const { return path_; }
    const std::string& temporaryPath() const { return tempPath_; }
    bool committed() const { return committed_; }

private:
    [[noreturn]] void fail(const std::string& what, int error);

    std::string path_;
    std::string tempPath_;
    int fd_ = -1;
    std::uint64_t end_ = 0;
    bool pending_ = false;  // the temporary file exists and is ours to remove
    bool committed_ = false;
};

/// This machine's host name (gethostname), or "unknown-host".
std::string hostName();

/// "<pid>@<host>-": what a temporary file's name holds between ".tmp-" and mkstemp's six
/// characters, so that another process can tell whose temporary file it sees.
std::string temporaryTag();

/// Whether the temporary file at `path` ("....tmp-<pid>@<host>-XXXXXX") may still be written by
/// a running process, so that cleaning up after a killed run must leave it alone:
///  - written on this host by another process that is still alive: yes;
///  - on this host by this process, or by a process that has ended: no;
///  - on another host: yes if it was modified in the last `otherHostSeconds` (its writer cannot be
///    asked; an abandoned one is removed once it is that old);
///  - a name without the tag (written before tags existed): no.
/// Never throws; a file that cannot be examined counts as not in use.
bool temporaryMayBeInUse(const std::string& path, double otherHostSeconds = 600);

/// Writes `bytes` to `path` atomically (an AtomicFile in one call).
/// @throws IoError naming the path.
void writeFileAtomically(const std::string& path, std::string_view bytes);

}  // namespace pmsc
