#include "cli/CommandRegistry.h"

namespace pmsc::cli {

namespace {

/// Function-local, so it exists before any registration runs whatever the order of static
/// initialisation across object files.
std::vector<Command>& registry() {
    static std::vector<Command> commands;
    return commands;
}

}  // namespace

const std::vector<Command>& registeredCommands() { return registry(); }

CommandRegistration::CommandRegistration(const Command& command) { registry().push_back(command); }

}  // namespace pmsc::cli
