// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <atomic>

namespace pmsc::cli {

/// Installs a SIGINT/SIGTERM handler that only raises a flag, so long
/// operations stop at their next progress check and unwind normally (removing
/// their temporary files) instead of dying mid-write. A second signal a second
/// or more after the first terminates at once (default action); one within a
/// second of the first is the same request delivered twice (`timeout` and
/// process-group signalling send it to the child and to its group) and is ignored.
void installInterruptHandler();

/// The flag the handler raises; long loops poll it (and engines take it as
/// their cancel flag).
const std::atomic<bool>& interruptFlag();

/// True once SIGINT or SIGTERM was received.
bool interrupted();

}  // namespace pmsc::cli
