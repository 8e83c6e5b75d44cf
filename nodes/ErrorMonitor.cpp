#include "nodes/ErrorMonitor.h"

#include <limits>

namespace pmsc::nodes {

Route ErrorMonitor::operator()(FrameSlot& slot) const {
    if (slot.failed()) return Route::Done;
    if (!slot.keysFinite) {
        slot.keyRmsError = std::numeric_limits<double>::quiet_NaN();
        slot.decision = CacheDecision{CacheState::Miss, 1.0};
        return Route::FailThrough;
    }
    slot.keyRmsError = pm_.keyRmsError(slot.keyValues.data(), slot.coords.data());
    slot.decision = policy_.decide(slot.keyRmsError);
    if (slot.decision.state == CacheState::Hit || keepPm_) return Route::Reconstruct;
    return Route::FailThrough;
}

}  // namespace pmsc::nodes
