// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FrameSlot.h"
#include "pmsc/Model.h"
#include "pmsc/PointEvaluator.h"

#include <span>
#include <vector>

namespace pmsc::nodes {

/// Step 1 of the runtime (section 6): the expensive evaluator runs on the key
/// points only. An evaluator exception becomes a failure of the frame (the
/// sink applies the policy). Non-finite key values are not an error: they mark
/// the frame for a full fail-through (section 5's safety net), see FrameSlot::keysFinite.
/// Thread-safe (concurrent frames).
class KeyPointEvaluator {
public:
    static constexpr const char* kName = "keys";

    /// @param piecePoints > 0: the keys are evaluated in parallel pieces of this many points
    ///        (EngineOptions::keyPiecePoints); 0: in one call.
    /// @param sentinels   non-empty: these points (HitCheck::sentinels(), ascending) are evaluated
    ///        in the keys' call, into FrameSlot::sentinelValues, for an evaluator whose calls share
    ///        work between their points (see Engine.cpp, sentinelsWithTheKeys).
    KeyPointEvaluator(const Model& model, const PointEvaluator& evaluator, Index piecePoints = 0,
                      std::span<const Index> sentinels = {});

    void operator()(FrameSlot& slot) const;

private:
    const Model& model_;
    const PointEvaluator& evaluator_;
    Index piecePoints_;
    /// The one call's points: the keys, then the sentinels (empty: the keys alone).
    std::vector<Index> keysThenSentinels_;
};

}  // namespace pmsc::nodes
