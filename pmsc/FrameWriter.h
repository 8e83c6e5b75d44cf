// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <memory>
#include <string>
#include <vector>

namespace pmsc {

/// A file format for ONE frame of an evaluator's output, for programs that
/// write one file per frame (`pmsc run` on a render farm): a posed mesh as
/// .obj, an illumination grid as .vdb.
///
/// Why an interface here: the command line must write a format only the
/// evaluator understands (an .obj needs the mesh's faces, a .vdb needs the
/// grid's voxel layout and pulls in OpenVDB) without including those
/// libraries. The evaluator offers writers through FrameWriterProvider; the
/// caller finds them with dynamic_cast and keeps .npy as its own format.
///
/// Atomicity is the caller's job: it passes a temporary path in the final
/// folder, then flushes (fsync) and renames it, so a writer simply writes a
/// complete file at `path` and closes it.
///
/// Thread safety: both methods are const and must be safe to call
/// concurrently for different frames and paths.
class FrameWriter {
public:
    virtual ~FrameWriter() = default;

    /// Lower-case file extension with its dot (".obj", ".vdb"); also the name
    /// of the format on the command line without the dot (`--format obj`).
    virtual std::string extension() const = 0;

    /// Writes one frame to `path` (created or truncated).
    /// @param[in] frame  frame number (a writer may record it in the file).
    /// @param[in] values N*C doubles of the evaluator's pointCount() and
    ///                   channelCount(), point-major, channel-minor.
    /// @throws IoError naming `path` and the system's reason.
    virtual void write(const std::string& path, Index frame, const double* values) const = 0;

    /// True when `path` holds a complete output of this writer for a frame
    /// of this evaluator: it parses and has the right size (points,
    /// channels). Used to skip frames on a re-run; never throws.
    virtual bool isValid(const std::string& path) const = 0;
};

/// Mixin an evaluator (a PointEvaluator) inherits to offer its own per-frame
/// output formats. Not part of PointEvaluator so that evaluators without one
/// (replay) stay unchanged.
class FrameWriterProvider {
public:
    virtual ~FrameWriterProvider() = default;

    /// The formats this evaluator can write, preferred first. The writers may
    /// keep references into the evaluator and must not outlive it.
    virtual std::vector<std::shared_ptr<const FrameWriter>> frameWriters() const = 0;
};

}  // namespace pmsc
