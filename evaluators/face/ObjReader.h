// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

// The face rig's names for the project's one OBJ reader (pmsc/ObjIO.h).
#include "pmsc/ObjIO.h"

namespace pmsc::face {

using pmsc::ObjContent;
using pmsc::ObjMesh;
using pmsc::readObj;

}  // namespace pmsc::face
