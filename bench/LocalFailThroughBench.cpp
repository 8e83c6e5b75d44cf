// Local fail-through (speed goal): a frame where one region of R misses costs at most
// (region's points / N) of a full evaluation + 10%, measured in one run beside a whole-frame miss
// and a plain full evaluation of the same frames.
//
//   pmsc_local_bench                 Google Benchmark output, then one line per ratio:
//   local_miss / full <= points/N + 0.10 ?   whole_miss / full
//
// The evaluator costs the same per point (busy work, ~0.5 us), so cost is proportional to the
// points evaluated: the ideal ratio is the failing region's fail set / N. Engine at one thread:
// costs, not parallel speed, are compared.
#include "engine/Engine.h"
#include "pmsc/Model.h"

#include <benchmark/benchmark.h>

#include <Eigen/QR>

#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

namespace {

using pmsc::Index;

constexpr Index kPoints = 8192, kRegions = 8, kBasis = 4, kKeysPerRegion = 4, kFrames = 16;

/// Frame f: mean + B b(f) exactly (a hit) everywhere, plus, on region 0's points (its keys
/// included), a displacement the basis does not hold: region 0 misses, the others hit.
class RegionEvaluator : public pmsc::PointEvaluator {
public:
    RegionEvaluator(const pmsc::Model& m, bool miss) : model_(m), miss_(miss) {}
    std::string name() const override { return "bench-regions"; }
    Index pointCount() const override { return kPoints; }
    Index channelCount() const override { return 3; }
    Index frameCount() const override { return kFrames; }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override {
        for (size_t i = 0; i < points.size(); ++i) {
            const Index p = points[i];
            double busy = 0;
            for (int k = 0; k < 160; ++k) busy += std::sqrt(double(k + p + frame));  // ~0.5 us of work
            for (Index c = 0; c < 3; ++c) {
                double v = model_.mean[p * 3 + c] + 1e-30 * busy;
                for (Index j = 0; j < kBasis; ++j)
                    v += model_.basis(p * 3 + c, j) * std::sin(0.3 * double(frame) + double(j));
                if (miss_ && p < kPoints / kRegions) v += 0.5 * std::cos(double(p) * 0.01 + double(frame));
                out[i * 3 + c] = v;
            }
        }
    }

private:
    const pmsc::Model& model_;
    bool miss_;
};

/// A model built by hand with R contiguous regions of N/R points, each with its keys and the
/// rows of the global basis as its local basis (so a frame in the global subspace hits in every
/// region), feather bands of 64 points into each neighbour.
const pmsc::Model& model() {
    static const pmsc::Model m = [] {
        pmsc::Model m;
        m.points = kPoints;
        m.channels = 3;
        m.trainFrames = 10;
        Eigen::MatrixXd g(kPoints * 3, kBasis);
        for (Index i = 0; i < g.size(); ++i) g.data()[i] = std::sin(0.37 * double(i) + 0.1);
        m.basis = Eigen::HouseholderQR<Eigen::MatrixXd>(g).householderQ() *
                  Eigen::MatrixXd::Identity(kPoints * 3, kBasis);
        m.mean = Eigen::VectorXd::LinSpaced(kPoints * 3, -1, 1);
        m.singularValues = Eigen::VectorXd::LinSpaced(kBasis, 4, 1);
        m.totalEnergy = m.singularValues.squaredNorm();
        const Index size = kPoints / kRegions;
        for (Index r = 0; r < kRegions; ++r)
            for (Index k = 0; k < kKeysPerRegion; ++k)
                m.keyPoints.push_back(r * size + (k * size) / kKeysPerRegion + 7);
        m.projector = pmsc::makeProjector(m.basis, 3, m.keyPoints);
        m.epsMin = 1e-6;
        m.epsMax = 2e-6;
        pmsc::LocalRegions lr;
        lr.featherWidth = 1;
        lr.maxLocalFraction = 0.6;
        std::vector<std::vector<std::pair<Index, double>>> feather(static_cast<size_t>(kPoints));
        for (Index r = 0; r < kRegions; ++r) {
            pmsc::Region reg;
            for (Index p = r * size; p < (r + 1) * size; ++p) reg.points.push_back(p);
            for (Index k = 0; k < kKeysPerRegion; ++k) reg.keys.push_back(r * kKeysPerRegion + k);
            std::vector<Index> keyPoints;
            for (const Index k : reg.keys) keyPoints.push_back(m.keyPoints[size_t(k)]);
            reg.basis = m.basis.middleRows(r * size * 3, size * 3);
            reg.keyBasis = pmsc::gatherKeyRows(m.basis, 3, keyPoints);
            Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(reg.keyBasis);
            reg.projector = cod.pseudoInverse();
            reg.epsMin = 1e-6;
            reg.epsMax = 2e-6;
            lr.regions.push_back(std::move(reg));
            for (Index d = 1; d <= 64; ++d) {  // bands on both sides of each border
                if (r > 0) feather[size_t(r * size - d)].push_back({r, 1.0 - double(d) / 65.0});
                if (r + 1 < kRegions)
                    feather[size_t((r + 1) * size + d - 1)].push_back({r, 1.0 - double(d) / 65.0});
            }
        }
        lr.featherStart.push_back(0);
        for (Index p = 0; p < kPoints; ++p) {
            for (const auto& [r, f] : feather[size_t(p)]) {
                lr.featherRegion.push_back(r);
                lr.featherFactor.push_back(f);
            }
            lr.featherStart.push_back(Index(lr.featherRegion.size()));
        }
        m.regions = std::move(lr);
        m.validate();
        return m;
    }();
    return m;
}

class NullSink : public pmsc::engine::FrameSink {
public:
    void write(const pmsc::engine::FrameResult& r) override { benchmark::DoNotOptimize(r.values[0]); }
};

void fullEvaluation(benchmark::State& state) {
    const RegionEvaluator e(model(), true);
    std::vector<double> out(kPoints * 3);
    for (auto _ : state)
        for (Index f = 0; f < kFrames; ++f) e.evaluateAll(f, out.data());
    state.counters["seconds_per_frame"] = benchmark::Counter(
        double(kFrames), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void engineMiss(benchmark::State& state, bool local) {
    const RegionEvaluator e(model(), true);
    pmsc::engine::EngineOptions o;
    o.threads = 1;
    o.localFailThrough = local;
    pmsc::engine::Engine engine(model(), e, o);
    NullSink sink;
    double evaluated = 0;
    for (auto _ : state) {
        const auto stats = engine.run({0, kFrames, 1}, sink);
        evaluated = stats.pointsEvaluatedFraction;
        if (local && stats.localFrames != kFrames) state.SkipWithError("frames were not routed locally");
    }
    state.counters["seconds_per_frame"] = benchmark::Counter(
        double(kFrames), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
    state.counters["points_evaluated_fraction"] = evaluated;
}

void localMiss(benchmark::State& state) { engineMiss(state, true); }
void wholeFrameMiss(benchmark::State& state) { engineMiss(state, false); }

BENCHMARK(fullEvaluation)->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(localMiss)->Unit(benchmark::kMillisecond)->MinTime(1.0);
BENCHMARK(wholeFrameMiss)->Unit(benchmark::kMillisecond)->MinTime(1.0);

/// Collects each benchmark's real time per iteration for the ratios printed after the run.
class RatioReporter : public benchmark::ConsoleReporter {
public:
    std::map<std::string, double> seconds;
    std::map<std::string, double> fraction;
    void ReportRuns(const std::vector<Run>& runs) override {
        for (const Run& r : runs) {
            const std::string name = r.benchmark_name().substr(0, r.benchmark_name().find('/'));
            seconds[name] = r.GetAdjustedRealTime();
            const auto it = r.counters.find("points_evaluated_fraction");
            if (it != r.counters.end()) fraction[name] = it->second;
        }
        ConsoleReporter::ReportRuns(runs);
    }
};

}  // namespace

int main(int argc, char** argv) {
    benchmark::Initialize(&argc, argv);
    RatioReporter reporter;
    benchmark::RunSpecifiedBenchmarks(&reporter);
    const double full = reporter.seconds["fullEvaluation"];
    const double local = reporter.seconds["localMiss"];
    const double whole = reporter.seconds["wholeFrameMiss"];
    const double evaluated = reporter.fraction["localMiss"];
    const double regionShare = double(kPoints / kRegions) / double(kPoints);
    if (full > 0) {
        std::printf(
            "{\"region_points_over_n\": %.4f, \"points_evaluated_fraction\": %.4f, "
            "\"local_miss_over_full\": %.4f, \"goal\": %.4f, \"met\": %s, \"whole_frame_miss_over_full\": "
            "%.4f}\n",
            regionShare, evaluated, local / full, regionShare + 0.10,
            local / full <= regionShare + 0.10 ? "true" : "false", whole / full);
    }
    return 0;
}
