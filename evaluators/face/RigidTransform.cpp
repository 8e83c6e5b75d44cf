#include "evaluators/face/RigidTransform.h"

#include <Eigen/Dense>

#include <cmath>
#include <stdexcept>

namespace pmsc::face {

RigidTransform fitRigidTransform(std::span<const double> from, std::span<const double> to) {
    if (from.size() != to.size() || from.size() < 9 || from.size() % 3 != 0) {
        throw std::invalid_argument("fitRigidTransform: needs two equal sets of at least 3 points");
    }
    const Eigen::Index n = static_cast<Eigen::Index>(from.size() / 3);
    const Eigen::Map<const Eigen::Matrix3Xd> p(from.data(), 3, n);
    const Eigen::Map<const Eigen::Matrix3Xd> q(to.data(), 3, n);
    const Eigen::Vector3d pc = p.rowwise().mean();
    const Eigen::Vector3d qc = q.rowwise().mean();
    const Eigen::Matrix3d h = (p.colwise() - pc) * (q.colwise() - qc).transpose();
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
    d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
    RigidTransform t;
    t.rotation = svd.matrixV() * d * svd.matrixU().transpose();
    t.translation = qc - t.rotation * pc;
    return t;
}

void fitSphere(std::span<const double> points, Eigen::Vector3d& centre, double& radius) {
    const Eigen::Index n = static_cast<Eigen::Index>(points.size() / 3);
    if (n < 4) throw std::invalid_argument("fitSphere: needs at least 4 points");
    // |x|^2 = 2 c.x + (r^2 - |c|^2): linear in (c, r^2 - |c|^2).
    Eigen::MatrixXd a(n, 4);
    Eigen::VectorXd b(n);
    for (Eigen::Index i = 0; i < n; ++i) {
        const double* x = &points[static_cast<size_t>(3 * i)];
        a.row(i) << 2 * x[0], 2 * x[1], 2 * x[2], 1.0;
        b(i) = x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
    }
    const Eigen::Vector4d s = a.colPivHouseholderQr().solve(b);
    centre = s.head<3>();
    radius = std::sqrt(s(3) + centre.squaredNorm());
}

}  // namespace pmsc::face
