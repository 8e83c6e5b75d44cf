#include "evaluators/face/FleshDeformer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <numbers>
#include <string>
#include <utility>
#include <vector>

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

/// One control driving a muscle, and its weight in the muscle's contraction.
struct Term {
    int control;
    double weight;
};
/// An offset in model units (x: towards the character's left).
struct Offset {
    double x = 0, y = 0, z = 0;
};
/// Where one end of a muscle sits: `t` of the way from Multi-PIE landmark `a` to landmark `b`,
/// moved by `offset`, then `depth` under the skin (towards the head's centre); on the skull, or on
/// the jaw (moving with it).
struct Anchor {
    int a = 0, b = 0;
    double t = 0, depth = 0;
    Offset offset{};
    bool onJaw = false;
};
/// One muscle of the character's left side (+x), mirrored for the right.
struct Spec {
    const char* name = "";
    Anchor origin, insertion;
    double pull = 0, bulge = 0, width = 0;
    Term drivers[4] = {};  // the controls that contract it; entries of weight 0 are unused
    bool clench = false;   // contraction x (1 - jawOpen): the masseter bulges when the jaw is held shut
    bool midline = false;  // one muscle on the symmetry plane, not mirrored
};

// Anatomy after the usual textbook placement; landmark numbers are Multi-PIE's (+x side:
// jaw 9-16, brow 22-26, eye 42-47, nose 34-35, mouth corner 54).
constexpr Spec kMuscles[] = {
    {.name = "zygomaticus major",
     .origin = {.a = 15, .b = 45, .t = 0.35, .depth = 0.8},
     .insertion = {.a = 54, .b = 54, .t = 0, .depth = 0.3},
     .pull = 0.30,
     .bulge = 0.15,
     .width = 0.8,
     .drivers = {{MouthSmileL, 1.0}, {CheekSquintL, 0.3}}},
    {.name = "levator labii superioris",
     .origin = {.a = 47, .b = 35, .t = 0.3, .depth = 0.6},
     .insertion = {.a = 52, .b = 53, .t = 0.5, .depth = 0.3},
     .pull = 0.25,
     .bulge = 0.08,
     .width = 0.8,
     .drivers = {{MouthUpperUpL, 1.0}, {NoseSneerL, 0.4}}},
    {.name = "nasalis",
     .origin = {.a = 28, .b = 42, .t = 0.3, .depth = 0.5},
     .insertion = {.a = 35, .b = 35, .t = 0, .depth = 0.3},
     .pull = 0.20,
     .bulge = 0.05,
     .width = 0.4,
     .drivers = {{NoseSneerL, 1.0}}},
    {.name = "depressor anguli oris",
     .origin = {.a = 10, .b = 10, .t = 0, .depth = 0.8, .onJaw = true},
     .insertion = {.a = 54, .b = 54, .t = 0, .depth = 0.3},
     .pull = 0.25,
     .bulge = 0.08,
     .width = 1.0,
     .drivers = {{MouthFrownL, 1.0}}},
    {.name = "depressor labii inferioris",
     .origin = {.a = 9, .b = 9, .t = 0, .depth = 0.8, .onJaw = true},
     .insertion = {.a = 55, .b = 55, .t = 0, .depth = 0.3, .onJaw = true},
     .pull = 0.20,
     .bulge = 0.05,
     .width = 0.8,
     .drivers = {{MouthLowerDownL, 1.0}}},
    {.name = "mentalis",
     .origin = {.a = 57, .b = 8, .t = 0.4, .depth = 1.2, .offset = {.x = 0.6}, .onJaw = true},
     .insertion = {.a = 57, .b = 8, .t = 0.7, .depth = 0.2, .offset = {.x = 0.6}, .onJaw = true},
     .pull = 0.20,
     .bulge = 0.15,
     .width = 0.6,
     .drivers = {{MouthShrugLower, 1.0}}},
    {.name = "risorius",
     .origin = {.a = 12, .b = 12, .t = 0, .depth = 0.5},
     .insertion = {.a = 54, .b = 54, .t = 0, .depth = 0.3},
     .pull = 0.25,
     .bulge = 0.05,
     .width = 0.6,
     .drivers = {{MouthStretchL, 1.0}}},
    {.name = "buccinator",
     .origin = {.a = 12, .b = 54, .t = 0.3, .depth = 1.0},
     .insertion = {.a = 54, .b = 54, .t = 0, .depth = 0.5},
     .pull = 0.10,
     .bulge = 0.25,
     .width = 1.2,
     .drivers = {{MouthStretchL, 0.3}, {CheekPuffL, 1.0}}},
    {.name = "frontalis (medial)",
     .origin = {.a = 22, .b = 22, .t = 0, .depth = 0.5, .offset = {.y = 4.5, .z = -1.5}},
     .insertion = {.a = 22, .b = 22, .t = 0, .depth = 0.3, .offset = {.y = 0.5}},
     .pull = 0.25,
     .bulge = 0.03,
     .width = 1.5,
     .drivers = {{BrowInnerUpL, 1.0}}},
    {.name = "frontalis (lateral)",
     .origin = {.a = 25, .b = 25, .t = 0, .depth = 0.5, .offset = {.y = 4.5, .z = -1.5}},
     .insertion = {.a = 25, .b = 25, .t = 0, .depth = 0.3, .offset = {.y = 0.5}},
     .pull = 0.25,
     .bulge = 0.03,
     .width = 1.5,
     .drivers = {{BrowOuterUpL, 1.0}}},
    {.name = "corrugator",
     .origin = {.a = 22, .b = 27, .t = 0.5, .depth = 0.6},
     .insertion = {.a = 23, .b = 23, .t = 0, .depth = 0.3, .offset = {.y = 0.3}},
     .pull = 0.20,
     .bulge = 0.10,
     .width = 0.5,
     .drivers = {{BrowDownL, 1.0}}},
    {.name = "orbicularis oculi (lower)",
     .origin = {.a = 42, .b = 45, .t = 0.5, .depth = 1.0},
     .insertion = {.a = 46, .b = 47, .t = 0.5, .depth = 0.2, .offset = {.y = -1.0, .z = 0.2}},
     .pull = 0.15,
     .bulge = 0.10,
     .width = 1.2,
     .drivers = {{EyeSquintL, 1.0}, {CheekSquintL, 0.5}}},
    {.name = "orbicularis oculi (lateral)",
     .origin = {.a = 42, .b = 45, .t = 0.5, .depth = 1.0},
     .insertion = {.a = 45, .b = 45, .t = 0, .depth = 0.2, .offset = {.x = 0.9, .z = -0.4}},
     .pull = 0.15,
     .bulge = 0.08,
     .width = 1.0,
     .drivers = {{EyeSquintL, 1.0}}},
    {.name = "masseter",
     .origin = {.a = 14, .b = 15, .t = 0.5, .depth = 0.8, .offset = {.x = -0.6, .z = 0.8}},
     .insertion = {.a = 12, .b = 12, .t = 0, .depth = 0.8, .offset = {.y = 0.3}, .onJaw = true},
     .pull = 0.15,
     .bulge = 0.20,
     .width = 1.5,
     .drivers = {{MouthPressL, 1.0}},
     .clench = true},
    {.name = "platysma",
     .origin = {.a = 12, .b = 12, .t = 0, .depth = 0.3, .offset = {.x = -1.0, .y = -7.0, .z = -1.0}},
     .insertion = {.a = 10, .b = 11, .t = 0.5, .depth = 0.3, .onJaw = true},
     .pull = 0.20,
     .bulge = 0.05,
     .width = 2.0,
     .drivers = {{MouthStretchL, 0.7}, {MouthFrownL, 0.3}, {JawOpen, 0.2}}},
    {.name = "procerus",
     .origin = {.a = 28, .b = 28, .t = 0, .depth = 0.5},
     .insertion = {.a = 21, .b = 22, .t = 0.5, .depth = 0.3, .offset = {.y = 0.2}},
     .pull = 0.20,
     .bulge = 0.05,
     .width = 0.6,
     .drivers = {{BrowDownL, 0.5}, {BrowDownR, 0.5}, {NoseSneerL, 0.25}, {NoseSneerR, 0.25}},
     .midline = true},
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

/// A muscle end placed at rest (before mirroring).
Eigen::Vector3d placeAnchor(const std::vector<double>& rest, const Anchor& end) {
    auto landmark = [&](int i) {
        return Eigen::Vector3d(&rest[3 * IctFace::multiPie68()[static_cast<size_t>(i)]]);
    };
    const Eigen::Vector3d offset(end.offset.x, end.offset.y, end.offset.z);
    const Eigen::Vector3d p = (1 - end.t) * landmark(end.a) + end.t * landmark(end.b) + offset;
    return p + end.depth * (kHeadCentre - p).normalized();
}

/// The contraction of a muscle of `s` on `side` (0: left, 1: right, its drivers mirrored).
std::function<double(const ControlVector&)> contraction(const Spec& s, int side) {
    std::vector<Term> drivers;
    for (const Term& t : s.drivers)
        if (t.weight != 0) drivers.push_back(t);
    if (side == 1) {
        for (Term& t : drivers) t.control = mirrorControl(t.control);
    }
    const bool clench = s.clench;
    return [drivers, clench](const ControlVector& c) {
        double sum = 0;
        for (const Term& t : drivers) sum += t.weight * c[t.control];
        sum = std::clamp(sum, 0.0, 1.0);
        return clench ? sum * (1.0 - std::clamp(c[JawOpen], 0.0, 1.0)) : sum;
    };
}

/// The muscle of `s` on `side` (0: left, 1: right, mirrored in x), placed at rest.
FleshDeformer::Muscle placeMuscle(const std::vector<double>& rest, const Spec& s, int side) {
    FleshDeformer::Muscle m;
    m.name = s.midline ? std::string(s.name) : std::string(s.name) + (side == 0 ? " L" : " R");
    m.origin = placeAnchor(rest, s.origin);
    m.insertion = placeAnchor(rest, s.insertion);
    if (side == 1) {
        m.origin[0] = -m.origin[0];
        m.insertion[0] = -m.insertion[0];
    }
    m.originOnJaw = s.origin.onJaw;
    m.insertionOnJaw = s.insertion.onJaw;
    m.pull = s.pull;
    m.bulge = s.bulge;
    m.width = s.width;
    // A muscle's field spans about a third of its length, at least a few vertex rings.
    m.radius = std::clamp((m.insertion - m.origin).norm() / 3.0, 0.6, 2.0);
    m.outward = ((1 - kBelly) * m.origin + kBelly * m.insertion - kHeadCentre).normalized();
    m.contraction = contraction(s, side);
    return m;
}

}  // namespace

FleshDeformer::FleshDeformer(const IctFace& face) {
    for (const Spec& s : kMuscles) {
        for (int side = 0; side < (s.midline ? 1 : 2); ++side)
            muscles_.push_back(placeMuscle(face.neutral.positions, s, side));
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
