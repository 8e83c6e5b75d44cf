// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <atomic>

namespace pmsc::cli {

/// Installs a SIGINT/SIGTERM handler that only raises a flag, so long
/// operations stop at their next progress check and unwind normally (removing
/// their temporary files) instead of dying mid-write. A second signal
/// terminates at once (the handler restores the default action).
void installInterruptHandler();

/// The flag the handler raises; long loops poll it (and engines take it as
/// their cancel flag).
const std::atomic<bool>& interruptFlag();

/// True once SIGINT or SIGTERM was received.
bool interrupted();

}  // namespace pmsc::cli
