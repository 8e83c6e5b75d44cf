// The Cornell gather's training frames, a set of lights per call against one light per call.
// A point's gather rays do not depend on the light, so CornellEvaluator::evaluateAllFrames traces
// them once for the set and shades each light from them (the same values, bit for bit).
//
//   build/bin/pmsc_cornell_bench --benchmark_counters_tabular=true
//
// BM_FramesTogetherVersusAlone: the evaluator's framesSharingWork() (12) training lights, all
// points at the demo's 160 samples, 20,000 points, every core: together_ms, alone_ms and
// together_over_alone (the demo's training gathers take that share of their one-light-a-call time).
#include "TimeAlternately.h"
#include "evaluators/cornell/CornellEvaluator.h"

#include <benchmark/benchmark.h>

#include <numeric>
#include <vector>

namespace {

using namespace pmsc;
using namespace pmsc::cornell;

void BM_FramesTogetherVersusAlone(benchmark::State& state) {
    static const CornellEvaluator ev(CornellWorld::create(20000), LightRig{}.trainingLights(), 160);
    std::vector<Index> frames(static_cast<std::size_t>(ev.framesSharingWork()));
    std::iota(frames.begin(), frames.end(), Index{60});
    const std::size_t frameValues = static_cast<std::size_t>(ev.pointCount() * ev.channelCount());
    std::vector<double> together(frames.size() * frameValues), alone(together.size());
    bench::timeAlternately(
        state, "together", [&] { ev.evaluateAllFrames(frames, together.data()); }, "alone",
        [&] {
            for (std::size_t k = 0; k < frames.size(); ++k)
                ev.evaluateAll(frames[k], alone.data() + k * frameValues);
        });
    state.counters["frames"] = static_cast<double>(frames.size());
    if (together != alone) state.SkipWithError("frames together differ from frames alone");
}
BENCHMARK(BM_FramesTogetherVersusAlone)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
