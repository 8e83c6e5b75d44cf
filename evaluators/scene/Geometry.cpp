#include "evaluators/scene/Geometry.h"

#include <cmath>

namespace pmsc::scene {

double length(Vec3 a) { return std::sqrt(dot(a, a)); }

FrameSet positionsFrame(std::span<const Vec3> points) {
    FrameSet out(1, static_cast<Index>(points.size()), 3);
    for (std::size_t p = 0; p < points.size(); ++p) {
        out.values[3 * p] = points[p].x;
        out.values[3 * p + 1] = points[p].y;
        out.values[3 * p + 2] = points[p].z;
    }
    return out;
}

Vec3 normalize(Vec3 a) {
    const double l = length(a);
    return l > 0 ? a * (1.0 / l) : a;
}

}  // namespace pmsc::scene
