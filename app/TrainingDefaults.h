// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Training.h"

namespace pmsc::app {

/// What `pmsc train` and Python's `pmsc.train` do when not told otherwise: the library's
/// defaults, and regions for local fail-through chosen from the data (RegionChoice.h), learning
/// from every 3rd frame. One definition, so the two give the same model bytes.
TrainingOptions defaultTrainingOptions();

}  // namespace pmsc::app
