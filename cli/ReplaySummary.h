// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "app/Replay.h"

#include <ostream>

namespace pmsc::cli {

/// The short human summary of a replay: cache states, error percentiles of PM
/// alone and soft-cached, the thresholds and the speed.
void printReplaySummary(std::ostream& out, const Model& model, const app::ReplayResult& result,
                        bool epsOverridden);

}  // namespace pmsc::cli
