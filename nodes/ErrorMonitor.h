// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "nodes/FrameSlot.h"
#include "pmsc/HitCheck.h"
#include "pmsc/PointEvaluator.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/RegionMultiplier.h"
#include "pmsc/SoftCache.h"

namespace pmsc::nodes {

/// Where a frame goes after the error monitor.
enum class Route : int {
    Reconstruct = 0,  ///< a hit: point multiplication only
    FailThrough = 1,  ///< a blend or a miss: the fail-through branches
    Done = 2,         ///< a failed frame: straight to the sink
    Local = 3,        ///< local fail-through: one branch per region
    Check = 4,        ///< a hit whose check points must be computed first (ErrorMonitor::check)
};

/// Step 3 (section 5): the key points' RMS error decides hit / blend / miss
/// and the weight of the full result. Non-finite key values are a miss with
/// weight 1 (the PM result would be built from garbage). Thread-safe.
class ErrorMonitor {
public:
    static constexpr const char* kName = "monitor";

    /// @param[in] keepPm  the PM result is wanted for every frame (diagnostics), so a miss
    ///                    with finite keys still goes through reconstruction first
    ErrorMonitor(const PointMultiplier& pm, SoftCachePolicy policy, bool keepPm)
        : pm_(pm), policy_(policy), keepPm_(keepPm), check_(pm.model(), pm) {}
    /// With local fail-through: a frame that does not hit as a whole is decided region
    /// by region (each region's own projection, key error and thresholds). It goes the local
    /// route unless its feathered weights send more than the regions' largest local fraction of
    /// the points to the full calculation; then, like a frame whose keys are not finite, it fails
    /// through whole as before. A global hit stays a global hit: a frame the whole-frame test
    /// accepts is reconstructed exactly as without regions.
    /// The region keys (LocalRegions::extraKeyPoints) are evaluated here, through `evaluator`,
    /// only for such frames: a hit costs what it cost without regions. An evaluator failure
    /// there fails the frame.
    /// With `evaluator`, a hit that one part of the predicted error alone certifies is checked
    /// (HitCheck): the check's points are computed through `evaluator`, and a hit that fails the
    /// check is computed whole and blended with weight 0; every hit, and the points a local frame
    /// hands back as PM alone, when the model has sentinels. `piecePoints` > 0: those points are
    /// evaluated in parallel pieces of that many (EngineOptions::keyPiecePoints, as the keys).
    ErrorMonitor(const PointMultiplier& pm, SoftCachePolicy policy, bool keepPm,
                 const RegionMultiplier* regions, const PointEvaluator* evaluator, Index piecePoints = 0)
        : pm_(pm),
          policy_(policy),
          keepPm_(keepPm),
          regions_(regions),
          evaluator_(evaluator),
          piecePoints_(piecePoints),
          check_(pm.model(), pm) {}

    /// The whole decision: decide(), then check() where it asks for one. Never Route::Check.
    Route operator()(FrameSlot& slot) const;
    /// The decision up to a hit's check: Route::Check for a hit HitCheck::needed, whose check
    /// points are not computed yet (a caller may show the hit's point multiplication meanwhile).
    Route decide(FrameSlot& slot) const;
    /// A frame decide() sent to Route::Check: computes the check's points; a hit, or the whole
    /// frame (blended with weight 0).
    Route check(FrameSlot& slot) const;

private:
    /// A local frame: computes the sentinels it would hand back as PM alone (`checked` of them);
    /// the regions of those PM misses fail through too (`full` becomes the new count of points
    /// computed in full). False when the evaluator failed.
    bool checkLocal(FrameSlot& slot, Index& full, Index& checked) const;
    /// The frame's whole-frame route when it does not hit (regions did not take it locally).
    Route whole(FrameSlot& slot) const;
    /// Check points' values into `out`: the sentinels among `points` from the slot when the key node
    /// computed them (FrameSlot::sentinelsComputed), the others through evaluateInto().
    bool checkValuesInto(FrameSlot& slot, std::span<const Index> points, double* out, const char* what) const;
    /// Evaluates `points` of the slot's frame into `out`; false (the frame failed) on an exception.
    bool evaluateInto(FrameSlot& slot, std::span<const Index> points, double* out, const char* what) const;

    const PointMultiplier& pm_;
    SoftCachePolicy policy_;
    bool keepPm_;
    const RegionMultiplier* regions_ = nullptr;
    const PointEvaluator* evaluator_ = nullptr;
    Index piecePoints_ = 0;
    HitCheck check_;
};

}  // namespace pmsc::nodes
