#include "nodes/Blender.h"

#include "pmsc/SoftCache.h"

namespace pmsc::nodes {

void Blender::operator()(FrameSlot& slot, Index chunkIndex) const {
    const double w = slot.decision.weight;
    if (slot.failed() || slot.decision.state != CacheState::Blend) return;
    const FramePlan::Chunk& chunk = plan_.chunks[static_cast<size_t>(chunkIndex)];
    const Index c = plan_.channels;
    const double* pm;
    if (slot.pmValid) {
        pm = slot.pmValues.data() + chunk.firstOutput * c;
    } else {
        // The fail-through of this chunk is done with its part of the scratch buffer.
        double* tmp = slot.scratch.data() + chunk.firstOutput * c;
        if (plan_.allPoints) {
            pm_.reconstructRange(slot.coords.data(), chunk.firstOutput, chunk.outputCount, tmp);
        } else {
            pm_.reconstructPoints(slot.coords.data(),
                                  std::span<const Index>(plan_.outputPoints.data() + chunk.firstOutput,
                                                         static_cast<size_t>(chunk.outputCount)),
                                  tmp);
        }
        pm = tmp;
    }
    double* out = slot.values.data() + chunk.firstOutput * c;
    // Point by point, the same expression whatever the chunking or thread count; `out` holds the
    // full values. The weight is raised where PM is over the tolerance (guardedWeight).
    blendPoints(w, pm_.model().tolerance, c, pm, out, out, chunk.outputCount);
}

}  // namespace pmsc::nodes
