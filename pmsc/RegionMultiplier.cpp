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

RegionMultiplier::RegionMultiplier(const Model& model) : model_(model), regions_(regionsOf(model)) {
    const Index n = model.points;
    const Index c = model.channels;
    const Index r = regions_.regionCount();
    regionOf_ = regions_.regionOfPoints(n);
    ownPosition_.assign(size_t(n), -1);
    for (Index ri = 0; ri < r; ++ri) {
        const Region& g = regions_.regions[size_t(ri)];
        for (size_t i = 0; i < g.points.size(); ++i) ownPosition_[size_t(g.points[i])] = Index(i);
        Eigen::VectorXd mean(Index(g.keys.size()) * c);
        for (size_t i = 0; i < g.keys.size(); ++i) {
            const Index p = model.keyPoints[size_t(g.keys[i])];
            mean.segment(Index(i) * c, c) = model.mean.segment(p * c, c);
        }
        projectedKeyMean_.push_back(g.projector * mean);
        keyMean_.push_back(std::move(mean));
        coordsOffset_.push_back(coordsSize_);
        coordsSize_ += g.basisSize();
        policies_.emplace_back(g.epsMin, g.epsMax);
        failOffset_.push_back(failPoints_);
        failSets_.push_back(g.points);
    }
    // Feather bands, in point order, and where each entry's point sits in that region's fail set.
    featherPosition_.assign(regions_.featherRegion.size(), -1);
    for (Index p = 0; p < n; ++p) {
        for (Index e = regions_.featherStart[size_t(p)]; e < regions_.featherStart[size_t(p) + 1]; ++e) {
            auto& set = failSets_[size_t(regions_.featherRegion[size_t(e)])];
            featherPosition_[size_t(e)] = Index(set.size());
            set.push_back(p);
        }
    }
    failPoints_ = 0;
    for (Index ri = 0; ri < r; ++ri) {
        failOffset_[size_t(ri)] = failPoints_;
        failPoints_ += Index(failSets_[size_t(ri)].size());
    }
}

double RegionMultiplier::project(Index r, const double* keyValues, double* coords) const {
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
            const double v = keyValues[g.keys[i] * c + ch];
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

CacheDecision RegionMultiplier::decide(Index r, double keyRmsError) const {
    return policies_[size_t(r)].decide(keyRmsError);
}

void RegionMultiplier::pointWeights(std::span<const double> regionWeights, double* weights) const {
    const Index n = model_.points;
    for (Index p = 0; p < n; ++p) {
        double w = regionWeights[size_t(regionOf_[size_t(p)])];
        for (Index e = regions_.featherStart[size_t(p)]; e < regions_.featherStart[size_t(p) + 1]; ++e)
            w = std::max(w, regionWeights[size_t(regions_.featherRegion[size_t(e)])] * regions_.featherFactor[size_t(e)]);
        weights[p] = w;
    }
}

Index RegionMultiplier::fullValueAt(Index p, std::span<const double> regionWeights) const {
    const Index own = regionOf_[size_t(p)];
    if (regionWeights[size_t(own)] > 0) return failOffset_[size_t(own)] + ownPosition_[size_t(p)];
    for (Index e = regions_.featherStart[size_t(p)]; e < regions_.featherStart[size_t(p) + 1]; ++e) {
        const Index r = regions_.featherRegion[size_t(e)];
        if (regionWeights[size_t(r)] > 0) return failOffset_[size_t(r)] + featherPosition_[size_t(e)];
    }
    return -1;
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
        for (Index ch = 0; ch < c; ++ch) frame[row + ch] = model_.mean[row + ch] + tmp[Index(i) * c + ch];
    }
}

}  // namespace pmsc
