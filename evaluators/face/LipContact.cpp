#include "evaluators/face/LipContact.h"

#include <algorithm>
#include <cmath>

namespace pmsc::face {

Eigen::Vector3d closestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
    const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0 && d2 <= 0) return a;
    const Eigen::Vector3d bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0 && d4 <= d3) return b;
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + (d1 / (d1 - d3)) * ab;
    const Eigen::Vector3d cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0 && d5 <= d6) return c;
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + (d2 / (d2 - d6)) * ac;
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
        return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
    const double denom = 1.0 / (va + vb + vc);
    return a + ab * (vb * denom) + ac * (vc * denom);
}

double LipContact::response(double s, double stick) {
    const double depth = -s;
    double push = 0;
    if (depth >= kContactSoftness) {
        push = depth - 0.5 * kContactSoftness;
    } else if (depth > 0) {
        push = depth * depth / (2 * kContactSoftness);
    }
    double pull = 0;
    if (s > 0 && s < kStickRange && stick > 0) {
        const double t = s / kStickRange;
        pull = stick * s * (1 - t * t * (3 - 2 * t));  // s x (1 - smoothstep): 0 at contact and at release
    }
    return 0.5 * (push - pull);
}

LipContact::LipContact(const IctFace& face, const MeshTopology& topology,
                       const std::vector<double>& jawWeights)
    : triangles_(topology.triangles()) {
    const Index n = face.vertexCount();
    const std::vector<double>& rest = face.neutral.positions;
    auto at = [&](Index v) { return Eigen::Vector3d(&rest[3 * v]); };

    // The mouth box: Multi-PIE points 48-67 are the outer and inner lip contours.
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = Eigen::Vector3d::Constant(-INFINITY);
    for (size_t i = 48; i < 68; ++i) {
        lo = lo.cwiseMin(at(IctFace::multiPie68()[i]));
        hi = hi.cwiseMax(at(IctFace::multiPie68()[i]));
    }
    lo -= Eigen::Vector3d(kBoxMargin, kBoxMargin, kBoxDepth);
    hi += Eigen::Vector3d(kBoxMargin, kBoxMargin, kBoxMargin);
    const double cornerX = 0.5 * ((hi[0] - kBoxMargin) - (lo[0] + kBoxMargin));
    const VertexRegion& skin = IctFace::region("face");
    const VertexRegion& socket = IctFace::region("mouth_socket");
    side_.assign(static_cast<size_t>(n), -1);
    std::vector<std::int8_t>& side = side_;
    for (Index v = 0; v < n; ++v) {
        if (!skin.contains(v) && !socket.contains(v)) continue;
        const Eigen::Vector3d x = at(v);
        if ((x.array() < lo.array()).any() || (x.array() > hi.array()).any()) continue;
        side[v] = jawWeights[v] >= 0.5 ? 1 : 0;
    }
    // Triangles wholly on one side, with their centroids and bounding radii.
    std::vector<std::int32_t> sideTris[2];
    for (size_t t = 0; t < triangles_.size(); ++t) {
        const auto& tri = triangles_[t];
        const std::int8_t s0 = side[tri[0]];  // -1: neither lip
        if (s0 >= 0 && side[tri[1]] == s0 && side[tri[2]] == s0)
            sideTris[s0].push_back(static_cast<std::int32_t>(t));
    }
    zone_ = ContactZone(n);
    for (Index v = 0; v < n; ++v) {
        if (side[v] < 0) continue;
        const Eigen::Vector3d x = at(v);
        const auto& other = sideTris[1 - side[v]];
        double nearest = INFINITY;
        std::vector<std::int32_t> cands;
        for (std::int32_t t : other) {
            const auto& tri = triangles_[static_cast<size_t>(t)];
            const double d = (x - closestPointOnTriangle(x, at(tri[0]), at(tri[1]), at(tri[2]))).norm();
            nearest = std::min(nearest, d);
            if (d < kCandidateRadius) cands.push_back(t);
        }
        if (nearest >= kZoneRadius) continue;
        zone_.add(v, cands, triangles_);
        const double r = std::abs(x[0]) / cornerX;
        stickiness_.push_back(std::clamp(1 - r * r, 0.0, 1.0));
    }
    // Winding: at rest the lips touch without crossing, so most zone vertices lie on the outer
    // side of the nearest opposite triangle. Whichever sign the majority shows is "outward".
    Index outward = 0, inward = 0;
    for (Index v : zone_.vertices()) {
        const Eigen::Vector3d x = at(v);
        double best = INFINITY;
        double sign = 0;
        for (std::int32_t t : candidates(v)) {
            const auto& tri = triangles_[static_cast<size_t>(t)];
            const Eigen::Vector3d a = at(tri[0]), b = at(tri[1]), c = at(tri[2]);
            const Eigen::Vector3d q = closestPointOnTriangle(x, a, b, c);
            const double d2 = (x - q).squaredNorm();
            if (d2 < best) {
                best = d2;
                sign = (x - q).dot((b - a).cross(c - a));
            }
        }
        if (sign > 0) ++outward;
        if (sign < 0) ++inward;
    }
    orientation_ = inward > outward ? -1.0 : 1.0;
    for (Index v : zone_.vertices()) {
        const auto posed = [&](std::int32_t u) { return at(u); };
        const std::int32_t z = zone_.index(v);
        allowance_.push_back(0.0);
        // Signed distance at rest with the final orientation: apply() with a zero allowance.
        const Eigen::Vector3d x = at(v);
        double best = INFINITY;
        double s = 0;
        for (std::int32_t t : candidates(v)) {
            const auto& tri = triangles_[static_cast<size_t>(t)];
            const Eigen::Vector3d a = posed(tri[0]), b = posed(tri[1]), c = posed(tri[2]);
            const Eigen::Vector3d q = closestPointOnTriangle(x, a, b, c);
            const double d2 = (x - q).squaredNorm();
            const Eigen::Vector3d normal = (b - a).cross(c - a);
            if (d2 < best && normal.norm() > 0) {
                best = d2;
                s = (x - q).dot(orientation_ * normal.normalized());
            }
        }
        allowance_[static_cast<size_t>(z)] = std::min(0.0, s);
    }
}

}  // namespace pmsc::face
