// `pmsc serve SPEC`: any evaluator pmsc can make, served over the exec protocol on standard input
// and output, so another pmsc (`exec:pmsc serve SPEC`) runs it in a process of its own: an asset
// that crashes its importer then fails one request, not the run.
#include "cli/Args.h"
#include "cli/Commands.h"
#include "evaluators/EvaluatorRegistry.h"
#include "evaluators/exec/ExecProtocol.h"

#include <unistd.h>

namespace pmsc::cli {

int runServe(const std::vector<std::string>& args) {
    std::string spec;
    ArgParser parser("serve", "SPEC",
                     "Serves the evaluator SPEC (any of `pmsc evaluators`) over the exec protocol\n"
                     "(docs/exec-protocol.md) on standard input and output until standard input ends:\n"
                     "the child side of `--evaluator 'exec:pmsc serve SPEC'`. Messages go to stderr.");
    parser.positional("SPEC", "evaluator spec, e.g. synthetic:grid=400 or skin:ASSET", spec);
    if (!parser.parse(args)) return kExitOk;
    const auto evaluator = evaluators::makeEvaluator(spec);
    return evaluators::exec::serve(*evaluator, STDIN_FILENO, STDOUT_FILENO) == 0 ? kExitOk : kExitIo;
}

}  // namespace pmsc::cli
