// pmsc_engine_report: runs the engine benchmarks (EngineBench.cpp) and prints ONE JSON object
// with the four speed-goal ratios and the raw rates behind them. The usual Google Benchmark
// table goes to stderr; extra arguments are passed to Google Benchmark (e.g.
// --benchmark_repetitions=9, --benchmark_filter=Miss).
#include <benchmark/benchmark.h>
#include <nlohmann/json.hpp>

#include <fstream>
#include <iostream>
#include <map>
#include <string>
#include <thread>
#include <vector>

namespace {

/// Keeps the median (or the only run) of each benchmark's rates while printing the table.
class CollectingReporter : public benchmark::ConsoleReporter {
public:
    void ReportRuns(const std::vector<Run>& runs) override {
        ConsoleReporter::ReportRuns(runs);
        for (const Run& run : runs) {
            if (run.error_occurred) {  // a benchmark's own check failed (e.g. a frame did not hit)
                errors[run.benchmark_name()] = run.error_message;
                continue;
            }
            const bool median = run.run_type == Run::RT_Aggregate && run.aggregate_name == "median";
            if (run.run_type == Run::RT_Aggregate && !median) continue;
            const std::string name = run.run_name.str();
            if (!median && rates.count(name) && hasMedian[name]) continue;
            Rates& r = rates[name];
            if (auto it = run.counters.find("items_per_second"); it != run.counters.end())
                r.items = it->second;
            if (auto it = run.counters.find("bytes_per_second"); it != run.counters.end())
                r.bytes = it->second;
            if (auto it = run.counters.find("cpu_seconds_per_frame"); it != run.counters.end())
                r.cpuPerFrame = it->second;
            if (median) hasMedian[name] = true;
        }
    }
    struct Rates {
        double items = 0;
        double bytes = 0;
        double cpuPerFrame = 0;
    };
    std::map<std::string, Rates> rates;
    std::map<std::string, bool> hasMedian;
    std::map<std::string, std::string> errors;
};

std::vector<double> loadAverage() {
    std::ifstream in("/proc/loadavg");
    double a = 0, b = 0, c = 0;
    in >> a >> b >> c;
    return {a, b, c};
}

}  // namespace

