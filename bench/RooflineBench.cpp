// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// A scene's frame time against its roofline, in one run:
//
//   pmsc_roofline_bench --dir DEMO_OUT [--scene SPEC] [--frames A-B] [--threads T] [benchmark flags]
//
// DEMO_OUT is what `pmsc demo cornell|volume --out DEMO_OUT` writes: model.pmsc and scene.txt (the
// evaluator's spec, run from the folder the demo ran in). A hit cannot do without its key
// points' calculation (measured alone, one call per frame as the engine makes it, spread over
// the threads) and the bytes its reconstruction must read (the basis in the precision the run
// uses, and the mean) at the machine's read bandwidth with the same threads (measured on a
// buffer as large). The roofline is the larger of the two: frames in flight overlap one frame's
// keys with another's reconstruction, and a thread streaming alone takes more than its share of
// the bandwidth, so the engine measured under their sum on the Cornell box; the sum is printed
// too (keys_plus_bytes_ms). Each limit is the fastest of its runs (the keys: per frame, averaged
// over the frames). Benchmarks, in order:
//   BM_StreamRead      the bandwidth: T threads reading a buffer at least the double basis's size
//   BM_KeysAlone       what a hit computes of one frame: its key points, then its sentinels
//   BM_Full            the full calculation of one frame (evaluateAll): the speedup's numerator
//   BM_Engine/0 and /1 the engine over the frames, double and float basis: frame_ms,
//                      roofline_ms, of_roofline (roofline / frame time: 1 is the limit), speedup
#include "engine/Engine.h"
#include "evaluators/EvaluatorRegistry.h"
#include "pmsc/ModelIO.h"

#include <benchmark/benchmark.h>
#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

