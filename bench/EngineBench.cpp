// Engine benchmarks. Each speed goal is a ratio of two benchmarks run in
// the same process: pmsc_engine_report runs these and prints the ratios as one JSON object.
//
//   overhead:     plain serial loop vs the graph at 1 thread, trivial (recorded) evaluator, all hits
//   scaling:      the graph at 1 vs 2 threads, evaluator costing ~1 ms per frame (busy work)
//   miss:         a missed frame through the graph vs a plain full evaluation, linear-cost evaluator
//   reconstruct:  one frame's PM reconstruction at 160,000 points x 3 channels x 32 basis vs a
//                 memcpy of the basis' bytes (the memory roofline)
//   decode:       a 123 MB model file's bytes decoded with the checksum first vs beside the decode
#include "bench/EngineBenchSupport.h"
#include "engine/Engine.h"
#include "pmsc/ModelIO.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/SoftCache.h"

#include <benchmark/benchmark.h>

#include <cstring>
#include <ctime>
#include <memory>
#include <string>
#include <vector>

namespace pmsc::bench {
namespace {

// The paper's face (section 7): 2986 points, 85 basis vectors, 170 key points.
constexpr Index kFacePoints = 2986, kFaceBasis = 85, kFaceKeys = 170;
constexpr Index kFramesPerRun = 256;

const Model& faceModel() {
    static const Model m = makeModel(kFacePoints, 3, kFaceBasis, kFaceKeys);
    return m;
}

/// Process CPU seconds (all threads). Reported per frame beside the wall-time rates, so a run
/// on a busy machine still shows whether the graph adds work (CPU per frame) even when other
/// programs keep it from getting the second core (wall-time scaling).
double processCpuSeconds() {
    timespec ts{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

/// Sets the "cpu_seconds_per_frame" counter of a benchmark from a start time.
void setCpuPerFrame(benchmark::State& state, double cpuStart, Index framesPerIteration) {
    const double frames = double(state.iterations()) * double(framesPerIteration);
    if (frames > 0) state.counters["cpu_seconds_per_frame"] = (processCpuSeconds() - cpuStart) / frames;
}

/// A sink that touches every frame's output the same way in both loops.
class ChecksumSink : public engine::FrameSink {
public:
    void write(const engine::FrameResult& r) override { sum_ += r.values[0] + double(r.state); }
    double sum() const { return sum_; }

private:
    double sum_ = 0;
};

/// The plain way (sections 5-6), serial, no graph: key evaluation, projection, key error,
/// decision, reconstruction (or full evaluation and blend), hand the frame to the sink.
void plainLoop(const Model& model, const PointEvaluator& e, const PointMultiplier& pm,
               const SoftCachePolicy& policy, Index frames, engine::FrameSink& sink) {
    const Index c = model.channels;
    std::vector<double> keys(size_t(model.keyCount() * c)), coords(size_t(model.coordCount()));
    std::vector<double> out(size_t(model.points * c)), full(size_t(model.points * c));
    engine::FrameResult r;
    for (Index f = 0; f < frames; ++f) {
        e.evaluate(f, model.keyPoints, keys.data());
        pm.project(keys.data(), coords.data());
        const double err = pm.keyError(keys.data(), coords.data());
        const CacheDecision d = policy.decide(err);
        if (d.state == CacheState::Hit) {
            pm.reconstruct(coords.data(), out.data());
        } else {
            e.evaluateAll(f, full.data());
            if (d.state == CacheState::Blend) {
                pm.reconstruct(coords.data(), out.data());
                for (size_t x = 0; x < out.size(); ++x) out[x] = (1 - d.weight) * out[x] + d.weight * full[x];
            } else {
                out.swap(full);
            }
        }
        r.sequence = f;
        r.frame = f;
        r.state = d.state;
        r.weight = d.weight;
        r.keyError = err;
        r.values = out;
        sink.write(r);
    }
}

// ---- overhead: plain loop vs graph at 1 thread ---------------------------------------------

void BM_Overhead_PlainLoop(benchmark::State& state) {
    const Model& model = faceModel();
    const RecordedEvaluator e(model, kFramesPerRun);
    const PointMultiplier pm(model);
    const SoftCachePolicy policy(model.epsMin, model.epsMax);
    ChecksumSink sink;
    const double cpuStart = processCpuSeconds();
    for (auto _ : state) plainLoop(model, e, pm, policy, kFramesPerRun, sink);
    benchmark::DoNotOptimize(sink.sum());
    state.SetItemsProcessed(state.iterations() * kFramesPerRun);
    setCpuPerFrame(state, cpuStart, kFramesPerRun);
}

void BM_Overhead_Graph1Thread(benchmark::State& state) {
    const Model& model = faceModel();
    const RecordedEvaluator e(model, kFramesPerRun);
    engine::EngineOptions o;
    o.threads = 1;
    engine::Engine engine(model, e, o);
    ChecksumSink sink;
    const double cpuStart = processCpuSeconds();
    for (auto _ : state) engine.run({0, kFramesPerRun, 1}, sink);
    if (engine.lastStats().hits != kFramesPerRun) state.SkipWithError("expected every frame to hit");
    benchmark::DoNotOptimize(sink.sum());
    state.SetItemsProcessed(state.iterations() * kFramesPerRun);
    setCpuPerFrame(state, cpuStart, kFramesPerRun);
}

// ---- scaling: 1 vs 2 threads, ~1 ms of busy work per frame ----------------------------------

void BM_Scaling_Graph(benchmark::State& state) {
    const Model& model = faceModel();
    RecordedEvaluator e(model, 64);
    // A hit evaluates the 170 key points: 1 ms / 170 per point makes the frame cost ~1 ms.
    e.setMicrosecondsPerPoint(1000.0 / double(kFaceKeys));
    engine::EngineOptions o;
    o.threads = int(state.range(0));
    engine::Engine engine(model, e, o);
    ChecksumSink sink;
    const double cpuStart = processCpuSeconds();
    for (auto _ : state) engine.run({0, 64, 1}, sink);
    if (engine.lastStats().hits != 64) state.SkipWithError("expected every frame to hit");
    state.counters["peak_in_flight"] = double(engine.lastStats().peakFramesInFlight);
    state.SetItemsProcessed(state.iterations() * 64);
    setCpuPerFrame(state, cpuStart, 64);
}

// ---- miss: a missed frame through the graph vs a plain full evaluation ----------------------

constexpr double kMissMicrosPerPoint = 1.0;  // a full frame costs ~3 ms, linear in the points
constexpr Index kMissFrames = 8;

void BM_Miss_PlainFullEvaluation(benchmark::State& state) {
    const Model& model = faceModel();
    RecordedEvaluator e(model, kMissFrames);
    e.setMicrosecondsPerPoint(kMissMicrosPerPoint);
    std::vector<double> out(size_t(model.points * model.channels));
    ChecksumSink sink;
    engine::FrameResult r;
    const double cpuStart = processCpuSeconds();
    for (auto _ : state) {
        for (Index f = 0; f < kMissFrames; ++f) {
            e.evaluateAll(f, out.data());
            r.values = out;
            sink.write(r);
        }
    }
    benchmark::DoNotOptimize(sink.sum());
    state.SetItemsProcessed(state.iterations() * kMissFrames);
    setCpuPerFrame(state, cpuStart, kMissFrames);
}

void BM_Miss_Graph(benchmark::State& state) {
    const Model& model = faceModel();
    RecordedEvaluator e(model, kMissFrames);
    e.setMicrosecondsPerPoint(kMissMicrosPerPoint);
    engine::EngineOptions o;
    o.threads = int(state.range(0));
    o.policy = SoftCachePolicy(0, 0);  // every key error > 0: every frame is a miss
    engine::Engine engine(model, e, o);
    ChecksumSink sink;
    const double cpuStart = processCpuSeconds();
    for (auto _ : state) engine.run({0, kMissFrames, 1}, sink);
    if (engine.lastStats().misses != kMissFrames) state.SkipWithError("expected every frame to miss");
    state.SetItemsProcessed(state.iterations() * kMissFrames);
    setCpuPerFrame(state, cpuStart, kMissFrames);
}

// ---- reconstruction bandwidth vs memcpy ------------------------------------------------------

constexpr Index kBigPoints = 160000, kBigBasis = 32;

const Model& bigModel() {
    static const Model m = makeModel(kBigPoints, 3, kBigBasis, 64);
    return m;
}

std::int64_t basisBytes() { return std::int64_t(kBigPoints) * 3 * kBigBasis * std::int64_t(sizeof(double)); }

// Arg 0: the double basis (Eigen's GEMV); 1: the float basis in panels (BasisPrecision::Single,
// `pmsc run`'s choice for float frames). bytes_per_second counts the double basis's bytes in
// both, so the two rates compare directly with the memcpy's below.
void BM_Reconstruct_Frame(benchmark::State& state) {
    const Model& model = bigModel();
    const PointMultiplier pm(model, state.range(0) == 1 ? BasisPrecision::Single : BasisPrecision::Double);
    state.SetLabel(state.range(0) == 1 ? "single" : "double");
    std::vector<double> coords(static_cast<size_t>(kBigBasis)), out(static_cast<size_t>(kBigPoints * 3));
    for (Index j = 0; j < kBigBasis; ++j) coords[size_t(j)] = unit(5, std::uint64_t(j));
    for (auto _ : state) {
        pm.reconstruct(coords.data(), out.data());
        benchmark::DoNotOptimize(out.data());
        benchmark::ClobberMemory();
    }
    state.SetBytesProcessed(state.iterations() * basisBytes());
}

void BM_Memcpy_BasisBytes(benchmark::State& state) {
    const size_t n = size_t(basisBytes());
    std::vector<char> src(n, 1), dst(n, 0);
    for (auto _ : state) {
        std::memcpy(dst.data(), src.data(), n);
        benchmark::DoNotOptimize(dst.data());
        benchmark::ClobberMemory();
    }
    state.SetBytesProcessed(state.iterations() * std::int64_t(n));
}

// ---- reading a model: the checksum first, then the decode (0), or beside it (1) -------------------

// The bytes of bigModel()'s file (123 MB), decoded as `pmsc run` and `pmsc inspect` read them once
// the file is in memory. The ratio /0 over /1 is what computing the checksum beside the decode saves
// (pmsc::kChecksumThreadBytes); with one core it is about 1.
void BM_DecodeModel(benchmark::State& state) {
    static const std::string bytes = encodeModel(bigModel());
    const auto where = state.range(0) == 1 ? ChecksumThread::Beside : ChecksumThread::First;
    state.SetLabel(state.range(0) == 1 ? "checksum beside" : "checksum first");
    for (auto _ : state) {
        const Model m = decodeModel(bytes, "bench.pmsc", where);
        benchmark::DoNotOptimize(m.basis.data());
    }
    state.SetBytesProcessed(state.iterations() * std::int64_t(bytes.size()));
}

}  // namespace

BENCHMARK(BM_DecodeModel)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Overhead_PlainLoop)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Overhead_Graph1Thread)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Scaling_Graph)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Miss_PlainFullEvaluation)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Miss_Graph)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Reconstruct_Frame)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Memcpy_BasisBytes)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace pmsc::bench
