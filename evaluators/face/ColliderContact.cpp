#include "evaluators/face/ColliderContact.h"

#include <algorithm>
#include <cmath>

namespace pmsc::face {

ColliderContact::ColliderContact(std::string name, const std::vector<double>& rest,
                                 const MeshTopology& topology, const std::vector<char>& skin,
                                 const std::vector<char>& collider,
                                 const std::vector<Eigen::Vector3d>& inside)
    : name_(std::move(name)), triangles_(topology.triangles()) {
    const Index n = topology.vertexCount();
    auto at = [&](Index v) { return Eigen::Vector3d(&rest[3 * v]); };
    std::vector<std::int32_t> colliderTris;
    orientation_.assign(triangles_.size(), 1.0);
    for (size_t t = 0; t < triangles_.size(); ++t) {
        const auto& tri = triangles_[t];
        if (!collider[tri[0]] || !collider[tri[1]] || !collider[tri[2]]) continue;
        colliderTris.push_back(static_cast<std::int32_t>(t));
        const Eigen::Vector3d a = at(tri[0]), b = at(tri[1]), c = at(tri[2]);
        const Eigen::Vector3d centroid = (a + b + c) / 3.0;
        Eigen::Vector3d centre = inside.front();
        for (const Eigen::Vector3d& p : inside) {
            if ((p - centroid).squaredNorm() < (centre - centroid).squaredNorm()) centre = p;
        }
        orientation_[t] = (b - a).cross(c - a).dot(centroid - centre) >= 0 ? 1.0 : -1.0;
    }
    // Cheap rejection before the exact distance: a bounding sphere per triangle.
    std::vector<Eigen::Vector3d> centroid(colliderTris.size());
    std::vector<double> bound(colliderTris.size());
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = Eigen::Vector3d::Constant(-INFINITY);
    for (size_t i = 0; i < colliderTris.size(); ++i) {
        const auto& tri = triangles_[static_cast<size_t>(colliderTris[i])];
        centroid[i] = (at(tri[0]) + at(tri[1]) + at(tri[2])) / 3.0;
        bound[i] = 0;
        for (std::int32_t u : tri) {
            bound[i] = std::max(bound[i], (at(u) - centroid[i]).norm());
            lo = lo.cwiseMin(at(u));
            hi = hi.cwiseMax(at(u));
        }
    }
    lo.array() -= kCandidateRadius;
    hi.array() += kCandidateRadius;
    zone_ = ContactZone(n);
    for (Index v = 0; v < n; ++v) {
        if (!skin[v] || collider[v]) continue;
        const Eigen::Vector3d x = at(v);
        if ((x.array() < lo.array()).any() || (x.array() > hi.array()).any()) continue;
        double nearest = INFINITY;
        std::vector<std::int32_t> cands;
        for (size_t i = 0; i < colliderTris.size(); ++i) {
            const std::int32_t t = colliderTris[i];
            if ((x - centroid[i]).norm() - bound[i] >= kCandidateRadius) continue;
            const auto& tri = triangles_[static_cast<size_t>(t)];
            const double d = (x - closestPointOnTriangle(x, at(tri[0]), at(tri[1]), at(tri[2]))).norm();
            nearest = std::min(nearest, d);
            if (d < kCandidateRadius) cands.push_back(t);
        }
        if (nearest >= kZoneRadius) continue;
        {
            // A vertex already inside the collider at rest (where the scan's inner lip cuts into
            // a tooth) has no outside to be pushed back to; near such a vertex the nearest
            // triangle, and with it the sign, can flip under a tiny motion. Leave it out.
            double best = INFINITY, s = 0;
            for (std::int32_t t : cands) {
                const auto& tri = triangles_[static_cast<size_t>(t)];
                const Eigen::Vector3d a = at(tri[0]), b = at(tri[1]), c = at(tri[2]);
                const Eigen::Vector3d q = closestPointOnTriangle(x, a, b, c);
                if ((x - q).squaredNorm() < best) {
                    best = (x - q).squaredNorm();
                    s = (x - q).dot(orientation_[static_cast<size_t>(t)] * (b - a).cross(c - a));
                }
            }
            if (s < 0) continue;
        }
        zone_.add(v, cands, triangles_);
    }
}

}  // namespace pmsc::face
