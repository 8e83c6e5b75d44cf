// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"  // Index

#include <vector>

namespace pmsc {

/// What makes a model a cross point-multiplication model (paper section 7; section
/// CROSSPM of a version-2 model file, pmsc/Cross.h). The model's N points are the joint
/// (control, target) points: the first `controlPoints` are the control's, the rest the target's;
/// its mean and basis are the joint subspace of (control, target) training pairs and its keys
/// are control points only. At run time the control's key values give the coordinates and the
/// target's rows of the basis give the target: there is no fail-through (the target cannot be
/// computed), so instead each frame gets an error bound
///     bound(e) = quantile * (e + scale)
/// on the target's largest point error, from the control's key RMS e, learned on held-out
/// training pairs (leave-one-slice-out): `quantile` is the split-conformal quantile at `coverage`
/// of the held-out scores E_f / (e_f + scale), `scale` the median held-out key RMS.
struct CrossState {
    Index controlPoints = 0;          ///< Nc; the target has model.points - Nc points
    double coverage = 0;              ///< 1 - alpha of the bound
    double quantile = 0;              ///< conformal quantile of E / (e + scale)
    double scale = 0;                 ///< median held-out key RMS (data units); keeps the bound > 0 at e = 0
    Index slices = 0;                 ///< leave-one-slice-out folds the scores came from
    std::vector<double> keyRms;       ///< e_f: control key RMS of each held-out training pair
    std::vector<double> targetError;  ///< E_f: the target's largest point error on it

    double bound(double keyRms) const { return quantile * (keyRms + scale); }
    /// Checks the fields against a model of `points` joint points and `keys`.
    /// @throws std::invalid_argument naming the first problem.
    void validate(Index points, const std::vector<Index>& keys) const;
};

}  // namespace pmsc
