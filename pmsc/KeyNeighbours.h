// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"  // Index

#include <Eigen/Core>

#include <span>
#include <vector>

namespace pmsc {

struct Model;
struct ModelSectionCodec;

/// The points nearest each key point in space (Model::keyNeighbours; model-file section
/// "KEYNEAR"): where a hit that one part of the predicted error alone certifies is checked
/// (HitCheck.h). Why near the keys: a motion the training never saw shows first in the residuals of
/// the keys nearest it, and the fit bends PM towards those keys, so the points around them, which
/// the fit did not see, are where PM is furthest off.
struct KeyNeighbours {
    Index perKey = 0;  ///< points per key
    std::vector<Index>
        points;  ///< K * perKey: key k's nearest non-key points at [k*perKey, (k+1)*perKey), nearest first
    /// The positions were the training mean (a shape): `pmsc learn` recomputes them from the
    /// learned mean when the keys change. False: positions the user gave, which learn does not have.
    bool fromMean = true;

    /// Key number k's points.
    std::span<const Index> of(Index k) const {
        return {points.data() + k * perKey, static_cast<size_t>(perKey)};
    }
    /// Checks sizes and ranges against the model (N, K): throws std::invalid_argument naming the
    /// first problem.
    void validate(const Model& model) const;
};

/// Points per key the default keeps: 16 (with the 4 keys HitCheck reads, 64 points a check).
constexpr Index kNeighboursPerKey = 16;

/// The `perKey` points nearest each of `keys` (not themselves keys) by Euclidean distance of
/// `positions` (N x 3, one row per point); ties by point index. Deterministic.
/// @throws std::invalid_argument when perKey is not in [1, N - K] or a key is out of range.
KeyNeighbours nearestToKeys(const Eigen::Ref<const Eigen::MatrixXd>& positions, std::span<const Index> keys,
                            Index perKey, bool fromMean);

/// Codec of the "KEYNEAR" model-file section (ModelSections.h).
ModelSectionCodec keyNeighboursSectionCodec();

}  // namespace pmsc
