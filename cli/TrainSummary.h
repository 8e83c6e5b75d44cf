// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"
#include "pmsc/Model.h"
#include "pmsc/Training.h"

#include <ostream>
#include <string>

namespace pmsc::cli {

/// The short summary `pmsc train` (and the demos) print after training: sizes,
/// captured energy, training residual, eps and how it was set, warnings, time.
void printTrainSummary(std::ostream& out, const std::string& modelPath, const FrameSet& frames,
                       const Model& model, const TrainingReport& report, double seconds);

}  // namespace pmsc::cli
