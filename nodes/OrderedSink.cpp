#include "nodes/OrderedSink.h"

#include <algorithm>

#include <cassert>

namespace pmsc::nodes {

OrderedSink::OrderedSink(const FramePlan& plan, FrameSink& sink, FailurePolicy policy, RunControl& control)
    : plan_(plan), sink_(sink), policy_(policy), control_(control) {}

void OrderedSink::operator()(FrameSlot& slot) {
    assert(slot.sequence == expected_ && "the sequencer must deliver frames in order");
    ++expected_;
    // After a cancellation or a StopRun failure nothing more is delivered: the sink has seen
    // exactly the frames before the stop point, never a later or partial one.
    if (control_.cancelled() || control_.hasRunError()) return;

    FrameResult result;
    result.sequence = slot.sequence;
    result.frame = slot.frame;
    result.keyValues = slot.keyValues;
    if (slot.failed()) {
        control_.failed.fetch_add(1, std::memory_order_relaxed);
        if (policy_ == FailurePolicy::StopRun) {
            control_.stopAfter(slot.sequence);
            control_.setRunError(slot.error());
            return;
        }
        result.failed = true;
        result.error = slot.error();
    } else {
        result.state = slot.decision.state;
        result.weight = slot.decision.weight;
        result.keyError = slot.keyError;
        result.keysFinite = slot.keysFinite;
        result.points = plan_.outputPoints;
        result.values = slot.values;
        result.local = slot.local;
        result.pointsEvaluated = slot.pointsEvaluated;
        if (!slot.regionStates.empty()) {
            if (!slot.regionsEvaluated) {
                std::fill(slot.regionStates.begin(), slot.regionStates.end(), CacheState::Hit);
                std::fill(slot.regionKeyErrors.begin(), slot.regionKeyErrors.end(), 0.0);
            }
            result.regionStates = slot.regionStates;
            result.regionKeyErrors = slot.regionKeyErrors;
        }
        if (slot.local) {
            result.pointWeights = slot.pointWeights;
            result.fullPoints = std::span<const Index>(slot.localPoints.data(), size_t(slot.localCount));
            result.fullValues =
                std::span<const double>(slot.localFull.data(), size_t(slot.localCount * plan_.channels));
        }
        if (slot.pmValid) {
            result.pmValues = slot.pmValues;
        } else if (slot.decision.state == CacheState::Hit && !slot.pmValues.empty()) {
            result.pmValues = slot.values;  // a hit's output is the PM result itself
        }
    }
    try {
        sink_.write(result);
    } catch (...) {
        control_.abort(std::current_exception());
        return;
    }
    control_.delivered.fetch_add(1, std::memory_order_relaxed);
    if (result.failed) return;
    switch (slot.decision.state) {
        case CacheState::Hit:
            control_.hits.fetch_add(1, std::memory_order_relaxed);
            break;
        case CacheState::Blend:
            control_.blends.fetch_add(1, std::memory_order_relaxed);
            break;
        case CacheState::Miss:
            control_.misses.fetch_add(1, std::memory_order_relaxed);
            break;
    }
    if (!slot.keysFinite) control_.forcedMisses.fetch_add(1, std::memory_order_relaxed);
    if (slot.local) ++control_.localFrames;
    if (plan_.outputCount() > 0)
        control_.pointsEvaluatedFractionSum += double(slot.pointsEvaluated) / double(plan_.outputCount());
    if (!result.regionStates.empty()) {
        control_.regionStates.resize(result.regionStates.size(), {0, 0, 0});
        for (size_t r = 0; r < result.regionStates.size(); ++r)
            ++control_.regionStates[r][size_t(result.regionStates[r])];
    }
}

}  // namespace pmsc::nodes
