// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/ContactZone.h"
#include "evaluators/face/IctFace.h"
#include "evaluators/face/MeshTopology.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

namespace pmsc::face {

/// Lip contact and sticky lips: the last deformer of the rig, so nothing pushes the lips back
/// into each other after it.
///
/// Blendshapes add straight-line motions, so pressing (mouthPress, mouthRollLower, mouthClose
/// without jawOpen) drives one lip through the other. For every vertex of the lip zone the
/// deformer finds the closest point of the opposite lip's surface among candidate triangles and
/// its signed distance s along that triangle's outward normal. A penetration deeper than the
/// vertex had at rest (the scan's lips touch, a few vertices dip in by up to 0.08) pushes the
/// vertex out by half the depth (the opposite lip takes the other half), with a C1 ramp over the
/// first kContactSoftness units so the response has no kink. One Jacobi pass: each lip reads
/// the other's positions before contact, so a deep press is reduced (by about half in the
/// tests), not fully resolved. Lips that just parted (0 < s <
/// kStickRange) are pulled back together by lipStick x a stickiness that fades from the middle
/// of the mouth to its corners: the lips peel apart from the corners as the jaw opens.
///
/// Cost is uneven and needs a neighbourhood: only lip vertices pay, each testing the ~300
/// opposite-lip triangles within kCandidateRadius at rest (the relative slide of the lips under
/// jawLeft/jawRight/mouthLeft/mouthRight stays within that radius), and a lip vertex needs the
/// posed positions of all of those triangles' vertices.
class LipContact {
public:
    static constexpr double kBoxMargin = 0.8;         ///< mouth box around Multi-PIE points 48-67
    static constexpr double kBoxDepth = 2.5;          ///< how far behind the lip line the box reaches
    static constexpr double kZoneRadius = 0.6;        ///< a lip vertex has the other lip this close at rest
    static constexpr double kCandidateRadius = 1.0;   ///< opposite-lip triangles tested per vertex
    static constexpr double kContactSoftness = 0.05;  ///< width of the C1 onset of the push
    static constexpr double kStickRange = 0.4;        ///< separation at which sticky lips let go

    /// @param jawWeights skinning weights (JawDeformer::weights()): >= 0.5 is the lower lip.
    LipContact(const IctFace& face, const MeshTopology& topology, const std::vector<double>& jawWeights);

    /// True for vertices inside the mouth box (either lip side), the only vertices whose posed
    /// positions the contact reads.
    bool inMouthBox(Index v) const { return side_[static_cast<size_t>(v)] >= 0; }
    /// True for vertices of the lip zone.
    bool inZone(Index v) const { return zone_.contains(v); }
    /// Number of lip zone vertices.
    Index zoneSize() const { return zone_.size(); }
    const std::vector<Index>& zoneVertices() const { return zone_.vertices(); }
    /// Vertices whose posed positions the contact of zone vertex v reads (its candidate
    /// triangles' corners), ascending.
    std::span<const std::int32_t> inputVertices(Index v) const { return zone_.inputVertices(v); }
    /// Candidate triangles (indices into MeshTopology::triangles()) of zone vertex v.
    std::span<const std::int32_t> candidates(Index v) const { return zone_.candidates(v); }

    /// Displacement along the opposite lip's outward normal for a signed distance s and a
    /// stickiness (lipStick x the vertex's stickiness): half the C1-ramped penetration, minus
    /// the sticky pull.
    static double response(double s, double stick);

    /// The contact of zone vertex v at posed position x; `posed(u)` returns the posed position
    /// of vertex u for every u in inputVertices(v). Vertices outside the zone are returned as is.
    template <class Posed>
    Eigen::Vector3d apply(Index v, const Eigen::Vector3d& x, double lipStick, const Posed& posed) const;

    /// The stickiness of zone vertex v in [0, 1] (1 mid-mouth, 0 at the corners).
    double stickiness(Index v) const { return stickiness_[static_cast<size_t>(zone_.index(v))]; }

private:
    const std::vector<std::array<std::int32_t, 3>>& triangles_;
    std::vector<std::int8_t> side_;  // per vertex: 0 upper lip, 1 lower lip, -1 outside the mouth box
    ContactZone zone_;
    std::vector<double> stickiness_;  // per zone vertex
    std::vector<double> allowance_;   // per zone vertex: min(0, signed distance at rest)
    double orientation_ = 1.0;        // +1 if triangle winding gives outward normals, else -1
};

/// Closest point of triangle (a, b, c) to p (Ericson, Real-Time Collision Detection, 5.1.5).
Eigen::Vector3d closestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c);

template <class Posed>
Eigen::Vector3d LipContact::apply(Index v, const Eigen::Vector3d& x, double lipStick,
                                  const Posed& posed) const {
    const std::int32_t z = zone_.index(v);
    if (z < 0) return x;
    double best = INFINITY;
    Eigen::Vector3d nearest = x;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    for (std::int32_t t : candidates(v)) {
        const auto& tri = triangles_[static_cast<size_t>(t)];
        const Eigen::Vector3d a = posed(tri[0]);
        const Eigen::Vector3d b = posed(tri[1]);
        const Eigen::Vector3d c = posed(tri[2]);
        const Eigen::Vector3d q = closestPointOnTriangle(x, a, b, c);
        const double d2 = (x - q).squaredNorm();
        if (d2 < best) {  // strict: the first of equally near triangles wins, in a fixed order
            best = d2;
            nearest = q;
            normal = (b - a).cross(c - a);
        }
    }
    const double len = normal.norm();
    if (!(len > 0)) return x;
    normal *= orientation_ / len;
    const double s = (x - nearest).dot(normal);
    const double allowance = allowance_[static_cast<size_t>(z)];
    const double push =
        s < 0 ? response(s - allowance, 0.0) : response(s, lipStick * stickiness_[static_cast<size_t>(z)]);
    return x + push * normal;
}

}  // namespace pmsc::face
