#include "nodes/FailThroughEvaluator.h"

#include <cmath>
#include <string>

namespace pmsc::nodes {

namespace {

/// The index of the first non-finite value, or -1.
Index firstNonFinite(const double* v, Index n) {
    for (Index i = 0; i < n; ++i) {
        if (!std::isfinite(v[i])) return i;
    }
    return -1;
}

}  // namespace

void FailThroughEvaluator::operator()(FrameSlot& slot, Index chunkIndex) const {
    const FramePlan::Chunk& chunk = plan_.chunks[static_cast<size_t>(chunkIndex)];
    const Index c = plan_.channels;
    double* out = slot.values.data() + chunk.firstOutput * c;
    const std::span<const Index> rangePoints(plan_.outputPoints.data() + chunk.firstOutput,
                                             static_cast<size_t>(chunk.outputCount));
    try {
        if (plan_.wholeFrame) {
            if (plan_.allPoints) {
                evaluator_.evaluateAll(slot.frame, out);
            } else {
                evaluator_.evaluateAll(slot.frame, slot.scratch.data());
                for (Index i = 0; i < chunk.outputCount; ++i) {
                    const double* src = slot.scratch.data() + rangePoints[size_t(i)] * c;
                    for (Index ch = 0; ch < c; ++ch) out[i * c + ch] = src[ch];
                }
            }
        } else if (!slot.keysFinite || chunk.keyOutput.empty() ||
                   (plan_.keySentinels && !slot.sentinelsComputed)) {
            // No key values to reuse: evaluate the range straight into the output.
            evaluator_.evaluate(slot.frame, rangePoints, out);
        } else {
            // Evaluate the non-key points into this chunk's part of the scratch buffer, then
            // scatter them and the already known key values into the output range.
            double* tmp = slot.scratch.data() + chunk.firstOutput * c;
            evaluator_.evaluate(slot.frame, chunk.evalPoints, tmp);
            for (size_t i = 0; i < chunk.evalOutput.size(); ++i) {
                double* dst = slot.values.data() + chunk.evalOutput[i] * c;
                for (Index ch = 0; ch < c; ++ch) dst[ch] = tmp[Index(i) * c + ch];
            }
            const Index keys = Index(slot.keyValues.size()) / c;
            for (size_t j = 0; j < chunk.keyOutput.size(); ++j) {
                double* dst = slot.values.data() + chunk.keyOutput[j] * c;
                const Index number = chunk.keyNumber[j];
                const double* src = number < keys ? slot.keyValues.data() + number * c
                                                  : slot.sentinelValues.data() + (number - keys) * c;
                for (Index ch = 0; ch < c; ++ch) dst[ch] = src[ch];
            }
        }
    } catch (const std::exception& e) {
        slot.fail(kName, "evaluator '" + evaluator_.name() + "': " + e.what(), chunkIndex);
        return;
    } catch (...) {
        slot.fail(kName, "evaluator '" + evaluator_.name() + "': unknown exception", chunkIndex);
        return;
    }
    // The output never holds a NaN: a full evaluation that yields one is the evaluator's failure.
    const Index bad = firstNonFinite(out, chunk.outputCount * c);
    if (bad >= 0) {
        const Index point = rangePoints[size_t(bad / c)];
        slot.fail(kName,
                  "evaluator '" + evaluator_.name() + "' returned " + std::to_string(out[bad]) +
                      " at point " + std::to_string(point) + " channel " + std::to_string(bad % c),
                  chunkIndex);
    }
}

}  // namespace pmsc::nodes
