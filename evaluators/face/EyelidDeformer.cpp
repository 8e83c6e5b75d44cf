#include "evaluators/face/EyelidDeformer.h"

#include <cmath>
#include <numbers>
#include <span>

#include "evaluators/face/RigidTransform.h"

namespace pmsc::face {
namespace {

// Rotation about the x axis (the eye's horizontal axis) that adds a to the angle atan2(y, z).
inline void rotateYZ(double a, double y, double z, double& yOut, double& zOut) {
    const double c = std::cos(a);
    const double s = std::sin(a);
    yOut = c * y + s * z;
    zOut = c * z - s * y;
}

}  // namespace

EyelidDeformer::EyelidDeformer(const IctFace& face) {
    const Index n = face.vertexCount();
    const std::vector<double>& rest = face.neutral.positions;
    const char* scleras[2] = {"sclera_left", "sclera_right"};
    const char* blinks[2] = {"eyeBlink_L", "eyeBlink_R"};
    for (int e = 0; e < 2; ++e) {
        const VertexRegion& r = IctFace::region(scleras[e]);
        fitSphere(std::span<const double>(rest.data() + 3 * r.first, static_cast<size_t>(3 * r.size())),
                  centres_[e], radii_[e]);
    }
    eye_.assign(static_cast<size_t>(n), -1);
    angle_.assign(static_cast<size_t>(n), 0.0);
    const VertexRegion& eyeballL = IctFace::region("eyeball_left");
    const VertexRegion& eyeballR = IctFace::region("eyeball_right");
    for (int e = 0; e < 2; ++e) {
        const std::vector<double>& delta = face.deltas[face.expression(blinks[e])];
        std::vector<double>& res = residuals_[e];
        res = delta;  // non-lid vertices keep their whole blink motion as a plain blendshape
        const Eigen::Vector3d& c = centres_[e];
        for (Index v = 0; v < n; ++v) {
            if (eyeballL.contains(v) || eyeballR.contains(v)) continue;  // the eyes aim, they do not blink
            const Eigen::Vector3d x = Eigen::Vector3d(&rest[3 * v]) - c;
            const Eigen::Vector3d d(&delta[3 * v]);
            if (d.norm() <= kLidMinMotion || x.norm() >= kLidMaxRadius) continue;
            if ((e == 0) != (x[0] + c[0] > 0)) continue;  // the other eye's side
            const Eigen::Vector3d y = x + d;
            double a = std::atan2(y[1], y[2]) - std::atan2(x[1], x[2]);
            if (a > std::numbers::pi) a -= 2 * std::numbers::pi;
            if (a < -std::numbers::pi) a += 2 * std::numbers::pi;
            // The residual r, in the rest frame, satisfies c + R(a) (x + r) = scan.
            double ry, rz;
            rotateYZ(-a, y[1], y[2], ry, rz);
            eye_[v] = static_cast<std::int8_t>(e);
            angle_[v] = a;
            res[3 * v + 0] = y[0] - x[0];
            res[3 * v + 1] = ry - x[1];
            res[3 * v + 2] = rz - x[2];
        }
    }
}

Eigen::Vector3d EyelidDeformer::apply(Index v, const Eigen::Vector3d& q,
                                      const std::array<double, 2>& blink) const {
    const std::int8_t e = eye_[static_cast<size_t>(v)];  // -1: not an eyelid point
    if (e < 0) return q;
    const auto eye = static_cast<size_t>(static_cast<unsigned char>(e));  // 0 or 1 here
    const double a = blink[eye] * angle_[static_cast<size_t>(v)];
    if (a == 0.0) return q;
    const Eigen::Vector3d& c = centres_[eye];
    double y, z;
    rotateYZ(a, q[1] - c[1], q[2] - c[2], y, z);
    return {q[0], c[1] + y, c[2] + z};
}

}  // namespace pmsc::face
