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

FrameSet evaluateFrames(const PointEvaluator& evaluator, Index first, Index count) {
    if (first < 0 || count <= 0 || first + count > evaluator.frameCount()) {
        throw std::out_of_range("evaluateFrames: frames [" + std::to_string(first) + ", " +
                                std::to_string(first + count) + ") outside the " +
                                std::to_string(evaluator.frameCount()) + " frames of evaluator '" +
                                evaluator.name() + "'");
    }
    FrameSet set(count, evaluator.pointCount(), evaluator.channelCount());
    for (Index f = 0; f < count; ++f) evaluator.evaluateAll(first + f, set.frame(f));
    return set;
}

}  // namespace pmsc
