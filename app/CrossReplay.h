// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Model.h"
#include "pmsc/NpyIO.h"
#include "pmsc/PointEvaluator.h"

#include <nlohmann/json.hpp>

#include <atomic>
#include <functional>
#include <ostream>
#include <vector>

namespace pmsc::app {

/// One frame of a cross point-multiplication replay (pmsc/Cross.h).
struct CrossFrame {
    Index frame = 0;
    double keyRms = 0;  ///< the control's key RMS error (data units)
    double bound = 0;   ///< learned bound on the target's largest point error (CrossState::bound)
    /// The target's largest point error against the true targets (`--targets`); -1 when not given.
    double targetMaxError = -1;
};

struct CrossReplayResult {
    std::vector<CrossFrame> frames;  ///< in frame order
    double seconds = 0;              ///< wall time of the per-frame loop
    int threads = 0;
    bool measured = false;  ///< true targets were given
};

struct CrossReplayOptions {
    int threads = 0;  ///< 0: every core
    const std::atomic<bool>* cancel = nullptr;
    std::function<void(Index, Index)> progress;
};

/// Every frame of `control` through the cross model: its key points are read, projected, and the
/// target reconstructed (written to `out` when given, targetPoints x C). `truth`, when given,
/// holds the true targets (the model's target point count) and each frame's error is measured.
/// Output and rows do not depend on the thread count.
/// @pre control's N is the model's control point count and its C the model's (checked by the caller).
CrossReplayResult crossReplay(const Model& model, const PointEvaluator& control, const PointEvaluator* truth,
                              const CrossReplayOptions& options, NpyFrameWriter* out);

/// REPORT.json of a cross replay: "summary" (fail-through impossible, the bound's rule and
/// coverage, key RMS and bound percentiles, and with --targets the error percentiles and the
/// fraction of frames inside their bound) and one row per frame.
nlohmann::ordered_json crossReplayReport(const Model& model, const CrossReplayResult& result);

/// The per-frame columns and counts both the report and the printed summary are made of.
struct CrossTally {
    std::vector<double> key, bound, error;  ///< error only when the targets were measured
    Index inside = 0, overTolerance = 0;    ///< frames inside their bound; bounds over the tolerance
};
CrossTally tally(const Model& model, const CrossReplayResult& result);

}  // namespace pmsc::app
