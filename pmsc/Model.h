// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/CrossState.h"
#include "pmsc/FrameSet.h"
#include "pmsc/KeyError.h"
#include "pmsc/KeyNeighbours.h"
#include "pmsc/LearningState.h"
#include "pmsc/Regions.h"
#include "pmsc/Sentinels.h"

#include <Eigen/Core>

#include <optional>
#include <string>
#include <vector>

namespace pmsc {

/// Which key-point selector produced a model.
enum class Selector : int {
    Teleconnection = 0,  ///< the paper's section 4: Varimax blocks + teleconnection pairs
    QDeim = 1,           ///< QR with column pivoting on the basis (Drmac & Gugercin 2016)
};

/// A trained point-multiplication model: everything the runtime needs.
///
/// Units: eps are in the data's units. The key error they are compared with is
/// the model's KeyErrorNorm of each key point's Euclidean error over its channels
/// (see PointMultiplier::keyError), so a threshold reads like a point error.
struct Model {
    Index points = 0;       ///< N
    Index channels = 0;     ///< C
    Index trainFrames = 0;  ///< F used for training

    Eigen::VectorXd mean;  ///< N*C training mean (paper footnote 1)
    /// (N*C) x M, orthonormal columns a_i[x] (section 3); N x M when sharedChannels.
    Eigen::MatrixXd basis;
    /// The channels share one basis over the points (`TrainingOptions::sharedChannels`):
    /// basis is N x M, projector M x K, and a frame has M coordinates per channel (C*M in all,
    /// coords[j*C + c]); channel c of a frame is mean_c + basis * coords_c. Decision, for light:
    /// red, green and blue carry the same transport (same shadows, same paths), so they share
    /// spatial modes, and a light's colour, a factor per channel, is reproduced exactly when the
    /// training varied colour or intensity (the channel means then lie in, or near, the span), where a
    /// basis over (point, channel) rows spans only the colours it was trained with. The key
    /// values of all channels determine their coordinates through one K x M system.
    bool sharedChannels = false;
    Eigen::VectorXd singularValues;  ///< M singular values of the mean-removed training matrix
    double totalEnergy = 0;          ///< squared Frobenius norm of the mean-removed training matrix

    std::vector<Index> keyPoints;  ///< K point indices, in selection order, no duplicates
    /// M x (K*C) least-squares projector, key values -> pose-space coords (M x K when sharedChannels)
    Eigen::MatrixXd projector;

    Selector selector = Selector::Teleconnection;
    /// The measure eps applies to (section KEYERROR of a version-2 file; absent = Rms).
    KeyErrorNorm keyErrorNorm = KeyErrorNorm::Rms;
    double epsMin = 0;     ///< soft cache: at or below, a hit (section 5)
    double epsMax = 0;     ///< soft cache: at or above, a miss
    double tolerance = 0;  ///< calibration target (largest point error of a hit); 0 = not calibrated
    /// KeyErrorNorm::Predicted: the thresholds of its two parts, each calibrated for `tolerance`
    /// (section KEYERROR); the key error is tolerance * min(e_rms / rms, e_loo / loo).
    PredictedParts partEps;
    double trainMaxPointResidual = 0;  ///< largest point error of PM on the training set
    /// Every value training saw was >= 0 (light, density): PointMultiplier clamps what it
    /// reconstructs at 0 (section NONNEG; TrainingOptions::clampAtZero). Why: for a quantity that
    /// cannot be negative, max(PM, 0) is never further from the true value than PM, channel by
    /// channel, so the clamp can only shrink a point's error; where a light the training never
    /// saw makes PM ring below zero, it removes the error there (docs/calibration.md).
    bool nonNegative = false;

    // --- optional parts: each one is a tagged section of a version-2 model file (ModelSections.h)
    /// Local fail-through: regions with their own keys, projection and thresholds.
    std::optional<LocalRegions> regions;
    /// The points nearest each key, where a hit one part of the predicted error alone certifies
    /// is checked (HitCheck.h; section KEYNEAR).
    std::optional<KeyNeighbours> keyNeighbours;
    /// Points spread over what training saw move, computed beside every hit (HitCheck.h;
    /// Sentinels.h; section SENTINEL).
    std::optional<Sentinels> sentinels;
    /// `pmsc learn`: the incremental-SVD state beyond the basis and the key-selection
    /// settings (section LEARNSVD; written by `pmsc train --learn-rank` and `pmsc learn`).
    std::optional<LearningState> learning;
    /// The held-out scores eps were calibrated from, and the rule (section CALIBRAT; same).
    std::optional<CalibrationRecord> calibrationRecord;
    /// Cross point multiplication (paper section 7): the points are (control, target)
    /// and the keys the control's; no fail-through, an error bound instead (section CROSSPM).
    std::optional<CrossState> cross;

    Index basisSize() const { return basis.cols(); }
    /// Rows of the basis per point: C, or 1 when the channels share the basis.
    Index basisChannels() const { return sharedChannels ? 1 : channels; }
    /// Pose-space coordinates of one frame: M, or C*M when the channels share the basis.
    Index coordCount() const { return sharedChannels ? basis.cols() * channels : basis.cols(); }
    Index keyCount() const { return static_cast<Index>(keyPoints.size()); }
    /// Fraction of the training energy the basis captures.
    double energyCaptured() const;
    /// Checks sizes and invariants; throws std::invalid_argument naming the first problem.
    void validate() const;
};

/// Builds the least-squares projector pinv(B_K) for the rows of `basis` at
/// `keyPoints` (all C channels of each key). Computed with a complete
/// orthogonal decomposition, so a rank-deficient key system yields the
/// minimum-norm solution instead of garbage.
Eigen::MatrixXd makeProjector(const Eigen::MatrixXd& basis, Index channels,
                              const std::vector<Index>& keyPoints);

/// Gathers the (K*C) rows of a (N*C) x n matrix at the key points.
Eigen::MatrixXd gatherKeyRows(const Eigen::Ref<const Eigen::MatrixXd>& m, Index channels,
                              const std::vector<Index>& keyPoints);

}  // namespace pmsc
