// pmsc_scaleout_bench: training time on one training set
//   - in memory vs streamed from disk (out of core), both one process, in this process;
//   - `mpirun -n 2 pmsc train` vs `mpirun -n 1 pmsc train` (streamed; child processes, wall time),
// and prints the two ratios with the load average before and after (with 2 cores the
// 2-rank ratio means something only on an idle machine). Goal: 2 ranks <= 0.6 x 1 rank
// on a set where the Gram accumulation dominates.
//
// The set: examples/synthetic's deforming sheet, GRID x GRID points x 3 channels x FRAMES frames,
// written once as float64 .npy to a temporary folder. Environment: PMSC_SCALEOUT_GRID (300),
// PMSC_SCALEOUT_FRAMES (800: at 400 frames the
// F x F Gram accumulation, which grows as F^2, does not yet dominate MPI start-up and the per-pass
// reductions; idle-machine ratio 0.618 at 400 vs 0.52-0.57 at 800); Google Benchmark flags pass through.
//
//   build/bin/pmsc_scaleout_bench                # defaults: 90,000 points x 800 frames, 1.73 GB
#include "evaluators/synthetic/SyntheticSurface.h"
#include "pmsc/NpyIO.h"
#include "pmsc/RowBlocks.h"
#include "pmsc/Training.h"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

