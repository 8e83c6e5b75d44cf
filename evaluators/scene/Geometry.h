// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

// What the scenes share of geometry: a small vector type, colours and a pinhole camera.

#include "pmsc/FrameSet.h"

#include <array>
#include <span>
#include <string>

namespace pmsc::scene {

/// A small 3-vector of doubles (world space, millimetres). Kept free of Eigen and of the
/// ray tracers' types so this header stays cheap to include.
struct Vec3 {
    double x = 0, y = 0, z = 0;
};
inline Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec3 operator*(Vec3 a, double s) { return {a.x * s, a.y * s, a.z * s}; }
inline Vec3 operator*(double s, Vec3 a) { return a * s; }
inline double dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3 cross(Vec3 a, Vec3 b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
double length(Vec3 a);
Vec3 normalize(Vec3 a);

/// Positions as one frame of points.size() points x 3 channels (x, y, z): what
/// pmsc::PointPositionsProvider::pointPositions returns.
FrameSet positionsFrame(std::span<const Vec3> points);

/// RGB triple (reflectance, irradiance or radiance, linear).
using Rgb = std::array<double, 3>;

/// A pinhole camera: square image, vertical field of view in degrees.
struct Camera {
    std::string name;
    Vec3 eye, target, up{0, 1, 0};
    double fovYDegrees = 39.3077;
};

}  // namespace pmsc::scene
