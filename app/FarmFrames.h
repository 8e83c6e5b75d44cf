// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"
#include "pmsc/FrameWriter.h"
#include "pmsc/NpyIO.h"
#include "pmsc/PointEvaluator.h"

#include <memory>
#include <string>
#include <vector>

namespace pmsc::app {

/// Frames first, first+step, ..., up to and including `last` (the command line's "A-B[:STEP]").
struct FrameSpan {
    Index first = 0;
    Index last = 0;
    Index step = 1;
    Index count() const { return (last - first) / step + 1; }
    Index frame(Index i) const { return first + i * step; }
    /// "A-B" or "A-B:S", as typed.
    std::string text() const;
};

/// @throws InputError ("frames A-B are outside the evaluator's frames 0-F (SPEC)") unless every
/// frame of `span` is one of the evaluator's.
void checkFramesInside(const FrameSpan& span, const PointEvaluator& evaluator, const std::string& spec);

/// One output file per frame of a render-farm run (`pmsc run`), in one format:
/// `.npy` of shape (1, N, C), or a format the evaluator offers (pmsc::FrameWriter:
/// .obj for a mesh, .vdb for an illumination grid).
///
/// Names: DIR/frame.NNNNNN.EXT, the frame number zero-padded to six digits (wider
/// when larger), so a shell glob lists frames in order.
///
/// Every file appears atomically: it is written to "<name>.tmp-<pid>@<host>-XXXXXX" in the same
/// folder, flushed to disk (fsync), then renamed; a run killed at any instant leaves
/// either no file for a frame or a complete one, plus at most stray temporary files,
/// which the next run on those frames removes (removeStaleTemporaries()).
///
/// Thread safety: const methods may run concurrently for different frames.
class FrameOutput {
public:
    /// @param[in] dir      output folder (must exist)
    /// @param[in] format   "npy" or the extension (without dot) of one of `writers`
    /// @param[in] writers  what the evaluator offers (may be empty)
    /// @param[in] points, channels  N and C of every frame
    /// @param[in] dtype    element type of .npy frames
    /// @throws OptionError for a format neither npy nor offered (the offered ones are listed).
    FrameOutput(std::string dir, const std::string& format,
                const std::vector<std::shared_ptr<const FrameWriter>>& writers, Index points, Index channels,
                NpyDtype dtype);

    /// The final path of frame `frame`.
    std::string path(Index frame) const;
    /// ".npy", ".obj", ...
    const std::string& extension() const { return extension_; }

    /// True if the frame's file exists and is a complete, valid output: for .npy a
    /// (1, N, C) array of the right dtype whose length matches its header; for other
    /// formats the writer's own check. Never throws.
    bool isValid(Index frame) const;

    /// Writes the frame atomically (temporary file, fsync, rename).
    /// @param[in] values N*C doubles, point-major, channel-minor.
    /// @throws IoError naming the path; no temporary file is left behind.
    void write(Index frame, const double* values) const;

    /// Removes "<frame name>.tmp-*" files of the given frames, left by a killed run, but not
    /// those another live process may still be writing (pmsc::temporaryMayBeInUse()), so two
    /// runs on overlapping frames both finish: each renames its own temporary file, and the
    /// frame's bytes are the same whichever lands last. @return how many were removed.
    Index removeStaleTemporaries(const std::vector<Index>& frames) const;

private:
    std::string dir_;
    std::string extension_;
    std::shared_ptr<const FrameWriter> writer_;  // null: .npy
    Index points_, channels_;
    NpyDtype dtype_;
};

/// The formats an evaluator offers through pmsc::FrameWriterProvider (none for
/// evaluators that are not providers).
std::vector<std::shared_ptr<const FrameWriter>> offeredWriters(const PointEvaluator& evaluator);

/// Checks that `dir` is a folder this process can create files in, creating it
/// (and its parents) if missing, by creating and removing a probe file.
/// @throws IoError naming the folder and the system's reason.
void ensureWritableFolder(const std::string& dir);

}  // namespace pmsc::app
