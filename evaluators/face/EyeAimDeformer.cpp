#include "evaluators/face/EyeAimDeformer.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <numbers>

namespace pmsc::face {

EyeAimDeformer::EyeAimDeformer(const IctFace& face, const std::array<Eigen::Vector3d, 2>& centres)
    : centres_(centres), left_(IctFace::region("eyeball_left")), right_(IctFace::region("eyeball_right")) {
    (void)face;
}

EyeAimDeformer::Aim EyeAimDeformer::aim(const ControlVector& controls) const {
    constexpr double kDeg = std::numbers::pi / 180.0;
    const double yaw = controls[GazeYaw] * kDeg;
    const double pitch = controls[GazePitch] * kDeg;
    const double distance = std::max(controls[GazeDistance], kMinTargetDistance);
    const Eigen::Vector3d mid = 0.5 * (centres_[0] + centres_[1]);
    const Eigen::Vector3d target =
        mid + distance * Eigen::Vector3d(std::cos(pitch) * std::sin(yaw), std::sin(pitch),
                                         std::cos(pitch) * std::cos(yaw));
    Aim a;
    for (int e = 0; e < 2; ++e) {
        const Eigen::Vector3d u = (target - centres_[static_cast<size_t>(e)]).normalized();
        const double eyeYaw = std::atan2(u[0], u[2]);
        const double eyePitch = std::asin(std::clamp(u[1], -1.0, 1.0));
        // Ry(yaw) Rx(-pitch) turns the rest gaze +z into u.
        a.rotation[static_cast<size_t>(e)] = (Eigen::AngleAxisd(eyeYaw, Eigen::Vector3d::UnitY()) *
                                              Eigen::AngleAxisd(-eyePitch, Eigen::Vector3d::UnitX()))
                                                 .toRotationMatrix();
        a.yawDegrees[static_cast<size_t>(e)] = eyeYaw / kDeg;
        a.pitchDegrees[static_cast<size_t>(e)] = eyePitch / kDeg;
    }
    auto hinge = [](double x, double full) { return std::clamp(x / full, 0.0, 1.0); };
    // Left eye looking toward +x looks "out"; the right eye looking toward +x looks "in".
    a.lookWeights = {
        hinge(-a.pitchDegrees[0], kShapePitchDegrees), hinge(-a.pitchDegrees[1], kShapePitchDegrees),
        hinge(-a.yawDegrees[0], kShapeYawDegrees),     hinge(a.yawDegrees[1], kShapeYawDegrees),
        hinge(a.yawDegrees[0], kShapeYawDegrees),      hinge(-a.yawDegrees[1], kShapeYawDegrees),
        hinge(a.pitchDegrees[0], kShapePitchDegrees),  hinge(a.pitchDegrees[1], kShapePitchDegrees),
    };
    return a;
}

}  // namespace pmsc::face
