// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/scene/Geometry.h"

#include <cmath>
#include <cstdint>

namespace pmsc::scene {

/// Integer hash (the "lowbias32" finalizer of Chris Wellons' hash-prospector): decorrelates
/// neighbouring point ids so their sample patterns look independent.
inline std::uint32_t hash32(std::uint32_t x) {
    x ^= x >> 16;
    x *= 0x7feb352dU;
    x ^= x >> 15;
    x *= 0x846ca68bU;
    x ^= x >> 16;
    return x;
}

/// Van der Corput radical inverse in base 2, in [0, 1).
inline double radicalInverse2(std::uint32_t i) {
    i = (i << 16) | (i >> 16);
    i = ((i & 0x00ff00ffU) << 8) | ((i & 0xff00ff00U) >> 8);
    i = ((i & 0x0f0f0f0fU) << 4) | ((i & 0xf0f0f0f0U) >> 4);
    i = ((i & 0x33333333U) << 2) | ((i & 0xccccccccU) >> 2);
    i = ((i & 0x55555555U) << 1) | ((i & 0xaaaaaaaaU) >> 1);
    return i * (1.0 / 4294967296.0);
}

/// Sample `i` of `count` of the 2-D Hammersley set, toroidally shifted (Cranley-Patterson
/// rotation) by an offset that depends on the point id only.
///
/// Why this sequence: the gather's samples must depend on the point alone (never on the frame,
/// the batch or the thread), so a point's value is bit-identical whether it is evaluated alone,
/// among all points, or as a key point; and the same directions are reused every frame, which
/// makes the gather's residual noise a fixed per-point pattern that the training frames see
/// (and the basis can represent) instead of fresh noise in every frame.
inline void hammersleyShifted(std::uint32_t pointId, std::uint32_t i, std::uint32_t count, double& u,
                              double& v) {
    const std::uint32_t h1 = hash32(pointId * 2u + 0x68bc21ebU);
    const std::uint32_t h2 = hash32(h1 ^ 0x02e5be93U);
    u = (i + 0.5) / count + h1 * (1.0 / 4294967296.0);
    v = radicalInverse2(i) + h2 * (1.0 / 4294967296.0);
    u -= std::floor(u);
    v -= std::floor(v);
}

/// An orthonormal basis around a unit normal (Duff et al., "Building an Orthonormal Basis,
/// Revisited", JCGT 2017).
inline void orthonormalBasis(Vec3 n, Vec3& t, Vec3& b) {
    const double sign = std::copysign(1.0, n.z);
    const double a = -1.0 / (sign + n.z);
    const double c = n.x * n.y * a;
    t = {1.0 + sign * n.x * n.x * a, sign * c, -sign * n.x};
    b = {c, sign + n.y * n.y * a, -n.y};
}

/// Cosine-weighted direction on the hemisphere around n (pdf = cos / pi), from (u, v) in [0,1)^2.
inline Vec3 cosineDirection(Vec3 n, Vec3 t, Vec3 b, double u, double v) {
    const double r = std::sqrt(u);
    const double phi = 2.0 * M_PI * v;
    const double z = std::sqrt(std::max(0.0, 1.0 - u));
    return t * (r * std::cos(phi)) + b * (r * std::sin(phi)) + n * z;
}

}  // namespace pmsc::scene
