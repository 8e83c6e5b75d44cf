// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <string_view>

namespace pmsc {

/// Section 5: a hit uses the point-multiplication result, a miss fails through
/// to the full calculation, a blend interpolates the two.
enum class CacheState : int { Hit = 0, Blend = 1, Miss = 2 };

std::string_view toString(CacheState state);

/// The decision for one frame. `weight` is the weight of the FULL result:
/// output = (1 - weight) * pm + weight * full. 0 for a hit, 1 for a miss.
struct CacheDecision {
    CacheState state = CacheState::Hit;
    double weight = 0;
};

/// The soft-cache transition zone [epsMin, epsMax] of section 5.
///
/// err <= epsMin: hit (weight 0, the full calculation is never run);
/// err >= epsMax: miss (weight 1, the PM result is not needed);
/// otherwise blend with weight (err - epsMin) / (epsMax - epsMin).
/// epsMin == epsMax gives a hard switch. A NaN or infinite error is a miss.
class SoftCachePolicy {
public:
    /// @throws std::invalid_argument unless 0 <= epsMin <= epsMax, both finite.
    SoftCachePolicy(double epsMin, double epsMax);
    /// Every frame a miss, whatever its key error (0 included): the full calculation of every
    /// frame through the same engine, for a viewer's "full" view or a reference run.
    static SoftCachePolicy alwaysMiss();

    CacheDecision decide(double keyError) const;
    double epsMin() const { return epsMin_; }
    double epsMax() const { return epsMax_; }

private:
    struct Unchecked {};
    SoftCachePolicy(double epsMin, double epsMax, Unchecked) : epsMin_(epsMin), epsMax_(epsMax) {}
    double epsMin_;
    double epsMax_;
};

}  // namespace pmsc
