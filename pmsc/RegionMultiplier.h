// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Model.h"
#include "pmsc/SoftCache.h"

#include <span>
#include <vector>

namespace pmsc {

/// The runtime of local fail-through (paper section 9): each region's block projection
/// from its own keys, its key error and soft-cache decision, the feathered per-point weights of
/// the full result, and each region's reconstruction.
///
/// Thread safety: all methods are const and may run concurrently.
/// Buffers: key values are the model's K*C key values (all keys, model key order); a frame's
/// region coordinates are coordsSize() doubles, region r's at coordsOffset(r).
class RegionMultiplier {
public:
    /// Keeps a reference to `model` (which must have regions and outlive this object).
    /// @throws std::invalid_argument if the model has no regions.
    explicit RegionMultiplier(const Model& model);

    const LocalRegions& regions() const { return regions_; }
    Index regionCount() const { return regions_.regionCount(); }
    Index coordsSize() const { return coordsSize_; }
    Index coordsOffset(Index r) const { return coordsOffset_[size_t(r)]; }

    /// Region r's coordinates b_r = P_r (k_r - mean_{K_r}) and returns its key RMS error (the
    /// frame's measure, PointMultiplier::keyError, over the region's keys). NaN if a key value
    /// of the region is not finite. `regionKeyValues`: the values of LocalRegions::extraKeyPoints
    /// (E*C; may be null when the model has none).
    double project(Index r, const double* keyValues, const double* regionKeyValues, double* coords) const;
    /// Sets the full-result weight of each region holding one of `points` to 1 (it fails
    /// through). False when a point is in no region (nothing local can take it).
    bool failRegionsOf(std::span<const Index> points, std::span<double> regionWeights) const;
    /// Points of the region keys (LocalRegions::extraKeyPoints), evaluated for frames that do not
    /// hit as a whole.
    const std::vector<Index>& regionKeyPoints() const { return regions_.extraKeyPoints; }
    /// The region's soft-cache decision for its key error (its own calibrated thresholds).
    CacheDecision decide(Index r, double keyError) const;

    /// w_p for every point (N doubles) from the regions' full-result weights (Regions.h).
    void pointWeights(std::span<const double> regionWeights, double* weights) const;

    /// Region r's points: out[p*C + c] = mean + U_r b_r for each point p of r (a full-frame buffer:
    /// only r's points are written).
    void reconstruct(Index r, const double* coords, double* frame) const;

    /// The points a frame evaluates fully: those with w_p > 0 (`pointWeights` from
    /// pointWeights()), ascending, into `points` (room for N); returns how many. This is the
    /// union of the failing regions' fail sets, each point once: bands shared by two failing
    /// regions are evaluated once, and one call poses the union's dependency closure once.
    Index fullPoints(std::span<const double> pointWeights, Index* points) const;

private:
    const Model& model_;
    const LocalRegions& regions_;
    Index modelKeys_;
    std::vector<Index> regionOf_;
    std::vector<Eigen::VectorXd> keyMean_;  ///< per region, K_r*C
    std::vector<Eigen::VectorXd> projectedKeyMean_;
    std::vector<Index> coordsOffset_;
    Index coordsSize_ = 0;
    std::vector<SoftCachePolicy> policies_;
};

}  // namespace pmsc
