#include "nodes/KeyPointEvaluator.h"

#include "nodes/PointPieces.h"

#include <algorithm>
#include <cmath>

namespace pmsc::nodes {

KeyPointEvaluator::KeyPointEvaluator(const Model& model, const PointEvaluator& evaluator, Index piecePoints,
                                     std::span<const Index> sentinels)
    : model_(model), evaluator_(evaluator), piecePoints_(piecePoints) {
    if (sentinels.empty()) return;
    keysThenSentinels_ = model.keyPoints;
    keysThenSentinels_.insert(keysThenSentinels_.end(), sentinels.begin(), sentinels.end());
}

void KeyPointEvaluator::operator()(FrameSlot& slot) const {
    const Index c = model_.channels;
    try {
        if (keysThenSentinels_.empty()) {
            evaluateInPieces(evaluator_, slot.frame, model_.keyPoints, c, piecePoints_,
                             slot.keyValues.data());
        } else {
            thread_local std::vector<double> values;
            values.resize(keysThenSentinels_.size() * size_t(c));
            evaluateInPieces(evaluator_, slot.frame, keysThenSentinels_, c, piecePoints_, values.data());
            const auto keys = static_cast<std::ptrdiff_t>(slot.keyValues.size());
            std::copy(values.begin(), values.begin() + keys, slot.keyValues.begin());
            std::copy(values.begin() + keys, values.end(), slot.sentinelValues.begin());
            slot.sentinelsComputed = true;
        }
    } catch (const std::exception& e) {
        slot.fail(kName, "evaluator '" + evaluator_.name() + "': " + e.what());
        return;
    } catch (...) {
        slot.fail(kName, "evaluator '" + evaluator_.name() + "': unknown exception");
        return;
    }
    bool finite = true;
    for (const double v : slot.keyValues) finite = finite && std::isfinite(v);
    slot.keysFinite = finite;
}

}  // namespace pmsc::nodes
