#include "nodes/Blender.h"

namespace pmsc::nodes {

void Blender::operator()(FrameSlot& slot, Index chunkIndex) const {
    const double w = slot.decision.weight;
    if (slot.failed() || slot.decision.state != CacheState::Blend) return;
    const FramePlan::Chunk& chunk = plan_.chunks[static_cast<size_t>(chunkIndex)];
    const Index c = plan_.channels;
    const Index n = chunk.outputCount * c;
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
    // Element by element, the same expression whatever the chunking or thread count.
    for (Index i = 0; i < n; ++i) out[i] = (1.0 - w) * pm[i] + w * out[i];
}

}  // namespace pmsc::nodes
