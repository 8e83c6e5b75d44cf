// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

// The face rig's names for the project's one OBJ writer (pmsc/ObjIO.h): the demo's
// meshes and `pmsc run --format obj` frames hold the values exactly, as the skin evaluator's do.
#include "evaluators/face/ObjReader.h"

namespace pmsc::face {

using pmsc::formatObj;
using pmsc::ObjFrameWriter;
using pmsc::writeObj;

}  // namespace pmsc::face
