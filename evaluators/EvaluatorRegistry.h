// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/PointEvaluator.h"

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace pmsc::evaluators {

/// Makes an evaluator from the ARGS part of a NAME[:ARGS] spec.
using EvaluatorFactory = std::function<std::unique_ptr<PointEvaluator>(const std::string& args)>;

/// One kind of evaluator a user can name ("replay:FILE.npy", "skin:ASSET", ...).
struct EvaluatorKind {
    std::string name;     ///< "replay", "skin", ...: no ':' and not empty
    std::string args;     ///< what ARGS means, for help ("FILE.npy"); empty if none
    std::string summary;  ///< one line for help
    EvaluatorFactory make;
};

/// Maps evaluator specs to evaluators. withBuiltins() holds every calculation pmsc ships; a
/// program that embeds pmsc may start from it, or from an empty registry, and add its own.
class EvaluatorRegistry {
public:
    /// An empty registry.
    EvaluatorRegistry() = default;
    /// Every calculation pmsc ships, in this order: replay, skin, synthetic, cornell, face,
    /// face-control, volume, exec (evaluators/Builtins.cpp).
    static EvaluatorRegistry withBuiltins();

    /// Adds a kind after the others. @throws std::invalid_argument for an empty name, a name
    /// containing ':', a name already registered, or no factory.
    void add(EvaluatorKind kind);
    /// Every kind, in the order they were added.
    const std::vector<EvaluatorKind>& kinds() const { return kinds_; }

    /// Makes the evaluator a spec names. The text after the first ':' goes to the factory
    /// unchanged (paths may contain ':').
    /// @throws std::invalid_argument for an unknown name (the known ones are listed);
    ///         whatever the factory throws (InputError for a missing file, ...).
    std::unique_ptr<PointEvaluator> make(const std::string& spec) const;

private:
    std::vector<EvaluatorKind> kinds_;
};

/// The registry the `pmsc` program and the Python module use: withBuiltins(), built once.
const EvaluatorRegistry& builtinRegistry();

/// builtinRegistry().make(spec): "replay:FILE.npy", "volume:FILE.vdb", "face:DIR", ...
/// @throws as EvaluatorRegistry::make.
std::unique_ptr<PointEvaluator> makeEvaluator(const std::string& spec);

/// For factories whose ARGS are required: returns `args`, or throws std::invalid_argument
/// ("evaluator 'NAME' needs WHAT: 'NAME:WHAT'") when it is empty.
std::string requireArgs(const std::string& name, const std::string& what, const std::string& args);

}  // namespace pmsc::evaluators
