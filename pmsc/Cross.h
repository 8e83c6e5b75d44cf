// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/CrossState.h"
#include "pmsc/FrameSet.h"
#include "pmsc/Model.h"
#include "pmsc/ModelSections.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/Training.h"

#include <vector>

namespace pmsc {

/// Cross point multiplication (paper section 7): "the animator poses the control face
/// and the system uses the control face points to find the projection into the joint (control
/// face, simulated face) subspace and computes the corresponding simulated face. ... the Soft
/// Cache fail through to a full calculation is not possible."
struct CrossOptions {
    /// Subspace and key options, as `pmsc train` (M rule, key budget, selector, fiducials, ...).
    /// Fiducials and grid points are control point indices. `tolerance`, if set, is kept in the
    /// model (frames whose bound exceeds it are flagged); there is no eps to calibrate. Regions and
    /// a learning rank are refused: neither applies without a fail-through.
    TrainingOptions training;
    double coverage = 0.9;  ///< of the error bound (CrossState), in (0, 1)
    Index slices = 5;       ///< leave-one-slice-out folds of the training pairs that score the bound
};

struct CrossReport {
    TrainingReport training;  ///< the joint training (its calibration field is unused)
    Index controlPoints = 0, targetPoints = 0;
    /// Fraction of the held-out training pairs inside their bound (>= coverage by construction
    /// up to ties; the honest check is on frames training never saw).
    double heldOutCoverage = 0;
    double seconds = 0;         ///< training + scoring
    double scoringSeconds = 0;  ///< the leave-one-slice-out scoring alone
};

/// Learns a cross model from (control, target) pairs: frame f of `control` and frame f of
/// `target` are one pair. Same frame count and channel count; point counts may differ.
///
/// The joint matrix stacks each pair's control points above its target points (the model's
/// points: control first). Mean, SVD and M as `pmsc train`; keys by the model's selector with
/// candidates restricted to control points (TrainingOptions::keyCandidates), so the selection
/// still minimises the joint PM residual — control and target — over the training pairs. The
/// projector is pinv of the joint basis' control key rows, so run time needs only the control's
/// key points.
///
/// The bound: `slices` contiguous folds; for each, the joint mean and basis are recomputed without
/// it (keys kept, Calibration.h's frame-space route), and each held-out pair gives its control key
/// RMS e_f and its target's largest point error E_f. scale = median e_f; quantile = the
/// ceil((n+1) coverage)-th smallest E_f / (e_f + scale) (conformalQuantile). Promise: for a pair
/// exchangeable with the held-out training pairs, P(E > quantile (e + scale)) <= 1 - coverage
/// (split-conformal, with two approximations stated in docs/face.md: the scores come from fold
/// models trained on (S-1)/S of the pairs, not the final model, and the scale is taken from the
/// same scores).
/// @throws InputError for pairs that do not match (frame or channel counts), too few frames,
///         NaN/Inf, frames that do not vary; std::invalid_argument for bad options.
Model trainCross(const FrameSet& control, const FrameSet& target, const CrossOptions& options,
                 CrossReport* report = nullptr);

/// The run time of a cross model: the control's key values in, the target out.
/// Thread safety: const methods may run concurrently. Keeps a reference to the model.
class CrossMultiplier {
public:
    /// @throws std::invalid_argument unless `model` is a cross model (Model::cross).
    explicit CrossMultiplier(const Model& model);

    Index controlPoints() const { return state_.controlPoints; }
    Index targetPoints() const { return model_.points - state_.controlPoints; }
    Index channels() const { return model_.channels; }
    /// Control point indices whose values apply() needs, in this order (K of them).
    const std::vector<Index>& keyPoints() const { return model_.keyPoints; }
    const CrossState& state() const { return state_; }

    struct Result {
        double keyRms = 0;  ///< the control's key RMS error e (data units)
        double bound = 0;   ///< the learned bound on the target's largest point error
    };
    /// keyValues: K*C control values at keyPoints(); target: targetPoints()*C values written.
    Result apply(const double* keyValues, double* target) const;
    /// A whole control frame (controlPoints()*C values) -> target.
    Result applyFrame(const double* control, double* target) const;

private:
    const Model& model_;
    const CrossState& state_;
    PointMultiplier pm_;
};

/// Section CROSSPM of a model file (ModelSections.h).
ModelSectionCodec crossSectionCodec();

}  // namespace pmsc
