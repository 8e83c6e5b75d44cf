// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/PointEvaluator.h"

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace pmsc::cli {

/// Makes an evaluator from the ARGS part of a NAME[:ARGS] spec.
using EvaluatorFactory = std::function<std::unique_ptr<PointEvaluator>(const std::string& args)>;

/// One kind of evaluator the command line knows.
struct EvaluatorKind {
    std::string name;     ///< "replay", "cornell", "face", "skin"
    std::string args;     ///< what ARGS means, for help ("FILE.npy"); empty if none
    std::string summary;  ///< one line for help
    EvaluatorFactory make;
};

/// Every registered kind, in the order of the table in EvaluatorRegistry.cpp.
const std::vector<EvaluatorKind>& evaluatorKinds();

/// Makes the evaluator a spec names: "replay:FILE.npy", "cornell", "face:DIR", "skin:ASSET".
/// The text after the first ':' goes to the factory unchanged (paths may contain ':').
/// @throws std::invalid_argument for an unknown name (the known ones are listed);
///         whatever the factory throws (InputError for a missing file, ...).
std::unique_ptr<PointEvaluator> makeEvaluator(const std::string& spec);

}  // namespace pmsc::cli
