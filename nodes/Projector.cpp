#include "nodes/Projector.h"

namespace pmsc::nodes {

void Projector::operator()(FrameSlot& slot) const {
    if (slot.failed() || !slot.keysFinite) return;
    pm_.project(slot.keyValues.data(), slot.coords.data());
}

}  // namespace pmsc::nodes
