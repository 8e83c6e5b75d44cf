#include "nodes/KeyPointEvaluator.h"

#include <cmath>

namespace pmsc::nodes {

void KeyPointEvaluator::operator()(FrameSlot& slot) const {
    try {
        evaluator_.evaluate(slot.frame, model_.keyPoints, slot.keyValues.data());
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
