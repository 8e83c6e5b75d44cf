// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/FaceAnimation.h"
#include "pmsc/Model.h"
#include "pmsc/PointEvaluator.h"

#include <nlohmann/json.hpp>

#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace pmsc::face {

/// The face demo's section "local_fail_through" of report.json: regions, feather width, and
/// examples::localFailThroughReport() (errors in % of the head diagonal, frames over 1%) on three sets:
/// "validation" (the first 4 validation sequences: a sample, every frame of it through the engine twice and
/// posed fully three times), "novel" (the novel sequences) and "mixed" (the animation's mixed sequences:
/// novel controls for 1-3 s of a 5-8 s shot; absent when it has none).
/// @param step progress hook (stage, done, total) that may throw to cancel
/// @param maxFramesPerSet > 0: only the first frames of each set (`--quick`: a smoke test)
nlohmann::json localFailThroughSets(const Model& model, const PointEvaluator& evaluator,
                                    const FaceAnimation& animation, const std::vector<Index>& validationSeqs,
                                    const std::vector<Index>& novelSeqs, double percent, int threads,
                                    const std::function<void(std::string_view, double, double)>& step,
                                    Index maxFramesPerSet = 0);

}  // namespace pmsc::face
