// pmsc — the command line of Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// main() only dispatches: it finds the subcommand in the table below, runs it, and turns every
// typed error into ONE line on stderr and an exit code (app/ExitCodes.h).
#include "app/ExitCodes.h"
#include "cli/CommandRegistry.h"
#include "cli/Commands.h"
#include "cli/Interrupt.h"
#include "pmsc/Errors.h"
#include "pmsc/Training.h"  // pmsc::Cancelled

#include <algorithm>
#include <cstdio>
#include <exception>
#include <iostream>
#include <iterator>
#include <new>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

namespace {

using namespace pmsc::cli;

// The product's commands. Add a row per subcommand; a multi-word name ("demo cornell") wins over
// its shorter prefix ("demo"). One line per row. The demos register theirs (registeredCommands()).
// clang-format off
const Command kCommands[] = {
    {"train", "train a model (basis, key points, thresholds) from frames in a .npy file", runTrain},
    {"learn", "update a model with new frames (e.g. kept misses) without its training frames", runLearn},
    {"replay", "replay recorded frames through a model's soft cache and report its errors", runReplay},
    {"reconstruct", "drive the soft cache pass by pass through files, for a renderer that bakes the points asked", runReconstruct},
    {"inspect", "show a model file: sizes, key points, basis energy, thresholds", runInspect},
    {"run", "render-farm task: a frame range through the soft cache, one resumable file per frame", runRun},
    {"export-frames", "write an evaluator's frames (e.g. an animated asset's poses) as training .npy", runExportFrames},
    {"evaluators", "list the calculations --evaluator accepts, with their NAME[:ARGS] syntax", runEvaluators},
    {"serve", "serve an evaluator over the exec protocol on stdin/stdout (the child of exec:pmsc serve SPEC)", runServe},
    {"view", "relight a scene interactively in a browser (volume or Cornell box; one viewer)", runView},
};
// clang-format on

std::vector<std::string_view> words(std::string_view s) {
    std::vector<std::string_view> out;
    while (!s.empty()) {
        const auto space = s.find(' ');
        out.push_back(s.substr(0, space));
        if (space == std::string_view::npos) break;
        s.remove_prefix(space + 1);
    }
    return out;
}

/// Every command: the table's, then the registered ones by name.
std::vector<Command> allCommands() {
    std::vector<Command> all(std::begin(kCommands), std::end(kCommands));
    std::vector<Command> registered = registeredCommands();
    std::sort(registered.begin(), registered.end(),
              [](const Command& a, const Command& b) { return a.name < b.name; });
    all.insert(all.end(), registered.begin(), registered.end());
    return all;
}

/// The longest command name whose words start the arguments, or nullptr.
std::optional<Command> findCommand(const std::vector<std::string>& args, std::size_t& used) {
    std::optional<Command> best;
    used = 0;
    for (const auto& command : allCommands()) {
        const auto w = words(command.name);
        if (w.size() > args.size() || w.size() <= used) continue;
        bool match = true;
        for (std::size_t i = 0; i < w.size(); ++i) match = match && args[i] == w[i];
        if (match) {
            best = command;
            used = w.size();
        }
    }
    return best;
}

std::string usage() {
    std::ostringstream out;
    out << "usage: pmsc <command> [options]   (pmsc <command> --help for its options)\n\n"
           "Point multiplication and soft caching (Meyer & Anderson, Pixar): a statistical\n"
           "model computes all points of a frame from a few key points, and falls through to\n"
           "the full calculation when the key points say the model does not fit.\n\ncommands:\n";
    for (const auto& c : allCommands()) {
        std::string name(c.name);
        out << "  " << name << std::string(name.size() < 16 ? 16 - name.size() : 1, ' ') << c.summary << "\n";
    }
    out << "\nexit codes: 0 ok, 1 internal error, 2 bad input, 3 evaluator failure, 4 cannot write output,\n"
           "130 interrupted\n";
    return out.str();
}

/// Prints "pmsc: <message>" as one line, whatever the message holds.
int fail(int code, std::string message) {
    for (char& ch : message)
        if (ch == '\n' || ch == '\r') ch = ' ';
    std::cout.flush();
    std::fprintf(stderr, "pmsc: %s\n", message.c_str());
    return code;
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<std::string> args(argv + 1, argv + argc);
    if (args.empty()) {
        std::cerr << usage();
        return kExitBadInput;
    }
    if (args[0] == "--help" || args[0] == "-h" || args[0] == "help") {
        std::cout << usage();
        return kExitOk;
    }
    std::size_t used = 0;
    const std::optional<Command> command = findCommand(args, used);
    if (!command) return fail(kExitBadInput, "unknown command '" + args[0] + "' (see 'pmsc --help')");
    args.erase(args.begin(), args.begin() + static_cast<std::ptrdiff_t>(used));

    installInterruptHandler();
    try {
        // A signal that arrives after the command finished its outputs changes nothing: the
        // outputs are complete, so the command's own code stands.
        return command->run(args);
    } catch (...) {
        const ExitReason reason = exitReason(std::current_exception());
        return fail(reason.code, reason.message);
    }
}
