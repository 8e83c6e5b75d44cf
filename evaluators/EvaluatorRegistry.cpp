#include "evaluators/EvaluatorRegistry.h"

#include <stdexcept>

namespace pmsc::evaluators {

std::string requireArgs(const std::string& name, const std::string& what, const std::string& args) {
    if (args.empty())
        throw std::invalid_argument("evaluator '" + name + "' needs " + what + ": '" + name + ":" + what +
                                    "'");
    return args;
}

void EvaluatorRegistry::add(EvaluatorKind kind) {
    if (kind.name.empty() || kind.name.find(':') != std::string::npos)
        throw std::invalid_argument("evaluator kind name '" + kind.name +
                                    "' must be non-empty and contain no ':'");
    if (!kind.make) throw std::invalid_argument("evaluator kind '" + kind.name + "' has no factory");
    for (const auto& k : kinds_)
        if (k.name == kind.name)
            throw std::invalid_argument("evaluator kind '" + kind.name + "' is already registered");
    kinds_.push_back(std::move(kind));
}

std::unique_ptr<PointEvaluator> EvaluatorRegistry::make(const std::string& spec) const {
    const auto colon = spec.find(':');
    const std::string name = spec.substr(0, colon);
    const std::string args = colon == std::string::npos ? std::string() : spec.substr(colon + 1);
    std::string known;
    for (const auto& kind : kinds_) {
        if (kind.name == name) return kind.make(args);
        known += (known.empty() ? "" : ", ") + kind.name;
    }
    throw std::invalid_argument("unknown evaluator '" + name + "' (known: " + known + ")");
}

}  // namespace pmsc::evaluators
