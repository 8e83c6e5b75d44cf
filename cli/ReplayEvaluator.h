// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/NpyIO.h"
#include "pmsc/PointEvaluator.h"

#include <string>

namespace pmsc::cli {

/// Recorded frames standing in for the expensive calculation (`pmsc replay`,
/// evaluator spec "replay:FILE.npy"): evaluating a point of a frame reads its
/// recorded value. This is how a user measures, on frames they already have,
/// what point multiplication and the soft cache would have produced.
///
/// Thread-safe: the frames are read once, in the constructor, and only read after.
class ReplayEvaluator : public PointEvaluator {
public:
    /// Reads the whole file. @throws InputError as pmsc::readFrames().
    explicit ReplayEvaluator(const std::string& path);
    /// Takes frames already in memory (the demo, tests).
    ReplayEvaluator(FrameFile frames, std::string source);

    std::string name() const override { return "replay"; }
    Index pointCount() const override { return file_.frames.points; }
    Index channelCount() const override { return file_.frames.channels; }
    Index frameCount() const override { return file_.frames.frames; }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override;
    void evaluateAll(Index frame, double* out) const override;

    /// The dtype the frames were recorded in (outputs are written in it).
    NpyDtype dtype() const { return file_.dtype; }
    const FrameSet& frames() const { return file_.frames; }
    const std::string& source() const { return source_; }

private:
    void checkFrame(Index frame) const;

    FrameFile file_;
    std::string source_;
};

}  // namespace pmsc::cli
