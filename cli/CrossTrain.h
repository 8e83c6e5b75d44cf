// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "app/Train.h"

#include <string>

namespace pmsc::cli {

/// `pmsc train --frames CONTROL.npy --targets TARGET.npy` (cross point multiplication): trains
/// (app::trainCrossFiles) and prints the summary.
int runTrainCross(const app::TrainOptions& request, bool quiet);

}  // namespace pmsc::cli
