// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace pmsc::cli {

/// A subcommand of `pmsc`: its name (one or more words: "train", "demo cornell"), the line
/// `pmsc --help` shows, and what runs it (the arguments after the name; an exit code back).
struct Command {
    std::string_view name;
    std::string_view summary;
    int (*run)(const std::vector<std::string>& args);
};

/// Commands added to `pmsc` from above the product. Decision: the demos (examples/commands) register
/// their `pmsc demo ...` commands themselves, with a CommandRegistration at namespace scope linked
/// into the program as object files, so the command line below them never names them and the
/// dependencies point one way (examples/ -> cli/ -> app/ ...).
const std::vector<Command>& registeredCommands();

/// Registers `command` at static initialisation: `const CommandRegistration r{{"demo x", "...", run}};`
struct CommandRegistration {
    explicit CommandRegistration(const Command& command);
};

}  // namespace pmsc::cli
