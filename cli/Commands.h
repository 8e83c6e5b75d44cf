// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "app/ExitCodes.h"

#include <string>
#include <vector>

namespace pmsc::cli {

// The exit codes, the replay and the runs the command line shares with the Python module.
using namespace pmsc::app;

/// The subcommands of `pmsc`. Each takes the arguments after its name and returns
/// an exit code (app/ExitCodes.h); errors are thrown as the typed exceptions of
/// pmsc/Errors.h and turned into one stderr line and an exit code by main().
/// One declaration per command; main.cpp's table maps names to them (the demos register
/// their own commands: cli/CommandRegistry.h).
int runTrain(const std::vector<std::string>& args);         // cli/TrainCommand.cpp
int runReplay(const std::vector<std::string>& args);        // cli/ReplayCommand.cpp
int runInspect(const std::vector<std::string>& args);       // cli/InspectCommand.cpp
int runReconstruct(const std::vector<std::string>& args);   // cli/ReconstructCommand.cpp
int runLearn(const std::vector<std::string>& args);         // cli/LearnCommand.cpp
int runRun(const std::vector<std::string>& args);           // cli/RunCommand.cpp (render farm)
int runExportFrames(const std::vector<std::string>& args);  // cli/ExportFramesCommand.cpp
int runEvaluators(const std::vector<std::string>& args);    // cli/EvaluatorsCommand.cpp
int runServe(const std::vector<std::string>& args);         // cli/ServeCommand.cpp
int runView(const std::vector<std::string>& args);          // cli/ViewCommand.cpp (viewer/)

}  // namespace pmsc::cli
