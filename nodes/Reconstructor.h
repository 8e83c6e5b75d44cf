// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FrameSlot.h"
#include "pmsc/PointMultiplier.h"

namespace pmsc::nodes {

/// Step 4 for a hit (section 6): the point-multiplication reconstruction of the
/// output points only — all N, or the consumer's subset, so a query for a few
/// points costs a few rows of the basis, not all of them. Thread-safe.
class Reconstructor {
public:
    static constexpr const char* kName = "reconstruct";

    Reconstructor(const PointMultiplier& pm, const FramePlan& plan) : pm_(pm), plan_(plan) {}

    /// Writes the PM result into slot.values (a hit), or into slot.pmValues
    /// when the frame goes on to a fail-through and the PM result is kept. A frame estimate()
    /// reconstructed already is not reconstructed again: a hit takes the estimate's buffer.
    /// @return true if the frame is finished (a hit), false if it continues to the fail-through
    bool operator()(FrameSlot& slot) const;
    /// Writes the PM result into slot.pmValues (which must be kept) whatever the decision: the
    /// estimate of a hit shown before its check (EngineOptions::estimateBeforeCheck).
    void estimate(FrameSlot& slot) const;

private:
    /// The PM result of the plan's output points into `out`.
    void reconstructInto(const FrameSlot& slot, double* out) const;

    const PointMultiplier& pm_;
    const FramePlan& plan_;
};

}  // namespace pmsc::nodes
