#include "examples/face/FleshDeformer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <utility>

namespace pmsc::face {
namespace {

// Elastic constants of the Kelvinlet (shear modulus 1: the loads are normalized anyway).
constexpr double kA = 1.0 / (4.0 * std::numbers::pi);
constexpr double kB = kA / (4.0 * (1.0 - FleshDeformer::kPoisson));

// Gauss-Legendre nodes and weights on [-1, 1], 5 points.
constexpr std::array<double, 5> kNodes = {-0.9061798459386640, -0.5384693101056831, 0.0, 0.5384693101056831,
                                          0.9061798459386640};
constexpr std::array<double, 5> kWeights = {0.2369268850561891, 0.4786286704993665, 0.5688888888888889,
                                            0.4786286704993665, 0.2369268850561891};
// The part of a muscle that pulls the skin: from 35% of the way from origin to the insertion.
constexpr double kLoadStart = 0.35;
// Where the belly bulges, as a fraction of the way from origin to insertion.
constexpr double kBelly = 0.6;
// Muscles lie under the skin: landmark points are pushed this far towards the head's centre.
const Eigen::Vector3d kHeadCentre(0.0, 1.0, 0.0);

struct Term {
    int control;
    double weight;
};
struct Spec {  // one muscle of the character's left side (+x), mirrored for the right
    const char* name;
    int originA, originB;
    double originT, originDepth;
    Eigen::Vector3d originOffset;
    bool originOnJaw;
    int insertionA, insertionB;
    double insertionT, insertionDepth;
    Eigen::Vector3d insertionOffset;
    bool insertionOnJaw;
    double pull, bulge, width;
    std::vector<Term> drivers;
    bool clench;   // contraction x (1 - jawOpen): the masseter bulges when the jaw is held shut
    bool midline;  // one muscle on the symmetry plane, not mirrored
};

int mirrorControl(int c) {
    const std::string_view name = controlName(c);
    if (name.size() > 2 && name[name.size() - 2] == '_') {
        std::string other(name);
        other.back() = other.back() == 'L' ? 'R' : 'L';
        return controlIndex(other);
    }
    if (c == MouthLeft) return MouthRight;
    if (c == MouthRight) return MouthLeft;
    if (c == JawLeft) return JawRight;
    if (c == JawRight) return JawLeft;
    return c;
}

// Single-scale regularized Kelvinlet displacement for load f at offset r.
inline void kelvinlet(const Eigen::Vector3d& r, const Eigen::Vector3d& f, double eps, Eigen::Vector3d& u) {
    const double r2 = r.squaredNorm() + eps * eps;
    const double inv = 1.0 / std::sqrt(r2);
    const double inv3 = inv * inv * inv;
    const double diag = (kA - kB) * inv + 0.5 * kA * eps * eps * inv3;
    u += diag * f + (kB * inv3 * r.dot(f)) * r;
}

}  // namespace

FleshDeformer::FleshDeformer(const IctFace& face) {
    const std::vector<double>& rest = face.neutral.positions;
    auto landmark = [&](int i) {
        return Eigen::Vector3d(&rest[3 * IctFace::multiPie68()[static_cast<size_t>(i)]]);
    };
    auto place = [&](int a, int b, double t, double depth, const Eigen::Vector3d& offset) -> Eigen::Vector3d {
        const Eigen::Vector3d p = (1 - t) * landmark(a) + t * landmark(b) + offset;
        return p + depth * (kHeadCentre - p).normalized();
    };
    const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
    // Anatomy after the usual textbook placement; landmark numbers are Multi-PIE's (+x side:
    // jaw 9-16, brow 22-26, eye 42-47, nose 34-35, mouth corner 54).
    const std::vector<Spec> specs = {
        {"zygomaticus major",
         15,
         45,
         0.35,
         0.8,
         zero,
         false,
         54,
         54,
         0,
         0.3,
         zero,
         false,
         0.30,
         0.15,
         0.8,
         {{MouthSmileL, 1.0}, {CheekSquintL, 0.3}},
         false,
         false},
        {"levator labii superioris",
         47,
         35,
         0.3,
         0.6,
         zero,
         false,
         52,
         53,
         0.5,
         0.3,
         zero,
         false,
         0.25,
         0.08,
         0.8,
         {{MouthUpperUpL, 1.0}, {NoseSneerL, 0.4}},
         false,
         false},
        {"nasalis",
         28,
         42,
         0.3,
         0.5,
         zero,
         false,
         35,
         35,
         0,
         0.3,
         zero,
         false,
         0.20,
         0.05,
         0.4,
         {{NoseSneerL, 1.0}},
         false,
         false},
        {"depressor anguli oris",
         10,
         10,
         0,
         0.8,
         zero,
         true,
         54,
         54,
         0,
         0.3,
         zero,
         false,
         0.25,
         0.08,
         1.0,
         {{MouthFrownL, 1.0}},
         false,
         false},
        {"depressor labii inferioris",
         9,
         9,
         0,
         0.8,
         zero,
         true,
         55,
         55,
         0,
         0.3,
         zero,
         true,
         0.20,
         0.05,
         0.8,
         {{MouthLowerDownL, 1.0}},
         false,
         false},
        {"mentalis",
         57,
         8,
         0.4,
         1.2,
         Eigen::Vector3d(0.6, 0, 0),
         true,
         57,
         8,
         0.7,
         0.2,
         Eigen::Vector3d(0.6, 0, 0),
         true,
         0.20,
         0.15,
         0.6,
         {{MouthShrugLower, 1.0}},
         false,
         false},
        {"risorius",
         12,
         12,
         0,
         0.5,
         zero,
         false,
         54,
         54,
         0,
         0.3,
         zero,
         false,
         0.25,
         0.05,
         0.6,
         {{MouthStretchL, 1.0}},
         false,
         false},
        {"buccinator",
         12,
         54,
         0.3,
         1.0,
         zero,
         false,
         54,
         54,
         0,
         0.5,
         zero,
         false,
         0.10,
         0.25,
         1.2,
         {{MouthStretchL, 0.3}, {CheekPuffL, 1.0}},
         false,
         false},
        {"frontalis (medial)",
         22,
         22,
         0,
         0.5,
         Eigen::Vector3d(0, 4.5, -1.5),
         false,
         22,
         22,
         0,
         0.3,
         Eigen::Vector3d(0, 0.5, 0),
         false,
         0.25,
         0.03,
         1.5,
         {{BrowInnerUpL, 1.0}},
         false,
         false},
        {"frontalis (lateral)",
         25,
         25,
         0,
         0.5,
         Eigen::Vector3d(0, 4.5, -1.5),
         false,
         25,
         25,
         0,
         0.3,
         Eigen::Vector3d(0, 0.5, 0),
         false,
         0.25,
         0.03,
         1.5,
         {{BrowOuterUpL, 1.0}},
         false,
         false},
        {"corrugator",
         22,
         27,
         0.5,
         0.6,
         zero,
         false,
         23,
         23,
         0,
         0.3,
         Eigen::Vector3d(0, 0.3, 0),
         false,
         0.20,
         0.10,
         0.5,
         {{BrowDownL, 1.0}},
         false,
         false},
        {"orbicularis oculi (lower)",
         42,
         45,
         0.5,
         1.0,
         zero,
         false,
         46,
         47,
         0.5,
         0.2,
         Eigen::Vector3d(0, -1.0, 0.2),
         false,
         0.15,
         0.10,
         1.2,
         {{EyeSquintL, 1.0}, {CheekSquintL, 0.5}},
         false,
         false},
        {"orbicularis oculi (lateral)",
         42,
         45,
         0.5,
         1.0,
         zero,
         false,
         45,
         45,
         0,
         0.2,
         Eigen::Vector3d(0.9, 0, -0.4),
         false,
         0.15,
         0.08,
         1.0,
         {{EyeSquintL, 1.0}},
         false,
         false},
        {"masseter",
         14,
         15,
         0.5,
         0.8,
         Eigen::Vector3d(-0.6, 0, 0.8),
         false,
         12,
         12,
         0,
         0.8,
         Eigen::Vector3d(0, 0.3, 0),
         true,
         0.15,
         0.20,
         1.5,
         {{MouthPressL, 1.0}},
         true,
         false},
        {"platysma",
         12,
         12,
         0,
         0.3,
         Eigen::Vector3d(-1.0, -7.0, -1.0),
         false,
         10,
         11,
         0.5,
         0.3,
         zero,
         true,
         0.20,
         0.05,
         2.0,
         {{MouthStretchL, 0.7}, {MouthFrownL, 0.3}, {JawOpen, 0.2}},
         false,
         false},
        {"procerus",
         28,
         28,
         0,
         0.5,
         zero,
         false,
         21,
         22,
         0.5,
         0.3,
         Eigen::Vector3d(0, 0.2, 0),
         false,
         0.20,
         0.05,
         0.6,
         {{BrowDownL, 0.5}, {BrowDownR, 0.5}, {NoseSneerL, 0.25}, {NoseSneerR, 0.25}},
         false,
         true},
    };
    for (const Spec& s : specs) {
        for (int side = 0; side < (s.midline ? 1 : 2); ++side) {
            Muscle m;
            m.name = s.midline ? std::string(s.name) : std::string(s.name) + (side == 0 ? " L" : " R");
            m.origin = place(s.originA, s.originB, s.originT, s.originDepth, s.originOffset);
            m.insertion =
                place(s.insertionA, s.insertionB, s.insertionT, s.insertionDepth, s.insertionOffset);
            if (side == 1) {
                m.origin[0] = -m.origin[0];
                m.insertion[0] = -m.insertion[0];
            }
            m.originOnJaw = s.originOnJaw;
            m.insertionOnJaw = s.insertionOnJaw;
            m.pull = s.pull;
            m.bulge = s.bulge;
            m.width = s.width;
            // A muscle's field spans about a third of its length, at least a few vertex rings.
            m.radius = std::clamp((m.insertion - m.origin).norm() / 3.0, 0.6, 2.0);
            m.outward = ((1 - kBelly) * m.origin + kBelly * m.insertion - kHeadCentre).normalized();
            std::vector<Term> drivers = s.drivers;
            if (side == 1) {
                for (Term& t : drivers) t.control = mirrorControl(t.control);
            }
            const bool clench = s.clench;
            m.contraction = [drivers, clench](const ControlVector& c) {
                double sum = 0;
                for (const Term& t : drivers) sum += t.weight * c[t.control];
                sum = std::clamp(sum, 0.0, 1.0);
                return clench ? sum * (1.0 - std::clamp(c[JawOpen], 0.0, 1.0)) : sum;
            };
            muscles_.push_back(std::move(m));
        }
    }
}

FleshDeformer::Pose FleshDeformer::prepare(const ControlVector& controls, const RigidTransform& jaw) const {
    Pose pose;
    const double normalization = 2.0 / (1.5 * kA - kB);  // bi-scale load giving displacement g at the centre
    for (const Muscle& m : muscles_) {
        const double c = m.contraction(controls);
        if (c <= 0) continue;  // no load, no field: skipping it is exact
        const Eigen::Vector3d origin = m.originOnJaw ? jaw(m.origin) : m.origin;
        const Eigen::Vector3d insertion = m.insertionOnJaw ? jaw(m.insertion) : m.insertion;
        const Eigen::Vector3d outward =
            m.insertionOnJaw ? Eigen::Vector3d(jaw.rotation * m.outward) : m.outward;
        const Eigen::Vector3d fibre = origin - insertion;
        const double length = fibre.norm();
        if (!(length > 0)) continue;
        const Eigen::Vector3d direction = fibre / length;
        Eigen::Vector3d across = direction.cross(outward);
        across = across.norm() > 1e-9 ? across.normalized() : Eigen::Vector3d(direction.unitOrthogonal());
        const double eps = m.radius;
        for (int f = 0; f < kFibres; ++f) {
            const double offset =
                kFibres > 1 ? m.width * (static_cast<double>(f) / (kFibres - 1) - 0.5) : 0.0;
            const Eigen::Vector3d shift = offset * across;
            for (int k = 0; k < kQuadrature; ++k) {
                const double t =
                    kLoadStart + (1 - kLoadStart) * 0.5 * (kNodes[k] + 1);  // origin 0, insertion 1
                const Eigen::Vector3d centre = origin + t * (insertion - origin) + shift;
                const double w =
                    0.5 * kWeights[k] / kFibres;  // quadrature weights of [0, 1], split over fibres
                pose.samples.push_back({centre, (c * m.pull * w * normalization * eps) * direction, eps});
            }
            const Eigen::Vector3d belly = origin + kBelly * (insertion - origin) + shift;
            pose.samples.push_back({belly, (c * m.bulge / kFibres * normalization * eps) * outward, eps});
        }
    }
    return pose;
}

Eigen::Vector3d FleshDeformer::displacement(const Eigen::Vector3d& x, const Pose& pose) const {
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    for (const Sample& sample : pose.samples) {
        const Eigen::Vector3d r = x - sample.centre;
        kelvinlet(r, sample.force, sample.radius, u);
        kelvinlet(r, -sample.force, 2 * sample.radius,
                  u);  // bi-scale: minus the same load at twice the radius
    }
    return u;
}

}  // namespace pmsc::face
