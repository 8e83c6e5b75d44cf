// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// exec:COMMAND against real child processes: `pmsc serve` and a Python replay child answer bit for
// bit what the same calculation answers in process; every fault a child can make (crash, hang,
// short answer, NaN, exit at start, garbage, its own error) is one EvaluatorError line naming the
// command, the child is replaced, and the engine's failure policies hold.
#include "engine/Engine.h"
#include "engine/FrameSetSink.h"
#include "evaluators/EvaluatorRegistry.h"
#include "evaluators/ReplayEvaluator.h"
#include "evaluators/exec/ExecEvaluator.h"
#include "evaluators/exec/Isolated.h"
#include "evaluators/scene/PointCacheGrid.h"
#include "pmsc/Errors.h"
#include "pmsc/NpyIO.h"
#include "pmsc/PointPositions.h"
#include "pmsc/Training.h"
#include "tests/common/TempDir.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <csignal>
#include <filesystem>
#include <numeric>
#include <random>
#include <thread>

namespace pmsc::evaluators::exec {
namespace {

const std::string kPmsc = PMSC_BINARY;
const std::string kSource = PMSC_SOURCE_DIR;
const std::string kPython = PMSC_PYTHON;
const std::string kFault = kPython + " " + kSource + "/tests/evaluators/exec/fault_child.py";

std::string messageOf(const std::function<void()>& f) {
    try {
        f();
    } catch (const EvaluatorError& e) {
        return e.what();
    }
    return "";
}

void expectContains(const std::string& text, std::initializer_list<std::string> parts) {
    EXPECT_EQ(text.find('\n'), std::string::npos) << "not one line: " << text;
    for (const auto& p : parts)
        EXPECT_NE(text.find(p), std::string::npos) << "'" << p << "' not in: " << text;
}

ExecOptions options(const std::string& command, int timeoutMs = 20'000) {
    ExecOptions o;
    o.command = command;
    o.timeout = std::chrono::milliseconds(timeoutMs);
    return o;
}

TEST(ExecArgs, TimeoutThenTheWholeCommand) {
    const ExecOptions a = parseExecArgs("timeout=2.5:python3 child.py --scene a:b");
    EXPECT_EQ(a.timeout.count(), 2500);
    EXPECT_EQ(a.command, "python3 child.py --scene a:b");
    EXPECT_EQ(parseExecArgs("renderer --bake").command, "renderer --bake");
    EXPECT_EQ(parseExecArgs("renderer --bake").timeout.count(), 600'000);
    EXPECT_THROW(parseExecArgs(""), InputError);
    EXPECT_THROW(parseExecArgs("timeout=3:"), InputError);
    EXPECT_THROW(parseExecArgs("timeout=abc:x"), InputError);
    EXPECT_THROW(parseExecArgs("timeout=-1:x"), InputError);
    EXPECT_THROW(makeEvaluator("exec"), std::invalid_argument);
}

TEST(ExecEvaluator, ServedSyntheticEqualsInProcessBitForBit) {
    const std::string spec = "synthetic:grid=12:frames=30:seed=4";
    const auto local = makeEvaluator(spec);
    ExecEvaluator child(options(kPmsc + " serve " + spec));
    ASSERT_EQ(child.pointCount(), local->pointCount());
    ASSERT_EQ(child.channelCount(), local->channelCount());
    ASSERT_EQ(child.frameCount(), local->frameCount());
    const Index n = local->pointCount(), c = local->channelCount();

    std::vector<Index> shuffled(static_cast<std::size_t>(n));
    std::iota(shuffled.begin(), shuffled.end(), Index{0});
    std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(7));
    shuffled.resize(37);
    std::vector<Index> run(20);
    std::iota(run.begin(), run.end(), Index{50});
    for (const auto& points : {shuffled, run}) {
        std::vector<double> a(points.size() * static_cast<std::size_t>(c)), b(a.size());
        local->evaluate(9, points, a.data());
        child.evaluate(9, points, b.data());
        EXPECT_EQ(a, b);
    }
    std::vector<double> a(static_cast<std::size_t>(n * c)), b(a.size());
    local->evaluateAll(29, a.data());
    child.evaluateAll(29, b.data());
    EXPECT_EQ(a, b);
    EXPECT_EQ(child.childrenStarted(), 1u);
}

TEST(ExecEvaluator, AVersion2ChildSaysWhereItsPointsAreAndOthersSayInOneLineThatTheyCannot) {
    // pmsc serve (version 2) of an evaluator with positions answers them bit for bit.
    const std::string spec = "cornell:points=3000,samples=8";
    const auto local = makeEvaluator(spec);
    ExecEvaluator child(options(kPmsc + " serve " + spec));
    EXPECT_EQ(child.protocolVersion(), 2u);
    const FrameSet got = child.pointPositions();
    const FrameSet want = dynamic_cast<const PointPositionsProvider&>(*local).pointPositions();
    ASSERT_EQ(got.points, local->pointCount());
    EXPECT_EQ(got.channels, 3);
    EXPECT_EQ(got.values, want.values);
    // The child serves on after a positions request.
    std::vector<double> a(3 * 3), b(a.size());
    const std::vector<Index> points = {0, 1000, 2999};
    local->evaluate(4, points, a.data());
    child.evaluate(4, points, b.data());
    EXPECT_EQ(a, b);

    // An evaluator whose points have no places, served: one line naming it, and the child serves on.
    ExecEvaluator synthetic(options(kPmsc + " serve synthetic:grid=12:frames=30:seed=4"));
    try {
        (void)synthetic.pointPositions();
        ADD_FAILURE() << "no InputError";
    } catch (const InputError& e) {
        expectContains(e.what(), {"no positions", "'synthetic' has no point positions"});
    }
    std::vector<double> one(3);
    EXPECT_NO_THROW(synthetic.evaluate(0, std::vector<Index>{5}, one.data()));
    EXPECT_EQ(synthetic.childrenStarted(), 1u);

    // A version-1 child (examples/exec/replay_child.py) is never asked.
    const auto dir = std::filesystem::temp_directory_path() / ("pmsc-exec-v1-" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    FrameSet frames(2, 5, 3);
    writeFrames((dir / "f.npy").string(), frames, NpyDtype::Float64);
    ExecEvaluator v1(
        options(kPython + " " + kSource + "/examples/exec/replay_child.py " + (dir / "f.npy").string()));
    EXPECT_EQ(v1.protocolVersion(), 1u);
    try {
        (void)v1.pointPositions();
        ADD_FAILURE() << "no InputError";
    } catch (const InputError& e) {
        expectContains(e.what(), {"protocol version 1", "no positions request"});
    }
    std::filesystem::remove_all(dir);
}

TEST(ExecEvaluator, AChildWithPositionsWritesItsFramesAsAPointLightCache) {
    // `pmsc run --format vdb` through an exec child: the values at the child's own positions.
    const std::string spec = "cornell:points=3000,samples=8";
    ExecEvaluator child(options(kPmsc + " serve " + spec));
    const auto writers = child.frameWriters();
    ASSERT_EQ(writers.size(), 1u);
    EXPECT_EQ(writers[0]->extension(), ".vdb");
    std::vector<double> values(size_t(child.pointCount() * child.channelCount()));
    child.evaluateAll(4, values.data());
    const test::TempDir dir;
    const std::filesystem::path path = dir.file("frame.vdb");
    writers[0]->write(path.string(), 4, values.data());
    EXPECT_TRUE(writers[0]->isValid(path.string()));
    Index channels = 0;
    const std::vector<double> back =
        scene::PointCacheGrid::sample(path.string(), child.pointPositions().values, channels);
    ASSERT_EQ(channels, 3);
    ASSERT_EQ(back.size(), values.size());
    size_t own = 0;  // points alone in their voxel get their own value back (in float)
    for (size_t i = 0; i < back.size(); i += 3)
        own += std::abs(back[i] - values[i]) <= 1e-6 * std::abs(values[i]) + 1e-12;
    EXPECT_GT(own, size_t(0.85 * double(child.pointCount()))) << own;
    std::filesystem::remove(path);
    EXPECT_FALSE(writers[0]->isValid(path.string()));

    // A child whose points have no places: no .vdb on offer (and it serves on).
    ExecEvaluator synthetic(options(kPmsc + " serve synthetic:grid=12:frames=30:seed=4"));
    EXPECT_TRUE(synthetic.frameWriters().empty());
    std::vector<double> one(3);
    EXPECT_NO_THROW(synthetic.evaluate(0, std::vector<Index>{5}, one.data()));
}

TEST(ExecEvaluator, AnAnswerStreamedInBlocksEqualsInProcessBitForBit) {
    const std::string spec =
        "synthetic:grid=190:frames=4:seed=2";  // 36,100 points: three blocks of pmsc serve
    const auto local = makeEvaluator(spec);
    ExecEvaluator child(options(kPmsc + " serve " + spec));
    std::vector<double> a(static_cast<std::size_t>(local->pointCount() * 3)), b(a.size());
    for (Index f = 0; f < 4; ++f) {
        local->evaluateAll(f, a.data());
        child.evaluateAll(f, b.data());
        ASSERT_EQ(a, b) << "frame " << f;
    }
}

TEST(ExecEvaluator, PythonReplayChildEqualsTheReplayEvaluator) {
    const auto dir = std::filesystem::temp_directory_path() / ("pmsc-exec-" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);
    FrameSet frames(6, 40, 3);
    std::mt19937 rng(3);
    std::normal_distribution<double> normal;
    for (Index f = 0; f < 6; ++f)
        for (Index p = 0; p < 40; ++p)
            for (Index ch = 0; ch < 3; ++ch) frames.frame(f)[p * 3 + ch] = normal(rng);
    const std::string npy = (dir / "frames.npy").string();
    writeFrames(npy, frames, NpyDtype::Float64);

    ReplayEvaluator local(npy);
    ExecEvaluator child(options(kPython + " " + kSource + "/examples/exec/replay_child.py " + npy));
    ASSERT_EQ(child.pointCount(), 40);
    ASSERT_EQ(child.frameCount(), 6);
    const std::vector<Index> points = {39, 0, 17, 5, 6, 7};
    std::vector<double> a(points.size() * 3), b(a.size());
    for (Index f = 0; f < 6; ++f) {
        local.evaluate(f, points, a.data());
        child.evaluate(f, points, b.data());
        EXPECT_EQ(a, b) << "frame " << f;
    }
    std::vector<double> all(40 * 3);
    child.evaluateAll(2, all.data());
    EXPECT_EQ(all[3 * 17 + 1], frames.frame(2)[3 * 17 + 1]);
    std::filesystem::remove_all(dir);
}

TEST(ExecEvaluator, ACrashFailsThatCallAndANewChildServesTheNext) {
    ExecEvaluator child(options(kFault + " crash=5"));
    std::vector<double> out(3 * 3);
    const std::vector<Index> points = {1, 2, 9};
    child.evaluate(4, points, out.data());
    expectContains(
        messageOf([&] { child.evaluate(5, points, out.data()); }),
        {"exec '", "fault_child.py crash=5'", "killed by signal 11", "frame 5", "Segmentation fault"});
    EXPECT_EQ(child.idleChildren(), 0u);
    child.evaluate(6, points, out.data());
    EXPECT_EQ(child.childrenStarted(), 2u);
    EXPECT_EQ(child.idleChildren(), 1u);
}

TEST(ExecEvaluator, EveryFaultIsOneLineNamingTheCommand) {
    std::vector<double> out(50 * 3);
    const std::vector<Index> points = {3, 4};
    {
        ExecEvaluator child(options(kFault + " hang=2", 1000));
        const auto start = std::chrono::steady_clock::now();
        expectContains(messageOf([&] { child.evaluate(2, points, out.data()); }),
                       {"fault_child.py hang=2'", "did not answer within 1", "frame 2"});
        EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(10));
        child.evaluate(3, points, out.data());  // a new child
    }
    {
        ExecEvaluator child(options(kFault + " short=2"));
        expectContains(messageOf([&] { child.evaluate(2, points, out.data()); }),
                       {"fault_child.py short=2'", "too few bytes", "exited with code 0", "frame 2"});
    }
    {
        ExecEvaluator child(options(kFault + " nan=2"));
        expectContains(messageOf([&] { child.evaluateAll(2, out.data()); }),
                       {"non-finite value", "point 25 channel 1", "frame 2"});
    }
    {
        ExecEvaluator child(options(kFault + " error=2"));
        expectContains(messageOf([&] { child.evaluate(2, points, out.data()); }),
                       {"frame 2: light 'key' has no shader in frame 2"});
        child.evaluate(3, points, out.data());  // the same child serves on
        EXPECT_EQ(child.childrenStarted(), 1u);
    }
    expectContains(
        messageOf([&] { ExecEvaluator child(options(kFault + " exit")); }),
        {"fault_child.py exit'", "exited with code 3 before its hello", "no licence for this renderer"});
    expectContains(messageOf([&] { ExecEvaluator child(options(kFault + " garbage")); }),
                   {"did not start with the hello 'PMSCEXEC'"});
    expectContains(messageOf([&] { ExecEvaluator child(options("/nonexistent/renderer --bake")); }),
                   {"/nonexistent/renderer --bake'", "exited with code 127", "not found"});
    // Bad indices never reach the child.
    ExecEvaluator child(options(kFault));
    const std::vector<Index> bad = {50};
    EXPECT_THROW(child.evaluate(0, bad, out.data()), std::out_of_range);
    EXPECT_THROW(child.evaluate(20, points, out.data()), std::out_of_range);
}

TEST(ExecEvaluator, ConcurrentCallsGetAChildEach) {
    ExecEvaluator child(options(kFault + " sleep=50"));
    const std::vector<Index> points = {0, 1, 2};
    std::vector<std::thread> threads;
    std::vector<std::vector<double>> outs(3, std::vector<double>(9));
    for (int t = 0; t < 3; ++t)
        threads.emplace_back([&, t] { child.evaluate(t, points, outs[static_cast<std::size_t>(t)].data()); });
    for (auto& t : threads) t.join();
    EXPECT_EQ(child.childrenStarted(), 3u);
    EXPECT_EQ(child.idleChildren(), 3u);
}

/// A model of the fault child's clean frames 0-11, so the engine can run its frames.
Model trainOnCleanFrames() {
    ExecEvaluator clean(options(kFault));
    TrainingOptions t;
    t.basis = 4;
    t.maxKeys = 8;
    return train(evaluateFrames(clean, 0, 12), t);
}

std::unique_ptr<engine::FrameSetSink> runEngine(const Model& model, const PointEvaluator& e,
                                                engine::FailurePolicy policy) {
    engine::EngineOptions o;
    o.threads = 2;
    o.failurePolicy = policy;
    o.chunkPoints = 16;
    o.policy = SoftCachePolicy{1e-9, 2e-9};  // every frame fails through, so full evaluations run too
    engine::Engine engine(model, e, o);
    auto sink = std::make_unique<engine::FrameSetSink>(20, model.points, model.channels);
    engine.run({0, 20, 1}, *sink);
    return sink;
}

TEST(ExecEvaluator, EveryCallPaysASetUpSoAMissedFrameIsAskedForOncePerThread) {
    const std::string spec = "synthetic:grid=12:frames=30:seed=4";
    const auto local = makeEvaluator(spec);
    ExecEvaluator child(options(kPmsc + " serve " + spec));
    EXPECT_TRUE(child.failThroughShape().callSetUp);
    EXPECT_FALSE(local->failThroughShape().callSetUp);
    TrainingOptions t;
    t.basis = 4;
    t.maxKeys = 8;
    const Model model = train(evaluateFrames(*local, 0, 30), t);
    auto run = [&](const PointEvaluator& e) {
        engine::EngineOptions o;
        o.threads = 2;
        o.policy = SoftCachePolicy{0, 0};  // every frame misses
        engine::Engine engine(model, e, o);
        engine::FrameSetSink sink(30, model.points, model.channels);
        engine.run({0, 30, 1}, sink);
        EXPECT_EQ(engine.lastStats().misses, 30);
        return std::vector<double>(sink.values().frame(0),
                                   sink.values().frame(0) + 30 * model.points * model.channels);
    };
    EXPECT_EQ(run(child), run(*local));
    EXPECT_LE(child.childrenStarted(), 2u) << "one child per thread";
}

TEST(ExecEvaluator, TheEnginesFailurePoliciesHoldForAChildThatCrashes) {
    const Model model = trainOnCleanFrames();
    ExecEvaluator clean(options(kFault)), crashing(options(kFault + " crash=5"));
    const auto reference = runEngine(model, clean, engine::FailurePolicy::StopRun);
    const auto marked = runEngine(model, crashing, engine::FailurePolicy::MarkFailedAndContinue);
    for (Index f = 0; f < 20; ++f) {
        EXPECT_EQ(marked->info()[static_cast<std::size_t>(f)].failed, f == 5) << f;
        if (f == 5) continue;
        for (Index x = 0; x < model.points * model.channels; ++x)
            ASSERT_EQ(marked->values().frame(f)[x], reference->values().frame(f)[x]) << f << " " << x;
    }
    ExecEvaluator stopping(options(kFault + " crash=5"));
    try {
        runEngine(model, stopping, engine::FailurePolicy::StopRun);
        ADD_FAILURE() << "StopRun did not stop";
    } catch (const EvaluatorError& e) {
        expectContains(e.what(), {"frame 5", "killed by signal 11"});
    }
}

}  // namespace
}  // namespace pmsc::evaluators::exec