namespace {

using pmsc::Index;
using Clock = std::chrono::steady_clock;

struct Setup {
    std::string dir, scene, frames;
    int threads = 0;
    pmsc::Model model;
    std::unique_ptr<pmsc::PointEvaluator> evaluator;
    Index first = 0, last = -1;
};

Setup& setup() {
    static Setup s;
    return s;
}

double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

/// The fastest of `runs` timings of f(), in seconds: a limit is what the machine can do, and
/// on a shared machine the slower runs measure the neighbours.
template <typename F>
double fastestSeconds(int runs, F&& f) {
    double best = 1e300;
    for (int r = 0; r < runs; ++r) {
        const auto start = Clock::now();
        f();
        best = std::min(best, secondsSince(start));
    }
    return best;
}

/// The median of `runs` timings of f(), in seconds: a typical run.
template <typename F>
double medianSeconds(int runs, F&& f) {
    std::vector<double> t;
    for (int r = 0; r < runs; ++r) {
        const auto start = Clock::now();
        f();
        t.push_back(secondsSince(start));
    }
    std::nth_element(t.begin(), t.begin() + runs / 2, t.end());
    return t[static_cast<size_t>(runs / 2)];
}

/// Bytes a hit's reconstruction reads: the basis in the precision, and the mean.
double hitBytes(pmsc::BasisPrecision precision) {
    const pmsc::Model& m = setup().model;
    const double basis = static_cast<double>(m.basis.size()) *
                         (precision == pmsc::BasisPrecision::Single ? sizeof(float) : sizeof(double));
    return basis + static_cast<double>(m.mean.size()) * sizeof(double);
}

/// A buffer of at least the double basis's bytes (and past any cache), read by the threads in
/// blocks: the read bandwidth a reconstruction can have. The read xors 64-bit words into eight
/// accumulators, one cycle each, so the loop waits on memory and not on its own arithmetic.
struct Stream {
    std::vector<std::uint64_t> buffer;
    Stream() {
        const double bytes = std::max(hitBytes(pmsc::BasisPrecision::Double), 256.0 * (1 << 20));
        buffer.assign(static_cast<size_t>(bytes / sizeof(std::uint64_t)), 1);
    }
    std::uint64_t read() const {
        return tbb::parallel_reduce(
            tbb::blocked_range<size_t>(0, buffer.size(), 1 << 15), std::uint64_t(0),
            [&](const tbb::blocked_range<size_t>& r, std::uint64_t acc) {
                std::uint64_t x[8] = {};
                for (size_t i = r.begin(); i + 8 <= r.end(); i += 8)
                    for (size_t k = 0; k < 8; ++k) x[k] ^= buffer[i + k];
                for (const std::uint64_t v : x) acc ^= v;
                return acc;
            },
            [](std::uint64_t a, std::uint64_t b) { return a ^ b; });
    }
    double bytes() const { return static_cast<double>(buffer.size() * sizeof(std::uint64_t)); }
};

struct Measured {
    double bandwidth = 0;    ///< bytes/s, T threads
    double keySeconds = 0;   ///< one frame's key points, one call
    double fullSeconds = 0;  ///< one frame's full calculation
};

tbb::task_arena& arena() {
    static tbb::task_arena a(setup().threads);
    return a;
}

double measureBandwidth() {
    static const double bw = [] {
        const Stream stream;
        std::uint64_t sink = 0;
        const double t = fastestSeconds(25, [&] { arena().execute([&] { sink ^= stream.read(); }); });
        benchmark::DoNotOptimize(sink);
        return stream.bytes() / t;
    }();
    return bw;
}

/// The points a hit computes after its keys: the model's sentinels (pmsc::HitCheck), ascending.
std::vector<Index> sentinelPoints(const pmsc::Model& model) {
    std::vector<Index> points;
    if (model.sentinels) points = model.sentinels->points;
    std::sort(points.begin(), points.end());
    return points;
}

/// What a hit must compute: its keys, then its sentinels (a second call, as the error monitor
/// makes it).
double measureKeys() {
    static const double seconds = [] {
        const Setup& s = setup();
        const Index k = s.model.keyCount(), c = s.model.channels;
        const std::vector<Index> sentinels = sentinelPoints(s.model);
        std::vector<double> out(static_cast<size_t>(std::max<Index>(k, Index(sentinels.size())) * c));
        // Frames differ (a light far from the medium marches longer rays): the mean over the run's
        // frames of each frame's fastest of three calls.
        double total = 0;
        for (Index frame = s.first; frame <= s.last; ++frame) {
            total += fastestSeconds(3, [&] { s.evaluator->evaluate(frame, s.model.keyPoints, out.data()); });
            if (!sentinels.empty())
                total += fastestSeconds(3, [&] { s.evaluator->evaluate(frame, sentinels, out.data()); });
        }
        return total / static_cast<double>(s.last - s.first + 1);
    }();
    return seconds;
}

double measureFull() {
    static const double seconds = [] {
        const Setup& s = setup();
        std::vector<double> out(static_cast<size_t>(s.model.points * s.model.channels));
        Index frame = s.first;
        return medianSeconds(3, [&] {
            arena().execute([&] { s.evaluator->evaluateAll(frame, out.data()); });
            ++frame;
        });
    }();
    return seconds;
}

/// Counts what it receives and keeps nothing: the engine's cost alone.
struct CountingSink final : pmsc::FrameSink {
    Index frames = 0, hits = 0;
    void write(const pmsc::FrameResult& f) override {
        ++frames;
        hits += f.state == pmsc::CacheState::Hit ? 1 : 0;
        benchmark::DoNotOptimize(f.values.data());
    }
};

void BM_StreamRead(benchmark::State& state) {
    const Stream stream;
    std::uint64_t total = 0;
    for (auto _ : state) arena().execute([&] { total ^= stream.read(); });
    benchmark::DoNotOptimize(total);
    state.SetBytesProcessed(static_cast<std::int64_t>(stream.bytes()) * state.iterations());
}

void BM_KeysAlone(benchmark::State& state) {
    const Setup& s = setup();
    const std::vector<Index> sentinels = sentinelPoints(s.model);
    std::vector<double> out(
        static_cast<size_t>(std::max<Index>(s.model.keyCount(), Index(sentinels.size())) * s.model.channels));
    Index frame = s.first;
    for (auto _ : state) {
        s.evaluator->evaluate(frame, s.model.keyPoints, out.data());
        if (!sentinels.empty()) s.evaluator->evaluate(frame, sentinels, out.data());
        frame = frame == s.last ? s.first : frame + 1;
    }
    state.counters["keys"] = static_cast<double>(s.model.keyCount());
    state.counters["sentinels"] = static_cast<double>(sentinels.size());
}

void BM_Full(benchmark::State& state) {
    const Setup& s = setup();
    std::vector<double> out(static_cast<size_t>(s.model.points * s.model.channels));
    Index frame = s.first;
    for (auto _ : state) {
        arena().execute([&] { s.evaluator->evaluateAll(frame, out.data()); });
        frame = frame == s.last ? s.first : frame + 1;
    }
}

void BM_Engine(benchmark::State& state) {
    const Setup& s = setup();
    const auto precision = state.range(0) == 1 ? pmsc::BasisPrecision::Single : pmsc::BasisPrecision::Double;
    state.SetLabel(precision == pmsc::BasisPrecision::Single ? "float basis" : "double basis");
    pmsc::engine::EngineOptions o;
    o.threads = s.threads;
    o.basisPrecision = precision;
    pmsc::engine::Engine engine(s.model, *s.evaluator, o);
    const Index frames = s.last - s.first + 1;
    Index hits = 0;
    double seconds = 0;  // the runs' own wall time: the counters below are per frame of it
    for (auto _ : state) {
        CountingSink sink;
        const auto start = Clock::now();
        engine.run(pmsc::engine::FrameRange{s.first, frames, 1}, sink);
        seconds += secondsSince(start);
        hits = sink.hits;
    }
    const double frame = seconds / static_cast<double>(state.iterations() * frames);
    const double bandwidth = measureBandwidth(), keys = measureKeys(), full = measureFull();
    const double bytes = hitBytes(precision) / bandwidth;
    const double roofline = std::max(keys / s.threads, bytes);
    state.counters["frames"] = static_cast<double>(frames);
    state.counters["hit_rate"] = static_cast<double>(hits) / static_cast<double>(frames);
    state.counters["frame_ms"] = 1e3 * frame;
    state.counters["keys_ms"] = 1e3 * keys;
    state.counters["bytes_ms"] = 1e3 * bytes;
    state.counters["roofline_ms"] = 1e3 * roofline;
    state.counters["of_roofline"] = roofline / frame;
    state.counters["keys_plus_bytes_ms"] = 1e3 * (keys / s.threads + bytes);
    state.counters["of_keys_plus_bytes"] = (keys / s.threads + bytes) / frame;
    state.counters["speedup"] = full / frame;
}

/// Reads --dir, --scene, --frames and --threads out of argv (the rest goes to benchmark).
bool parseArguments(int& argc, char** argv) {
    Setup& s = setup();
    std::vector<char*> rest{argv[0]};
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&](const char* name) -> const char* {
            if (i + 1 >= argc) {
                std::fprintf(stderr, "pmsc_roofline_bench: %s needs a value\n", name);
                std::exit(2);
            }
            return argv[++i];
        };
        if (a == "--dir")
            s.dir = value("--dir");
        else if (a == "--scene")
            s.scene = value("--scene");
        else if (a == "--frames")
            s.frames = value("--frames");
        else if (a == "--threads")
            s.threads = std::atoi(value("--threads"));
        else
            rest.push_back(argv[i]);
    }
    argc = static_cast<int>(rest.size());
    std::copy(rest.begin(), rest.end(), argv);
    return !s.dir.empty();
}

