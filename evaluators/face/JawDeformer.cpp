#include "evaluators/face/JawDeformer.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>

namespace pmsc::face {
namespace {

// Laplacian smoothing of the raw weights. Four Jacobi sweeps at one half spread the shear over
// about two rings of the face mesh (~0.5 model units): enough to remove the stair-steps of the
// per-vertex projection without bleeding the jaw into the upper lip.
constexpr int kWeightSmoothingSweeps = 4;
constexpr double kWeightSmoothingStep = 0.5;

}  // namespace

JawDeformer::Motion JawDeformer::toMotion(const RigidTransform& t, const Eigen::Vector3d& centre) {
    Motion m;
    const Eigen::AngleAxisd aa(t.rotation);
    m.axis = aa.axis();
    m.angle = aa.angle();
    m.centre = centre;
    m.slide = t(centre) - centre;
    return m;
}

RigidTransform JawDeformer::Motion::at(double c) const {
    RigidTransform t = RigidTransform::aboutAxis(axis, c * angle, centre);
    t.translation += c * slide;
    return t;
}

JawDeformer::JawDeformer(const IctFace& face, const MeshTopology& topology) {
    const Index n = face.vertexCount();
    const std::vector<double>& rest = face.neutral.positions;
    const VertexRegion& lower = IctFace::region("teeth_lower");
    const VertexRegion& upper = IctFace::region("teeth_upper");
    const std::span<const double> lowerRest(rest.data() + 3 * lower.first,
                                            static_cast<size_t>(3 * lower.size()));

    std::array<RigidTransform, 4> fitted;
    for (size_t k = 0; k < kControls.size(); ++k) {
        const std::vector<double>& delta = face.deltas[face.expression(controlName(kControls[k]))];
        std::vector<double> posed(lowerRest.begin(), lowerRest.end());
        for (size_t i = 0; i < posed.size(); ++i) posed[i] += delta[static_cast<size_t>(3 * lower.first) + i];
        fitted[k] = fitRigidTransform(lowerRest, posed);
    }

    // jawOpen is a hinge: its pivot is the point of the axis nearest the teeth's centroid that
    // the transform leaves fixed (least squares; the axial slide of a hinge is ~0).
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (Index v = lower.first; v <= lower.last; ++v) centroid += Eigen::Vector3d(&rest[3 * v]);
    centroid /= static_cast<double>(lower.size());
    {
        const Eigen::AngleAxisd aa(fitted[0].rotation);
        axis_ = aa.axis();
        openAngle_ = aa.angle();
        const Eigen::Matrix3d a = Eigen::Matrix3d::Identity() - fitted[0].rotation;
        // Solve (I - R) c = t in the plane orthogonal to the axis, through the centroid's foot.
        const Eigen::Vector3d c0 = a.completeOrthogonalDecomposition().solve(fitted[0].translation);
        pivot_ = c0 + axis_ * axis_.dot(centroid - c0);
    }
    motions_[0] = toMotion(fitted[0], pivot_);
    for (size_t k = 1; k < 4; ++k) motions_[k] = toMotion(fitted[k], centroid);

    // Raw weights: the jawOpen delta projected on the bone's full-open displacement.
    const std::vector<double>& openDelta = face.deltas[face.expression("jawOpen")];
    const RigidTransform open = motions_[0].at(1.0);
    std::vector<double> raw(static_cast<size_t>(n), 0.0);
    std::vector<char> fixed(static_cast<size_t>(n), 0);
    for (Index v = 0; v < n; ++v) {
        const Eigen::Vector3d x(&rest[3 * v]);
        const Eigen::Vector3d d = open(x) - x;
        const Eigen::Vector3d delta(&openDelta[3 * v]);
        const double dd = d.squaredNorm();
        if (dd > 1e-6 && delta.squaredNorm() > 1e-8) raw[v] = std::clamp(delta.dot(d) / dd, 0.0, 1.0);
        if (lower.contains(v)) {
            raw[v] = 1.0;
            fixed[v] = 1;
        } else if (upper.contains(v)) {
            raw[v] = 0.0;
            fixed[v] = 1;
        }
    }
    weights_ = raw;
    std::vector<double> next(weights_.size());
    for (int sweep = 0; sweep < kWeightSmoothingSweeps; ++sweep) {
        for (Index v = 0; v < n; ++v) {
            const auto nb = topology.neighbours(v);
            if (fixed[v] || nb.empty()) {
                next[v] = weights_[v];
                continue;
            }
            double sum = 0;
            for (std::int32_t u : nb) sum += weights_[u];
            next[v] =
                weights_[v] + kWeightSmoothingStep * (sum / static_cast<double>(nb.size()) - weights_[v]);
        }
        weights_.swap(next);
    }
    // Exact zeros where the jaw has no influence, so apply() can skip those vertices.
    for (double& w : weights_) {
        if (w < 1e-4) w = 0.0;
    }

    // Residual correctives: find q with skin(q) = scan, i.e. ((1-w) I + w R) q + w t = e.
    for (size_t k = 0; k < 4; ++k) {
        ControlVector pose = restPose();
        pose[kControls[k]] = 1.0;
        const RigidTransform t = transform(pose);
        const std::vector<double>& delta = face.deltas[face.expression(controlName(kControls[k]))];
        std::vector<double>& res = residuals_[k];
        res.assign(static_cast<size_t>(3 * n), 0.0);
        for (Index v = 0; v < n; ++v) {
            const Eigen::Vector3d x(&rest[3 * v]);
            const Eigen::Vector3d e = x + Eigen::Vector3d(&delta[3 * v]);
            const double w = weights_[v];
            const Eigen::Matrix3d a = (1.0 - w) * Eigen::Matrix3d::Identity() + w * t.rotation;
            const Eigen::Vector3d q = a.partialPivLu().solve(e - w * t.translation);
            for (int c = 0; c < 3; ++c) res[3 * v + c] = q[c] - x[c];
        }
    }
}

RigidTransform JawDeformer::transform(const ControlVector& controls) const {
    RigidTransform t = motions_[0].at(controls[JawOpen]);
    for (size_t k = 1; k < 4; ++k) {
        const double c = controls[kControls[k]];
        if (c != 0.0) t = motions_[k].at(c) * t;
    }
    return t;
}

}  // namespace pmsc::face
