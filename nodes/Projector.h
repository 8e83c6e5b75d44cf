// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FrameSlot.h"
#include "pmsc/PointMultiplier.h"

namespace pmsc::nodes {

/// Step 2 (section 6): the least-squares projection of the key values onto the
/// basis, giving the frame's pose-space coordinates. A few hundred
/// multiply-adds; skipped for a failed frame or non-finite keys. Thread-safe.
class Projector {
public:
    static constexpr const char* kName = "project";

    explicit Projector(const PointMultiplier& pm) : pm_(pm) {}
    void operator()(FrameSlot& slot) const;

private:
    const PointMultiplier& pm_;
};

}  // namespace pmsc::nodes