void load() {
    Setup& s = setup();
    s.model = pmsc::readModel(s.dir + "/model.pmsc");
    if (s.scene.empty()) {
        std::ifstream in(s.dir + "/scene.txt");
        if (!std::getline(in, s.scene) || s.scene.empty())
            throw std::runtime_error(s.dir + "/scene.txt: no scene spec (give --scene SPEC)");
    }
    s.evaluator = pmsc::evaluators::makeEvaluator(s.scene);
    if (s.evaluator->pointCount() != s.model.points || s.evaluator->channelCount() != s.model.channels)
        throw std::runtime_error("the scene '" + s.scene + "' does not have the model's points and channels");
    s.last = s.evaluator->frameCount() - 1;
    if (!s.frames.empty()) {
        const auto dash = s.frames.find('-');
        s.first = std::stoll(s.frames.substr(0, dash));
        s.last = dash == std::string::npos ? s.first : std::stoll(s.frames.substr(dash + 1));
    }
    if (s.first < 0 || s.last < s.first || s.last >= s.evaluator->frameCount())
        throw std::runtime_error("--frames " + s.frames + ": outside the scene's 0-" +
                                 std::to_string(s.evaluator->frameCount() - 1));
    if (s.threads <= 0) s.threads = tbb::info::default_concurrency();
}

}  // namespace

int main(int argc, char** argv) {
    if (!parseArguments(argc, argv)) {
        std::fprintf(stderr,
                     "usage: pmsc_roofline_bench --dir DEMO_OUT [--scene SPEC] [--frames A-B] [--threads T] "
                     "[benchmark flags]\n  DEMO_OUT: a `pmsc demo cornell|volume --out` folder\n");
        return 2;
    }
    try {
        load();
    } catch (const std::exception& e) {
        std::fprintf(stderr, "pmsc_roofline_bench: %s\n", e.what());
        return 2;
    }
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism,
                                    static_cast<size_t>(setup().threads));
    benchmark::RegisterBenchmark("BM_StreamRead", BM_StreamRead)
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
    benchmark::RegisterBenchmark("BM_KeysAlone", BM_KeysAlone)->Unit(benchmark::kMillisecond)->UseRealTime();
    benchmark::RegisterBenchmark("BM_Full", BM_Full)
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime()
        ->Iterations(3);
    benchmark::RegisterBenchmark("BM_Engine", BM_Engine)
        ->Arg(0)
        ->Arg(1)
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime()
        ->MinTime(2.0);
    benchmark::Initialize(&argc, argv);
    benchmark::RunSpecifiedBenchmarks();
    benchmark::Shutdown();
    return 0;
}
