// `pmsc evaluators`: every calculation the program accepts as --evaluator NAME[:ARGS].
#include "cli/Args.h"
#include "cli/Commands.h"
#include "evaluators/EvaluatorRegistry.h"

#include <algorithm>
#include <iostream>

namespace pmsc::cli {

namespace {

std::string evaluatorSyntax(const evaluators::EvaluatorKind& kind) {
    if (kind.args.empty()) return kind.name;
    // Optional arguments are written "[a=1][:b=2]" or "[a=1,b=2]": the ':' goes inside the brackets.
    if (kind.args.front() == '[') return kind.name + "[:" + kind.args.substr(1);
    return kind.name + ":" + kind.args;
}

}  // namespace

int runEvaluators(const std::vector<std::string>& args) {
    ArgParser parser("evaluators", "",
                     "Lists every evaluator the program accepts (pmsc run --evaluator, pmsc export-frames),\n"
                     "one per line: its name, its NAME[:ARGS] syntax, and what it calculates. Python's\n"
                     "pmsc.evaluators() returns the same names.");
    if (!parser.parse(args)) return kExitOk;
    const auto& kinds = evaluators::builtinRegistry().kinds();
    std::size_t nameWidth = 0, syntaxWidth = 0;
    for (const auto& kind : kinds) {
        nameWidth = std::max(nameWidth, kind.name.size());
        syntaxWidth = std::max(syntaxWidth, evaluatorSyntax(kind).size());
    }
    for (const auto& kind : kinds) {
        const std::string syntax = evaluatorSyntax(kind);
        std::cout << kind.name << std::string(nameWidth + 2 - kind.name.size(), ' ') << syntax
                  << std::string(syntaxWidth + 2 - syntax.size(), ' ') << kind.summary << "\n";
    }
    return kExitOk;
}

}  // namespace pmsc::cli
