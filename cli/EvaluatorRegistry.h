// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/EvaluatorRegistry.h"

#include <memory>
#include <string>
#include <vector>

namespace pmsc::cli {

using evaluators::EvaluatorKind;

/// The evaluators the `pmsc` program knows: the library's built-ins (replay, skin) and the
/// paper's demos (cornell, face), in that order.
const evaluators::EvaluatorRegistry& evaluatorRegistry();

/// evaluatorRegistry().kinds().
const std::vector<EvaluatorKind>& evaluatorKinds();

/// evaluatorRegistry().make(spec): "replay:FILE.npy", "cornell", "face:DIR", "skin:ASSET".
/// @throws std::invalid_argument for an unknown name (the known ones are listed);
///         whatever the factory throws (InputError for a missing file, ...).
std::unique_ptr<PointEvaluator> makeEvaluator(const std::string& spec);

}  // namespace pmsc::cli
