// pmsc_face_bench — the face rig's speed goal (speedup >= 8 over posing
// all points with the same rig) as a ratio of two Google Benchmarks run in the same process:
//
//   BM_FaceFullPose  the rig posing all 26,719 points of a frame (FaceRig::evaluateAll)
//   BM_FacePmsc      the rig posing the model's key points and sentinels in one call (as the engine
//                    asks a whole-frame rig), the projection, the key error and the reconstruction
//                    of all points (what a hit costs)
//   BM_FaceKeyPose, BM_FaceReconstruct: the two big parts of BM_FacePmsc (BM_FaceKeyPose's
//                    counters: the dependency closure the keys pose, FaceRig::closureSize)
//   BM_FaceSentinelPose: a hit's sentinels posed alone (with a model that has them), and the keys
//                    and sentinels in one call against two (counter one_call_over_two: what the
//                    engine's one call saves)
//   BM_FaceKeyErrorPredictedVsRms: the key error of a frame in `pmsc train --tolerance`'s default
//                    measure (the predicted point error: the key RMS and the leave-one-out error)
//                    against the key RMS alone, timed alternately (counter predicted_over_rms)
//
// After the runs it prints one JSON line {"speedup": full / pmsc, "key_cost_fraction": ...} from
// the CPU times. The model: DIR/face.pmsc of `pmsc demo face --out DIR` when PMSC_FACE_MODEL
// names it (the demo's own keys and basis), otherwise one trained here from 10 sequences of the
// demo's animation (M = 48, 170 keys, Multi-PIE fiducials). ICT data: PMSC_ICT_FACEKIT_DIR, or
// the folder CMake was configured with.
#include "TimeAlternately.h"
#include "evaluators/face/FaceEvaluator.h"
#include "pmsc/HitCheck.h"
#include "pmsc/ModelIO.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/Training.h"

#include <benchmark/benchmark.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace {

using namespace pmsc;

struct Setup {
    std::unique_ptr<face::FaceEvaluator> evaluator;
    Model model;
    std::vector<Index> frames;  // frames to cycle through (validation-like)
};

const Setup& setup() {
    static const Setup s = [] {
        Setup x;
        const char* dir = std::getenv("PMSC_ICT_FACEKIT_DIR");
        x.evaluator = face::makeFaceEvaluator(dir ? dir : PMSC_ICT_FACEKIT_DIR);
        const face::FaceAnimation& animation = x.evaluator->animation();
        if (const char* path = std::getenv("PMSC_FACE_MODEL")) {
            x.model = readModel(path);
        } else {
            std::vector<Index> sequences;
            for (Index s = 0; s < 10; ++s) sequences.push_back(s);
            const std::vector<Index> training = animation.framesOf(sequences);
            FrameSet frames(static_cast<Index>(training.size()), x.evaluator->pointCount(), 3);
            tbb::parallel_for(size_t{0}, training.size(), [&](size_t i) {
                x.evaluator->evaluateAll(training[i], frames.frame(static_cast<Index>(i)));
            });
            TrainingOptions o;
            o.basis = 48;
            o.maxKeys = 170;
            o.fiducials.assign(face::IctFace::multiPie68().begin(), face::IctFace::multiPie68().end());
            x.model = train(frames, o);
        }
        for (Index f = animation.sequences()[12].firstFrame;
             f < animation.frameCount() && x.frames.size() < 64; f += 3) {
            x.frames.push_back(f);
        }
        return x;
    }();
    return s;
}

void BM_FaceFullPose(benchmark::State& state) {
    const Setup& s = setup();
    std::vector<double> out(static_cast<size_t>(3 * s.evaluator->pointCount()));
    size_t i = 0;
    for (auto _ : state) {
        s.evaluator->evaluateAll(s.frames[i++ % s.frames.size()], out.data());
        benchmark::DoNotOptimize(out.data());
    }
}

void BM_FaceKeyPose(benchmark::State& state) {
    const Setup& s = setup();
    std::vector<double> keys(static_cast<size_t>(3 * s.model.keyCount()));
    size_t i = 0;
    for (auto _ : state) {
        s.evaluator->evaluate(s.frames[i++ % s.frames.size()], s.model.keyPoints, keys.data());
        benchmark::DoNotOptimize(keys.data());
    }
    // The dependency closure the keys pose: what a key costs beyond its own point.
    const auto closure = s.evaluator->rig().closureSize(s.model.keyPoints);
    state.counters["keys"] = static_cast<double>(s.model.keyCount());
    state.counters["closure_blendshapes"] = static_cast<double>(closure.blendshapes);
    state.counters["closure_relax"] = static_cast<double>(closure.relax);
    state.counters["closure_contact"] = static_cast<double>(closure.contact);
}

void BM_FaceReconstruct(benchmark::State& state) {
    const Setup& s = setup();
    const PointMultiplier pm(s.model);
    std::vector<double> coords(static_cast<size_t>(s.model.coordCount()), 0.1),
        out(static_cast<size_t>(3 * s.model.points));
    for (auto _ : state) {
        pm.reconstruct(coords.data(), out.data());
        benchmark::DoNotOptimize(out.data());
    }
}

/// The model's sentinels, ascending (what a hit's check computes); empty without them.
std::vector<Index> sentinels(const Model& model) { return HitCheck::sentinelsOf(model); }

