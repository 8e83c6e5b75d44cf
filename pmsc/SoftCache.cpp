#include "pmsc/SoftCache.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace pmsc {

std::string_view toString(CacheState state) {
    switch (state) {
        case CacheState::Hit:
            return "hit";
        case CacheState::Blend:
            return "blend";
        case CacheState::Miss:
            return "miss";
    }
    return "unknown";
}

SoftCachePolicy::SoftCachePolicy(double epsMin, double epsMax) : epsMin_(epsMin), epsMax_(epsMax) {
    if (!std::isfinite(epsMin) || !std::isfinite(epsMax) || epsMin < 0 || epsMax < epsMin) {
        throw std::invalid_argument("soft cache: need 0 <= eps_min <= eps_max, both finite; got [" +
                                    std::to_string(epsMin) + ", " + std::to_string(epsMax) + "]");
    }
}

SoftCachePolicy SoftCachePolicy::alwaysMiss() {
    // Below every key error: "err <= epsMin" never holds and "err >= epsMax" always does.
    return SoftCachePolicy(-1.0, -1.0, Unchecked{});
}

CacheDecision SoftCachePolicy::decide(double keyError) const {
    // A non-finite key error means the key values themselves are broken (or the projection
    // blew up): the PM result cannot be trusted, so fail through entirely.
    if (!std::isfinite(keyError)) return {CacheState::Miss, 1.0};
    if (keyError <= epsMin_) return {CacheState::Hit, 0.0};
    // Checked after the hit test so that epsMin == epsMax is a hard switch at that value.
    if (keyError >= epsMax_) return {CacheState::Miss, 1.0};
    // Strictly inside (epsMin, epsMax), so epsMax > epsMin and the weight is in (0, 1).
    const double w = (keyError - epsMin_) / (epsMax_ - epsMin_);
    return {CacheState::Blend, w};
}

double guardedWeight(double weight, double pointError, double tolerance) {
    if (!(tolerance > 0) || !(pointError > tolerance)) return weight;
    // A hair under T, so that rounding in (1 - w') pm + w' full cannot carry the point over it.
    constexpr double kUnder = 1.0 - 1e-9;
    return std::max(weight, 1.0 - kUnder * tolerance / pointError);
}

double blendedError(double weight, double pmError, double tolerance) {
    return (1.0 - guardedWeight(weight, pmError, tolerance)) * pmError;
}

void blendPoints(double weight, double tolerance, Index channels, const double* pm, const double* full,
                 double* out, Index points) {
    for (Index p = 0; p < points; ++p) {
        const Index row = p * channels;
        double squared = 0;
        for (Index c = 0; c < channels; ++c) {
            const double d = pm[row + c] - full[row + c];
            squared += d * d;
        }
        const double w = guardedWeight(weight, std::sqrt(squared), tolerance);
        for (Index c = 0; c < channels; ++c) out[row + c] = (1.0 - w) * pm[row + c] + w * full[row + c];
    }
}

}  // namespace pmsc
