// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FrameSink.h"
#include "nodes/FrameSlot.h"
#include "nodes/RunControl.h"
#include "pmsc/SoftCache.h"

namespace pmsc::nodes {

/// The serial, in-order end of the graph (after the sequencer): hands each
/// finished frame to the user's FrameSink, applies the failure policy, and counts.
/// Decision: under StopRun the sink sees exactly the frames before the first
/// failing frame in range order, whatever the thread count, so a caller can
/// keep or delete a deterministic prefix.
class OrderedSink {
public:
    OrderedSink(const FramePlan& plan, FrameSink& sink, FailurePolicy policy, RunControl& control);

    /// Delivers (or drops) the frame in `slot`. Not reentrant: one call at a time.
    void operator()(FrameSlot& slot);

private:
    const FramePlan& plan_;
    FrameSink& sink_;
    FailurePolicy policy_;
    RunControl& control_;
    Index expected_ = 0;
};

}  // namespace pmsc::nodes
