// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// What a calculation pays for living in a child process (exec:COMMAND), in one run:
//  - the same synthetic surface evaluated in process and through `pmsc serve` in a child, a whole
//    frame per call, at about the paper's face size (55 x 55 = 3,025 points, the face has 2,986)
//    and at 160,000 points (400 x 400): exec_over_in_process per size (goal at 160,000: <= 1.10);
//  - a child that costs about 1 ms a request (pmsc_exec_ripple --work-us 1000), 200 requests from
//    2 worker threads against 1: workers_2_over_1 throughput (goal >= 1.8 on two free cores).
// Prints one JSON object after the benchmarks (about 30 s). Run: build/bin/pmsc_exec_bench
#include "evaluators/EvaluatorRegistry.h"
#include "evaluators/exec/ExecEvaluator.h"

#include <benchmark/benchmark.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <cstdio>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace {

using pmsc::Index;

const std::string kPmsc = PMSC_BINARY;
const std::string kRipple = PMSC_RIPPLE_CHILD;
constexpr Index kFrames = 48;

std::string syntheticSpec(Index grid) {
    return "synthetic:grid=" + std::to_string(grid) + ":frames=" + std::to_string(kFrames);
}

void wholeFrames(benchmark::State& state, const pmsc::PointEvaluator& evaluator) {
    std::vector<double> out(static_cast<std::size_t>(evaluator.pointCount() * evaluator.channelCount()));
    Index frame = 0;
    for (auto _ : state) {
        evaluator.evaluateAll(frame, out.data());
        benchmark::DoNotOptimize(out.data());
        frame = (frame + 1) % kFrames;
    }
    state.counters["points"] = static_cast<double>(evaluator.pointCount());
}

void inProcess(benchmark::State& state) {
    const auto evaluator = pmsc::evaluators::makeEvaluator(syntheticSpec(state.range(0)));
    wholeFrames(state, *evaluator);
}

void inChild(benchmark::State& state) {
    pmsc::evaluators::exec::ExecOptions o;
    o.command = kPmsc + " serve " + syntheticSpec(state.range(0));
    const pmsc::evaluators::exec::ExecEvaluator evaluator(o);
    wholeFrames(state, evaluator);
}

/// 200 requests of 16 points to a child that spins 1 ms each, from `state.range(0)` workers.
void workers(benchmark::State& state) {
    pmsc::evaluators::exec::ExecOptions o;
    o.command = kRipple + " --grid 32 --work-us 1000";
    const pmsc::evaluators::exec::ExecEvaluator evaluator(o);
    const int threads = static_cast<int>(state.range(0));
    tbb::task_arena arena(threads);
    std::vector<Index> points(16);
    for (Index i = 0; i < 16; ++i) points[static_cast<std::size_t>(i)] = i * 7;
    for (auto _ : state) {
        arena.execute([&] {
            tbb::parallel_for(0, 200, [&](int r) {
                std::vector<double> out(points.size() * 3);
                evaluator.evaluate(r % 240, points, out.data());
                benchmark::DoNotOptimize(out.data());
            });
        });
    }
}

// Decision: 7 repetitions of 0.5 s, run in random interleaved order (main turns it on), and the
// ratios from their medians. The child's time depends on both cores, which a virtual machine's
// neighbours disturb now and then; interleaved repetitions put a disturbance on both sides of a
// ratio, and the median drops the repetition it hit.
void medianOfRepetitions(benchmark::internal::Benchmark* b, int repetitions) {
    b->Unit(benchmark::kMillisecond)
        ->MinTime(0.5)
        ->Repetitions(repetitions)
        ->ReportAggregatesOnly(true)
        ->UseRealTime();
}
BENCHMARK(inProcess)->Arg(55)->Arg(400)->Apply([](auto* b) { medianOfRepetitions(b, 7); });
BENCHMARK(inChild)->Arg(55)->Arg(400)->Apply([](auto* b) { medianOfRepetitions(b, 7); });
BENCHMARK(workers)->Arg(1)->Arg(2)->Apply([](auto* b) { medianOfRepetitions(b, 5); });

/// Each benchmark's median real time per iteration (its only run's without repetitions), by name
/// and argument, for the ratios printed after the run.
class RatioReporter : public benchmark::ConsoleReporter {
public:
    std::map<std::string, double> seconds;
    void ReportRuns(const std::vector<Run>& runs) override {
        for (const Run& r : runs)
            if (r.run_type == Run::RT_Iteration ? r.repetitions <= 1 : r.aggregate_name == "median")
                seconds[r.run_name.function_name + "/" + r.run_name.args] = r.GetAdjustedRealTime();
        ConsoleReporter::ReportRuns(runs);
    }
};

double ratio(std::map<std::string, double>& s, const std::string& a, const std::string& b) {
    return s[b] > 0 ? s[a] / s[b] : 0;
}

}  // namespace

int main(int argc, char** argv) {
    // Interleaved repetitions by default; a later --benchmark_enable_random_interleaving=false wins.
    std::vector<char*> args(argv, argv + argc);
    std::string interleave = "--benchmark_enable_random_interleaving=true";
    args.insert(args.begin() + 1, interleave.data());
    int count = static_cast<int>(args.size());
    benchmark::Initialize(&count, args.data());
    RatioReporter reporter;
    benchmark::RunSpecifiedBenchmarks(&reporter);
    auto& s = reporter.seconds;
    const double small = ratio(s, "inChild/55", "inProcess/55");
    const double large = ratio(s, "inChild/400", "inProcess/400");
    const double scaling = ratio(s, "workers/1", "workers/2");
    std::printf(
        "{\"exec_over_in_process_3025_points\": %.3f, \"exec_over_in_process_160000_points\": %.3f, "
        "\"goal_160000\": 1.10, \"met_160000\": %s, \"workers_2_over_1\": %.3f, \"goal_workers\": 1.8, "
        "\"met_workers\": %s}\n",
        small, large, large > 0 && large <= 1.10 ? "true" : "false", scaling,
        scaling >= 1.8 ? "true" : "false");
    return 0;
}
