// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <string>
#include <vector>

namespace pmsc::demos {

/// The `pmsc demo ...` commands. Each file registers its own with the command line
/// (cli/CommandRegistry.h); `pmsc demo` without options runs runDemoCornell.
int runDemo(const std::vector<std::string>& args);           // DemoCommand.cpp
int runDemoSynthetic(const std::vector<std::string>& args);  // DemoCommand.cpp (evaluators/synthetic)
int runDemoCornell(const std::vector<std::string>& args);    // CornellDemoCommand.cpp (examples/cornell)
int runDemoVolume(const std::vector<std::string>& args);     // VolumeDemoCommand.cpp (examples/volume)
int runDemoFace(const std::vector<std::string>& args);       // FaceDemoCommand.cpp (examples/face)
int runDemoCross(const std::vector<std::string>& args);      // CrossDemoCommand.cpp (examples/face)
int runDemoLearn(const std::vector<std::string>& args);      // LearnDemoCommand.cpp (examples/face)

}  // namespace pmsc::demos
