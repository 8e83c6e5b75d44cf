// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FrameSlot.h"
#include "pmsc/PointEvaluator.h"
#include "pmsc/RegionMultiplier.h"

namespace pmsc::nodes {

/// One region of a locally failed-through frame (issue 9; paper section 9, "compute the full
/// calculation on a subset of the domain"): the engine sends a frame's regions as separate
/// messages to an unlimited node, so the regions' point multiplications and the failing
/// regions' full evaluations run as parallel branches.
///
/// Branch r reconstructs region r's points from its own coordinates (unless its weight is 1:
/// nothing of that PM would be used) and, when its weight is above 0, evaluates its fail set
/// (its points and its feather band) into its part of the slot's full-values buffer. Branches
/// write disjoint parts of the slot. An evaluator failure or a non-finite value fails the frame.
/// Thread-safe (concurrent regions and frames).
class LocalBranch {
public:
    static constexpr const char* kName = "local";

    LocalBranch(const PointEvaluator& evaluator, const RegionMultiplier& regions, Index channels)
        : evaluator_(evaluator), regions_(regions), channels_(channels) {}

    void operator()(FrameSlot& slot, Index region) const;

private:
    const PointEvaluator& evaluator_;
    const RegionMultiplier& regions_;
    Index channels_;
};

/// The end of a locally failed-through frame, after every branch: the feathered blend
/// out_p = (1 - w_p) PM_p + w_p full_p for every point with w_p > 0 (the same expression as the
/// whole-frame Blender). Runs once per frame, in the task of the frame's last branch.
class LocalCombiner {
public:
    static constexpr const char* kName = "feather";

    LocalCombiner(const RegionMultiplier& regions, Index channels) : regions_(regions), channels_(channels) {}

    void operator()(FrameSlot& slot) const;

private:
    const RegionMultiplier& regions_;
    Index channels_;
};

}  // namespace pmsc::nodes
