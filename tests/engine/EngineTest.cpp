// Engine tests: order, bounded work in flight, failures, NaN, determinism, cancellation,
// fail-through routing, bounded memory. CI runs them under ThreadSanitizer (label "engine").
#include "engine/Engine.h"
#include "engine/FrameSetSink.h"
#include "nodes/FrameSlot.h"
#include "pmsc/Errors.h"
#include "pmsc/Sentinels.h"
#include "tests/common/SmallModel.h"
#include "tests/engine/Synthetic.h"

#include <gtest/gtest.h>

#include <map>
#include <mutex>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <numeric>
#include <random>
#include <string>

namespace pmsc::engine {
namespace {

using pmsc::test::withSentinels;
using testing::SyntheticEvaluator;
using testing::withWatchdog;

/// `make` throws an InputError whose message holds `words`.
template <class Make>
void expectInputError(Make&& make, const std::string& words) {
    try {
        make();
        ADD_FAILURE() << "no InputError; expected one saying '" << words << "'";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
}

/// Checks order and finiteness as frames arrive; keeps a copy of what it is told to keep.
class CheckingSink : public FrameSink {
public:
    explicit CheckingSink(const SyntheticEvaluator* e = nullptr, bool keep = true)
        : evaluator_(e), keep_(keep) {}
    void write(const FrameResult& r) override {
        if (evaluator_) evaluator_->frameDelivered();
        EXPECT_EQ(r.sequence, Index(frames.size())) << "frames out of order";
        frames.push_back(r.frame);
        states.push_back(r.state);
        failed.push_back(r.failed);
        for (const double v : r.values)
            ASSERT_TRUE(std::isfinite(v)) << "non-finite output, frame " << r.frame;
        if (keep_) values.emplace_back(r.values.begin(), r.values.end());
        if (throwAt == Index(frames.size()) - 1) throw IoError("disk full (injected)");
        peakLiveSlots = std::max(peakLiveSlots, nodes::FrameSlot::liveCount());
    }
    std::vector<Index> frames;
    std::vector<CacheState> states;
    std::vector<char> failed;
    std::vector<std::vector<double>> values;
    Index throwAt = -1;
    Index peakLiveSlots = 0;

private:
    const SyntheticEvaluator* evaluator_;
    bool keep_;
};

struct Fixture : ::testing::Test {
    Model model = testing::makeModel(/*points*/ 600, /*channels*/ 3, /*basis*/ 8, /*keys*/ 20);
    SyntheticEvaluator evaluator{model, 400};
    SoftCachePolicy policy = testing::syntheticPolicy(model, evaluator);

    EngineOptions options(int threads) const {
        EngineOptions o;
        o.threads = threads;
        o.policy = policy;
        o.chunkPoints = 64;
        return o;
    }
};

TEST_F(Fixture, MatchesThePlainSerialAlgorithmFrameByFrame) {
    Engine engine(model, evaluator, options(2));
    CheckingSink sink;
    RunStats stats;
    withWatchdog(60, "run", [&] { stats = engine.run({0, 40, 1}, sink); });
    ASSERT_EQ(sink.frames.size(), 40u);
    for (Index f = 0; f < 40; ++f) {
        CacheDecision d;
        const auto expected = testing::referenceFrame(model, evaluator, policy, f, &d);
        EXPECT_EQ(sink.states[size_t(f)], d.state) << "frame " << f;
        ASSERT_EQ(sink.values[size_t(f)].size(), expected.size());
        for (size_t x = 0; x < expected.size(); ++x) {
            ASSERT_NEAR(sink.values[size_t(f)][x], expected[x], 1e-9) << "frame " << f << " value " << x;
        }
    }
    // The synthetic classes give 2 hits, 1 blend, 1 miss per 4 frames.
    EXPECT_EQ(stats.hits, 20);
    EXPECT_EQ(stats.blends, 10);
    EXPECT_EQ(stats.misses, 10);
    EXPECT_EQ(stats.framesDelivered, 40);
}

TEST_F(Fixture, KeepsFrameOrderUnderRandomEvaluatorDelays) {
    evaluator.maxDelayMicros = 2000;
    EngineOptions o = options(2);
    o.maxFramesInFlight = 6;
    Engine engine(model, evaluator, o);
    CheckingSink sink(&evaluator, false);
    withWatchdog(120, "run", [&] { engine.run({10, 120, 2}, sink); });
    ASSERT_EQ(sink.frames.size(), 120u);
    for (Index i = 0; i < 120; ++i) EXPECT_EQ(sink.frames[size_t(i)], 10 + 2 * i);
}

TEST_F(Fixture, NeverHasMoreFramesInFlightThanTheBound) {
    evaluator.maxDelayMicros = 500;
    for (const Index bound : {Index(1), Index(3)}) {
        SyntheticEvaluator e(model, 400);
        e.maxDelayMicros = 500;
        EngineOptions o = options(2);
        o.maxFramesInFlight = bound;
        Engine engine(model, e, o);
        CheckingSink sink(&e, false);
        RunStats stats;
        withWatchdog(120, "run", [&] { stats = engine.run({0, 200, 1}, sink); });
        EXPECT_EQ(sink.frames.size(), 200u);
        EXPECT_LE(e.peakInFlight(), bound) << "evaluator saw more frames at once than the bound";
        EXPECT_LE(stats.peakFramesInFlight, bound);
        EXPECT_GE(e.peakInFlight(), 1);
    }
}

TEST_F(Fixture, AMemoryLimitCutsTheFramesInFlightAndNotTheResults) {
    EngineOptions o = options(2);
    o.maxFramesInFlight = 8;
    Engine free(model, evaluator, o);
    CheckingSink expected;
    RunStats freeStats;
    withWatchdog(60, "run", [&] { freeStats = free.run({0, 40, 1}, expected); });
    EXPECT_EQ(freeStats.maxFramesInFlight, 8);
    // Room for three frame buffers and a half: three in flight, the same frames out.
    const std::uint64_t perFrame = free.frameBytes();
    ASSERT_GT(perFrame, std::uint64_t(model.points * model.channels * 8));
    o.memoryLimit = perFrame * 7 / 2;
    Engine limited(model, evaluator, o);
    CheckingSink got;
    RunStats stats;
    withWatchdog(60, "run", [&] { stats = limited.run({0, 40, 1}, got); });
    EXPECT_EQ(stats.maxFramesInFlight, 3);
    EXPECT_LE(stats.peakFramesInFlight, 3);
    EXPECT_EQ(got.frames, expected.frames);
    EXPECT_EQ(got.values, expected.values);
    o.memoryLimit = perFrame - 1;  // not one frame
    expectInputError([&] { Engine none(model, evaluator, o); }, "cannot hold one frame in flight");
}

TEST_F(Fixture, AnExceptionOnARandomFrameEndsTheRunWithFrameAndNode) {
    std::mt19937 rng(1234);
    for (int trial = 0; trial < 6; ++trial) {
        SyntheticEvaluator e(model, 400);
        e.maxDelayMicros = 300;
        const Index bad = Index(rng() % 150);
        const bool inKeys = trial % 2 == 0;
        // A full-evaluation failure needs a frame that fails through: class 2 is a miss.
        if (inKeys) {
            e.throwInKeysAt = bad;
        } else {
            e.throwInFullAt = bad - bad % 4 + 2;
        }
        const Index badFrame = inKeys ? bad : bad - bad % 4 + 2;
        Engine engine(model, e, options(2));
        CheckingSink sink(nullptr, false);
        std::string message;
        withWatchdog(60, "failing run", [&] {
            try {
                engine.run({0, 200, 1}, sink);
            } catch (const EvaluatorError& err) {
                message = err.what();
            }
        });
        ASSERT_FALSE(message.empty()) << "no EvaluatorError for frame " << badFrame;
        EXPECT_NE(message.find("frame " + std::to_string(badFrame) + ":"), std::string::npos) << message;
        EXPECT_NE(message.find(inKeys ? "node 'keys'" : "node 'fail-through'"), std::string::npos) << message;
        EXPECT_NE(message.find("injected"), std::string::npos) << message;
        // StopRun: exactly the frames before the failing one, none after, none partial.
        ASSERT_EQ(Index(sink.frames.size()), badFrame) << message;
        EXPECT_EQ(engine.lastStats().failed, 1);
    }
}

TEST_F(Fixture, MarkFailedAndContinueDeliversEveryFrame) {
    evaluator.throwInKeysAt = 7;
    evaluator.throwInFullAt = 14;  // class 2: a miss
    EngineOptions o = options(2);
    o.failurePolicy = FailurePolicy::MarkFailedAndContinue;
    Engine engine(model, evaluator, o);
    CheckingSink sink;
    RunStats stats;
    withWatchdog(60, "run", [&] { stats = engine.run({0, 30, 1}, sink); });
    ASSERT_EQ(sink.frames.size(), 30u);
    for (Index f = 0; f < 30; ++f) EXPECT_EQ(bool(sink.failed[size_t(f)]), f == 7 || f == 14) << f;
    EXPECT_TRUE(sink.values[7].empty());
    EXPECT_EQ(stats.failed, 2);
    EXPECT_EQ(stats.hits + stats.blends + stats.misses, 28);
}

TEST_F(Fixture, ASinkExceptionEndsTheRunUnchanged) {
    Engine engine(model, evaluator, options(2));
    CheckingSink sink;
    sink.throwAt = 5;
    withWatchdog(60, "run", [&] { EXPECT_THROW(engine.run({0, 100, 1}, sink), IoError); });
    EXPECT_EQ(sink.frames.size(), 6u);  // the sixth write threw; no write after it
}

TEST_F(Fixture, NanInKeyValuesForcesAFullEvaluation) {
    evaluator.nanInKeysAt = 4;  // class 0: would be a hit
    Engine engine(model, evaluator, options(2));
    CheckingSink sink;
    RunStats stats;
    withWatchdog(60, "run", [&] { stats = engine.run({0, 8, 1}, sink); });
    ASSERT_EQ(sink.frames.size(), 8u);
    EXPECT_EQ(sink.states[4], CacheState::Miss);
    EXPECT_EQ(stats.forcedMisses, 1);
    EXPECT_GT(evaluator.fullCalls(4), 0);
    // The output is the full evaluation, keys included (they were evaluated again).
    for (Index p = 0; p < model.points; ++p)
        for (Index c = 0; c < 3; ++c)
            ASSERT_EQ(sink.values[4][size_t(p * 3 + c)], evaluator.value(4, p, c)) << p;
}

TEST_F(Fixture, NanInTheFullEvaluationIsAnEvaluatorErrorNeverAnOutput) {
    evaluator.nanInFullAt = 6;  // class 2: a miss
    evaluator.nanPoint = 123;
    {
        Engine engine(model, evaluator, options(2));
        CheckingSink sink;
        std::string message;
        withWatchdog(60, "run", [&] {
            try {
                engine.run({0, 20, 1}, sink);
            } catch (const EvaluatorError& e) {
                message = e.what();
            }
        });
        EXPECT_NE(message.find("frame 6:"), std::string::npos) << message;
        EXPECT_NE(message.find("point 123"), std::string::npos) << message;
        EXPECT_EQ(sink.frames.size(), 6u);
    }
    {
        EngineOptions o = options(1);
        o.failurePolicy = FailurePolicy::MarkFailedAndContinue;
        Engine engine(model, evaluator, o);
        CheckingSink sink;  // asserts every delivered value is finite
        withWatchdog(60, "run", [&] { engine.run({0, 20, 1}, sink); });
        EXPECT_EQ(sink.frames.size(), 20u);
        EXPECT_TRUE(sink.failed[6]);
    }
}

TEST_F(Fixture, OutputIsIdenticalBitForBitAtOneAndTwoThreads) {
    evaluator.maxDelayMicros = 200;
    std::vector<FrameSet> results;
    for (const int threads : {1, 2, 2}) {
        EngineOptions o = options(threads);
        o.chunkPoints = 0;  // the automatic chunking must not depend on the thread count
        Engine engine(model, evaluator, o);
        FrameSetSink sink(60, model.points, 3);
        withWatchdog(60, "run", [&] { engine.run({0, 60, 1}, sink); });
        results.push_back(sink.values());
    }
    for (size_t i = 1; i < results.size(); ++i) {
        ASSERT_EQ(results[i].values.size(), results[0].values.size());
        EXPECT_EQ(std::memcmp(results[i].values.data(), results[0].values.data(),
                              results[0].values.size() * sizeof(double)),
                  0)
            << "run " << i;
    }
}

TEST_F(Fixture, CancellationFromAnotherThreadStopsWithinAFrame) {
    SyntheticEvaluator slow(model, 400);
    slow.busyMicros = 2000;  // ~2 ms per evaluator call
    std::atomic<bool> cancel{false};
    slow.cancelWatch = &cancel;
    EngineOptions o = options(2);
    o.cancel = &cancel;
    o.maxFramesInFlight = 8;
    Engine engine(model, slow, o);
    CheckingSink sink(nullptr, false);
    std::chrono::steady_clock::time_point cancelledAt;
    std::thread canceller([&] {
        std::this_thread::sleep_for(std::chrono::milliseconds(60));
        cancelledAt = std::chrono::steady_clock::now();
        cancel.store(true);
    });
    bool threwCancelled = false;
    withWatchdog(60, "cancelled run", [&] {
        try {
            engine.run({0, 400, 1}, sink);
        } catch (const Cancelled&) {
            threwCancelled = true;
        }
    });
    const auto returnedAt = std::chrono::steady_clock::now();
    canceller.join();
    EXPECT_TRUE(threwCancelled);
    EXPECT_TRUE(engine.lastStats().cancelled);
    EXPECT_LT(sink.frames.size(), 400u);
    // Delivered frames are a prefix, and the run ended within about one frame's time. The
    // measure that does not depend on how busy the machine is: no evaluator call (2 ms each)
    // begins after the flag, except one per thread that was already past its check when the
    // flag flipped. The wall-time bound only catches a run that keeps going; it is loose
    // (a frame is ~4 ms) because a loaded CI machine under a sanitizer may not schedule us.
    for (size_t i = 0; i < sink.frames.size(); ++i) EXPECT_EQ(sink.frames[i], Index(i));
    EXPECT_LE(slow.callsAfterCancel(), 2) << "evaluator calls began after the cancellation";
    const double ms = std::chrono::duration<double, std::milli>(returnedAt - cancelledAt).count();
    EXPECT_LT(ms, 250.0) << "took " << ms << " ms to stop";
}

TEST_F(Fixture, HitsNeverCallTheFailThroughEvaluator) {
    Engine engine(model, evaluator, options(2));
    CheckingSink sink;
    withWatchdog(60, "run", [&] { engine.run({0, 80, 1}, sink); });
    for (Index f = 0; f < 80; ++f) {
        EXPECT_EQ(evaluator.keyCalls(f), 1) << f;
        if (sink.states[size_t(f)] == CacheState::Hit) {
            EXPECT_EQ(evaluator.fullCalls(f), 0) << "hit frame " << f << " failed through";
        } else {
            EXPECT_EQ(evaluator.fullCalls(f), int(engine.lastStats().chunks)) << f;
        }
    }
    // Key points are evaluated once per frame: a fail-through evaluates only the others.
    EXPECT_EQ(evaluator.pointsEvaluated(), 40 * (model.points - model.keyCount()));
}

TEST_F(Fixture, PointsWantedLimitsReconstructionAndFailThrough) {
    std::vector<Index> wanted = {599, 3, model.keyPoints[2], 42, 301};
    EngineOptions o = options(2);
    o.pointsWanted = wanted;
    Engine engine(model, evaluator, o);
    CheckingSink sink;
    withWatchdog(60, "run", [&] { engine.run({0, 12, 1}, sink); });
    ASSERT_EQ(engine.outputPoints(), wanted);
    for (Index f = 0; f < 12; ++f) {
        const auto full = testing::referenceFrame(model, evaluator, policy, f);
        ASSERT_EQ(sink.values[size_t(f)].size(), wanted.size() * 3);
        for (size_t i = 0; i < wanted.size(); ++i)
            for (Index c = 0; c < 3; ++c)
                EXPECT_NEAR(sink.values[size_t(f)][i * 3 + size_t(c)], full[size_t(wanted[i] * 3 + c)], 1e-9);
    }
    // 6 frames of 12 fail through (blends and misses); each evaluates the 4 wanted non-key points.
    EXPECT_EQ(evaluator.pointsEvaluated(), 6 * 4);
}

TEST_F(Fixture, WholeFrameFailThroughGivesTheSameResult) {
    EngineOptions o = options(2);
    o.wholeFrameFailThrough = true;
    Engine engine(model, evaluator, o);
    CheckingSink sink;
    withWatchdog(60, "run", [&] { engine.run({0, 12, 1}, sink); });
    EXPECT_EQ(engine.lastStats().chunks, 1);
    for (Index f = 0; f < 12; ++f) {
        const auto expected = testing::referenceFrame(model, evaluator, policy, f);
        for (size_t x = 0; x < expected.size(); ++x)
            ASSERT_NEAR(sink.values[size_t(f)][x], expected[x], 1e-9);
    }
}

TEST_F(Fixture, KeepPointMultiplicationHandsThePmResultOfEveryFrame) {
    EngineOptions o = options(2);
    o.keepPointMultiplication = true;
    Engine engine(model, evaluator, o);
    FrameSetSink sink(12, model.points, 3, /*keepPm*/ true);
    withWatchdog(60, "run", [&] { engine.run({0, 12, 1}, sink); });
    const PointMultiplier pm(model);
    for (Index f = 0; f < 12; ++f) {
        std::vector<double> k(size_t(model.keyCount() * 3)), b(size_t(model.basisSize())),
            r(size_t(model.points * 3));
        for (Index i = 0; i < model.keyCount(); ++i)
            for (Index c = 0; c < 3; ++c)
                k[size_t(i * 3 + c)] = evaluator.value(f, model.keyPoints[size_t(i)], c);
        pm.project(k.data(), b.data());
        pm.reconstruct(b.data(), r.data());
        for (size_t x = 0; x < r.size(); ++x) ASSERT_EQ(sink.pmValues().frame(f)[x], r[x]) << f;
        const auto expected = testing::referenceFrame(model, evaluator, policy, f);
        for (size_t x = 0; x < r.size(); ++x) ASSERT_NEAR(sink.values().frame(f)[x], expected[x], 1e-9);
    }
}

TEST_F(Fixture, EstimateAndChunkCallbacksShowEachFailThroughAsItFinishes) {
    // What an interactive client sees: a frame that does not hit reports its point multiplication
    // once, before any branch, then every branch's final values; together they are the frame.
    std::mutex m;
    std::map<Index, std::vector<double>> estimates;                // frame -> PM values
    std::map<Index, std::vector<std::pair<Index, Index>>> ranges;  // frame -> (first, count)
    std::map<Index, std::vector<double>> assembled;                // frame -> values from the chunks
    EngineOptions o = options(2);
    o.onEstimate = [&](const FrameEstimate& e) {
        std::lock_guard<std::mutex> lock(m);
        EXPECT_NE(e.state, CacheState::Hit);
        EXPECT_TRUE(ranges[e.frame].empty()) << "a branch finished before the estimate of frame " << e.frame;
        EXPECT_EQ(estimates.count(e.frame), 0u);
        estimates[e.frame].assign(e.values.begin(), e.values.end());
    };
    o.onChunk = [&](const ChunkFinished& c) {
        std::lock_guard<std::mutex> lock(m);
        EXPECT_EQ(estimates.count(c.frame), 1u)
            << "a branch of frame " << c.frame << " came before its estimate";
        const Index count = Index(c.values.size()) / 3;
        ranges[c.frame].push_back({c.firstOutput, count});
        auto& a = assembled[c.frame];
        a.resize(size_t(model.points * 3));
        std::copy(c.values.begin(), c.values.end(), a.begin() + std::ptrdiff_t(c.firstOutput * 3));
    };
    Engine engine(model, evaluator, o);
    FrameSetSink sink(12, model.points, 3, /*keepPm*/ true);
    withWatchdog(60, "run", [&] { engine.run({0, 12, 1}, sink); });
    Index failedThrough = 0;
    for (Index f = 0; f < 12; ++f) {
        if (sink.info()[size_t(f)].state == CacheState::Hit) {
            EXPECT_EQ(estimates.count(f), 0u);
            continue;
        }
        ++failedThrough;
        ASSERT_EQ(estimates.count(f), 1u) << f;
        for (size_t x = 0; x < estimates[f].size(); ++x)
            ASSERT_EQ(estimates[f][x], sink.pmValues().frame(f)[x]);
        auto r = ranges[f];
        std::sort(r.begin(), r.end());
        Index next = 0;
        for (const auto& [first, count] : r) {
            EXPECT_EQ(first, next);
            next = first + count;
        }
        EXPECT_EQ(next, model.points) << "the branches of frame " << f << " do not cover its points once";
        for (size_t x = 0; x < assembled[f].size(); ++x)
            ASSERT_EQ(assembled[f][x], sink.values().frame(f)[x]);
    }
    EXPECT_GT(failedThrough, 0);
}

TEST_F(Fixture, KeysInParallelPiecesGiveTheSameFrames) {
    // Latency over throughput (one frame at a time): the keys in pieces of 2 points.
    auto runWith = [&](Index piece, int threads) {
        EngineOptions o = options(threads);
        o.keyPiecePoints = piece;
        Engine engine(model, evaluator, o);
        FrameSetSink sink(12, model.points, 3);
        withWatchdog(60, "run", [&] { engine.run({0, 12, 1}, sink); });
        return std::vector<double>(sink.values().frame(0), sink.values().frame(0) + 12 * model.points * 3);
    };
    EXPECT_EQ(runWith(0, 2), runWith(2, 2));
    EXPECT_EQ(runWith(0, 1), runWith(2, 2));
}

/// Delegates to another evaluator and records the frame and size of every evaluate() call;
/// `setUp` declares that every call pays a set-up (FailThroughShape::callSetUp).
class CallSizes : public PointEvaluator {
public:
    explicit CallSizes(const PointEvaluator& inner, bool setUp = false, bool wholeFrame = false)
        : inner_(inner), setUp_(setUp), wholeFrame_(wholeFrame) {}
    FailThroughShape failThroughShape() const override {
        FailThroughShape shape = inner_.failThroughShape();
        shape.callSetUp = shape.callSetUp || setUp_;
        shape.wholeFrame = shape.wholeFrame || wholeFrame_;
        return shape;
    }
    std::string name() const override { return inner_.name(); }
    Index pointCount() const override { return inner_.pointCount(); }
    Index channelCount() const override { return inner_.channelCount(); }
    Index frameCount() const override { return inner_.frameCount(); }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            calls_.emplace_back(frame, static_cast<Index>(points.size()));
        }
        inner_.evaluate(frame, points, out);
    }
    /// Records an event of the caller's beside the calls (a negative `size` tells them apart).
    void mark(Index frame, Index size) const {
        std::lock_guard<std::mutex> lock(mutex_);
        calls_.emplace_back(frame, size);
    }
    Index largest() const {
        Index most = 0;
        for (const auto& call : calls()) most = std::max(most, call.second);
        return most;
    }
    std::vector<std::pair<Index, Index>> calls() const {
        std::lock_guard<std::mutex> lock(mutex_);
        return calls_;
    }

private:
    const PointEvaluator& inner_;
    bool setUp_;
    bool wholeFrame_;
    mutable std::mutex mutex_;
    mutable std::vector<std::pair<Index, Index>> calls_;
};

TEST_F(Fixture, AHitsCheckPointsGoInTheKeysPiecesToo) {
    // One frame at a time (pmsc view): the sentinels every hit computes are evaluated in pieces
    // as the keys are, with the same frames as in one call.
    const Model checked = withSentinels(model, 1e300);  // every check passes: every frame stays a hit
    const pmsc::Sentinels& s = *checked.sentinels;
    auto runWith = [&](Index piece, Index& largest) {
        CallSizes counting(evaluator);
        EngineOptions o = options(2);
        o.policy = SoftCachePolicy(1e300, 1e300);
        o.keyPiecePoints = piece;
        Engine engine(checked, counting, o);
        FrameSetSink sink(6, checked.points, 3);
        RunStats stats;
        withWatchdog(60, "run", [&] { stats = engine.run({0, 6, 1}, sink); });
        EXPECT_EQ(stats.hits, 6);
        largest = counting.largest();
        return std::vector<double>(sink.values().frame(0), sink.values().frame(0) + 6 * checked.points * 3);
    };
    Index whole = 0, pieces = 0;
    EXPECT_EQ(runWith(0, whole), runWith(4, pieces));
    EXPECT_EQ(whole, static_cast<Index>(s.points.size())) << "in one call: the sentinels together";
#if defined(__SANITIZE_THREAD__)
    EXPECT_EQ(pieces, whole) << "ThreadSanitizer builds evaluate in one call (nodes/PointPieces.h)";
#else
    EXPECT_LE(pieces, 4) << "in pieces: no call of more than 4 points";
#endif
}

TEST_F(Fixture, AHitsEstimateBeforeItsCheckComesBetweenTheKeysAndTheSentinelsAndChangesNoFrame) {
    // pmsc view's order for a hit: keys, the reconstruction handed to onEstimate, then the
    // sentinels. A hit the check lets stand is delivered as it was shown; one it refuses blends
    // with weight 0 and is shown once. Either way the frames are those of a run without it.
    for (const double tolerance : {1e300, 1e-12}) {  // every check passes; every check refuses
        const Model checked = withSentinels(model, tolerance);
        const auto sentinels = static_cast<Index>(checked.sentinels->points.size());
        std::vector<CacheState> states;  // as delivered (the same with and without the option)
        auto runWith = [&](bool early, std::map<Index, std::vector<double>>& shown, RunStats& stats) {
            const CallSizes counting(evaluator);
            EngineOptions o = options(2);
            o.policy = SoftCachePolicy(1e300, 1e300);  // every key error is a hit's
            o.estimateBeforeCheck = early;
            std::mutex m;
            o.onEstimate = [&](const FrameEstimate& e) {
                std::lock_guard<std::mutex> lock(m);
                EXPECT_EQ(shown.count(e.frame), 0u) << "frame " << e.frame << " shown twice";
                EXPECT_EQ(e.state, early ? CacheState::Hit : CacheState::Blend) << "frame " << e.frame;
                shown[e.frame].assign(e.values.begin(), e.values.end());
                counting.mark(e.frame, -1);
            };
            Engine engine(checked, counting, o);
            FrameSetSink sink(6, checked.points, 3);
            withWatchdog(60, "run", [&] { stats = engine.run({0, 6, 1}, sink); });
            if (early) {
                for (Index f = 0; f < 6; ++f) EXPECT_EQ(sink.info()[size_t(f)].state, states[size_t(f)]) << f;
            } else {
                for (Index f = 0; f < 6; ++f) states.push_back(sink.info()[size_t(f)].state);
            }
            if (early) {
                std::map<Index, std::vector<Index>> perFrame;
                for (const auto& [frame, size] : counting.calls()) perFrame[frame].push_back(size);
                for (const auto& [frame, sizes] : perFrame) {
                    EXPECT_GE(sizes.size(), 3u) << frame;
                    if (sizes.size() < 3) continue;
                    EXPECT_EQ(sizes[0], checked.keyCount()) << "frame " << frame << ": the keys first";
                    EXPECT_EQ(sizes[1], -1) << "frame " << frame << ": then its image";
                    EXPECT_EQ(sizes[2], sentinels) << "frame " << frame << ": then the sentinels";
                }
            }
            return std::vector<double>(sink.values().frame(0),
                                       sink.values().frame(0) + 6 * checked.points * 3);
        };
        std::map<Index, std::vector<double>> shownLate, shownEarly;
        RunStats late, early;
        const std::vector<double> plain = runWith(false, shownLate, late);
        EXPECT_EQ(runWith(true, shownEarly, early), plain) << "tolerance " << tolerance;
        EXPECT_EQ(shownEarly.size(), 6u) << "every hit is shown once, before its check";
        // At T = 1e-12 the check refuses the frames PM does not reproduce to the last bits.
        EXPECT_EQ(early.hits + early.blends, 6);
        EXPECT_EQ(early.blends > 0, tolerance < 1) << "tolerance " << tolerance;
        for (Index f = 0; f < 6; ++f) {
            const std::vector<double>& values = shownEarly[f];
            if (states[size_t(f)] == CacheState::Hit) {
                EXPECT_EQ(shownLate.count(f), 0u)
                    << "without the option a hit is not shown before it is delivered";
                EXPECT_TRUE(std::equal(values.begin(), values.end(),
                                       plain.begin() + std::ptrdiff_t(f * checked.points * 3)))
                    << "frame " << f << ": the image shown is the hit delivered";
            } else {
                EXPECT_EQ(values, shownLate[f])
                    << "frame " << f << ": a refused hit's image is its point multiplication";
            }
        }
    }
}

TEST_F(Fixture, AnEvaluatorWhoseCallsShareWorkComputesAHitsSentinelsInTheKeysCall) {
    // A child process or a whole-frame rig: a hit asks once, for its keys and sentinels together,
    // and every frame is delivered as by an evaluator asked for them in two calls.
    for (const double tolerance : {1e300, 1e-12}) {  // every check passes; every check refuses
        const Model checked = withSentinels(model, tolerance);
        const auto sentinels = static_cast<Index>(checked.sentinels->points.size());
        auto runWith = [&](const CallSizes& counting, std::vector<CacheState>& states, RunStats& stats) {
            EngineOptions o = options(2);
            o.policy = SoftCachePolicy(1e300, 1e300);  // every key error is a hit's
            Engine engine(checked, counting, o);
            FrameSetSink sink(6, checked.points, 3);
            withWatchdog(60, "run", [&] { stats = engine.run({0, 6, 1}, sink); });
            for (Index f = 0; f < 6; ++f) states.push_back(sink.info()[size_t(f)].state);
            return std::vector<double>(sink.values().frame(0),
                                       sink.values().frame(0) + 6 * checked.points * 3);
        };
        std::vector<CacheState> twoCalls, oneCall;
        RunStats apart, together;
        const CallSizes plain(evaluator);
        const std::vector<double> expected = runWith(plain, twoCalls, apart);
        for (const bool wholeFrame : {false, true}) {
            const CallSizes sharing(evaluator, !wholeFrame, wholeFrame);
            oneCall.clear();
            EXPECT_EQ(runWith(sharing, oneCall, together), expected) << "tolerance " << tolerance;
            EXPECT_EQ(oneCall, twoCalls);
            EXPECT_EQ(together.hits, apart.hits);
            EXPECT_EQ(together.blends, apart.blends);
            EXPECT_EQ(together.blends > 0, tolerance < 1) << "at 1e-12 the check refuses hits";
            std::map<Index, std::vector<Index>> perFrame;
            for (const auto& [frame, size] : sharing.calls()) perFrame[frame].push_back(size);
            ASSERT_EQ(perFrame.size(), 6u);
            for (const auto& [frame, sizes] : perFrame) {
                EXPECT_EQ(sizes.front(), checked.keyCount() + sentinels)
                    << "frame " << frame << ": the keys and the sentinels in one call";
                if (oneCall[size_t(frame)] == CacheState::Hit) {
                    EXPECT_EQ(sizes.size(), 1u) << "frame " << frame << ": a hit asks once";
                } else if (!wholeFrame) {
                    EXPECT_EQ(std::accumulate(sizes.begin(), sizes.end(), Index(0)), checked.points)
                        << "frame " << frame << ": every point once (the fail-through reuses both)";
                }
                EXPECT_EQ(std::count(sizes.begin(), sizes.end(), sentinels), 0)
                    << "frame " << frame << ": the sentinels are not asked for again";
            }
        }
    }
    // With a client that shows a hit before its check, the keys come alone (the previous test).
}

TEST_F(Fixture, AFailureOfTheKeysAndSentinelsCallFailsTheFrameAtTheKeys) {
    // The synthetic evaluator throws on frame 3 in any call but the model's own key list: here the
    // keys' and sentinels' call, so the frame fails in the key node, and no frame after it is sent.
    const Model checked = withSentinels(model, 1e300);
    evaluator.throwInFullAt = 3;
    const CallSizes sharing(evaluator, /*setUp*/ true);
    EngineOptions o = options(1);
    o.policy = SoftCachePolicy(1e300, 1e300);
    Engine engine(checked, sharing, o);
    FrameSetSink sink(6, checked.points, 3);
    std::string message;
    withWatchdog(60, "run", [&] {
        try {
            engine.run({0, 6, 1}, sink);
        } catch (const EvaluatorError& e) {
            message = e.what();
        }
    });
    EXPECT_NE(message.find("frame 3: node 'keys'"), std::string::npos) << message;
    EXPECT_NE(message.find("injected full failure"), std::string::npos) << message;
    EXPECT_EQ(engine.lastStats().failed, 1);
    EXPECT_EQ(engine.lastStats().hits, 3);
}

TEST_F(Fixture, AnEstimateBeforeTheCheckNeedsSomeoneToShowItTo) {
    EngineOptions o = options(2);
    o.estimateBeforeCheck = true;
    expectInputError([&] { Engine engine(model, evaluator, o); }, "estimateBeforeCheck needs onEstimate");
}

TEST_F(Fixture, AnEvaluatorWhoseCallsPayASetUpFailsThroughInOneCallPerThread) {
    // Every frame misses (eps 0), or blends (eps 0 to infinity: PM reconstructed in the
    // fail-through's chunks and blended with the full values): each asks for its keys, then for
    // the rest of its points, with the same values as in the automatic chunks.
    for (const bool blend : {false, true}) {
        auto runWith = [&](const PointEvaluator& e, int threads) {
            EngineOptions o = options(threads);
            o.chunkPoints = 0;     // automatic
            o.keyPiecePoints = 4;  // ignored: each piece would pay the set-up
            o.policy = SoftCachePolicy(0, blend ? 1e300 : 0);
            Engine engine(model, e, o);
            FrameSetSink sink(12, model.points, 3);
            RunStats stats;
            withWatchdog(60, "run", [&] { stats = engine.run({0, 12, 1}, sink); });
            EXPECT_EQ(blend ? stats.blends : stats.misses, 12);
            return std::vector<double>(sink.values().frame(0),
                                       sink.values().frame(0) + 12 * model.points * 3);
        };
        const std::vector<double> plain = runWith(evaluator, 2);
        for (const int threads : {1, 2, 3}) {
            const CallSizes counting(evaluator, /*setUp*/ true);
            EXPECT_EQ(runWith(counting, threads), plain) << threads << " threads: the same values";
            std::map<Index, std::vector<Index>> perFrame;
            for (const auto& [frame, size] : counting.calls()) perFrame[frame].push_back(size);
            ASSERT_EQ(perFrame.size(), 12u);
            for (const auto& [frame, sizes] : perFrame) {
                EXPECT_EQ(Index(sizes.size()), 1 + threads)
                    << "frame " << frame << ": the keys, a call per thread";
                EXPECT_EQ(sizes.front(), model.keyCount()) << "frame " << frame << ": the keys in one call";
                EXPECT_EQ(std::accumulate(sizes.begin(), sizes.end(), Index(0)), model.points)
                    << "frame " << frame << ": every point once (the fail-through reuses the keys)";
            }
        }
    }
}

TEST(EngineLarge, AHitOfALargeFrameReconstructsInBlocksTheSameAtAnyThreadCount) {
    // From 65,536 points a hit reconstructs in parallel blocks; the blocks depend on N only.
    const Model model = testing::makeModel(70000, 3, 4, 12);
    SyntheticEvaluator evaluator(model, 3);
    const PointMultiplier pm(model);
    auto runWith = [&](int threads) {
        EngineOptions o;
        o.threads = threads;
        o.policy = SoftCachePolicy(1e300, 1e300);  // every frame a hit
        Engine engine(model, evaluator, o);
        FrameSetSink sink(3, model.points, 3);
        withWatchdog(120, "run", [&] { engine.run({0, 3, 1}, sink); });
        return std::vector<double>(sink.values().frame(0), sink.values().frame(0) + 3 * model.points * 3);
    };
    const auto one = runWith(1), two = runWith(2);
    EXPECT_EQ(one, two);
    // And it is the reconstruction of the frame's coordinates.
    std::vector<double> k(size_t(model.keyCount() * 3)), b(size_t(model.basisSize())),
        r(size_t(model.points * 3));
    for (Index i = 0; i < model.keyCount(); ++i)
        for (Index c = 0; c < 3; ++c)
            k[size_t(i * 3 + c)] = evaluator.value(0, model.keyPoints[size_t(i)], c);
    pm.project(k.data(), b.data());
    pm.reconstruct(b.data(), r.data());
    for (size_t x = 0; x < r.size(); ++x) ASSERT_NEAR(one[x], r[x], 1e-12 * (1 + std::abs(r[x]))) << x;
}

TEST(EngineMemory, HundredThousandFramesRunInBoundedMemory) {
    const Model model = testing::makeModel(12, 3, 3, 4);
    SyntheticEvaluator evaluator(model, 100000);
    EngineOptions o;
    o.threads = 2;
    o.maxFramesInFlight = 4;
    o.policy = testing::syntheticPolicy(model, evaluator);
    CheckingSink sink(&evaluator, false);
    {
        Engine engine(model, evaluator, o);
        RunStats stats;
        withWatchdog(300, "100k frames", [&] { stats = engine.run({0, 100000, 1}, sink); });
        EXPECT_EQ(stats.framesDelivered, 100000);
        EXPECT_LE(sink.peakLiveSlots, 4) << "frame buffers grew with the range";
        EXPECT_LE(evaluator.peakInFlight(), 4);
        // A second run reuses the engine's buffers.
        CheckingSink second(&evaluator, false);
        withWatchdog(60, "second run", [&] { engine.run({0, 1000, 1}, second); });
        EXPECT_EQ(nodes::FrameSlot::liveCount(), 4);
    }
    EXPECT_EQ(nodes::FrameSlot::liveCount(), 0);
}

TEST_F(Fixture, StatsAndProgress) {
    EngineOptions o = options(2);
    Index calls = 0, lastDone = 0;
    bool monotonic = true;
    o.progress = [&](const Progress& p) {
        ++calls;
        monotonic = monotonic && p.framesDone == lastDone + 1 && p.framesTotal == 24;
        lastDone = p.framesDone;
    };
    Engine engine(model, evaluator, o);
    CheckingSink sink;
    RunStats stats;
    withWatchdog(60, "run", [&] { stats = engine.run({0, 24, 1}, sink); });
    EXPECT_EQ(calls, 24);
    EXPECT_TRUE(monotonic);
    const auto j = nlohmann::json::parse(stats.toJson());
    EXPECT_EQ(j.at("frames_delivered").get<Index>(), 24);
    EXPECT_EQ(j.at("hits").get<Index>() + j.at("blends").get<Index>() + j.at("misses").get<Index>(), 24);
    EXPECT_GT(j.at("frames_per_second").get<double>(), 0);
    bool sawKeys = false;
    for (const auto& n : j.at("nodes")) {
        if (n.at("node") == "keys") {
            sawKeys = true;
            EXPECT_EQ(n.at("calls").get<Index>(), 24);
            EXPECT_GT(n.at("seconds").get<double>(), 0);
        }
        if (n.at("node") == "fail-through") {
            EXPECT_EQ(n.at("calls").get<Index>(), 12 * stats.chunks);
        }
    }
    EXPECT_TRUE(sawKeys);
}

TEST_F(Fixture, RejectsBadOptionsAndRanges) {
    EngineOptions o = options(2);
    o.pointsWanted = {1, 1};
    EXPECT_THROW(Engine(model, evaluator, o), InputError);
    o.pointsWanted = {600};
    EXPECT_THROW(Engine(model, evaluator, o), InputError);
    o = options(-1);
    EXPECT_THROW(Engine(model, evaluator, o), InputError);
    const Model other = testing::makeModel(500, 3, 8, 20);
    EXPECT_THROW(Engine(other, evaluator, options(1)), InputError);
    Engine engine(model, evaluator, options(1));
    CheckingSink sink;
    EXPECT_THROW(engine.run({390, 20, 1}, sink), InputError);
    EXPECT_THROW(engine.run({0, 10, 0}, sink), InputError);
    EXPECT_EQ(engine.run({0, 0, 1}, sink).framesDelivered, 0);
}

}  // namespace
}  // namespace pmsc::engine
