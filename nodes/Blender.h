// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FrameSlot.h"
#include "pmsc/PointMultiplier.h"

namespace pmsc::nodes {

/// Section 5's transition zone, per fail-through chunk: output =
/// (1 - w) * PM + w * full, point by point, with w the frame's weight of
/// the full result, raised at a point whose PM value is over the model's tolerance
/// (pmsc::blendPoints), so no blended point is handed back over it. Runs after the chunk's full evaluation;
/// reconstructs the PM values of the same chunk (unless kept from the Reconstructor), so a blended frame's
/// reconstruction is split across cores as well. A no-op for a miss (w == 1). Thread-safe (disjoint chunks).
class Blender {
public:
    static constexpr const char* kName = "blend";

    Blender(const PointMultiplier& pm, const FramePlan& plan) : pm_(pm), plan_(plan) {}

    void operator()(FrameSlot& slot, Index chunk) const;

private:
    const PointMultiplier& pm_;
    const FramePlan& plan_;
};

}  // namespace pmsc::nodes
