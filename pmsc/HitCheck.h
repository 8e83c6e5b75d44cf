// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Model.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/Sentinels.h"
#include "pmsc/SoftCache.h"

#include <span>
#include <vector>

namespace pmsc {

/// The keys whose neighbours a check computes: the kCheckedKeys with the largest (leave-one-out)
/// residuals. With kNeighboursPerKey = 16, at most 64 points besides the region keys.
constexpr Index kCheckedKeys = 4;

/// A checked hit stands when PM's largest error at the region keys is at most kConfirmedShare of the
/// tolerance and at the key neighbours at most kNeighbourShare of it; otherwise the frame is
/// computed whole and blended with weight 0 (PM, and the full value wherever PM is over the
/// tolerance). Why 0.7 at the region keys: chosen on the novelty suite's sets A-C
/// (docs/calibration.md), where it took every hit over T out (0.8 let 6 of set C's through) and kept
/// 178 of set B's 184 validation hits (0.5 kept 154). Why 0.9 at the neighbours: they sit where the
/// error is (next to the keys that show it), so a smaller margin is enough; with them sets D and E,
/// which the region keys alone let through (27 and 4 frames over T), have none, and the check only
/// adds points to the region keys' check, so it refuses every hit that check refused. 0.9 at both
/// kept more hits (5,460 against 5,315 on sets A-H, both bases) and let 10 more frames over T.
constexpr double kConfirmedShare = 0.7;
constexpr double kNeighbourShare = 0.9;

/// The check of a hit: PM against the calculation at points it did not fit.
///
/// Every hit of a model with sentinels (Sentinels.h; any key error, shared channels or not) computes
/// them: points spread over what the
/// training saw move, so a motion the training never saw shows at one of them wherever its error
/// patch is wider than their spacing. A hit that one part of the predicted error alone certifies
/// (KeyErrorNorm::Predicted, partsDisagree) also computes
///  - the region keys (LocalRegions::extraKeyPoints), a few in every region of local fail-through;
///  - the key neighbours (KeyNeighbours) of the kCheckedKeys keys with the largest leave-one-out
///    residuals: a motion training never saw shows first at the keys nearest it, and the fit bends
///    PM towards those keys, so the points around them are where PM is furthest off (on the suite's
///    hits over T, the largest error of those 64 points was 0.95-1.2 T).
/// Why those: such a hit rests on one measure while the other says the frame is off what training
/// saw; on the novelty suite's first sets every hit over the tolerance at the defaults was one.
/// None of these points is in the projection, so PM's error there is a prediction, not a fit.
/// The sentinels also check a local frame's points that regions judged hits (ErrorMonitor).
///
/// Thread safety: all methods are const and may run concurrently.
class HitCheck {
public:
    /// Keeps references to `model` and `pm` (PM of the same model), which must outlive it.
    HitCheck(const Model& model, const PointMultiplier& pm);

    /// The model has points to check at: sentinels (any key error), or region keys or key
    /// neighbours (a predicted key error).
    bool available() const { return available_; }
    /// A frame with this decision and these parts is checked: a hit, when the model has sentinels;
    /// a hit whose parts disagree, when it has region keys or key neighbours.
    bool needed(const CacheDecision& decision, PredictedParts parts) const;
    /// The points the check of this frame computes, ascending, each once: the sentinels, and when
    /// the parts disagree the region keys and key neighbours.
    std::vector<Index> points(const double* keyValues, const double* coords, PredictedParts parts) const;
    /// The sentinels, ascending (empty without them).
    std::span<const Index> sentinels() const { return sentinels_; }
    /// What sentinels() is for a HitCheck of `model`, without building one.
    static std::vector<Index> sentinelsOf(const Model& model);
    /// For check points computed with the sentinels beforehand (the engine's key node, for an
    /// evaluator whose calls share work): copies into `out` (points.size()*C) the values of the
    /// sentinels among `points` from `sentinelValues` (sentinels() order, S*C), and returns the
    /// positions in `points` of the others, which are still to be computed.
    std::vector<size_t> copySentinelValues(std::span<const Index> points, const double* sentinelValues,
                                           double* out) const;
    /// The sentinels a local frame hands back as PM alone (weight 0 of the full result in
    /// `pointWeights`, N values), ascending: the ones its check computes.
    std::vector<Index> unblendedSentinels(std::span<const double> pointWeights) const;
    /// The hit stands: PM's error at each of `points` against its computed value (`values`,
    /// points.size()*C) is at most kConfirmedShare * T at a region key, kSentinelShare * T at a
    /// sentinel and kNeighbourShare * T at any other point (NaN fails), and every computed
    /// sentinel passes the slope check with its computed neighbours (kSentinelSlopeShare).
    bool passes(const double* coords, std::span<const Index> points, const double* values) const;
    /// The points of `points` where PM is further from `values` than passes() allows, ascending.
    std::vector<Index> offPoints(const double* coords, std::span<const Index> points,
                                 const double* values) const;

private:
    const Model& model_;
    const PointMultiplier& pm_;
    std::vector<Index> regionKeys_;  ///< ascending
    std::vector<Index> sentinels_;   ///< ascending
    std::vector<Index> sentinelAt_;  ///< sentinels_[i]'s position in the model's list
    bool predicted_ = false;         ///< the key error has two parts that can disagree
    bool available_ = false;
    /// The sentinels' rows of the mean and of the basis, gathered once, column-major: (S*C) x M, or
    /// S x M with shared channels. Why: a hit reconstructs PM at its sentinels, and gathering their
    /// rows from the whole basis reads a cache line per sentinel and basis vector (1,024 x M misses
    /// over a basis of tens of MB); from these few MB reconstructAt computes the same values.
    Eigen::VectorXd sentinelMean_;
    Eigen::MatrixXd sentinelBasis_;

    /// PM at `points` (points.size()*C values), as PointMultiplier::reconstructPoints computes it
    /// (reconstructAt, clamped as it clamps), the sentinels among them from the rows gathered above.
    void reconstruct(const double* coords, std::span<const Index> points, double* out) const;

    bool disagree(PredictedParts parts) const;
    /// Appends to `off` the sentinels the slope check refuses (kSentinelSlopeShare), from PM's
    /// error at each computed sentinel (`atSentinel`, by position in the model's list, NaN where
    /// not computed).
    void slopeCheck(const std::vector<double>& atSentinel, std::vector<Index>& off) const;
};

}  // namespace pmsc
