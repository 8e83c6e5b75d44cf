#include "pmsc/HitCheck.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

namespace pmsc {

HitCheck::HitCheck(const Model& model, const PointMultiplier& pm) : model_(model), pm_(pm) {
    if (model.regions) regionKeys_ = model.regions->extraKeyPoints;
    std::sort(regionKeys_.begin(), regionKeys_.end());
    sentinels_ = sentinelsOf(model);
    sentinelAt_.assign(sentinels_.size(), -1);  // each one's first position in the model's list
    if (model.sentinels) {
        const std::vector<Index>& chosen = model.sentinels->points;
        for (size_t i = chosen.size(); i-- > 0;)
            sentinelAt_[size_t(std::lower_bound(sentinels_.begin(), sentinels_.end(), chosen[i]) -
                               sentinels_.begin())] = static_cast<Index>(i);
    }
    if (!sentinels_.empty()) {
        const Index c = model.channels, width = model.sharedChannels ? 1 : c;
        const auto s = static_cast<Index>(sentinels_.size());
        sentinelMean_.resize(s * c);
        sentinelBasis_.resize(s * width, model.basisSize());
        for (Index i = 0; i < s; ++i) {
            const Index p = sentinels_[size_t(i)];
            sentinelMean_.segment(i * c, c) = model.mean.segment(p * c, c);
            sentinelBasis_.middleRows(i * width, width) = model.basis.middleRows(p * width, width);
        }
    }
    predicted_ = model.keyErrorNorm == KeyErrorNorm::Predicted && !model.sharedChannels;
    available_ =
        !sentinels_.empty() || (predicted_ && (!regionKeys_.empty() || model.keyNeighbours.has_value()));
}

std::vector<Index> HitCheck::sentinelsOf(const Model& model) {
    if (!model.sentinels) return {};
    std::vector<Index> points = model.sentinels->points;
    std::sort(points.begin(), points.end());
    points.erase(std::unique(points.begin(), points.end()), points.end());
    return points;
}

bool HitCheck::disagree(PredictedParts parts) const {
    return predicted_ && partsDisagree(parts, model_.partEps);
}

bool HitCheck::needed(const CacheDecision& decision, PredictedParts parts) const {
    if (!available_ || decision.state != CacheState::Hit) return false;
    return !sentinels_.empty() || disagree(parts);
}

std::vector<Index> HitCheck::points(const double* keyValues, const double* coords,
                                    PredictedParts parts) const {
    std::vector<Index> out = sentinels_;
    if (!disagree(parts)) return out;  // ascending already
    out.insert(out.end(), regionKeys_.begin(), regionKeys_.end());
    if (model_.keyNeighbours) {
        const Index k = model_.keyCount();
        std::vector<double> residual(static_cast<size_t>(k));
        pm_.keyResiduals(keyValues, coords, residual.data());
        std::vector<Index> order(static_cast<size_t>(k));
        std::iota(order.begin(), order.end(), Index{0});
        const Index checked = std::min(kCheckedKeys, k);
        // Largest residual first, NaN first of all (a key that is not finite is the worst), ties
        // by key number: the same keys on every machine.
        std::partial_sort(order.begin(), order.begin() + checked, order.end(), [&](Index a, Index b) {
            const double ra = residual[size_t(a)], rb = residual[size_t(b)];
            if (std::isnan(ra) != std::isnan(rb)) return std::isnan(ra);
            if (ra != rb) return ra > rb;
            return a < b;
        });
        for (Index i = 0; i < checked; ++i) {
            const auto near = model_.keyNeighbours->of(order[size_t(i)]);
            out.insert(out.end(), near.begin(), near.end());
        }
    }
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
}

std::vector<Index> HitCheck::unblendedSentinels(std::span<const double> pointWeights) const {
    std::vector<Index> out;
    for (const Index p : sentinels_) {
        if (pointWeights[size_t(p)] == 0.0) out.push_back(p);
    }
    return out;
}

std::vector<size_t> HitCheck::copySentinelValues(std::span<const Index> points, const double* sentinelValues,
                                                 double* out) const {
    const auto c = static_cast<size_t>(model_.channels);
    std::vector<size_t> others;
    for (size_t i = 0; i < points.size(); ++i) {
        const auto s = std::lower_bound(sentinels_.begin(), sentinels_.end(), points[i]);
        if (s != sentinels_.end() && *s == points[i]) {
            std::copy_n(sentinelValues + size_t(s - sentinels_.begin()) * c, c, out + i * c);
        } else {
            others.push_back(i);
        }
    }
    return others;
}

bool HitCheck::passes(const double* coords, std::span<const Index> points, const double* values) const {
    return offPoints(coords, points, values).empty();
}

void HitCheck::reconstruct(const double* coords, std::span<const Index> points, double* out) const {
    const Index c = model_.channels;
    std::vector<Index> at, others;  // positions in sentinels_ of the sentinels, the other points
    std::vector<size_t> atOut, othersOut;
    for (size_t i = 0; i < points.size(); ++i) {
        const auto s = std::lower_bound(sentinels_.begin(), sentinels_.end(), points[i]);
        if (s != sentinels_.end() && *s == points[i]) {
            at.push_back(static_cast<Index>(s - sentinels_.begin()));
            atOut.push_back(i);
        } else {
            others.push_back(points[i]);
            othersOut.push_back(i);
        }
    }
    if (!others.empty()) {
        std::vector<double> pm(others.size() * size_t(c));
        pm_.reconstructPoints(coords, others, pm.data());
        for (size_t i = 0; i < others.size(); ++i)
            std::copy_n(pm.data() + i * size_t(c), c, out + othersOut[i] * size_t(c));
    }
    if (at.empty()) return;
    std::vector<double> pm(at.size() * size_t(c));
    reconstructAt(sentinelMean_, sentinelBasis_, c, model_.sharedChannels, model_.nonNegative, coords, at,
                  pm.data());
    for (size_t i = 0; i < at.size(); ++i)
        std::copy_n(pm.data() + i * size_t(c), c, out + atOut[i] * size_t(c));
}

std::vector<Index> HitCheck::offPoints(const double* coords, std::span<const Index> points,
                                       const double* values) const {
    const Index c = model_.channels;
    std::vector<double> pm(points.size() * size_t(c));
    reconstruct(coords, points, pm.data());
    std::vector<Index> off;
    // PM's error at each computed sentinel, by its position in the model's list (NaN: not computed).
    std::vector<double> atSentinel;
    if (!sentinels_.empty()) atSentinel.assign(model_.sentinels->points.size(), std::nan(""));
    for (size_t i = 0; i < points.size(); ++i) {
        double squared = 0;
        for (Index ch = 0; ch < c; ++ch) {
            const double d = pm[i * size_t(c) + size_t(ch)] - values[i * size_t(c) + size_t(ch)];
            squared += d * d;
        }
        const double error = std::sqrt(squared);
        const bool regionKey = std::binary_search(regionKeys_.begin(), regionKeys_.end(), points[i]);
        const auto s = std::lower_bound(sentinels_.begin(), sentinels_.end(), points[i]);
        const bool sentinel = s != sentinels_.end() && *s == points[i];
        if (sentinel) atSentinel[size_t(sentinelAt_[size_t(s - sentinels_.begin())])] = error;
        const double share = regionKey ? kConfirmedShare : sentinel ? kSentinelShare : kNeighbourShare;
        if (!(error <= share * model_.tolerance)) off.push_back(points[i]);  // NaN is off
    }
    const size_t before = off.size();
    slopeCheck(atSentinel, off);
    if (off.size() != before) {
        std::sort(off.begin(), off.end());
        off.erase(std::unique(off.begin(), off.end()), off.end());
    }
    return off;
}

void HitCheck::slopeCheck(const std::vector<double>& atSentinel, std::vector<Index>& off) const {
    if (atSentinel.empty() || model_.sentinels->perSentinel <= 0) return;
    const Sentinels& s = *model_.sentinels;
    const size_t k = size_t(s.perSentinel);
    const double reach = kSentinelSlopeShare * s.coveringRadius;
    for (size_t i = 0; i < atSentinel.size(); ++i) {
        const double e = atSentinel[i];
        if (std::isnan(e)) continue;  // not computed, or off already (a NaN error)
        double slope = 0;
        for (size_t n = i * k; n < (i + 1) * k; ++n) {
            const double other = atSentinel[size_t(s.neighbours[n])];
            if (!std::isnan(other)) slope = std::max(slope, std::abs(e - other) / s.neighbourDistances[n]);
        }
        if (!(e + reach * slope <= model_.tolerance)) off.push_back(s.points[i]);
    }
}

}  // namespace pmsc
