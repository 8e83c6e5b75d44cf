// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/FaceControls.h"
#include "evaluators/face/IctFace.h"

#include <Eigen/Core>

#include <array>

namespace pmsc::face {

/// Eyes that aim: each eyeball (sclera and iris) turns rigidly about its centre to look at a
/// gaze target, so the two eyes converge on near targets. The target sits gazeDistance units
/// from the midpoint of the eyes, in the direction (gazeYaw, gazePitch) degrees.
///
/// The skin follows the eyes through the ICT eyeLook shapes, whose weights are each eye's own
/// yaw or pitch over the angle the shape was sculpted for (kShapeYawDegrees,
/// kShapePitchDegrees), clamped to [0, 1]: a hinge nonlinearity (only one of In/Out, Up/Down is
/// ever active).
class EyeAimDeformer {
public:
    static constexpr double kShapeYawDegrees = 30.0;
    static constexpr double kShapePitchDegrees = 25.0;
    static constexpr double kMinTargetDistance = 5.0;  ///< closer targets are clamped (model units)

    /// Per-pose state: each eye's rotation and the eyeLook shape weights.
    struct Aim {
        std::array<Eigen::Matrix3d, 2> rotation;  ///< eye 0 left (+x), 1 right
        std::array<double, 2> yawDegrees{};       ///< + toward +x
        std::array<double, 2> pitchDegrees{};     ///< + up
        /// Weights of eyeLookDown_L, eyeLookDown_R, eyeLookIn_L, eyeLookIn_R, eyeLookOut_L,
        /// eyeLookOut_R, eyeLookUp_L, eyeLookUp_R (the order of kLookShapes).
        std::array<double, 8> lookWeights{};
    };
    static constexpr std::array<const char*, 8> kLookShapes = {
        "eyeLookDown_L", "eyeLookDown_R", "eyeLookIn_L", "eyeLookIn_R",
        "eyeLookOut_L",  "eyeLookOut_R",  "eyeLookUp_L", "eyeLookUp_R"};

    /// @param centres eyeball centres (left, right), e.g. EyelidDeformer::centre().
    EyeAimDeformer(const IctFace& face, const std::array<Eigen::Vector3d, 2>& centres);

    Aim aim(const ControlVector& controls) const;

    /// Eye of an eyeball vertex (0, 1) or -1.
    int eyeOf(Index v) const {
        if (v >= left_.first && v <= left_.last) return 0;
        if (v >= right_.first && v <= right_.last) return 1;
        return -1;
    }
    Eigen::Vector3d apply(Index v, const Eigen::Vector3d& q, const Aim& aim) const {
        const int e = eyeOf(v);
        if (e < 0) return q;
        const Eigen::Vector3d& c = centres_[static_cast<size_t>(e)];
        return c + aim.rotation[static_cast<size_t>(e)] * (q - c);
    }
    const Eigen::Vector3d& centre(int eye) const { return centres_[static_cast<size_t>(eye)]; }

private:
    std::array<Eigen::Vector3d, 2> centres_;
    VertexRegion left_;
    VertexRegion right_;
};

}  // namespace pmsc::face
