#include "pmsc/RegionMultiplier.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace pmsc {

namespace {
const LocalRegions& regionsOf(const Model& model) {
    if (!model.regions) throw std::invalid_argument("RegionMultiplier: the model has no regions");
    return *model.regions;
}
}  // namespace

RegionMultiplier::RegionMultiplier(const Model& model)
    : model_(model), regions_(regionsOf(model)), modelKeys_(model.keyCount()) {
    const Index n = model.points;
    const Index c = model.channels;
    const Index r = regions_.regionCount();
    regionOf_ = regions_.regionOfPoints(n);
    for (Index ri = 0; ri < r; ++ri) {
        const Region& g = regions_.regions[size_t(ri)];
        Eigen::VectorXd mean(Index(g.keys.size()) * c);
        for (size_t i = 0; i < g.keys.size(); ++i) {
            const Index p = regions_.keyPoint(model, g.keys[i]);
            mean.segment(Index(i) * c, c) = model.mean.segment(p * c, c);
        }
        projectedKeyMean_.push_back(g.projector * mean);
        keyMean_.push_back(std::move(mean));
        coordsOffset_.push_back(coordsSize_);
        coordsSize_ += g.basisSize();
        policies_.emplace_back(g.epsMin, g.epsMax);
    }
}

double RegionMultiplier::project(Index r, const double* keyValues, const double* regionKeyValues,
                                 double* coords) const {
    const Region& g = regions_.regions[size_t(r)];
    const Index c = model_.channels;
    const Index kc = Index(g.keys.size()) * c;
    double local[768];
    std::vector<double> heap;
    double* k = local;
    if (kc > 768) {
        heap.resize(size_t(kc));
        k = heap.data();
    }
    for (size_t i = 0; i < g.keys.size(); ++i) {
        for (Index ch = 0; ch < c; ++ch) {
            const Index key = g.keys[i];
            const double v =
                key < modelKeys_ ? keyValues[key * c + ch] : regionKeyValues[(key - modelKeys_) * c + ch];
            if (!std::isfinite(v)) return std::numeric_limits<double>::quiet_NaN();
            k[Index(i) * c + ch] = v;
        }
    }
    Eigen::Map<const Eigen::VectorXd> kv(k, kc);
    Eigen::Map<Eigen::VectorXd> b(coords, g.basisSize());
    b.noalias() = g.projector * kv;
    b -= projectedKeyMean_[size_t(r)];
    // Residual of the region's keys, RMS over keys of each key's Euclidean error (Model.h).
    Eigen::VectorXd residual = kv - keyMean_[size_t(r)];
    residual.noalias() -= g.keyBasis * b;
    return std::sqrt(residual.squaredNorm() / double(g.keys.size()));
}

CacheDecision RegionMultiplier::decide(Index r, double keyError) const {
    return policies_[size_t(r)].decide(keyError);
}

void RegionMultiplier::pointWeights(std::span<const double> regionWeights, double* weights) const {
    const Index n = model_.points;
    for (Index p = 0; p < n; ++p) {
        double w = regionWeights[size_t(regionOf_[size_t(p)])];
        for (Index e = regions_.featherStart[size_t(p)]; e < regions_.featherStart[size_t(p) + 1]; ++e)
            w = std::max(w, regionWeights[size_t(regions_.featherRegion[size_t(e)])] *
                                regions_.featherFactor[size_t(e)]);
        weights[p] = w;
    }
}

bool RegionMultiplier::failRegionsOf(std::span<const Index> points, std::span<double> regionWeights) const {
    for (const Index p : points) {
        const Index r = regionOf_[size_t(p)];
        if (r < 0) return false;
        regionWeights[size_t(r)] = 1.0;
    }
    return true;
}

Index RegionMultiplier::fullPoints(std::span<const double> pointWeights, Index* points) const {
    Index count = 0;
    for (size_t p = 0; p < pointWeights.size(); ++p)
        if (pointWeights[p] > 0) points[count++] = Index(p);
    return count;
}

void RegionMultiplier::reconstruct(Index r, const double* coords, double* frame) const {
    const Region& g = regions_.regions[size_t(r)];
    const Index c = model_.channels;
    const Index rows = Index(g.points.size()) * c;
    // Region rows of the mean, then + U_r b_r in one GEMV into a contiguous temporary, scattered.
    Eigen::Map<const Eigen::VectorXd> b(coords, g.basisSize());
    thread_local Eigen::VectorXd tmp;
    tmp.resize(rows);
    tmp.noalias() = g.basis * b;
    for (size_t i = 0; i < g.points.size(); ++i) {
        const Index row = g.points[i] * c;
        for (Index ch = 0; ch < c; ++ch) {
            const double v = model_.mean[row + ch] + tmp[Index(i) * c + ch];
            frame[row + ch] = model_.nonNegative && v < 0 ? 0.0 : v;  // as PointMultiplier's output
        }
    }
}

}  // namespace pmsc
