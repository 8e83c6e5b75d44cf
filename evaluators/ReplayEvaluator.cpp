#include "evaluators/ReplayEvaluator.h"

#include <algorithm>
#include <stdexcept>
#include <utility>

namespace pmsc::evaluators {

ReplayEvaluator::ReplayEvaluator(const std::string& path)
    : mapped_(std::make_unique<const MappedFrames>(path)),
      source_(path),
      frames_(mapped_->info().frames),
      points_(mapped_->info().points),
      channels_(mapped_->info().channels),
      dtype_(mapped_->info().dtype) {}

ReplayEvaluator::ReplayEvaluator(FrameFile frames, std::string source)
    : memory_(std::move(frames)),
      source_(std::move(source)),
      frames_(memory_.frames.frames),
      points_(memory_.frames.points),
      channels_(memory_.frames.channels),
      dtype_(memory_.dtype) {}

void ReplayEvaluator::checkFrame(Index frame) const {
    if (frame < 0 || frame >= frameCount())
        throw std::out_of_range("replay: frame " + std::to_string(frame) + " outside the " +
                                std::to_string(frameCount()) + " frames of " + source_);
}

void ReplayEvaluator::evaluate(Index frame, std::span<const Index> points, double* out) const {
    checkFrame(frame);
    if (mapped_) {
        mapped_->read(frame, points, out);
        return;
    }
    const Index c = channelCount();
    const double* values = memory_.frames.frame(frame);
    for (std::size_t i = 0; i < points.size(); ++i) {
        const Index p = points[i];
        if (p < 0 || p >= pointCount())
            throw std::out_of_range("replay: point " + std::to_string(p) + " outside [0, " +
                                    std::to_string(pointCount()) + ")");
        std::copy_n(values + p * c, c, out + static_cast<Index>(i) * c);
    }
}

void ReplayEvaluator::evaluateAll(Index frame, double* out) const {
    checkFrame(frame);
    if (mapped_) {
        mapped_->readFrame(frame, out);
        return;
    }
    std::copy_n(memory_.frames.frame(frame), memory_.frames.rows(), out);
}

}  // namespace pmsc::evaluators
