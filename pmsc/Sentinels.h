// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"  // Index

#include <Eigen/Core>

#include <span>
#include <vector>

namespace pmsc {

struct Model;
struct ModelSectionCodec;

/// Points spread evenly over the part of the shape training saw move, computed for real beside
/// every hit (Model::sentinels; model-file section "SENTINEL"; checked by HitCheck).
///
/// Why: the keys see what they were chosen for. A control the training never moved can bend a
/// patch of points that no key, and no key's neighbour, sits in; the key error then looks like an
/// ordinary frame's and the hit hands back points over the tolerance (the novelty suite,
/// docs/calibration.md). PM's error at a point it did not fit is a prediction, so computing a few
/// such points tests the part of the frame the keys cannot see. They are chosen by farthest-point
/// sampling, so every moving point lies within `coveringRadius` of one: an error patch that
/// reaches over kSentinelShare * T across a disc of that radius anywhere on the moving part is seen.
/// That is the promise, and its limit: a patch over T narrower than the spacing can slip between
/// sentinels.
struct Sentinels {
    std::vector<Index> points;  ///< in the order farthest-point sampling chose them, no keys, no duplicates
    /// The largest distance from a moving point to its nearest sentinel, in the positions' units.
    double coveringRadius = 0;
    /// The positions were the training mean (a shape): `pmsc learn` chooses them again from the
    /// learned mean and basis. False: positions the user gave, which learn keeps.
    bool fromMean = true;

    /// Checks ranges against the model (N): throws std::invalid_argument naming the first problem.
    void validate(const Model& model) const;
};

/// Sentinels `pmsc train` chooses unless told (--sentinels): 1024. Why: on the novelty suite's
/// sets A-H (the face, 26,719 points, 600 training frames, both basis sizes) 1024 at
/// kSentinelShare = 0.8 left no frame over T where 512 left 30 and 256 left 70, and refused 1.3%
/// of the validation frames' hits; sets I-L, made after, had none over T with them (192 without).
constexpr Index kDefaultSentinels = 1024;

/// At most one point in kSentinelSpacing is a sentinel: a hit's check costs at most 1/16 of the
/// full calculation besides the keys. Why: the count the face needs (1024 of 26,719 points, 1 in 26)
/// would be 40% of a 2,592-point body; on small point sets the spacing, not the count, is what
/// a user can afford, and `pmsc inspect` prints the covering radius it gives.
constexpr Index kSentinelSpacing = 16;

/// A hit stands only where PM is within kSentinelShare * T of every sentinel's computed value.
/// Why 0.8: on sets A-H, 0.9 let 10 frames over T through and 0.7 refused 4.5% of the validation
/// hits against 1.3% at 0.8.
constexpr double kSentinelShare = 0.8;

/// A point moves when its RMS motion in the basis is at least this share of the largest point's.
constexpr double kMovingShare = 1e-3;

/// Each point's RMS motion over the training frames as the basis holds it: the norm of its rows of
/// basis * diag(singular values) (up to the common factor 1/sqrt(F)). Needs only the model, so train
/// and learn choose from the same measure.
Eigen::VectorXd basisMotion(const Model& model);

/// The sentinels a model of `points` points gets when `requested` are asked for:
/// min(requested, points / kSentinelSpacing).
Index sentinelCount(Index requested, Index points);

/// `count` sentinels among the moving points (motion >= kMovingShare * the largest) that are not
/// keys, by farthest-point sampling of `positions` (N x 3) from the point that moves most; fewer
/// when fewer points qualify (none: an empty set). Ties by point index: deterministic.
/// @throws std::invalid_argument when the sizes disagree or a key is out of range.
Sentinels farthestPointSentinels(const Eigen::Ref<const Eigen::MatrixXd>& positions,
                                 const Eigen::Ref<const Eigen::VectorXd>& motion, std::span<const Index> keys,
                                 Index count, bool fromMean);

/// Codec of the "SENTINEL" model-file section (ModelSections.h).
ModelSectionCodec sentinelsSectionCodec();

}  // namespace pmsc
