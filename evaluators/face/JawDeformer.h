// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/FaceControls.h"
#include "evaluators/face/IctFace.h"
#include "evaluators/face/MeshTopology.h"
#include "evaluators/face/RigidTransform.h"

#include <array>
#include <vector>

namespace pmsc::face {

/// The jaw: a rigid bone that rotates about its hinge (jawOpen), swings sideways (jawLeft,
/// jawRight) and slides forward (jawForward), skinned to the face by linear blend skinning with
/// the skull (paper section 7: "an articulation variable sets the pivot of another" is the kind
/// of nonlinearity point multiplication must survive; here the skin follows a rotation).
///
/// Everything is derived from the ICT scans, nothing is hand-placed:
/// - the bone's motion for each jaw expression is the rigid transform that best maps the lower
///   teeth of the neutral onto those of the expression (Kabsch); jawOpen is a 25 degree hinge
///   rotation, and its axis and pivot are read off that transform;
/// - the skinning weight of a vertex is how much of the bone's motion its jawOpen delta shows
///   (the delta projected on the bone's displacement there, clamped to [0, 1]), then smoothed
///   over the mesh so the skin shears smoothly between skull and jaw; the lower teeth are 1;
/// - each jaw expression keeps a residual corrective shape, computed so that skinning the neutral
///   plus the residual at control value 1 reproduces the scan exactly (the residual is added
///   before skinning, so it rides the jaw).
class JawDeformer {
public:
    /// Jaw expressions, in the order of residual().
    static constexpr std::array<int, 4> kControls = {JawOpen, JawLeft, JawRight, JawForward};

    JawDeformer(const IctFace& face, const MeshTopology& topology);

    /// The bone's transform for a pose: forward o right o left o open, each interpolated from its
    /// fitted rigid transform (rotation angle and translation scale with the control).
    RigidTransform transform(const ControlVector& controls) const;

    /// Linear blend skinning between skull (identity) and jaw: q + w (T q - q).
    Eigen::Vector3d apply(Index v, const Eigen::Vector3d& q, const RigidTransform& jaw) const {
        const double w = weights_[static_cast<size_t>(v)];
        if (w == 0.0) return q;
        return q + w * (jaw(q) - q);
    }

    /// Skinning weight of vertex v in [0, 1].
    double weight(Index v) const { return weights_[static_cast<size_t>(v)]; }
    const std::vector<double>& weights() const { return weights_; }
    /// Residual corrective of kControls[k] (3 doubles per vertex, added before skinning).
    const std::vector<double>& residual(int k) const { return residuals_[static_cast<size_t>(k)]; }
    /// The hinge: a point on the jawOpen rotation axis, the unit axis, and the full-open angle.
    const Eigen::Vector3d& pivot() const { return pivot_; }
    const Eigen::Vector3d& hingeAxis() const { return axis_; }
    double openAngle() const { return openAngle_; }

private:
    struct Motion {  // a fitted rigid transform as an angle about an axis through a centre + a slide
        Eigen::Vector3d axis = Eigen::Vector3d::UnitX();
        double angle = 0;
        Eigen::Vector3d centre = Eigen::Vector3d::Zero();
        Eigen::Vector3d slide = Eigen::Vector3d::Zero();
        RigidTransform at(double c) const;
    };
    static Motion toMotion(const RigidTransform& t, const Eigen::Vector3d& centre);

    std::array<Motion, 4> motions_;
    Eigen::Vector3d pivot_;
    Eigen::Vector3d axis_;
    double openAngle_ = 0;
    std::vector<double> weights_;
    std::array<std::vector<double>, 4> residuals_;
};

}  // namespace pmsc::face
