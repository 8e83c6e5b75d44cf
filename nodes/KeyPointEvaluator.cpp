#include "nodes/KeyPointEvaluator.h"

#include "nodes/PointPieces.h"

#include <cmath>

namespace pmsc::nodes {

void KeyPointEvaluator::operator()(FrameSlot& slot) const {
    try {
        evaluateInPieces(evaluator_, slot.frame, model_.keyPoints, model_.channels, piecePoints_,
                         slot.keyValues.data());
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
