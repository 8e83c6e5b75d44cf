#include "evaluators/scene/Geometry.h"

#include <cmath>

namespace pmsc::scene {

double length(Vec3 a) { return std::sqrt(dot(a, a)); }

Vec3 normalize(Vec3 a) {
    const double l = length(a);
    return l > 0 ? a * (1.0 / l) : a;
}

}  // namespace pmsc::scene
