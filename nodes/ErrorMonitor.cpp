#include "nodes/ErrorMonitor.h"

#include "nodes/PointPieces.h"

#include <algorithm>
#include <exception>
#include <limits>
#include <string>
#include <vector>

namespace pmsc::nodes {

Route ErrorMonitor::operator()(FrameSlot& slot) const {
    const Route route = decide(slot);
    return route == Route::Check ? check(slot) : route;
}

Route ErrorMonitor::decide(FrameSlot& slot) const {
    if (slot.failed()) return Route::Done;
    if (!slot.keysFinite) {
        slot.keyError = std::numeric_limits<double>::quiet_NaN();
        slot.decision = CacheDecision{CacheState::Miss, 1.0};
        slot.pointsEvaluated = Index(slot.values.size()) / pm_.model().channels;
        return Route::FailThrough;
    }
    slot.keyError = pm_.keyError(slot.keyValues.data(), slot.coords.data(), &slot.keyErrorParts);
    slot.decision = policy_.decide(slot.keyError);
    if (evaluator_ != nullptr && check_.needed(slot.decision, slot.keyErrorParts)) return Route::Check;
    if (slot.decision.state == CacheState::Hit) {
        slot.pointsEvaluated = 0;
        return Route::Reconstruct;
    }
    if (!regions_) return whole(slot);
    const std::vector<Index>& regionKeys = regions_->regionKeyPoints();
    // A non-finite region key value makes its regions' errors NaN, so they miss; an exception
    // fails the frame like one from the key-point evaluator.
    if (!regionKeys.empty() && !evaluateInto(slot, regionKeys, slot.regionKeyValues.data(), "region keys"))
        return Route::Done;
    const Index r = regions_->regionCount();
    for (Index i = 0; i < r; ++i) {
        const double e = regions_->project(i, slot.keyValues.data(), slot.regionKeyValues.data(),
                                           slot.regionCoords.data() + regions_->coordsOffset(i));
        const CacheDecision d = regions_->decide(i, e);
        slot.regionKeyErrors[size_t(i)] = e;
        slot.regionStates[size_t(i)] = d.state;
        slot.regionWeights[size_t(i)] = d.weight;
    }
    slot.regionsEvaluated = true;
    regions_->pointWeights(slot.regionWeights, slot.pointWeights.data());
    Index full = regions_->fullPoints(slot.pointWeights, slot.localPoints.data());
    const double most = regions_->regions().maxLocalFraction * double(slot.pointWeights.size());
    if (double(full) <= most) {
        Index checked = 0;
        if (!checkLocal(slot, full, checked)) return Route::Done;
        if (double(full) <= most) {
            slot.local = true;
            slot.localCount = full;
            slot.pointsEvaluated = full + checked;
            return Route::Local;
        }
    }
    return whole(slot);
}

bool ErrorMonitor::checkLocal(FrameSlot& slot, Index& full, Index& checked) const {
    // The sentinels the local frame would hand back as PM alone (weight 0 of the full result) are
    // computed, as a hit's are: a region judged a hit may carry a motion its keys do not see. Each
    // region holding one that PM misses by more than its share of T fails through as well.
    if (evaluator_ == nullptr || check_.sentinels().empty()) return true;
    const std::vector<Index> points = check_.unblendedSentinels(slot.pointWeights);
    checked = static_cast<Index>(points.size());
    if (points.empty()) return true;
    thread_local std::vector<double> values;
    values.resize(points.size() * size_t(pm_.model().channels));
    if (!checkValuesInto(slot, points, values.data(), "sentinels")) return false;
    const std::vector<Index> off = check_.offPoints(slot.coords.data(), points, values.data());
    if (off.empty()) return true;
    if (!regions_->failRegionsOf(off, slot.regionWeights)) {  // the frame fails through whole
        full = Index(slot.pointWeights.size());
        return true;
    }
    for (size_t r = 0; r < slot.regionWeights.size(); ++r) {
        if (slot.regionWeights[r] == 1.0) slot.regionStates[r] = CacheState::Miss;
    }
    regions_->pointWeights(slot.regionWeights, slot.pointWeights.data());
    full = regions_->fullPoints(slot.pointWeights, slot.localPoints.data());
    return true;
}

Route ErrorMonitor::check(FrameSlot& slot) const {
    const std::vector<Index> points =
        check_.points(slot.keyValues.data(), slot.coords.data(), slot.keyErrorParts);
    thread_local std::vector<double> values;
    values.resize(points.size() * size_t(pm_.model().channels));
    if (!checkValuesInto(slot, points, values.data(), "check points")) return Route::Done;
    if (check_.passes(slot.coords.data(), points, values.data())) {
        slot.pointsEvaluated = static_cast<Index>(points.size());
        return Route::Reconstruct;
    }
    // The check saw PM off at a computed point: the whole frame is computed and blended with
    // weight 0, so every point is PM or, where PM is over T, moved to within T of the full value
    // (pmsc::blendPoints).
    slot.decision = CacheDecision{CacheState::Blend, 0.0};
    return whole(slot);
}

Route ErrorMonitor::whole(FrameSlot& slot) const {
    slot.pointsEvaluated = Index(slot.values.size()) / pm_.model().channels;
    return keepPm_ ? Route::Reconstruct : Route::FailThrough;
}

bool ErrorMonitor::checkValuesInto(FrameSlot& slot, std::span<const Index> points, double* out,
                                   const char* what) const {
    if (!slot.sentinelsComputed) return evaluateInto(slot, points, out, what);
    const std::vector<size_t> othersAt = check_.copySentinelValues(points, slot.sentinelValues.data(), out);
    if (othersAt.empty()) return true;
    const auto c = static_cast<size_t>(pm_.model().channels);
    thread_local std::vector<Index> others;
    thread_local std::vector<double> values;
    others.clear();
    for (const size_t i : othersAt) others.push_back(points[i]);
    values.resize(others.size() * c);
    if (!evaluateInto(slot, others, values.data(), what)) return false;
    for (size_t j = 0; j < others.size(); ++j) std::copy_n(values.data() + j * c, c, out + othersAt[j] * c);
    return true;
}

bool ErrorMonitor::evaluateInto(FrameSlot& slot, std::span<const Index> points, double* out,
                                const char* what) const {
    try {
        evaluateInPieces(*evaluator_, slot.frame, points, pm_.model().channels, piecePoints_, out);
        return true;
    } catch (const std::exception& e) {
        slot.fail(kName, "evaluator '" + evaluator_->name() + "' (" + what + "): " + e.what());
    } catch (...) {
        slot.fail(kName, "evaluator '" + evaluator_->name() + "' (" + what + "): unknown exception");
    }
    return false;
}

}  // namespace pmsc::nodes