void BM_FacePmsc(benchmark::State& state) {
    const Setup& s = setup();
    const PointMultiplier pm(s.model);
    const std::vector<Index> check = sentinels(s.model);
    std::vector<Index> posed = s.model.keyPoints;  // the keys, then the sentinels: one call
    posed.insert(posed.end(), check.begin(), check.end());
    std::vector<double> values(3 * posed.size()), coords(static_cast<size_t>(s.model.coordCount()));
    std::vector<double> out(static_cast<size_t>(3 * s.model.points));
    size_t i = 0;
    for (auto _ : state) {
        const Index frame = s.frames[i++ % s.frames.size()];
        s.evaluator->evaluate(frame, posed, values.data());
        pm.project(values.data(), coords.data());
        benchmark::DoNotOptimize(pm.keyError(values.data(), coords.data()));
        pm.reconstruct(coords.data(), out.data());
        benchmark::DoNotOptimize(out.data());
    }
    state.counters["sentinels"] = static_cast<double>(check.size());
}

/// A hit's sentinels posed alone, and the keys and sentinels in one call against two calls
/// (counter one_call_over_two: what the engine's one call saves for this whole-frame rig).
void BM_FaceSentinelPose(benchmark::State& state) {
    const Setup& s = setup();
    const std::vector<Index> check = sentinels(s.model);
    if (check.empty()) {
        state.SkipWithError("the model has no sentinels (PMSC_FACE_MODEL: a model of pmsc demo face)");
        return;
    }
    std::vector<Index> both = check;
    both.insert(both.end(), s.model.keyPoints.begin(), s.model.keyPoints.end());
    std::sort(both.begin(), both.end());
    std::vector<double> out(3 * both.size());
    double two = 0, one = 0;
    size_t i = 0;
    for (auto _ : state) {
        const Index frame = s.frames[i++ % s.frames.size()];
        s.evaluator->evaluate(frame, check, out.data());
        benchmark::DoNotOptimize(out.data());
        state.PauseTiming();
        const auto t0 = std::chrono::steady_clock::now();
        s.evaluator->evaluate(frame, s.model.keyPoints, out.data());
        s.evaluator->evaluate(frame, check, out.data());
        const auto t1 = std::chrono::steady_clock::now();
        s.evaluator->evaluate(frame, both, out.data());
        const auto t2 = std::chrono::steady_clock::now();
        two += std::chrono::duration<double>(t1 - t0).count();
        one += std::chrono::duration<double>(t2 - t1).count();
        state.ResumeTiming();
    }
    const auto closure = s.evaluator->rig().closureSize(check);
    state.counters["sentinels"] = static_cast<double>(check.size());
    state.counters["closure_relax"] = static_cast<double>(closure.relax);
    state.counters["closure_contact"] = static_cast<double>(closure.contact);
    state.counters["one_call_over_two"] = two > 0 ? one / two : 0.0;
}

void BM_FaceKeyErrorPredictedVsRms(benchmark::State& state) {
    const Setup& s = setup();
    Model rms = s.model, predicted = s.model;
    rms.keyErrorNorm = KeyErrorNorm::Rms;
    predicted.keyErrorNorm = KeyErrorNorm::Predicted;
    predicted.tolerance = 1;
    predicted.partEps = {1, 1};
    const PointMultiplier pmRms(rms), pmPredicted(predicted);
    std::vector<double> keys(static_cast<size_t>(3 * s.model.keyCount())),
        coords(static_cast<size_t>(s.model.coordCount()));
    s.evaluator->evaluate(s.frames[0], s.model.keyPoints, keys.data());
    pmRms.project(keys.data(), coords.data());
    pmsc::bench::timeAlternately(
        state, "predicted",
        [&] { benchmark::DoNotOptimize(pmPredicted.keyError(keys.data(), coords.data())); }, "rms",
        [&] { benchmark::DoNotOptimize(pmRms.keyError(keys.data(), coords.data())); });
}

BENCHMARK(BM_FaceFullPose)->Unit(benchmark::kMillisecond)->MinTime(2.0);
BENCHMARK(BM_FacePmsc)->Unit(benchmark::kMillisecond)->MinTime(2.0);
BENCHMARK(BM_FaceKeyPose)->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(BM_FaceSentinelPose)->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(BM_FaceReconstruct)->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(BM_FaceKeyErrorPredictedVsRms)->Unit(benchmark::kMicrosecond)->MinTime(1.0);

// Keeps each benchmark's CPU time per iteration for the ratio printed at the end.
class RatioReporter : public benchmark::ConsoleReporter {
public:
    void ReportRuns(const std::vector<Run>& runs) override {
        for (const Run& r : runs) cpu[r.benchmark_name()] = r.GetAdjustedCPUTime();
        ConsoleReporter::ReportRuns(runs);
    }
    std::map<std::string, double> cpu;
};

}  // namespace

int main(int argc, char** argv) {
    benchmark::Initialize(&argc, argv);
    setup();  // load, rig, model: outside the timings
    RatioReporter reporter;
    benchmark::RunSpecifiedBenchmarks(&reporter);
    // Names carry their arguments ("BM_FacePmsc/min_time:2.000"): look them up by prefix.
    auto cpu = [&](const std::string& name) {
        for (const auto& [key, value] : reporter.cpu) {
            if (key.rfind(name + "/", 0) == 0 || key == name) return value;
        }
        return 0.0;
    };
    const double full = cpu("BM_FaceFullPose"), pmsc = cpu("BM_FacePmsc"), keys = cpu("BM_FaceKeyPose");
    if (full > 0 && pmsc > 0) {
        std::printf(
            "{\"full_pose_ms\": %.3f, \"pmsc_ms\": %.3f, \"speedup\": %.2f, \"key_cost_fraction\": %.4f}\n",
            full, pmsc, full / pmsc, keys / full);
    }
    benchmark::Shutdown();
    return 0;
}