namespace pmsc::evaluators::exec {
namespace {

std::string isolatedMessage(const std::function<std::string()>& work, IsolationLimits limits = {}) {
    try {
        runIsolated(work, "test: ", limits);
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

TEST(Isolated, ReturnsTheWorksBytesAndItsErrors) {
    EXPECT_EQ(runIsolated([] { return std::string("posing arrays\0with zeros", 24); }, "test: "),
              std::string("posing arrays\0with zeros", 24));
    const std::string big(3 << 20, 'x');  // more than a pipe holds
    EXPECT_EQ(runIsolated([&] { return big; }, "test: "), big);
    EXPECT_EQ(isolatedMessage([]() -> std::string { throw InputError("test: has no animation to pose"); }),
              "test: has no animation to pose");
}

TEST(Isolated, ACrashAHangAndAnOverAllocationFailOnlyTheChild) {
    expectContains(isolatedMessage([]() -> std::string {
                       std::raise(SIGSEGV);
                       return "";
                   }),
                   {"test: the importer crashed", "signal 11"});
    IsolationLimits quick;
    quick.timeout = std::chrono::milliseconds(300);
    const auto start = std::chrono::steady_clock::now();
    expectContains(isolatedMessage(
                       []() -> std::string {
                           std::this_thread::sleep_for(std::chrono::hours(1));
                           return "";
                       },
                       quick),
                   {"test: the importer did not finish within 0.3 s"});
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
    IsolationLimits small;
    small.addressSpace = std::uint64_t{512} << 20;
    expectContains(isolatedMessage(
                       []() -> std::string {
                           std::vector<char> huge(std::size_t{23} << 30, 1);  // what a damaged .x asked for
                           return std::string(1, huge.back());
                       },
                       small),
                   {"test: the importer ran out of memory (limit 0.5 GiB)"});
}

}  // namespace
}  // namespace pmsc::evaluators::exec
