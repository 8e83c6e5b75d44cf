// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

namespace pmsc {

/// Mixin an evaluator (a PointEvaluator) inherits when its points have places in space that its
/// values are not: light gathered at surface points or scattered at voxels. Training reads them
/// for what needs distances between points (regions, key neighbours, sentinels), which values that
/// are themselves positions (a face) give by their mean. `pmsc export-frames --positions` writes
/// them for `pmsc train --positions`. Not part of PointEvaluator so that evaluators whose points
/// have no place (a recording) stay unchanged.
class PointPositionsProvider {
public:
    virtual ~PointPositionsProvider() = default;

    /// The points' positions in world units: one frame of N points x 3 channels (x, y, z), point
    /// order, the same for every frame.
    virtual FrameSet pointPositions() const = 0;
};

}  // namespace pmsc
