// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/IctFace.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <vector>

namespace pmsc::face {

/// Eyelids that rotate over the eyeballs (blinks): each lid vertex turns about the eye's
/// horizontal axis through the eyeball's centre by blink x its own angle, so the lid slides over
/// the eye on a sphere instead of cutting through it along the straight line of a blendshape.
///
/// Derived from the scans: the eye centres are sphere fits to the scleras; a vertex belongs to a
/// lid if eyeBlink moves it by more than kLidMinMotion within kLidMaxRadius of the centre; its
/// angle is the angle its eyeBlink motion sweeps about the axis. What a rotation cannot express
/// (the lid's sideways and radial motion in the scan) is a residual corrective expressed in the
/// lid's rest frame, added before the rotation, so at blink 1 the rig reproduces the scan.
class EyelidDeformer {
public:
    static constexpr double kLidMinMotion = 0.01;  ///< model units
    static constexpr double kLidMaxRadius = 4.0;   ///< model units (eyeball radius is ~1.6)

    explicit EyelidDeformer(const IctFace& face);

    /// Eye of a lid vertex: 0 left (+x), 1 right, -1 not a lid vertex.
    int eyeOf(Index v) const { return eye_[static_cast<size_t>(v)]; }
    /// Rotation angle (radians) of a lid vertex at blink 1.
    double angle(Index v) const { return angle_[static_cast<size_t>(v)]; }
    const Eigen::Vector3d& centre(int eye) const { return centres_[static_cast<size_t>(eye)]; }
    double eyeballRadius(int eye) const { return radii_[static_cast<size_t>(eye)]; }
    /// Residual corrective of eyeBlink_L (eye 0) or eyeBlink_R (eye 1), 3 doubles per vertex.
    const std::vector<double>& residual(int eye) const { return residuals_[static_cast<size_t>(eye)]; }

    /// Rotates lid vertex v at position q about its eye's axis by blink x angle(v). Distance to
    /// the eye centre is preserved exactly (up to rounding). Non-lid vertices are returned as is.
    Eigen::Vector3d apply(Index v, const Eigen::Vector3d& q, const std::array<double, 2>& blink) const;

private:
    std::array<Eigen::Vector3d, 2> centres_;
    std::array<double, 2> radii_{};
    std::vector<std::int8_t> eye_;
    std::vector<double> angle_;
    std::array<std::vector<double>, 2> residuals_;
};

}  // namespace pmsc::face
