// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <span>

namespace pmsc::face {

/// x -> rotation * x + translation.
struct RigidTransform {
    Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
    Eigen::Vector3d translation = Eigen::Vector3d::Zero();

    Eigen::Vector3d operator()(const Eigen::Vector3d& x) const { return rotation * x + translation; }
    /// (this o other)(x) = this(other(x)).
    RigidTransform operator*(const RigidTransform& other) const {
        return {rotation * other.rotation, rotation * other.translation + translation};
    }
    /// Rotation by `angle` radians about the unit `axis` through `centre`.
    static RigidTransform aboutAxis(const Eigen::Vector3d& axis, double angle,
                                    const Eigen::Vector3d& centre) {
        RigidTransform t;
        t.rotation = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
        t.translation = centre - t.rotation * centre;
        return t;
    }
};

/// Least-squares rigid transform taking `from` to `to` (Kabsch; 3 doubles per point).
RigidTransform fitRigidTransform(std::span<const double> from, std::span<const double> to);

/// Least-squares sphere through points (3 doubles per point): centre and radius.
void fitSphere(std::span<const double> points, Eigen::Vector3d& centre, double& radius);

}  // namespace pmsc::face
