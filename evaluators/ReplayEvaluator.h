// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/NpyIO.h"
#include "pmsc/PointEvaluator.h"

#include <memory>
#include <string>

namespace pmsc::evaluators {

/// Recorded frames standing in for the expensive calculation (`pmsc replay`,
/// evaluator spec "replay:FILE.npy"): evaluating a point of a frame reads its
/// recorded value. This is how a user measures, on frames they already have,
/// what point multiplication and the soft cache would have produced.
///
/// From a path the file is memory-mapped (pmsc::MappedFrames), so a recorded shot larger than
/// memory replays, and a farm task reading a slice touches only that slice's pages.
/// Thread-safe: the frames are only read.
class ReplayEvaluator : public PointEvaluator {
public:
    /// Maps the file and checks it as pmsc::readFrames() does. @throws InputError.
    explicit ReplayEvaluator(const std::string& path);
    /// Takes frames already in memory (the demo, tests).
    ReplayEvaluator(FrameFile frames, std::string source);

    std::string name() const override { return "replay"; }
    Index pointCount() const override { return points_; }
    Index channelCount() const override { return channels_; }
    Index frameCount() const override { return frames_; }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override;
    void evaluateAll(Index frame, double* out) const override;

    /// The dtype the frames were recorded in (outputs are written in it).
    NpyDtype dtype() const { return dtype_; }
    const std::string& source() const { return source_; }

private:
    void checkFrame(Index frame) const;

    std::unique_ptr<const MappedFrames> mapped_;  ///< from a path
    FrameFile memory_;                            ///< or frames handed over in memory
    std::string source_;
    Index frames_ = 0, points_ = 0, channels_ = 0;
    NpyDtype dtype_ = NpyDtype::Float64;
};

}  // namespace pmsc::evaluators
