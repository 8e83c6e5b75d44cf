// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FrameSlot.h"
#include "pmsc/PointEvaluator.h"

namespace pmsc::nodes {

/// One branch of a frame's fail-through (section 5: "go on to perform the full
/// calculation on all of the points"): the evaluator on one chunk of the
/// output points. The engine sends a frame's chunks as separate messages to an
/// unlimited-concurrency node, so one missed frame keeps every core busy.
///
/// Each chunk writes only its own output range, so the result does not depend
/// on how chunks are scheduled. Key points are not re-evaluated (FramePlan);
/// when the frame's keys were not finite, the whole range is evaluated. A
/// non-finite value from the evaluator fails the frame: the output never holds
/// a NaN. Thread-safe (concurrent chunks and frames).
class FailThroughEvaluator {
public:
    static constexpr const char* kName = "fail-through";

    FailThroughEvaluator(const PointEvaluator& evaluator, const FramePlan& plan)
        : evaluator_(evaluator), plan_(plan) {}

    void operator()(FrameSlot& slot, Index chunk) const;

private:
    const PointEvaluator& evaluator_;
    const FramePlan& plan_;
};

}  // namespace pmsc::nodes
