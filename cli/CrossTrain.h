// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Training.h"

#include <string>

namespace pmsc::cli {

/// `pmsc train --frames CONTROL.npy --targets TARGET.npy` (cross point multiplication),
/// after TrainCommand parsed and checked the options. Pairs that cannot match (frame or channel
/// counts) fail from the headers, before anything is read or written.
int runTrainCross(const std::string& controlPath, const std::string& targetsPath, const std::string& outPath,
                  const TrainingOptions& training, double coverage, Index slices, bool quiet);

}  // namespace pmsc::cli
