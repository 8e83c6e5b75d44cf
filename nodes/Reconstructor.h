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
    /// when the frame goes on to a fail-through and the PM result is kept.
    /// @return true if the frame is finished (a hit), false if it continues to the fail-through
    bool operator()(FrameSlot& slot) const;

private:
    const PointMultiplier& pm_;
    const FramePlan& plan_;
};

}  // namespace pmsc::nodes
