// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <array>
#include <cmath>
#include <random>

namespace pmsc::synthetic {

/// A smooth random signal of time in [-1, 1]: a sum of three sinusoids with
/// random periods (between minPeriod and maxPeriod frames) and phases, scaled by
/// the sum of their amplitudes. Animation curves for the generators: smooth in
/// time like real animation, reproducible from a seed, and cheap to evaluate
/// at any frame independently (so evaluators stay thread-safe and per-frame).
class SmoothNoise {
public:
    SmoothNoise() = default;
    SmoothNoise(std::mt19937_64& rng, double minPeriod, double maxPeriod) {
        std::uniform_real_distribution<double> period(minPeriod, maxPeriod), phase(0, 2 * M_PI),
            amp(0.3, 1.0);
        double sum = 0;
        for (auto& w : waves_) {
            w = {2 * M_PI / period(rng), phase(rng), amp(rng)};
            sum += w.amplitude;
        }
        for (auto& w : waves_) w.amplitude /= sum;
    }

    double operator()(double t) const {
        double v = 0;
        for (const auto& w : waves_) v += w.amplitude * std::sin(w.omega * t + w.phase);
        return v;
    }

private:
    struct Wave {
        double omega = 0, phase = 0, amplitude = 0;
    };
    std::array<Wave, 3> waves_{};
};

}  // namespace pmsc::synthetic
