// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#include "app/FarmFrames.h"

#include "app/OptionError.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <unordered_set>

#include <unistd.h>

namespace fs = std::filesystem;

namespace pmsc::app {

std::string FrameSpan::text() const {
    std::string t = std::to_string(first) + "-" + std::to_string(last);
    if (step != 1) t += ":" + std::to_string(step);
    return t;
}

void checkFramesInside(const FrameSpan& span, const PointEvaluator& evaluator, const std::string& spec) {
    if (span.last >= evaluator.frameCount())
        throw InputError("frames " + span.text() + " are outside the evaluator's frames 0-" +
                         std::to_string(evaluator.frameCount() - 1) + " (" + spec + ")");
}

namespace {

std::string frameName(Index frame, const std::string& extension) {
    char digits[32];
    std::snprintf(digits, sizeof digits, "%06lld", static_cast<long long>(frame));
    return std::string("frame.") + digits + extension;
}

std::string systemError(int error) { return std::strerror(error); }

}  // namespace

FrameOutput::FrameOutput(std::string dir, const std::string& format,
                         const std::vector<std::shared_ptr<const FrameWriter>>& writers, Index points,
                         Index channels, NpyDtype dtype)
    : dir_(std::move(dir)), points_(points), channels_(channels), dtype_(dtype) {
    if (format == "npy") {
        extension_ = ".npy";
        return;
    }
    std::string offered = "npy";
    for (auto& w : writers) {
        if (w->extension() == "." + format) {
            writer_ = w;
            extension_ = w->extension();
            return;
        }
        offered += ", " + w->extension().substr(1);
    }
    throw OptionError("--format: this evaluator writes " + offered + ", not '" + format + "'");
}

std::string FrameOutput::path(Index frame) const {
    return (fs::path(dir_) / frameName(frame, extension_)).string();
}

bool FrameOutput::isValid(Index frame) const {
    const std::string p = path(frame);
    std::error_code ec;
    if (!fs::is_regular_file(p, ec)) return false;
    if (writer_) return writer_->isValid(p);
    try {
        const NpyInfo info = readNpyInfo(p);  // checks the length against the shape
        return info.frames == 1 && info.points == points_ && info.channels == channels_ &&
               info.dtype == dtype_;
    } catch (const std::exception&) {
        return false;
    }
}

void FrameOutput::write(Index frame, const double* values) const {
    const std::string p = path(frame);
    if (!writer_) {
        NpyFrameWriter npy(p, 1, points_, channels_, dtype_);  // AtomicFile: temporary, fsync, rename
        npy.writeFrame(0, values);
        npy.commit();
        return;
    }
    // The evaluator's writer fills AtomicFile's temporary file by name (pmsc::FrameWriter);
    // commit() syncs it, renames it into place and syncs the folder.
    AtomicFile file(p);
    try {
        writer_->write(file.temporaryPath(), frame, values);
    } catch (const IoError&) {
        throw;
    } catch (const std::exception& e) {
        throw IoError(p + ": " + e.what());
    }
    file.commit();
}

Index FrameOutput::removeStaleTemporaries(const std::vector<Index>& frames) const {
    std::unordered_set<std::string> ours;
    for (Index f : frames) ours.insert(frameName(f, extension_));
    Index removed = 0;
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(dir_, ec)) {
        const std::string name = entry.path().filename().string();
        const auto tmp = name.find(".tmp-");
        if (tmp == std::string::npos || !ours.count(name.substr(0, tmp))) continue;
        // Another live run writing the same frame (overlapping ranges, or the same task started
        // twice): leave its file alone; both runs write identical bytes and each renames its own.
        if (temporaryMayBeInUse(entry.path().string())) continue;
        std::error_code rm;
        if (fs::remove(entry.path(), rm)) ++removed;
    }
    return removed;
}

std::vector<std::shared_ptr<const FrameWriter>> offeredWriters(const PointEvaluator& evaluator) {
    if (const auto* provider = dynamic_cast<const FrameWriterProvider*>(&evaluator))
        return provider->frameWriters();
    return {};
}

void ensureWritableFolder(const std::string& dir) {
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) throw IoError(dir + ": cannot create the output folder: " + ec.message());
    if (!fs::is_directory(dir, ec)) throw IoError(dir + ": not a folder");
    std::string probe = (fs::path(dir) / ".pmsc-write-test-XXXXXX").string();
    const int fd = ::mkstemp(probe.data());
    if (fd < 0) throw IoError(dir + ": cannot create files in the output folder: " + systemError(errno));
    ::close(fd);
    ::unlink(probe.c_str());
}

}  // namespace pmsc::app
