// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <tbb/task_arena.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <functional>
#include <string>
#include <string_view>

namespace pmsc::examples {

// What the demo drivers (`pmsc demo volume`, `cornell`, `face`, `learn`, `cross`) set up before
// their first step: the output folder, the clock and the stage timings, the progress hook, the
// worker arena.

/// The clock the demos time their stages with.
using DemoClock = std::chrono::steady_clock;

/// Seconds from `t` to now.
double secondsSince(DemoClock::time_point t);

/// CPU seconds of the calling thread: a frame timed on one thread, unaffected by other processes
/// time-slicing a shared machine.
double threadCpuSeconds();

/// A demo's progress hook: (stage, done, total); false asks the demo to stop.
using DemoProgress = std::function<bool(std::string_view, double, double)>;

/// How a demo words the error when its output folder cannot be made (each keeps its own).
enum class FolderErrorWording {
    CannotCreate,  ///< "cannot create DIR: REASON" (volume, cornell)
    OutputFolder,  ///< "DIR: cannot create the output folder: REASON" (face, learn, cross)
};

/// Creates the folder `dir` (and its parents) if missing.
/// @throws pmsc::IoError when it cannot be made or is not a folder.
void createOutputFolder(const std::string& dir, FolderErrorWording wording);

/// What every step of a demo shares: the start time, the worker arena, the progress hook and
/// the stage timings (report.json's "seconds").
class DemoSetup {
public:
    /// `threads` (> 0): the arena's size; `cancelMessage`: what pmsc::Cancelled says when the
    /// hook asks to stop. `start`: when the demo started (the "total" timing counts from it).
    DemoSetup(int threads, const DemoProgress& hook, std::string cancelMessage,
              DemoClock::time_point start = DemoClock::now());

    /// Reports progress to the hook (if any).
    /// @throws pmsc::Cancelled when the hook returns false.
    void progress(std::string_view stage, double done, double total) const;

    /// Records the seconds since `t` as timings[stage] and returns them.
    double lap(const std::string& stage, DemoClock::time_point t);

    /// Records timings["total"] (seconds since the start) and returns the timings.
    const nlohmann::json& finish();

    const DemoClock::time_point start;
    const int threads;
    tbb::task_arena arena;
    nlohmann::json timings;

private:
    const DemoProgress& hook_;
    std::string cancelMessage_;
};

}  // namespace pmsc::examples
