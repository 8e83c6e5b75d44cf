#include "nodes/ErrorMonitor.h"

#include <exception>
#include <limits>
#include <string>

namespace pmsc::nodes {

Route ErrorMonitor::operator()(FrameSlot& slot) const {
    if (slot.failed()) return Route::Done;
    if (!slot.keysFinite) {
        slot.keyError = std::numeric_limits<double>::quiet_NaN();
        slot.decision = CacheDecision{CacheState::Miss, 1.0};
        slot.pointsEvaluated = Index(slot.values.size()) / pm_.model().channels;
        return Route::FailThrough;
    }
    PredictedParts parts;
    slot.keyError = pm_.keyError(slot.keyValues.data(), slot.coords.data(), &parts);
    slot.decision = policy_.decide(slot.keyError);
    // A hit that one part of the predicted error certifies and the other does not is checked at the
    // region keys (partsDisagree, kConfirmedShare): PM's largest error there, against their
    // computed values.
    const Model& model = pm_.model();
    const bool confirm = slot.decision.state == CacheState::Hit && regions_ &&
                         !regions_->regionKeyPoints().empty() &&
                         model.keyErrorNorm == KeyErrorNorm::Predicted && partsDisagree(parts, model.partEps);
    if (slot.decision.state == CacheState::Hit && !confirm) {
        slot.pointsEvaluated = 0;
        return Route::Reconstruct;
    }
    if (regions_) {
        const std::vector<Index>& regionKeys = regions_->regionKeyPoints();
        if (!regionKeys.empty()) {
            // A non-finite region key value makes its regions' errors NaN, so they miss; an
            // exception fails the frame like one from the key-point evaluator.
            try {
                evaluator_->evaluate(slot.frame, regionKeys, slot.regionKeyValues.data());
            } catch (const std::exception& e) {
                slot.fail(kName, "evaluator '" + evaluator_->name() + "' (region keys): " + e.what());
                return Route::Done;
            } catch (...) {
                slot.fail(kName, "evaluator '" + evaluator_->name() + "' (region keys): unknown exception");
                return Route::Done;
            }
        }
        if (confirm) {
            const double largest =
                pm_.largestErrorAt(slot.coords.data(), regionKeys, slot.regionKeyValues.data());
            if (largest <= kConfirmedShare * model.tolerance) {
                slot.pointsEvaluated = 0;
                return Route::Reconstruct;
            }
            // The check saw PM off at a computed point: the whole frame is computed and blended
            // with weight 0, so every point is PM or, where PM is over T, moved to within T of
            // the full value (pmsc::blendPoints). The regions' own tests are what missed it.
            slot.decision = CacheDecision{CacheState::Blend, 0.0};
            slot.pointsEvaluated = Index(slot.values.size()) / model.channels;
            return keepPm_ ? Route::Reconstruct : Route::FailThrough;
        }
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
        const Index full = regions_->fullPoints(slot.pointWeights, slot.localPoints.data());
        if (double(full) <= regions_->regions().maxLocalFraction * double(slot.pointWeights.size())) {
            slot.local = true;
            slot.localCount = full;
            slot.pointsEvaluated = full;
            return Route::Local;
        }
    }
    slot.pointsEvaluated = Index(slot.values.size()) / pm_.model().channels;
    if (keepPm_) return Route::Reconstruct;
    return Route::FailThrough;
}

}  // namespace pmsc::nodes
