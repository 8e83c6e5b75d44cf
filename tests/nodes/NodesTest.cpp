// Node bodies tested without a graph: each is a plain callable on a FrameSlot.
#include "nodes/Blender.h"
#include "nodes/ErrorMonitor.h"
#include "nodes/FailThroughEvaluator.h"
#include "nodes/FramePlan.h"
#include "nodes/FrameSlot.h"
#include "nodes/FrameSource.h"
#include "nodes/KeyPointEvaluator.h"
#include "nodes/OrderedSink.h"
#include "nodes/Projector.h"
#include "nodes/Reconstructor.h"
#include "pmsc/Errors.h"
#include "tests/engine/Synthetic.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

namespace pmsc::nodes {
namespace {

using testing::SyntheticEvaluator;

struct Nodes : ::testing::Test {
    Model model = testing::makeModel(100, 3, 5, 8);
    SyntheticEvaluator evaluator{model, 50};
    PointMultiplier pm{model};
    SoftCachePolicy policy = testing::syntheticPolicy(model, evaluator);
};

TEST_F(Nodes, FramePlanChunksCoverEveryOutputPointOnceAndSkipKeys) {
    const FramePlan plan = FramePlan::make(model, {}, 16, false);
    EXPECT_TRUE(plan.allPoints);
    EXPECT_EQ(plan.chunks.size(), 7u);  // ceil(100 / 16)
    std::set<Index> covered;
    Index keys = 0;
    for (const auto& c : plan.chunks) {
        EXPECT_EQ(Index(c.evalPoints.size() + c.keyOutput.size()), c.outputCount);
        for (size_t i = 0; i < c.evalPoints.size(); ++i) {
            EXPECT_GE(c.evalOutput[i], c.firstOutput);
            EXPECT_LT(c.evalOutput[i], c.firstOutput + c.outputCount);
            EXPECT_TRUE(covered.insert(c.evalOutput[i]).second);
            EXPECT_EQ(plan.outputPoints[size_t(c.evalOutput[i])], c.evalPoints[i]);
        }
        for (size_t j = 0; j < c.keyOutput.size(); ++j) {
            EXPECT_TRUE(covered.insert(c.keyOutput[j]).second);
            EXPECT_EQ(model.keyPoints[size_t(c.keyNumber[j])], plan.outputPoints[size_t(c.keyOutput[j])]);
            ++keys;
        }
    }
    EXPECT_EQ(Index(covered.size()), 100);
    EXPECT_EQ(keys, model.keyCount());
}

TEST_F(Nodes, FramePlanValidatesTheWantedPoints) {
    const std::vector<Index> wanted = {5, 1, 2, 3};
    const FramePlan plan = FramePlan::make(model, wanted, 2, false);
    EXPECT_FALSE(plan.allPoints);
    EXPECT_EQ(plan.outputPoints, wanted);
    EXPECT_EQ(plan.chunks.size(), 2u);
    const std::vector<Index> identity = {0, 1, 2};
    EXPECT_FALSE(FramePlan::make(model, identity, 2, false).allPoints);  // not all N
    EXPECT_THROW(FramePlan::make(model, std::vector<Index>{1, 1}, 2, false), InputError);
    EXPECT_THROW(FramePlan::make(model, std::vector<Index>{-1}, 2, false), InputError);
    EXPECT_THROW(FramePlan::make(model, std::vector<Index>{100}, 2, false), InputError);
    EXPECT_THROW(FramePlan::make(model, {}, 0, false), InputError);
    EXPECT_EQ(FramePlan::make(model, {}, 7, true).chunks.size(), 1u);
}

/// Runs the bodies of one frame in graph order, serially.
std::vector<double> runFrame(const Model& model, const PointEvaluator& e, const PointMultiplier& pm,
                             const SoftCachePolicy& policy, const FramePlan& plan, FrameSlot& slot,
                             Index frame) {
    slot.reset(0, frame);
    KeyPointEvaluator{model, e}(slot);
    Projector{pm}(slot);
    const Route route = ErrorMonitor{pm, policy, false}(slot);
    if (route == Route::Reconstruct) {
        EXPECT_TRUE((Reconstructor{pm, plan}(slot)));
    } else if (route == Route::FailThrough) {
        // Chunks in reverse order: the result must not depend on the order branches run in.
        for (Index c = Index(plan.chunks.size()) - 1; c >= 0; --c) {
            FailThroughEvaluator{e, plan}(slot, c);
            Blender{pm, plan}(slot, c);
        }
    }
    return slot.values;
}

TEST_F(Nodes, BodiesInSequenceGiveTheSoftCachedFrame) {
    const FramePlan plan = FramePlan::make(model, {}, 16, false);
    FrameSlot slot(plan, model.keyCount(), model.basisSize(), false);
    for (Index f = 0; f < 8; ++f) {
        CacheDecision d;
        const auto expected = testing::referenceFrame(model, evaluator, policy, f, &d);
        const auto got = runFrame(model, evaluator, pm, policy, plan, slot, f);
        EXPECT_EQ(slot.decision.state, d.state) << f;
        for (size_t x = 0; x < got.size(); ++x) ASSERT_NEAR(got[x], expected[x], 1e-10) << f;
    }
}

TEST_F(Nodes, ErrorMonitorRoutesByTheSoftCachePolicy) {
    const FramePlan plan = FramePlan::make(model, {}, 16, false);
    FrameSlot slot(plan, model.keyCount(), model.basisSize(), false);
    const ErrorMonitor monitor(pm, policy, false);
    const ErrorMonitor keeping(pm, policy, true);
    const Route expected[4] = {Route::Reconstruct, Route::FailThrough, Route::FailThrough,
                               Route::Reconstruct};
    for (Index f = 0; f < 4; ++f) {
        slot.reset(0, f);
        KeyPointEvaluator{model, evaluator}(slot);
        Projector{pm}(slot);
        EXPECT_EQ(monitor(slot), expected[f]) << f;
        EXPECT_EQ(keeping(slot), Route::Reconstruct) << "keepPm reconstructs every frame";
    }
    slot.reset(0, 0);
    slot.keysFinite = false;
    EXPECT_EQ(monitor(slot), Route::FailThrough);
    EXPECT_EQ(slot.decision.state, CacheState::Miss);
    EXPECT_EQ(slot.decision.weight, 1.0);
    EXPECT_TRUE(std::isnan(slot.keyError));
    slot.fail("keys", "boom");
    EXPECT_EQ(monitor(slot), Route::Done);
}

TEST_F(Nodes, ErrorMonitorChecksAHitOnePartAloneCertifies) {
    // The fixture's model with a predicted key error whose RMS part certifies every frame and whose
    // leave-one-out part certifies none, and 4 neighbours per key: every hit is checked.
    Model checked = model;
    checked.keyErrorNorm = KeyErrorNorm::Predicted;
    checked.partEps = {1e6, 1e-12};
    KeyNeighbours near;
    near.perKey = 4;
    std::set<Index> keys(checked.keyPoints.begin(), checked.keyPoints.end());
    for (Index k = 0; k < checked.keyCount(); ++k) {
        for (Index p = 0, taken = 0; taken < near.perKey; ++p) {
            const Index point = (checked.keyPoints[size_t(k)] + 1 + p) % checked.points;
            if (keys.count(point)) continue;
            near.points.push_back(point);
            ++taken;
        }
    }
    checked.keyNeighbours = near;
    const FramePlan plan = FramePlan::make(checked, {}, 16, false);
    FrameSlot slot(plan, checked.keyCount(), checked.basisSize(), false);
    const auto route = [&](double tolerance) {
        checked.tolerance = tolerance;
        const PointMultiplier pmChecked(checked);
        const SoftCachePolicy hitsAll(tolerance, 2 * tolerance);
        slot.reset(0, 1);
        KeyPointEvaluator{checked, evaluator}(slot);
        Projector{pmChecked}(slot);
        return ErrorMonitor{pmChecked, hitsAll, false, nullptr, &evaluator}(slot);
    };
    // PM within the tolerance at the checked points: a hit, which paid for them.
    EXPECT_EQ(route(1e6), Route::Reconstruct);
    EXPECT_EQ(slot.decision.state, CacheState::Hit);
    EXPECT_GT(slot.pointsEvaluated, 0);
    EXPECT_LE(slot.pointsEvaluated, kCheckedKeys * near.perKey);
    // PM off at a checked point (the data's noise against a tiny tolerance): the whole frame,
    // blended with weight 0.
    EXPECT_EQ(route(1e-12), Route::FailThrough);
    EXPECT_EQ(slot.decision.state, CacheState::Blend);
    EXPECT_EQ(slot.decision.weight, 0.0);
    EXPECT_EQ(slot.pointsEvaluated, checked.points);
    // Without an evaluator the monitor cannot check, and the hit is PM's (the one-frame tools).
    checked.tolerance = 1e-12;
    const PointMultiplier pmChecked(checked);
    slot.reset(0, 1);
    KeyPointEvaluator{checked, evaluator}(slot);
    Projector{pmChecked}(slot);
    EXPECT_EQ((ErrorMonitor{pmChecked, SoftCachePolicy(1e-12, 2e-12), false}(slot)), Route::Reconstruct);
}

TEST_F(Nodes, ErrorMonitorChecksEveryHitAtItsSentinels) {
    // Both parts of the predicted error certify every frame, so only the sentinels check a hit.
    Model checked = model;
    checked.keyErrorNorm = KeyErrorNorm::Predicted;
    checked.partEps = {1e6, 1e6};
    const std::set<Index> keys(checked.keyPoints.begin(), checked.keyPoints.end());
    Sentinels sentinels;
    for (Index p = 0; p < checked.points && sentinels.points.size() < 5; p += 3)
        if (!keys.count(p)) sentinels.points.push_back(p);
    checked.sentinels = sentinels;
    const FramePlan plan = FramePlan::make(checked, {}, 16, false);
    FrameSlot slot(plan, checked.keyCount(), checked.basisSize(), false);
    const auto route = [&](double tolerance) {
        checked.tolerance = tolerance;
        const PointMultiplier pmChecked(checked);
        const SoftCachePolicy hitsAll(1e6, 2e6);
        slot.reset(0, 1);
        KeyPointEvaluator{checked, evaluator}(slot);
        Projector{pmChecked}(slot);
        return ErrorMonitor{pmChecked, hitsAll, false, nullptr, &evaluator}(slot);
    };
    EXPECT_EQ(route(1e6), Route::Reconstruct) << "PM within 0.8 T at every sentinel";
    EXPECT_EQ(slot.pointsEvaluated, 5) << "a hit pays for its sentinels";
    EXPECT_EQ(route(1e-12), Route::FailThrough) << "PM off at a sentinel: the whole frame";
    EXPECT_EQ(slot.decision.state, CacheState::Blend);
    EXPECT_EQ(slot.decision.weight, 0.0);
    EXPECT_EQ(slot.pointsEvaluated, checked.points);
}

TEST_F(Nodes, BlenderIsTheLinearInterpolationOfSectionFive) {
    const FramePlan plan = FramePlan::make(model, {}, 100, false);
    FrameSlot slot(plan, model.keyCount(), model.basisSize(), false);
    slot.reset(0, 1);
    for (Index j = 0; j < model.basisSize(); ++j) slot.coords[size_t(j)] = 0.5 * double(j + 1);
    std::vector<double> pmValues(slot.values.size());
    pm.reconstruct(slot.coords.data(), pmValues.data());
    for (size_t x = 0; x < slot.values.size(); ++x) slot.values[x] = 10.0 + double(x);  // "full"
    slot.decision = {CacheState::Blend, 0.25};
    Blender{pm, plan}(slot, 0);
    for (size_t x = 0; x < slot.values.size(); ++x) {
        EXPECT_NEAR(slot.values[x], 0.75 * pmValues[x] + 0.25 * (10.0 + double(x)), 1e-12);
    }
    const std::vector<double> before = slot.values;
    slot.decision = {CacheState::Miss, 1.0};
    Blender{pm, plan}(slot, 0);
    EXPECT_EQ(slot.values, before) << "a miss is not blended";
}

TEST_F(Nodes, FailThroughReusesKeyValuesAndCatchesEvaluatorFailures) {
    const FramePlan plan = FramePlan::make(model, {}, 32, false);
    FrameSlot slot(plan, model.keyCount(), model.basisSize(), false);
    slot.reset(0, 2);
    KeyPointEvaluator{model, evaluator}(slot);
    slot.keyValues[0] = 1234.5;  // a marker: the output at key 0 must come from the key values
    for (Index c = 0; c < Index(plan.chunks.size()); ++c) FailThroughEvaluator{evaluator, plan}(slot, c);
    EXPECT_FALSE(slot.failed());
    EXPECT_EQ(slot.values[size_t(model.keyPoints[0] * 3)], 1234.5);
    EXPECT_EQ(slot.values[5 * 3 + 1], evaluator.value(2, 5, 1));

    evaluator.throwInFullAt = 3;
    slot.reset(7, 3);
    KeyPointEvaluator{model, evaluator}(slot);
    FailThroughEvaluator{evaluator, plan}(slot, 2);
    FailThroughEvaluator{evaluator, plan}(slot, 1);
    ASSERT_TRUE(slot.failed());
    // The lowest chunk's failure is kept, whichever ran first.
    EXPECT_EQ(slot.error(), "frame 3: node 'fail-through': evaluator 'synthetic': injected full failure");
}

TEST_F(Nodes, KeyPointEvaluatorTurnsExceptionsIntoFrameFailures) {
    const FramePlan plan = FramePlan::make(model, {}, 32, false);
    FrameSlot slot(plan, model.keyCount(), model.basisSize(), false);
    evaluator.throwInKeysAt = 9;
    slot.reset(0, 9);
    KeyPointEvaluator{model, evaluator}(slot);
    ASSERT_TRUE(slot.failed());
    EXPECT_EQ(slot.error(), "frame 9: node 'keys': evaluator 'synthetic': injected key failure");
    evaluator.nanInKeysAt = 10;
    slot.reset(1, 10);
    KeyPointEvaluator{model, evaluator}(slot);
    EXPECT_FALSE(slot.failed());
    EXPECT_FALSE(slot.keysFinite);
}

TEST_F(Nodes, FrameSourceStopsAtTheEndTheStopPointOrACancellation) {
    std::atomic<bool> cancel{false};
    RunControl control(&cancel);
    FrameSource source({5, 10, 3}, control);
    Index seq = -1;
    ASSERT_TRUE(source.next(seq));
    EXPECT_EQ(seq, 0);
    control.stopAfter(2);
    ASSERT_TRUE(source.next(seq));
    ASSERT_TRUE(source.next(seq));
    EXPECT_EQ(seq, 2);
    EXPECT_FALSE(source.next(seq));
    RunControl other(&cancel);
    FrameSource second({0, 10, 1}, other);
    bool hooked = false;
    other.setCancelHook([&] { hooked = true; });
    ASSERT_TRUE(second.next(seq));
    cancel = true;
    EXPECT_FALSE(second.next(seq));
    EXPECT_TRUE(hooked);
    EXPECT_TRUE(other.externallyCancelled());
    EXPECT_EQ(FrameRange({5, 10, 3}).last(), 32);
}

struct RecordingSink : FrameSink {
    std::vector<FrameResult> seen;
    void write(const FrameResult& r) override { seen.push_back(r); }
};

TEST_F(Nodes, OrderedSinkAppliesTheFailurePolicy) {
    const FramePlan plan = FramePlan::make(model, {}, 32, false);
    FrameSlot slot(plan, model.keyCount(), model.basisSize(), false);
    for (const FailurePolicy policyKind : {FailurePolicy::StopRun, FailurePolicy::MarkFailedAndContinue}) {
        RunControl control;
        RecordingSink sink;
        OrderedSink body(plan, sink, policyKind, control);
        for (Index s = 0; s < 4; ++s) {
            slot.reset(s, 100 + s);
            if (s == 1) slot.fail("keys", "broken");
            body(slot);
        }
        if (policyKind == FailurePolicy::StopRun) {
            ASSERT_EQ(sink.seen.size(), 1u);
            EXPECT_TRUE(control.hasRunError());
            EXPECT_EQ(control.runError(), "frame 101: node 'keys': broken");
            EXPECT_EQ(control.stopSequence(), 1);
        } else {
            ASSERT_EQ(sink.seen.size(), 4u);
            EXPECT_TRUE(sink.seen[1].failed);
            EXPECT_TRUE(sink.seen[1].values.empty());
            EXPECT_EQ(sink.seen[2].values.size(), size_t(300));
            EXPECT_FALSE(control.hasRunError());
        }
        EXPECT_EQ(control.failed.load(), 1);
    }
}

}  // namespace
}  // namespace pmsc::nodes
