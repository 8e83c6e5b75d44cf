// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/ContactZone.h"
#include "evaluators/face/LipContact.h"
#include "evaluators/face/MeshTopology.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace pmsc::face {

/// One-sided contact of skin against a rigid part that moves under it: the eyelids against the
/// eyeballs, which turn with the gaze and carry the cornea's bulge under the lids. (The same
/// class does not serve the lips against the teeth: see FaceRig.)
///
/// A vertex of the contact zone (a candidate skin vertex within kZoneRadius of the collider at
/// rest, and outside it: vertices the scan already has inside are left out) finds the closest point of the
/// collider among its candidate triangles (within kCandidateRadius at rest) and its signed distance s along
/// that triangle's outward normal. A penetration (s < 0) is pushed out with the C1 ramp of
/// LipContact::response, in full: the collider does not give way. The rest pose is untouched.
///
/// Uneven cost and a neighbourhood: only zone vertices pay, each testing its candidate
/// triangles, and each needs the posed collider vertices of those triangles.
class ColliderContact {
public:
    static constexpr double kZoneRadius = 0.5;
    static constexpr double kCandidateRadius = 0.8;

    /// @param rest      rest positions (3 per vertex)
    /// @param skin      per vertex: may this vertex touch the collider?
    /// @param collider  per vertex: is it part of the collider? Its triangles are those with
    ///                  all three corners in the collider.
    /// @param inside    a point inside the collider at rest for each collider triangle's side
    ///                  test: normals are oriented away from the nearest of these points.
    ColliderContact(std::string name, const std::vector<double>& rest, const MeshTopology& topology,
                    const std::vector<char>& skin, const std::vector<char>& collider,
                    const std::vector<Eigen::Vector3d>& inside);

    const std::string& name() const { return name_; }
    bool inZone(Index v) const { return zone_.contains(v); }
    Index zoneSize() const { return zone_.size(); }
    const std::vector<Index>& zoneVertices() const { return zone_.vertices(); }
    /// Collider vertices the contact of zone vertex v reads, ascending.
    std::span<const std::int32_t> inputVertices(Index v) const { return zone_.inputVertices(v); }
    std::span<const std::int32_t> candidates(Index v) const { return zone_.candidates(v); }
    /// Signed distance of zone vertex v at x to the posed collider (outward positive), and the
    /// outward normal of the nearest triangle.
    template <class Posed>
    double signedDistance(Index v, const Eigen::Vector3d& x, const Posed& posed,
                          Eigen::Vector3d& normal) const;
    /// The contact of zone vertex v at x; other vertices are returned as is.
    template <class Posed>
    Eigen::Vector3d apply(Index v, const Eigen::Vector3d& x, const Posed& posed) const;

private:
    std::string name_;
    const std::vector<std::array<std::int32_t, 3>>& triangles_;
    std::vector<double> orientation_;  // per triangle: +1 or -1 so that the winding normal points outward
    ContactZone zone_;
};

template <class Posed>
double ColliderContact::signedDistance(Index v, const Eigen::Vector3d& x, const Posed& posed,
                                       Eigen::Vector3d& normal) const {
    double best = INFINITY;
    Eigen::Vector3d nearest = x;
    normal = Eigen::Vector3d::Zero();
    for (std::int32_t t : candidates(v)) {
        const auto& tri = triangles_[static_cast<size_t>(t)];
        const Eigen::Vector3d a = posed(tri[0]);
        const Eigen::Vector3d b = posed(tri[1]);
        const Eigen::Vector3d c = posed(tri[2]);
        const Eigen::Vector3d q = closestPointOnTriangle(x, a, b, c);
        const double d2 = (x - q).squaredNorm();
        if (d2 < best) {
            best = d2;
            nearest = q;
            normal = orientation_[static_cast<size_t>(t)] * (b - a).cross(c - a);
        }
    }
    const double len = normal.norm();
    if (!(len > 0)) return INFINITY;
    normal /= len;
    return (x - nearest).dot(normal);
}

template <class Posed>
Eigen::Vector3d ColliderContact::apply(Index v, const Eigen::Vector3d& x, const Posed& posed) const {
    if (!zone_.contains(v)) return x;
    Eigen::Vector3d normal;
    const double s = signedDistance(v, x, posed, normal);
    if (!std::isfinite(s)) return x;
    // LipContact::response pushes by half (two lips share a contact); the collider is rigid.
    const double push = 2.0 * LipContact::response(s, 0.0);
    return x + push * normal;
}

}  // namespace pmsc::face
