#include "nodes/FramePlan.h"

#include "pmsc/Errors.h"

#include <algorithm>
#include <numeric>
#include <string>

namespace pmsc::nodes {

FramePlan FramePlan::make(const Model& model, std::span<const Index> wanted, Index chunkPoints,
                          bool wholeFrame, std::span<const Index> keySentinels) {
    if (chunkPoints <= 0) {
        throw InputError("engine: chunk size must be positive, got " + std::to_string(chunkPoints));
    }
    FramePlan plan;
    plan.points = model.points;
    plan.channels = model.channels;
    plan.wholeFrame = wholeFrame;

    if (wanted.empty()) {
        plan.outputPoints.resize(static_cast<size_t>(model.points));
        std::iota(plan.outputPoints.begin(), plan.outputPoints.end(), Index{0});
    } else {
        std::vector<char> seen(static_cast<size_t>(model.points), 0);
        for (const Index p : wanted) {
            if (p < 0 || p >= model.points) {
                throw InputError("engine: wanted point " + std::to_string(p) + " outside [0, " +
                                 std::to_string(model.points) + ")");
            }
            if (seen[static_cast<size_t>(p)]++) {
                throw InputError("engine: wanted point " + std::to_string(p) + " listed twice");
            }
        }
        plan.outputPoints.assign(wanted.begin(), wanted.end());
    }
    const Index n = plan.outputCount();
    plan.allPoints = n == model.points;
    for (Index i = 0; plan.allPoints && i < n; ++i) plan.allPoints = plan.outputPoints[size_t(i)] == i;

    std::vector<Index> keyNumberOf(static_cast<size_t>(model.points), -1);
    for (Index k = 0; k < model.keyCount(); ++k) keyNumberOf[size_t(model.keyPoints[size_t(k)])] = k;
    // Training never makes a key a sentinel; a point that were both would copy the key's value.
    for (size_t i = 0; i < keySentinels.size(); ++i) {
        Index& number = keyNumberOf[size_t(keySentinels[i])];
        if (number < 0) number = model.keyCount() + Index(i);
    }
    plan.keySentinels = !keySentinels.empty();

    // Whole-frame fail-through: one branch whose evaluateAll() covers everything.
    const Index step = wholeFrame ? std::max<Index>(n, 1) : chunkPoints;
    for (Index first = 0; first < n || (n == 0 && plan.chunks.empty()); first += step) {
        Chunk chunk;
        chunk.firstOutput = first;
        chunk.outputCount = std::min(step, n - first);
        for (Index i = first; i < first + chunk.outputCount; ++i) {
            const Index p = plan.outputPoints[size_t(i)];
            const Index k = keyNumberOf[size_t(p)];
            if (k >= 0) {
                chunk.keyOutput.push_back(i);
                chunk.keyNumber.push_back(k);
            } else {
                chunk.evalPoints.push_back(p);
                chunk.evalOutput.push_back(i);
            }
        }
        plan.chunks.push_back(std::move(chunk));
        if (n == 0) break;
    }
    return plan;
}

}  // namespace pmsc::nodes
