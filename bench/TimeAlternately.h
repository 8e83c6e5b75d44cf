// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <benchmark/benchmark.h>

#include <chrono>
#include <string>

namespace pmsc::bench {

/// Runs `a` then `b` in every iteration and sets the counters NAME_A_ms, NAME_B_ms and
/// NAME_A_over_NAME_B: two ways of the same work timed side by side in one run, so the ratio does
/// not depend on how busy the machine was.
template <class A, class B>
void timeAlternately(benchmark::State& state, const std::string& nameA, A&& a, const std::string& nameB,
                     B&& b) {
    double secondsA = 0, secondsB = 0;
    using Clock = std::chrono::steady_clock;
    for (auto _ : state) {
        const auto t0 = Clock::now();
        a();
        const auto t1 = Clock::now();
        b();
        const auto t2 = Clock::now();
        secondsA += std::chrono::duration<double>(t1 - t0).count();
        secondsB += std::chrono::duration<double>(t2 - t1).count();
    }
    const double iterations = static_cast<double>(state.iterations());
    state.counters[nameA + "_ms"] = 1e3 * secondsA / iterations;
    state.counters[nameB + "_ms"] = 1e3 * secondsB / iterations;
    state.counters[nameA + "_over_" + nameB] = secondsA / secondsB;
}

}  // namespace pmsc::bench
