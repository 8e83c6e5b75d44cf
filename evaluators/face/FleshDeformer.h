// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/FaceControls.h"
#include "evaluators/face/IctFace.h"
#include "evaluators/face/RigidTransform.h"

#include <Eigen/Core>

#include <functional>
#include <string>
#include <vector>

namespace pmsc::face {

/// Secondary soft tissue: the facial muscles as elastic line loads (regularized Kelvinlets,
/// de Goes and James, "Regularized Kelvinlets", SIGGRAPH 2017 — Pixar's closed-form elastic
/// brushes), applied on top of the primary shapes and bones.
///
/// Each muscle runs from an origin on the skull or the jaw to an insertion in the skin, both
/// placed from the Multi-PIE landmarks. When its driving controls contract it, it pulls the skin
/// about its insertion towards its origin and its belly bulges outwards. A muscle is a sheet of
/// kFibres parallel fibres across its width; the pull of each fibre is a line load integrated
/// with kQuadrature Gauss-Legendre samples, each a bi-scale regularized Kelvinlet (radius eps
/// and 2 eps: the field falls off as 1/r^3) in an incompressible-like tissue (Poisson ratio
/// kPoisson). Muscles attached to the jaw move and turn with it, so their pull direction
/// depends on the jaw angle: another nonlinearity.
///
/// The elastic field of a load reaches every point of the body, so every skin vertex sums the
/// field of every sample of every contracted muscle: exact, no truncation window, and the most
/// expensive stage of the rig (a contracted muscle costs 2 x kFibres x (kQuadrature + 1)
/// Kelvinlets per vertex). Cost is uneven across points and poses: vertices with flesh weight 0
/// (rigid parts, and the lips, whose shape comes from their scans and their contact) pay
/// nothing, and a pose pays only for the muscles it contracts. The deformer reads only the
/// vertex itself: no neighbourhood.
class FleshDeformer {
public:
    static constexpr int kQuadrature = 5;
    static constexpr int kFibres = 3;
    static constexpr double kPoisson = 0.45;

    /// A muscle, as placed at rest.
    struct Muscle {
        std::string name;
        Eigen::Vector3d origin;
        Eigen::Vector3d insertion;
        bool originOnJaw = false;
        bool insertionOnJaw = false;
        double pull = 0;    ///< model units of skin motion at full contraction
        double bulge = 0;   ///< model units of outward bulge at full contraction
        double radius = 1;  ///< eps of the Kelvinlets
        double width = 1;   ///< across the fibres (model units)
        Eigen::Vector3d outward = Eigen::Vector3d::UnitZ();       ///< rest direction of the bulge
        std::function<double(const ControlVector&)> contraction;  ///< in [0, 1]
    };

    /// One posed Kelvinlet sample: centre, load (normalized force), radius.
    struct Sample {
        Eigen::Vector3d centre;
        Eigen::Vector3d force;
        double radius;
    };
    /// Per-pose state: the Kelvinlet samples of the contracted muscles.
    struct Pose {
        std::vector<Sample> samples;
    };

    explicit FleshDeformer(const IctFace& face);

    const std::vector<Muscle>& muscles() const { return muscles_; }
    Pose prepare(const ControlVector& controls, const RigidTransform& jaw) const;
    /// Displacement of a point at posed position x (before weighting by the vertex's flesh weight).
    Eigen::Vector3d displacement(const Eigen::Vector3d& x, const Pose& pose) const;

private:
    std::vector<Muscle> muscles_;
};

}  // namespace pmsc::face