namespace {

using pmsc::Index;

int envInt(const char* name, int fallback) {
    const char* v = std::getenv(name);
    return v && *v ? std::atoi(v) : fallback;
}

struct Data {
    std::string dir, path;
    int grid = 0, frames = 0;
};

const Data& data() {
    static Data d = [] {
        Data out;
        out.grid = envInt("PMSC_SCALEOUT_GRID", 300);
        out.frames = envInt("PMSC_SCALEOUT_FRAMES", 800);
        std::string pattern =
            (std::filesystem::temp_directory_path() / "pmsc-scaleout-bench-XXXXXX").string();
        if (!::mkdtemp(pattern.data())) throw std::runtime_error("mkdtemp failed");
        out.dir = pattern;
        out.path = out.dir + "/train.npy";
        pmsc::synthetic::SurfaceOptions o;
        o.grid = out.grid;
        o.frames = out.frames;
        o.seed = 3;
        const pmsc::synthetic::SyntheticSurface surface(o);
        std::vector<Index> all(static_cast<std::size_t>(surface.pointCount()));
        std::iota(all.begin(), all.end(), Index{0});
        std::vector<double> frame(all.size() * 3);
        pmsc::NpyFrameWriter writer(out.path, o.frames, surface.pointCount(), 3, pmsc::NpyDtype::Float64);
        for (Index f = 0; f < o.frames; ++f) {
            surface.evaluate(f, all, frame.data());
            writer.writeFrame(f, frame.data());
        }
        writer.commit();
        std::fprintf(stderr, "training set: %d frames x %d points x 3 channels, %.0f MB at %s\n", out.frames,
                     out.grid * out.grid, double(out.frames) * out.grid * out.grid * 3 * 8 / 1e6,
                     out.path.c_str());
        return out;
    }();
    return d;
}

pmsc::TrainingOptions options() {
    pmsc::TrainingOptions o;
    o.maxKeys = 40;
    o.maxBasis = 32;
    return o;
}
const char* kCliOptions = "--max-keys 40 --max-basis 32 --out-of-core --quiet";

void BM_Train_InMemory(benchmark::State& state) {
    const pmsc::FrameSet frames = pmsc::readFrames(data().path).frames;
    for (auto _ : state) benchmark::DoNotOptimize(pmsc::train(frames, options()).keyPoints.data());
}
BENCHMARK(BM_Train_InMemory)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

void BM_Train_OutOfCore(benchmark::State& state) {
    const std::vector<pmsc::Shot> shots = pmsc::openShots({data().path});
    const Index n = shots.front().info.points;
    for (auto _ : state) {
        // 64 MiB blocks, as pmsc train picks without a memory limit.
        pmsc::NpyBlocks blocks(shots, {0, n},
                               std::max<Index>(1, (Index{64} << 20) / (3 * data().frames * 8)));
        pmsc::SingleProcess one;
        benchmark::DoNotOptimize(pmsc::train(blocks, one, options()).keyPoints.data());
    }
}
BENCHMARK(BM_Train_OutOfCore)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

void BM_Train_MpiRanks(benchmark::State& state) {
    const int ranks = static_cast<int>(state.range(0));
    // yield_when_idle: a rank waiting in a collective gives its core away instead of spinning,
    // which matters when the 2 ranks share 2 cores with anything else.
    const std::string command = std::string(
                                    "env OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 "
                                    "OMPI_MCA_mpi_yield_when_idle=1 ") +
                                PMSC_MPIEXEC + " --oversubscribe -n " + std::to_string(ranks) + " " +
                                PMSC_BINARY + " train --frames " + data().path + " --out " + data().dir +
                                "/model-" + std::to_string(ranks) + ".pmsc " + kCliOptions + " > " +
                                data().dir + "/log-" + std::to_string(ranks) + ".txt 2>&1";
    for (auto _ : state) {
        if (std::system(command.c_str()) != 0) state.SkipWithError(("failed: " + command).c_str());
    }
    // The busiest rank's CPU seconds (the summary's "cpu" line): the critical path when each rank
    // has a core of its own, which wall time shows only on an idle machine.
    std::ifstream log(data().dir + "/log-" + std::to_string(ranks) + ".txt");
    std::string line;
    double busiest = 0;
    while (std::getline(log, line)) {
        if (line.rfind("  cpu ", 0) != 0) continue;
        std::string rest = line.substr(6);
        for (char& c : rest)
            if (c == ',') c = ' ';
        std::istringstream values(rest);
        double v = 0;
        while (values >> v) busiest = std::max(busiest, v);
    }
    state.counters["busiest_rank_cpu_s"] = busiest;
}
BENCHMARK(BM_Train_MpiRanks)->Arg(1)->Arg(2)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

class Collect : public benchmark::ConsoleReporter {
public:
    void ReportRuns(const std::vector<Run>& runs) override {
        ConsoleReporter::ReportRuns(runs);
        for (const Run& run : runs) {
            if (run.error_occurred || run.run_type == Run::RT_Aggregate) continue;
            seconds[run.run_name.str()].push_back(run.GetAdjustedRealTime());
            if (auto it = run.counters.find("busiest_rank_cpu_s"); it != run.counters.end())
                cpu[run.run_name.str()].push_back(it->second);
        }
    }
    double median(const std::string& name, bool busiestCpu = false) const {
        const auto& from = busiestCpu ? cpu : seconds;
        auto it = from.find(name);
        if (it == from.end() || it->second.empty()) return 0;
        std::vector<double> v = it->second;
        std::sort(v.begin(), v.end());
        return v[v.size() / 2];
    }
    std::map<std::string, std::vector<double>> seconds, cpu;
};

std::string loadAverage() {
    std::ifstream in("/proc/loadavg");
    std::string a, b, c;
    in >> a >> b >> c;
    return a + " " + b + " " + c;
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<std::string> storage = {argv[0], "--benchmark_repetitions=3",
                                        "--benchmark_enable_random_interleaving=true"};
    for (int i = 1; i < argc; ++i) storage.emplace_back(argv[i]);
    std::vector<char*> args;
    for (auto& s : storage) args.push_back(s.data());
    int count = static_cast<int>(args.size());
    benchmark::Initialize(&count, args.data());
    if (benchmark::ReportUnrecognizedArguments(count, args.data())) return 2;
    data();  // write the set before any timing
    const std::string before = loadAverage();
    Collect reporter;
    benchmark::RunSpecifiedBenchmarks(&reporter);
    benchmark::Shutdown();
    const double inMemory = reporter.median("BM_Train_InMemory/iterations:1/real_time");
    const double outOfCore = reporter.median("BM_Train_OutOfCore/iterations:1/real_time");
    const double one = reporter.median("BM_Train_MpiRanks/1/iterations:1/real_time");
    const double two = reporter.median("BM_Train_MpiRanks/2/iterations:1/real_time");
    std::printf("load average before %s, after %s (2 cores)\n", before.c_str(), loadAverage().c_str());
    if (inMemory > 0 && outOfCore > 0) {
        std::printf("out of core / in memory: %.3f (%.2f s / %.2f s, medians)\n", outOfCore / inMemory,
                    outOfCore, inMemory);
    }
    if (one > 0 && two > 0) {
        std::printf("2 ranks / 1 rank: %.3f (%.2f s / %.2f s, medians; goal <= 0.6)\n", two / one, two, one);
    }
    const double oneCpu = reporter.median("BM_Train_MpiRanks/1/iterations:1/real_time", true);
    const double twoCpu = reporter.median("BM_Train_MpiRanks/2/iterations:1/real_time", true);
    if (oneCpu > 0 && twoCpu > 0) {
        std::printf("2 ranks / 1 rank by the busiest rank's CPU time: %.3f (%.2f s / %.2f s, medians)\n",
                    twoCpu / oneCpu, twoCpu, oneCpu);
    }
    std::filesystem::remove_all(data().dir);
    return 0;
}
