// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

// The error measures every report of the project shares (`pmsc replay`, the face and
// learning demos), so one percentile means the same thing in each.

#include "pmsc/FrameSet.h"  // Index

#include <vector>

namespace pmsc {

/// Largest Euclidean distance between the same point of two frames (N points x C channels,
/// point-major, channel-minor): the paper's "largest point error" of a reconstruction.
/// @param[out] where if not null, the point where it is reached (0 when every distance is 0).
double maxPointError(const double* a, const double* b, Index points, Index channels = 3,
                     Index* where = nullptr);

/// The q-percentile (q in [0, 1]) of a sample, by nearest rank: the ceil(q n)-th smallest of the
/// n values (the smallest for q = 0, the largest for q = 1); 0 for an empty sample.
///
/// Decision: nearest rank, not NumPy's default linear interpolation. Every percentile
/// pmsc reports is of per-frame largest point errors, read as "99.5% of the frames were at or under
/// this"; with nearest rank that sentence is exactly true and the value is one a frame really had,
/// while an interpolated value can lie between two frames' errors and cover a fraction of frames
/// other than the one it names. It is also the rank statistic the calibration's conformal quantile
/// uses (Calibration.h). `pmsc replay` used the interpolated definition and the face demo nearest
/// rank, so the same frames gave two different p99.5 values.
double percentile(std::vector<double> values, double q);

/// p50, p99, p99.5 (percentile()) and the largest value of a sample; zeros for an empty one.
struct Percentiles {
    double p50 = 0, p99 = 0, p995 = 0, max = 0;
};
Percentiles percentiles(std::vector<double> values);

}  // namespace pmsc
