// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

namespace pmsc {

struct ModelSectionCodec;

/// Codec of the "LEARNSVD" model-file section: Model::learning (LearningState.h).
ModelSectionCodec learningSectionCodec();
/// Codec of the "CALIBRAT" model-file section: Model::calibrationRecord (LearningState.h).
ModelSectionCodec calibrationSectionCodec();

}  // namespace pmsc
