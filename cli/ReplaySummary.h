// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "app/CrossReplay.h"
#include "app/Replay.h"

#include <ostream>

namespace pmsc::cli {

/// The short human summary of a replay: cache states, error percentiles of PM
/// alone and soft-cached, the thresholds and the speed.
void printReplaySummary(std::ostream& out, const Model& model, const app::ReplayResult& result,
                        bool epsOverridden);

/// What a cross replay did (app::crossReplay), as `pmsc replay` prints it for a cross model.
void printCrossReplaySummary(std::ostream& out, const Model& model, const app::CrossReplayResult& result);

}  // namespace pmsc::cli