int main(int argc, char** argv) {
    // Defaults: several interleaved repetitions, medians; the caller's flags come after and win.
    std::vector<std::string> storage = {argv[0], "--benchmark_repetitions=5",
                                        "--benchmark_enable_random_interleaving=true",
                                        "--benchmark_report_aggregates_only=false"};
    for (int i = 1; i < argc; ++i) storage.emplace_back(argv[i]);
    std::vector<char*> args;
    for (auto& s : storage) args.push_back(s.data());
    int count = int(args.size());
    benchmark::Initialize(&count, args.data());
    if (benchmark::ReportUnrecognizedArguments(count, args.data())) return 2;

    const auto loadBefore = loadAverage();
    CollectingReporter reporter;
    reporter.SetOutputStream(&std::cerr);
    reporter.SetErrorStream(&std::cerr);
    benchmark::RunSpecifiedBenchmarks(&reporter);
    benchmark::Shutdown();

    const auto rate = [&](const std::string& name, bool bytes = false) {
        const auto it = reporter.rates.find(name);
        if (it == reporter.rates.end()) return 0.0;
        return bytes ? it->second.bytes : it->second.items;
    };
    const auto cpu = [&](const std::string& name) {
        const auto it = reporter.rates.find(name);
        return it == reporter.rates.end() ? 0.0 : it->second.cpuPerFrame;
    };
    const auto ratio = [](double a, double b) {
        return b > 0 ? nlohmann::json(a / b) : nlohmann::json(nullptr);
    };

    const double plain = rate("BM_Overhead_PlainLoop/real_time");
    const double graph1 = rate("BM_Overhead_Graph1Thread/real_time");
    const double scale1 = rate("BM_Scaling_Graph/1/real_time");
    const double scale2 = rate("BM_Scaling_Graph/2/real_time");
    const double fullPlain = rate("BM_Miss_PlainFullEvaluation/real_time");
    const double miss1 = rate("BM_Miss_Graph/1/real_time");
    const double miss2 = rate("BM_Miss_Graph/2/real_time");
    const double reconstructBps = rate("BM_Reconstruct_Frame/0/real_time", true);
    const double floatReconstructBps = rate("BM_Reconstruct_Frame/1/real_time", true);
    const double memcpyBps = rate("BM_Memcpy_BasisBytes/real_time", true);

    nlohmann::json j;
    // Time ratios are rate ratios inverted: (1 / graph) / (1 / plain) = plain / graph.
    j["overhead_ratio"] = ratio(plain, graph1);
    j["scaling_2_threads"] = ratio(scale2, scale1);
    j["miss_cost_ratio"] = ratio(fullPlain, miss1);
    j["reconstruct_bandwidth_ratio"] = ratio(reconstructBps, memcpyBps);
    j["goals"] = {{"overhead_ratio", "<= 1.05"},
                  {"scaling_2_threads", ">= 1.8"},
                  {"miss_cost_ratio", "<= 1.05"},
                  {"reconstruct_bandwidth_ratio", ">= 0.7"}};
    j["overhead"] = {{"what",
                      "frames/s: plain serial loop vs graph at 1 thread; recorded evaluator, all hits, "
                      "2986 points x 3 x 85 basis, 170 keys"},
                     {"plain_loop_frames_per_second", plain},
                     {"graph_1_thread_frames_per_second", graph1},
                     {"plain_loop_cpu_seconds_per_frame", cpu("BM_Overhead_PlainLoop/real_time")},
                     {"graph_1_thread_cpu_seconds_per_frame", cpu("BM_Overhead_Graph1Thread/real_time")},
                     {"cpu_overhead_ratio", ratio(cpu("BM_Overhead_Graph1Thread/real_time"),
                                                  cpu("BM_Overhead_PlainLoop/real_time"))}};
    j["scaling"] = {{"what", "frames/s of the graph; evaluator ~1 ms of busy work per frame, all hits"},
                    {"graph_1_thread_frames_per_second", scale1},
                    {"graph_2_threads_frames_per_second", scale2},
                    {"graph_1_thread_cpu_seconds_per_frame", cpu("BM_Scaling_Graph/1/real_time")},
                    {"graph_2_threads_cpu_seconds_per_frame", cpu("BM_Scaling_Graph/2/real_time")},
                    {"note",
                     "wall-time scaling needs the second core free; CPU seconds per frame show "
                     "whether 2 threads add work"}};
    j["miss"] = {
        {"what",
         "missed frames/s: plain full evaluation vs through the graph; linear-cost evaluator "
         "(~1 us per point, 2986 points)"},
        {"plain_full_evaluation_frames_per_second", fullPlain},
        {"graph_1_thread_frames_per_second", miss1},
        {"graph_2_threads_frames_per_second", miss2},
        {"plain_full_evaluation_cpu_seconds_per_frame", cpu("BM_Miss_PlainFullEvaluation/real_time")},
        {"graph_1_thread_cpu_seconds_per_frame", cpu("BM_Miss_Graph/1/real_time")},
        {"cpu_miss_cost_ratio",
         ratio(cpu("BM_Miss_Graph/1/real_time"), cpu("BM_Miss_PlainFullEvaluation/real_time"))},
        {"miss_cost_ratio_2_threads", ratio(fullPlain, miss2)}};
    j["reconstruct"] = {{"what",
                         "bytes of double basis per second: one frame's reconstruction at 160000 points x 3 "
                         "x 32 basis vs memcpy of the same bytes; the float basis's frame in the same "
                         "units (its own bytes are half)"},
                        {"basis_bytes", 160000LL * 3 * 32 * 8},
                        {"reconstruct_bytes_per_second", reconstructBps},
                        {"float_basis_reconstruct_bytes_per_second", floatReconstructBps},
                        {"memcpy_bytes_per_second", memcpyBps}};
    j["machine"] = {{"hardware_threads", std::thread::hardware_concurrency()},
                    {"load_average_before", loadBefore},
                    {"load_average_after", loadAverage()}};
    if (!reporter.errors.empty()) j["errors"] = reporter.errors;
    std::cout << j.dump(2) << std::endl;
    return reporter.errors.empty() ? 0 : 1;
}
