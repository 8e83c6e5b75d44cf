#include "pmsc/PointEvaluator.h"

#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace pmsc {

void PointEvaluator::evaluateAll(Index frame, double* out) const {
    std::vector<Index> all(static_cast<size_t>(pointCount()));
    std::iota(all.begin(), all.end(), Index{0});
    evaluate(frame, all, out);
}

void PointEvaluator::evaluateAllFrames(std::span<const Index> frames, double* out) const {
    const std::size_t frameValues = static_cast<std::size_t>(pointCount() * channelCount());
    for (std::size_t k = 0; k < frames.size(); ++k) evaluateAll(frames[k], out + k * frameValues);
}

FrameSet evaluateFrames(const PointEvaluator& evaluator, Index first, Index count) {
    if (first < 0 || count <= 0 || first + count > evaluator.frameCount()) {
        throw std::out_of_range("evaluateFrames: frames [" + std::to_string(first) + ", " +
                                std::to_string(first + count) + ") outside the " +
                                std::to_string(evaluator.frameCount()) + " frames of evaluator '" +
                                evaluator.name() + "'");
    }
    FrameSet set(count, evaluator.pointCount(), evaluator.channelCount());
    std::vector<Index> frames(static_cast<std::size_t>(count));
    std::iota(frames.begin(), frames.end(), first);
    evaluator.evaluateAllFrames(frames, set.frame(0));
    return set;
}

}  // namespace pmsc
