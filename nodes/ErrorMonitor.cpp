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
    slot.keyError = pm_.keyError(slot.keyValues.data(), slot.coords.data());
    slot.decision = policy_.decide(slot.keyError);
    if (slot.decision.state == CacheState::Hit) {
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
