// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Calibration.h"
#include "pmsc/FrameSet.h"
#include "pmsc/IncrementalSvd.h"
#include "pmsc/Model.h"
#include "pmsc/Training.h"  // ProgressFn

#include <optional>
#include <string>
#include <vector>

namespace pmsc {

/// The incremental state of a model: its mean, frame count, total energy and the first M
/// singular triplets, followed by the LearningState's extra ones when the model has them.
IncrementalSubspace subspaceOf(const Model& model);

/// Options of learn(). Unset values keep what the model stored.
struct LearnOptions {
    Index basis = 0;  ///< M after the update; 0 = by the energy rule below, else the model's M
    /// M after the update = the smallest capturing this fraction of all frames' energy (the
    /// training's rule, applied to the updated singular values and the exact total energy);
    /// 0 = the model's stored rule (LearningState::basisEnergy; none stored: M kept).
    double energy = 0;
    /// Rank r of the state, during the update and kept after it; 0 = the model's
    /// (LearningState::maxRank, else M) kept, and up to 4 M during the update so M can grow.
    Index maxRank = 0;
    /// Default: the model's CalibrationRecord's, else Threshold for a predicted key error (the rule of
    /// its leave-one-out part) and MaxRatio for the others.
    std::optional<CalibrationRule> rule;
    std::optional<double> coverage;  ///< default: the model's, else 0.95
    /// Cross-fitting folds over the new frames for the calibration; 0 = slices of the training's
    /// size on all frames seen ((n + m) / S frames each, S the training's folds; at least one).
    Index slices = 0;
    /// The points' positions train was given (N x 3; --positions); empty: none. Learn chooses again
    /// from them what the model took from them: its sentinels (SentinelSource::Given) and its key
    /// neighbours, so both follow the new keys and the points the new frames move. Without them
    /// learn keeps the old sentinels less those that became keys, and drops the key neighbours
    /// (LearnReport::warnings says so).
    Eigen::MatrixXd positions;
    /// Models with regions: keep them, their keys, bases and thresholds learned again
    /// (relearnRegions); false: the learned model has none (every frame that misses fails through
    /// whole; --no-regions).
    bool regions = true;
    ProgressFn progress;  ///< optional; returning false cancels (pmsc::Cancelled)
};

/// What learn() did.
struct LearnReport {
    Index newFrames = 0;
    Index rankBefore = 0, rankAfter = 0;  ///< directions of the model's state before and after
    Index basisBefore = 0, basisAfter = 0;
    double basisEnergy = 0;                 ///< the energy rule M was chosen by; 0: M fixed
    Index keysKept = 0;                     ///< keys of the old model that are keys again
    double largestAngle = 0;                ///< largest principal angle between the old and the new M-basis
    double tailNorm = 0;                    ///< IncrementalSubspace::tailNorm() after the update
    double newFramesMaxPointError = 0;      ///< largest point error of the NEW model's PM on the new frames
    double oldModelNewFramesKeyRmsMax = 0;  ///< largest key RMS of the new frames under the OLD model
    CalibrationStats calibration;           ///< the new frames' cross-fitted scores and the thresholds
    double calibrationRatioOld = 0;         ///< the rule's ratio on the stored scores (0: none stored)
    double calibrationRatioNew = 0;         ///< the rule's ratio on the new frames' scores (0: too few)
    /// Models with regions: the learned model's region keys (LocalRegions::extraKeyPoints), the
    /// points its regions read that are not its keys (relearnRegions).
    Index regionKeys = 0;
    std::vector<std::string> warnings;
    double secondsSubspace = 0, secondsKeys = 0, secondsCalibration = 0, seconds = 0;
};

/// Updates a model with new frames without its training frames (paper section 5's nightly
/// training):
/// 1. mean and basis by Brand's incremental SVD (updateSubspace) of the model's state;
/// 2. keys selected again by the model's selector and settings on the rank-r surrogate of all
///    frames seen, U_r diag(sigma) (its Gram matrix is diag(sigma^2): every key-selection step
///    runs in the r-dimensional frame space), with the model's fiducials and grid points seeded;
///    M is chosen again by the training's energy rule when the model stores it (the new frames
///    add directions: keeping the old M loses them);
/// 3. the projector for the new keys and basis;
/// 4. eps: without a tolerance, the larger of the old eps_min and the new frames' largest key
///    RMS (eps_max = 1.5 eps_min, as training); with one, the new frames are scored by
///    cross-fitting (each of `slices` contiguous slices held out: the OLD state updated with the
///    other slices, computed in the span of the full update, updateInSpan; the new keys) and
///    r = the larger of the rule's ratio on those scores and on
///    the stored training scores; eps_min = T / r, eps_max = 2 eps_min;
/// 5. a model with regions keeps them, each region's keys, basis and thresholds learned again
///    from the state and the same folds (relearnRegions), unless LearnOptions::regions is false.
/// What is exact and what is approximate compared with training from scratch on all frames is
/// in docs/learning-and-calibration.md and IncrementalSvd.h.
/// @throws InputError if the frames' N or C differ from the model's, there are none, or a value
///         is NaN/Inf; std::invalid_argument for bad options; pmsc::Cancelled.
Model learn(const Model& model, const FrameSet& newFrames, const LearnOptions& options = {},
            LearnReport* report = nullptr);

}  // namespace pmsc
