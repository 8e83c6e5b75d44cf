#include "pmsc/AtomicFile.h"

#include "pmsc/Errors.h"

#include <cerrno>
#include <charconv>
#include <csignal>
#include <cstring>
#include <ctime>
#include <string>
#include <utility>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace pmsc {

std::string hostName() {
    char host[256] = {};
    if (::gethostname(host, sizeof host - 1) != 0 || host[0] == '\0') return "unknown-host";
    return host;
}

std::string temporaryTag() { return std::to_string(::getpid()) + "@" + hostName() + "-"; }

bool temporaryMayBeInUse(const std::string& path, double otherHostSeconds) {
    const auto tmp = path.rfind(".tmp-");
    const auto at = path.find('@', tmp == std::string::npos ? 0 : tmp);
    const auto dash = path.rfind('-');
    if (tmp == std::string::npos || at == std::string::npos || dash == std::string::npos || dash < at ||
        path.size() - dash != 7)
        return false;  // no tag: a temporary file from before tags, or not ours at all
    long long pid = 0;
    const char* first = path.data() + tmp + 5;
    const auto parsed = std::from_chars(first, path.data() + at, pid);
    if (parsed.ec != std::errc() || parsed.ptr != path.data() + at || pid <= 0) return false;
    const std::string host = path.substr(at + 1, dash - at - 1);
    if (host == hostName()) {
        if (pid == ::getpid()) return false;
        return ::kill(static_cast<pid_t>(pid), 0) == 0 || errno == EPERM;
    }
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) return false;
    return std::difftime(std::time(nullptr), st.st_mtime) < otherHostSeconds;
}

namespace {

std::string folderOf(const std::string& path) {
    const auto slash = path.find_last_of('/');
    if (slash == std::string::npos) return ".";
    if (slash == 0) return "/";
    return path.substr(0, slash);
}

}  // namespace

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)) {
    if (path_.empty()) throw IoError("cannot write a file with an empty name");
    // mkstemp keeps concurrent writers of the same output (two farm tasks, two
    // threads) from sharing a temporary file.
    std::string pattern = path_ + ".tmp-" + temporaryTag() + "XXXXXX";
    std::vector<char> buffer(pattern.begin(), pattern.end());
    buffer.push_back('\0');
    fd_ = ::mkstemp(buffer.data());
    if (fd_ < 0) {
        const int error = errno;
        throw IoError(path_ + ": cannot create a temporary file in '" + folderOf(path_) +
                      "': " + std::strerror(error));
    }
    tempPath_.assign(buffer.data());
    pending_ = true;
    // mkstemp creates 0600; an output should get the usual permissions (umask applies).
    const mode_t mask = ::umask(0);
    ::umask(mask);
    ::fchmod(fd_, 0666 & ~mask);
}

AtomicFile::~AtomicFile() {
    if (!committed_) abandon();
}

void AtomicFile::fail(const std::string& what, int error) {
    abandon();
    throw IoError(path_ + ": " + what + ": " + std::strerror(error));
}

void AtomicFile::write(const void* data, std::size_t bytes) {
    writeAt(end_, data, bytes);
    end_ += bytes;
}

void AtomicFile::writeAt(std::uint64_t offset, const void* data, std::size_t bytes) {
    if (fd_ < 0) throw IoError(path_ + ": write after the file was closed");
    const char* p = static_cast<const char*>(data);
    while (bytes > 0) {
        const ssize_t n = ::pwrite(fd_, p, bytes, static_cast<off_t>(offset));
        if (n < 0) {
            if (errno == EINTR) continue;
            fail("write failed", errno);
        }
        if (n == 0) fail("write failed", ENOSPC);
        p += n;
        offset += static_cast<std::uint64_t>(n);
        bytes -= static_cast<std::size_t>(n);
    }
}

void AtomicFile::commit() {
    if (committed_) return;
    if (fd_ < 0) throw IoError(path_ + ": commit after the file was abandoned");
    if (::fsync(fd_) != 0) fail("fsync failed", errno);
    if (::close(fd_) != 0) {
        fd_ = -1;
        fail("close failed", errno);
    }
    fd_ = -1;
    if (::rename(tempPath_.c_str(), path_.c_str()) != 0) fail("rename failed", errno);
    pending_ = false;
    committed_ = true;
    // Make the rename itself durable; a failure here cannot undo the rename and
    // the data are already synced, so it is not an error.
    const int dir = ::open(folderOf(path_).c_str(), O_RDONLY | O_DIRECTORY);
    if (dir >= 0) {
        ::fsync(dir);
        ::close(dir);
    }
}

void AtomicFile::abandon() noexcept {
    if (fd_ >= 0) {
        ::close(fd_);
        fd_ = -1;
    }
    if (pending_) {
        ::unlink(tempPath_.c_str());
        pending_ = false;
    }
}

void writeFileAtomically(const std::string& path, std::string_view bytes) {
    AtomicFile file(path);
    file.write(bytes.data(), bytes.size());
    file.commit();
}

}  // namespace pmsc
