// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"  // Index

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

/// The weight of the full result at one point of a blend whose full value is known: the frame's
/// (or the point's feathered) weight w, raised where the point multiplication is further than
/// `tolerance` T from the full value, so that the blended point is within T of it:
///   w' = max(w, 1 - T / e), e = |pm - full| (Euclidean over the point's channels).
/// Why: the key error decides the weight from calibrated bounds, and a frame that moves what
/// training never moved can break them (docs/calibration.md, the novelty suite); a blend has the
/// full value in hand, so its error is known, not estimated, and the promise can be kept exactly
/// where the full calculation ran. Continuous in w and e (no popping). w itself when T <= 0 (an
/// uncalibrated model) or e <= T. Only blends need it: a hit computes no full value and a miss
/// hands the full value back.
double guardedWeight(double weight, double pointError, double tolerance);

/// The largest point error of a blend whose point multiplication's largest point error is
/// `pmError`: (1 - w') pmError with w' = guardedWeight(weight, pmError, tolerance); at most the
/// tolerance (when there is one) whatever the weight. (1 - w'(e)) e grows with e, so the point with
/// PM's largest error keeps the largest blended error.
double blendedError(double weight, double pmError, double tolerance);

/// `points` points of `channels` values: out = (1 - w') pm + w' full with w' = guardedWeight(weight,
/// |pm - full| at the point, tolerance). `out` may be `pm` or `full`. The one blend expression of
/// the engine, `pmsc replay` and the C API, so each gives the same bits.
void blendPoints(double weight, double tolerance, Index channels, const double* pm, const double* full,
                 double* out, Index points);

}  // namespace pmsc
