// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"  // Index

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace pmsc {

struct Model;
struct ModelSectionCodec;

/// One region of local fail-through (paper section 9, "local fail through"): a set of
/// points whose errors rise and fall together, with its own key points, its own block projection
/// and its own calibrated key-error thresholds.
///
/// Why a block projection and not only a per-region error: one global least-squares projection
/// pushes a local unexplained motion into every coordinate, so every point of the frame carries
/// some of it. A region's own reconstruction mean_r + U_r b_r, with b_r from the region's keys
/// only, is untouched by what happens at keys outside it.
struct Region {
    std::vector<Index> points;  ///< the region's own points, ascending
    std::vector<Index> keys;    ///< key numbers (indices into Model::keyPoints), ascending
    Eigen::MatrixXd basis;      ///< (points*C) x M_r: local basis U_r at the region's points
    Eigen::MatrixXd keyBasis;   ///< (keys*C) x M_r: U_r at the region's keys (some may lie outside)
    Eigen::MatrixXd projector;  ///< M_r x (keys*C): pinv(keyBasis)
    double epsMin = 0;          ///< region hit at or below (key RMS of the region's keys, data units)
    double epsMax = 0;          ///< region miss at or above
    double ratio = 0;           ///< calibration's r (largest point error / key RMS), 0 if uncalibrated

    Index basisSize() const { return basis.cols(); }
};

/// The regions of a model (Model::regions; model-file section "REGIONS", format version 2).
///
/// Feathering (no visible seams): a point p of region q gets the full-result weight
///   w_p = max(w_q, max over its feather entries (r, f) of w_r * f)
/// where w_r is region r's soft-cache weight this frame and f = 1 - d / featherWidth falls
/// linearly with p's distance d to the nearest point of region r. So a region that misses is
/// evaluated fully, and the weight falls from 1 at its border to 0 one feather width into its
/// neighbours: continuous across the border, instead of a jump from the full result to PM.
/// The points of region r's band (feather entries naming r) are evaluated with r's points: its
/// fail set, one fixed subset per region, so an evaluator can cache its dependency closure.
struct LocalRegions {
    std::vector<Region> regions;
    double featherWidth = 0;  ///< in the units of the positions regions were learned from
    /// A frame whose fully evaluated points would exceed this fraction of N fails through whole
    /// (one full evaluation costs less than many partial ones).
    double maxLocalFraction = 0.6;
    /// Feather entries of point p: [featherStart[p], featherStart[p+1]) in featherRegion/featherFactor.
    /// Region keys: points evaluated, like the model's keys, for frames that miss as a
    /// whole, so that regions holding none of the model's keys see their own motion. Key number
    /// K + i in Region::keys is extraKeyPoints[i].
    std::vector<Index> extraKeyPoints;
    std::vector<Index> featherStart;  ///< N+1
    std::vector<Index> featherRegion;
    std::vector<double> featherFactor;  ///< in (0, 1]

    Index regionCount() const { return static_cast<Index>(regions.size()); }
    /// The point of key number `key` of a region: the model's key `key` (< K), else region key
    /// extraKeyPoints[key - K].
    Index keyPoint(const Model& model, Index key) const;
    /// region of every point (N entries), from Region::points.
    std::vector<Index> regionOfPoints(Index n) const;
    /// Region r's fail set: its points, then every point with a feather entry naming r, ascending
    /// in each part.
    std::vector<Index> failSet(Index r) const;

    /// Checks sizes and invariants against the model's core (N, C, K): every point in exactly
    /// one region, keys in range, sizes of every matrix, finite values, thresholds ordered,
    /// feather entries well formed. Throws std::invalid_argument naming the first problem.
    void validate(const Model& model) const;
};

/// Codec of the "REGIONS" model-file section (ModelSections.h).
ModelSectionCodec regionsSectionCodec();

}  // namespace pmsc
