// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Model.h"
#include "pmsc/PointEvaluator.h"

#include <nlohmann/json.hpp>

#include <functional>
#include <string>
#include <vector>

namespace pmsc::face {

/// Local fail-through (issue 9) on one set of frames, measured both ways against the full pose:
/// - errors: the engine with local fail-through (every core), each output against a full pose:
///   largest point error per frame (% of the head diagonal), local frames, fraction of points
///   evaluated fully (mean over the set's frames and over its non-hit frames);
/// - speed: the same frames at ONE thread through the engine with local fail-through, with
///   whole-frame fail-through (`--whole-frame-fail-through`), and full poses (evaluateAll), all in
///   this run: seconds per frame and speedups over full posing.
/// @param percent model units per % of the head diagonal
nlohmann::json localFailThroughReport(const Model& model, const PointEvaluator& evaluator,
                                      const std::vector<Index>& frames, double percent, int threads,
                                      const std::function<void(double done)>& progress = {});

}  // namespace pmsc::face
