// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

// Header-only run vocabulary (see nodes/FrameSink.h): the frames a run covers.

#include "pmsc/PointEvaluator.h"  // Index

namespace pmsc {

/// A range of evaluator frames: first, first+step, ..., `count` frames in all.
struct FrameRange {
    Index first = 0;
    Index count = 0;
    Index step = 1;  ///< > 0
    Index frame(Index sequence) const { return first + sequence * step; }
    Index last() const { return frame(count - 1); }
};

}  // namespace pmsc
