// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FrameRange.h"
#include "nodes/RunControl.h"

namespace pmsc::nodes {

/// The head of the graph (body of an input_node): stamps each frame with its
/// sequence number 0, 1, 2, ..., which the sequencer uses to restore order.
/// Stops at the end of the range, when the run is cancelled, or past the stop
/// point of a StopRun failure. Serial (input_node calls it from one thread at a time).
class FrameSource {
public:
    FrameSource(FrameRange range, RunControl& control) : range_(range), control_(control) {}

    /// @param[out] sequence the next sequence number
    /// @return false when there is nothing more to start
    bool next(Index& sequence);

private:
    FrameRange range_;
    RunControl& control_;
    Index next_ = 0;
};

}  // namespace pmsc::nodes
