#include "nodes/Reconstructor.h"

namespace pmsc::nodes {

bool Reconstructor::operator()(FrameSlot& slot) const {
    const bool hit = slot.decision.state == CacheState::Hit;
    double* out = hit ? slot.values.data() : slot.pmValues.data();
    if (plan_.allPoints) {
        pm_.reconstruct(slot.coords.data(), out);
    } else {
        pm_.reconstructPoints(slot.coords.data(), plan_.outputPoints, out);
    }
    slot.pmValid = !hit;
    return hit;
}

}  // namespace pmsc::nodes
