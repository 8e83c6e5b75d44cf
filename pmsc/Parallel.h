// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <functional>

namespace pmsc {

/// Runs `work` on min(cores, jobs) threads (this one included) and waits for all of them; the
/// first exception thrown on any of them is rethrown here. `work` takes its jobs from a shared
/// counter, so callers that want a result independent of the thread count give each job its own
/// output and combine the outputs in job order.
///
/// Decision: plain std::thread, not oneTBB. The mathematics links Eigen only, so a program that
/// embeds the training does not inherit a scheduler; the threads live for one call.
void runOnEveryCore(const std::function<void()>& work, Index jobs);

}  // namespace pmsc
