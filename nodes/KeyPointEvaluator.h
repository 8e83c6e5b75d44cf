// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FrameSlot.h"
#include "pmsc/Model.h"
#include "pmsc/PointEvaluator.h"

namespace pmsc::nodes {

/// Step 1 of the runtime (section 6): the expensive evaluator runs on the key
/// points only. An evaluator exception becomes a failure of the frame (the
/// sink applies the policy). Non-finite key values are not an error: they mark
/// the frame for a full fail-through (section 5's safety net), see FrameSlot::keysFinite.
/// Thread-safe (concurrent frames).
class KeyPointEvaluator {
public:
    static constexpr const char* kName = "keys";

    KeyPointEvaluator(const Model& model, const PointEvaluator& evaluator)
        : model_(model), evaluator_(evaluator) {}

    void operator()(FrameSlot& slot) const;

private:
    const Model& model_;
    const PointEvaluator& evaluator_;
};

}  // namespace pmsc::nodes
