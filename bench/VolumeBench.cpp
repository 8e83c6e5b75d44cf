// The volume evaluator's cost per voxel is linear in the voxels asked for, so a hit
// (the key voxels only) costs K/N of a full frame. Smoke of 60,000 voxels from the demo's mesh,
// one thread (serial evaluate(), as the engine calls it per key set or chunk), the demo's settings.
//
//   build/bin/pmsc_volume_bench --benchmark_counters_tabular=true
//
// BM_VolumeEvaluate/COUNT: COUNT random voxels per call; ns_per_voxel should be flat in COUNT.
// BM_ReconstructSharedVsSeparate: see below.
// BM_KeysVersusAll: 200 random voxels and all voxels in the same iteration; linearity =
// (keys time / K) / (all time / N), which should be 1 within 20% (keys cost K/N of all voxels).
#include "TimeAlternately.h"
#include "evaluators/volume/VolumeEvaluator.h"
#include "pmsc/PointMultiplier.h"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <numeric>
#include <random>

namespace {

using pmsc::bench::timeAlternately;

using namespace pmsc;
using namespace pmsc::volume;

struct Scene {
    std::shared_ptr<const VolumeWorld> world;
    std::unique_ptr<VolumeEvaluator> eval;
    std::vector<Index> shuffled;
};

const Scene& scene() {
    static const Scene s = [] {
        Scene s;
        FogOptions fog;
        fog.targetVoxels = 60000;
        s.world = VolumeWorld::create(
            DensityVolume::fromMesh(std::string(PMSC_ASSIMP_MODELS_DIR) + "/OBJ/WusonOBJ.obj", fog),
            MediumSettings{}, "bench");
        const VolumeRig rig;
        s.eval = std::make_unique<VolumeEvaluator>(s.world, rig.path(*s.world, 8));
        s.shuffled.resize(s.world->density.voxelCount());
        std::iota(s.shuffled.begin(), s.shuffled.end(), Index{0});
        std::mt19937 rng(7);
        std::shuffle(s.shuffled.begin(), s.shuffled.end(), rng);
        return s;
    }();
    return s;
}

void BM_VolumeEvaluate(benchmark::State& state) {
    const Scene& s = scene();
    const std::size_t count =
        state.range(0) > 0 ? static_cast<std::size_t>(state.range(0)) : s.shuffled.size();
    std::vector<Index> points(s.shuffled.begin(), s.shuffled.begin() + static_cast<std::ptrdiff_t>(count));
    std::sort(points.begin(), points.end());
    std::vector<double> out(3 * count);
    Index frame = 0;
    for (auto _ : state) {
        s.eval->evaluate(frame, points, out.data());
        benchmark::DoNotOptimize(out.data());
        frame = (frame + 1) % s.eval->frameCount();
    }
    state.counters["voxels"] = static_cast<double>(count);
    state.counters["ns_per_voxel"] =
        benchmark::Counter(static_cast<double>(state.iterations() * count),
                           benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_VolumeEvaluate)->Arg(200)->Arg(2000)->Arg(20000)->Arg(0)->Unit(benchmark::kMillisecond);

void BM_KeysVersusAll(benchmark::State& state) {
    const Scene& s = scene();
    const std::size_t k = 200, n = s.shuffled.size();
    std::vector<Index> keys(s.shuffled.begin(), s.shuffled.begin() + static_cast<std::ptrdiff_t>(k)), all(n);
    std::sort(keys.begin(), keys.end());
    std::iota(all.begin(), all.end(), Index{0});
    std::vector<double> out(3 * n);
    double keySeconds = 0, allSeconds = 0;
    Index frame = 0;
    using Clock = std::chrono::steady_clock;
    for (auto _ : state) {
        auto t0 = Clock::now();
        for (int r = 0; r < 20; ++r) s.eval->evaluate(frame, keys, out.data());  // 20 x K, a measurable time
        auto t1 = Clock::now();
        s.eval->evaluate(frame, all, out.data());
        auto t2 = Clock::now();
        keySeconds += std::chrono::duration<double>(t1 - t0).count() / 20;
        allSeconds += std::chrono::duration<double>(t2 - t1).count();
        benchmark::DoNotOptimize(out.data());
        frame = (frame + 1) % s.eval->frameCount();
    }
    state.counters["K"] = static_cast<double>(k);
    state.counters["N"] = static_cast<double>(n);
    state.counters["keys_over_all"] = keySeconds / allSeconds;
    state.counters["K_over_N"] = static_cast<double>(k) / static_cast<double>(n);
    state.counters["linearity"] =
        (keySeconds / static_cast<double>(k)) / (allSeconds / static_cast<double>(n));
}
BENCHMARK(BM_KeysVersusAll)->Unit(benchmark::kMillisecond)->Iterations(8);

// BM_ReconstructSharedVsSeparate/M: point multiplication's reconstruction of every voxel of the
// default demo's size (254,000 voxels, C = 3) from a model whose channels share the basis
// (N x M) and from one with a basis over (voxel, channel) rows ((N*3) x M), alternately in each
// iteration; shared_over_separate = the ratio of their times (the shared basis reads a third of
// the bytes). Random, not orthonormal, bases: the cost does not depend on the values.
Model reconstructionModel(Index n, Index m, bool shared) {
    Model model;
    model.points = n;
    model.channels = 3;
    model.trainFrames = 2;
    model.sharedChannels = shared;
    model.basis = Eigen::MatrixXd::Random(shared ? n : 3 * n, m);
    model.mean = Eigen::VectorXd::Random(3 * n);
    model.singularValues = Eigen::VectorXd::Ones(m);
    model.totalEnergy = 2.0 * static_cast<double>(m);
    for (Index k = 0; k < 2 * m; ++k) model.keyPoints.push_back(k * (n / (2 * m)));
    model.projector = makeProjector(model.basis, model.basisChannels(), model.keyPoints);
    return model;
}

void BM_ReconstructSharedVsSeparate(benchmark::State& state) {
    const Index n = 254000, m = state.range(0);
    const Model shared = reconstructionModel(n, m, true), separate = reconstructionModel(n, m, false);
    const PointMultiplier pmShared(shared), pmSeparate(separate);
    std::vector<double> coordsShared(static_cast<std::size_t>(shared.coordCount()), 0.1),
        coordsSeparate(static_cast<std::size_t>(separate.coordCount()), 0.1),
        out(static_cast<std::size_t>(3 * n));
    timeAlternately(
        state, "shared",
        [&] {
            pmShared.reconstruct(coordsShared.data(), out.data());
            benchmark::DoNotOptimize(out.data());
        },
        "separate",
        [&] {
            pmSeparate.reconstruct(coordsSeparate.data(), out.data());
            benchmark::DoNotOptimize(out.data());
        });
}
BENCHMARK(BM_ReconstructSharedVsSeparate)->Arg(40)->Arg(64)->Unit(benchmark::kMillisecond)->Iterations(30);

// BM_ReconstructSingleVsDouble/M: the same reconstruction (shared channels, 254,000 voxels) from
// the basis in float (BasisPrecision::Single, what `pmsc view` uses) and in double, alternately;
// single_over_double = the ratio of their times (the float basis is half the bytes).
void BM_ReconstructSingleVsDouble(benchmark::State& state) {
    const Index n = 254000, m = state.range(0);
    const Model model = reconstructionModel(n, m, true);
    const PointMultiplier single(model, BasisPrecision::Single), dbl(model, BasisPrecision::Double);
    std::vector<double> coords(static_cast<std::size_t>(model.coordCount()), 0.1),
        out(static_cast<std::size_t>(3 * n));
    timeAlternately(
        state, "single",
        [&] {
            single.reconstruct(coords.data(), out.data());
            benchmark::DoNotOptimize(out.data());
        },
        "double",
        [&] {
            dbl.reconstruct(coords.data(), out.data());
            benchmark::DoNotOptimize(out.data());
        });
}
BENCHMARK(BM_ReconstructSingleVsDouble)->Arg(40)->Arg(64)->Unit(benchmark::kMillisecond)->Iterations(30);

}  // namespace

BENCHMARK_MAIN();
