// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FrameSlot.h"
#include "pmsc/PointEvaluator.h"
#include "pmsc/RegionMultiplier.h"

namespace pmsc::nodes {

/// The branches of a locally failed-through frame (paper section 9, "compute the full
/// calculation on a subset of the domain"). The engine sends a local frame as messages() separate
/// messages to an unlimited node, so they run as parallel branches:
///  - messages 0 .. R-1, one per region: region r reconstructs its points from its own
///    coordinates (unless its weight is 1: nothing of that PM would be used);
///  - messages R .. R+P-1, one per piece: the frame's fully evaluated points (those with
///    w_p > 0, the union of the failing regions' fail sets; FrameSlot::localPoints) split into
///    P pieces of `piecePoints` (one piece when piecePoints is 0: an evaluator whose subset
///    poses share work, like the face rig's relax rings, poses the union's closure once), or
///    into `pieceCount` pieces of equal size when that is given (an evaluator whose every call
///    pays a set-up: one piece per thread).
///
/// Decision: the union, not one evaluation per failing region. On the ICT face's novel set the
/// failing regions' fail sets held 19,960 points a frame against 14,688 in their union (bands
/// shared by neighbours that fail together), and posing them region by region cost 30.2 ms
/// against 20.9 ms for the union in one call (one closure instead of dozens of small ones).
///
/// Branches write disjoint parts of the slot. An evaluator failure or a non-finite value fails
/// the frame. Thread-safe (concurrent branches and frames).
class LocalBranch {
public:
    static constexpr const char* kName = "local";

    /// @param piecePoints points per piece of the full evaluation; 0 = one piece
    /// @param pieceCount  > 0: that many pieces (at most one a point) instead of piecePoints
    LocalBranch(const PointEvaluator& evaluator, const RegionMultiplier& regions, Index channels,
                Index piecePoints, Index pieceCount = 0)
        : evaluator_(evaluator),
          regions_(regions),
          channels_(channels),
          piecePoints_(piecePoints),
          pieceCount_(pieceCount) {}

    /// How many branch messages the local frame in `slot` takes (regions, then pieces).
    Index messages(const FrameSlot& slot) const;
    void operator()(FrameSlot& slot, Index message) const;

private:
    void evaluatePiece(FrameSlot& slot, Index piece) const;
    /// Points per piece of the local frame in `slot`; 0 = one piece.
    Index piecePoints(const FrameSlot& slot) const;

    const PointEvaluator& evaluator_;
    const RegionMultiplier& regions_;
    Index channels_;
    Index piecePoints_;
    Index pieceCount_;
};

/// The end of a locally failed-through frame, after every branch: the feathered blend
/// out_p = (1 - w_p) PM_p + w_p full_p for every point with w_p > 0, w_p raised where PM_p is over
/// the tolerance (pmsc::blendPoints, the same expression as the whole-frame Blender). Runs once per frame, in
/// the task of the frame's last branch.
class LocalCombiner {
public:
    static constexpr const char* kName = "feather";

    /// @param tolerance the model's T: a point's weight is raised where its PM value is further
    ///                  than T from its full value (pmsc::guardedWeight); 0: never
    LocalCombiner(Index channels, double tolerance) : channels_(channels), tolerance_(tolerance) {}

    void operator()(FrameSlot& slot) const;

private:
    Index channels_;
    double tolerance_;
};

}  // namespace pmsc::nodes
