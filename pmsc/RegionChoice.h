// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/MeanShape.h"  // rmsMotion, the mean as a shape (rule 2)
#include "pmsc/Model.h"
#include "pmsc/RegionLearning.h"

#include <string>

namespace pmsc {

/// Share of the points a motion of the training data moves: for each of the rotated factors
/// (rotatedLoadings), the fewest points holding 90% of its energy, as a share of N, averaged over
/// the factors weighted by their energy. A face, whose motions each move a part (a lip, a brow,
/// the jaw), is local; a calculation where every control moves every point (light in a room, a
/// surface deformed whole) is not. In [0, 1].
double basisSupport(const Model& model);

/// The regions `pmsc train` learns when not told (RegionOptions::automatic), and why.
struct RegionChoice {
    Index count = 0;             ///< regions to learn; 0: the model stays whole (version 1)
    double featherFraction = 0;  ///< feather width for `count` regions, fraction of the diagonal
    double support = 1;          ///< basisSupport() of the model (1 when not measured)
    std::string reason;          ///< one line for the training summary: the figures and the decision
};

/// The rule (docs/local-fail-through.md, "Regions by default"), in order:
///  1. no tolerance: no regions (region thresholds from the training frames' key RMS route no
///     novel frame locally: every region of a novel frame misses);
///  2. no positions: none given, and the training mean is not a shape (not 3 channels, or the
///     frames' RMS motion `rmsMotion` is over kMostMotion of the mean's bounding-box diagonal:
///     light, not points moving): no regions;
///  3. basisSupport() above kMostSupport: no regions (the data pose whole: a local miss would
///     evaluate most of the points anyway, and a whole miss costs one evaluation, not many);
///  4. R = N / kPointsPerRegion, capped at kMostRegions; fewer than kFewestRegions: no regions;
///  5. feather width kFeatherTimesSqrtR / sqrt(R) of the diagonal (a region of a surface cut in
///     R is about diagonal / sqrt(R) across: the band is a fixed share of a region's width).
RegionChoice chooseRegions(const Model& model, const RegionOptions& options, double tolerance,
                           double rmsMotion);

}  // namespace pmsc
