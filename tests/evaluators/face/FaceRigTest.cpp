#include "evaluators/face/FaceRig.h"
#include "tests/common/FaceTestData.h"

#include <gtest/gtest.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstring>
#include <numeric>
#include <random>
#include <vector>

namespace pmsc::face {
namespace {

using test::fixture;

// A busy pose: speech, emotion, a half blink, a glance, sticky lips and lips pressed shut
// (contact at work), the jaw slightly open and to the side.
ControlVector busyPose() {
    ControlVector c = restPose();
    c[JawOpen] = 0.35;
    c[JawLeft] = 0.4;
    c[MouthSmileL] = 0.6;
    c[CheekSquintL] = 0.5;
    c[MouthPressL] = 0.5;
    c[MouthPressR] = 0.4;
    c[MouthClose] = 0.5;
    c[MouthRollLower] = 0.3;
    c[BrowInnerUpR] = 0.7;
    c[BrowDownL] = 0.4;
    c[EyeBlinkL] = 0.5;
    c[EyeBlinkR] = 0.8;
    c[GazeYaw] = 18;
    c[GazePitch] = 12;
    c[GazeDistance] = 40;
    c[LipStick] = 0.7;
    c[CheekPuffR] = 0.5;
    return c;
}

std::vector<double> poseAll(const ControlVector& c) {
    std::vector<double> out(static_cast<size_t>(3 * fixture().rig->pointCount()));
    fixture().rig->evaluateAll(c, out.data());
    return out;
}

Eigen::Vector3d at(const std::vector<double>& p, Index v) { return {p[3 * v], p[3 * v + 1], p[3 * v + 2]}; }

TEST(FaceRig, SubsetsEqualTheFullPoseBitForBit) {
    PMSC_REQUIRE_ICT();
    const FaceRig& rig = *fixture().rig;
    const ControlVector c = busyPose();
    const std::vector<double> full = poseAll(c);
    std::mt19937 rng(3);
    std::vector<std::vector<Index>> subsets;
    subsets.emplace_back(IctFace::multiPie68().begin(), IctFace::multiPie68().end());
    subsets.push_back(rig.lipContact().zoneVertices());  // every lip contact vertex
    subsets.push_back(rig.lidContact().zoneVertices());
    for (int k = 0; k < 6; ++k) {  // random subsets in random order, from 1 to 2000 points
        std::vector<Index> s(static_cast<size_t>(rig.pointCount()));
        std::iota(s.begin(), s.end(), Index{0});
        std::shuffle(s.begin(), s.end(), rng);
        s.resize(static_cast<size_t>(1 + k * 400));
        subsets.push_back(s);
    }
    for (const auto& s : subsets) {
        std::vector<double> out(3 * s.size());
        rig.evaluate(c, s, out.data());
        for (size_t i = 0; i < s.size(); ++i) {
            ASSERT_EQ(std::memcmp(&out[3 * i], &full[3 * s[i]], 3 * sizeof(double)), 0)
                << "point " << s[i] << " differs when posed in a subset of " << s.size();
        }
    }
}

TEST(FaceRig, KeysCostFarLessThanTheFullPose) {
    PMSC_REQUIRE_ICT();
    // Not a timing: the dependency closure of the 68 fiducials is a small part of the face.
    const auto closure = fixture().rig->closureSize(
        std::vector<Index>(IctFace::multiPie68().begin(), IctFace::multiPie68().end()));
    EXPECT_LT(closure.blendshapes, fixture().rig->pointCount() / 8);
    EXPECT_GE(closure.blendshapes, 68);
    EXPECT_GE(closure.relax, 68);
}

TEST(FaceRig, DeterministicAcrossThreadCountsAndChunkings) {
    PMSC_REQUIRE_ICT();
    const FaceRig& rig = *fixture().rig;
    const ControlVector c = busyPose();
    const Index n = rig.pointCount();
    auto chunked = [&](int threads, Index chunk) {
        std::vector<double> out(static_cast<size_t>(3 * n));
        tbb::task_arena arena(threads);
        arena.execute([&] {
            tbb::parallel_for(Index{0}, (n + chunk - 1) / chunk, [&](Index b) {
                std::vector<Index> points;
                for (Index v = b * chunk; v < std::min(n, (b + 1) * chunk); ++v) points.push_back(v);
                rig.evaluate(c, points, out.data() + 3 * b * chunk);
            });
        });
        return out;
    };
    const std::vector<double> serial = poseAll(c);
    EXPECT_EQ(chunked(1, 997), serial);
    EXPECT_EQ(chunked(2, 256), serial);
    EXPECT_EQ(chunked(2, 4096), serial);
}

TEST(FaceRig, RestPoseIsTheNeutralMesh) {
    PMSC_REQUIRE_ICT();
    // Contacts use the rest clearance as allowance, sticky lips are off, and the eyes look at
    // infinity (the rest pose's 60-unit target makes them converge by 3 degrees), so posing leaves
    // the scan where it is: relax and flesh act on displacements, which are zero.
    ControlVector c = restPose();
    c[GazeDistance] = 1e9;
    const std::vector<double> posed = poseAll(c);
    const std::vector<double>& rest = fixture().rig->restPositions();
    double worst = 0;
    for (size_t i = 0; i < rest.size(); ++i) worst = std::max(worst, std::abs(posed[i] - rest[i]));
    EXPECT_LT(worst, 1e-6);  // a target at 1e9 still turns the eyes by ~1e-7 degrees
}

TEST(FaceRig, JawRotatesTheLowerTeethRigidlyAboutItsHinge) {
    PMSC_REQUIRE_ICT();
    const FaceRig& rig = *fixture().rig;
    const VertexRegion& lower = IctFace::region("teeth_lower");
    const JawDeformer& jaw = rig.jaw();
    EXPECT_NEAR(jaw.openAngle() * 180 / 3.141592653589793, 25.3, 0.2);  // read off the jawOpen scan
    for (double open : {0.25, 0.5, 1.0}) {
        ControlVector c = restPose();
        c[JawOpen] = open;
        const std::vector<double> posed = poseAll(c);
        const RigidTransform t =
            RigidTransform::aboutAxis(jaw.hingeAxis(), open * jaw.openAngle(), jaw.pivot());
        double worst = 0;
        for (Index v = lower.first; v <= lower.last; v += 7) {
            // Lower teeth: weight 1, no relax, no flesh, no contact: the bone's rotation exactly,
            // plus the jawOpen residual (the scan's teeth are not perfectly rigid: < 0.025).
            const Eigen::Vector3d rest(&rig.restPositions()[3 * v]);
            worst = std::max(worst, (at(posed, v) - t(rest)).norm());
        }
        EXPECT_LT(worst, 0.025 * open + 1e-9) << "open " << open;
    }
}

TEST(FaceRig, JawOpenAtOneReproducesTheScanOnTheChin) {
    PMSC_REQUIRE_ICT();
    // Skinning plus the residual corrective reproduce the scan by construction; the chin is out of
    // the relax band, the mouth box and the contact zones, so only flesh (platysma, 0.2 x jawOpen)
    // moves it further.
    const IctFace& face = fixture().face;
    ControlVector c = restPose();
    c[JawOpen] = 1.0;
    const std::vector<double> posed = poseAll(c);
    const auto& delta = face.deltas[face.expression("jawOpen")];
    const Index chin = IctFace::multiPie68()[8];
    const Eigen::Vector3d scan =
        Eigen::Vector3d(&face.neutral.positions[3 * chin]) + Eigen::Vector3d(&delta[3 * chin]);
    EXPECT_LT((at(posed, chin) - scan).norm(), 0.15);
    EXPECT_GT(Eigen::Vector3d(&delta[3 * chin]).norm(), 3.0);  // and the chin did travel
}

TEST(FaceRig, EyelidsRotateOnSpheresAboutTheEyeCentres) {
    PMSC_REQUIRE_ICT();
    const EyelidDeformer& lids = fixture().rig->eyelids();
    Index lidVertices = 0;
    for (Index v = 0; v < fixture().rig->pointCount(); ++v) {
        const int e = lids.eyeOf(v);
        if (e < 0) continue;
        ++lidVertices;
        const Eigen::Vector3d q(&fixture().rig->restPositions()[3 * v]);
        for (double blink : {0.3, 1.0}) {
            const Eigen::Vector3d p = lids.apply(v, q, {blink, blink});
            EXPECT_NEAR((p - lids.centre(e)).norm(), (q - lids.centre(e)).norm(), 1e-12);
            EXPECT_DOUBLE_EQ(p[0], q[0]);  // the axis is the eye's horizontal (x) axis
        }
    }
    EXPECT_GT(lidVertices, 1000);
    // The upper lid closes by a large angle; the sclera fit is the ICT eyeball (radius ~1.58).
    EXPECT_NEAR(lids.eyeballRadius(0), 1.577, 0.01);
    EXPECT_NEAR(lids.centre(0)[0], -lids.centre(1)[0], 1e-9);
}

TEST(FaceRig, BlinkClosesTheLidOverTheEyeNotThroughIt) {
    PMSC_REQUIRE_ICT();
    const FaceRig& rig = *fixture().rig;
    const IctFace& face = fixture().face;
    // Upper lid landmark (Multi-PIE 43, left eye) at full blink reaches the scan's closed lid.
    const Index lid = IctFace::multiPie68()[43];
    ASSERT_EQ(rig.eyelids().eyeOf(lid), 0);
    ControlVector c = restPose();
    c[EyeBlinkL] = 1.0;
    const auto& delta = face.deltas[face.expression("eyeBlink_L")];
    const std::vector<double> closed = poseAll(c);
    EXPECT_LT((at(closed, lid) - Eigen::Vector3d(&face.neutral.positions[3 * lid]) -
               Eigen::Vector3d(&delta[3 * lid]))
                  .norm(),
              0.1);
    // Halfway, lid vertices that rotate by more than 20 degrees travel on arcs about the eye
    // centre, outside the straight chords a blendshape would follow.
    c[EyeBlinkL] = 0.5;
    const std::vector<double> half = poseAll(c);
    const Eigen::Vector3d centre = rig.eyelids().centre(0);
    double outside = 0;
    Index counted = 0;
    for (Index v = 0; v < rig.pointCount(); ++v) {
        if (rig.eyelids().eyeOf(v) != 0 || std::abs(rig.eyelids().angle(v)) < 20 * 3.141592653589793 / 180)
            continue;
        const Eigen::Vector3d chordMiddle =
            0.5 * (Eigen::Vector3d(&rig.restPositions()[3 * v]) + at(closed, v));
        outside += (at(half, v) - centre).norm() - (chordMiddle - centre).norm();
        ++counted;
    }
    ASSERT_GT(counted, 100);
    EXPECT_GT(outside / static_cast<double>(counted), 0.02);
}

TEST(FaceRig, EyesAimAtTheTargetAndStayOnTheirSpheres) {
    PMSC_REQUIRE_ICT();
    const FaceRig& rig = *fixture().rig;
    ControlVector c = restPose();
    c[GazeYaw] = 20;
    c[GazePitch] = -10;
    c[GazeDistance] = 30;
    const std::vector<double> posed = poseAll(c);
    const EyeAimDeformer::Aim aim = rig.eyes().aim(c);
    for (int e = 0; e < 2; ++e) {
        const VertexRegion& r = IctFace::region(e == 0 ? "eyeball_left" : "eyeball_right");
        const Eigen::Vector3d centre = rig.eyes().centre(e);
        for (Index v = r.first; v <= r.last; v += 11) {
            const Eigen::Vector3d rest(&rig.restPositions()[3 * v]);
            EXPECT_NEAR((at(posed, v) - centre).norm(), (rest - centre).norm(), 1e-9);
        }
        // The eye's forward axis points at the target: eyes converge on a near target.
        const Eigen::Vector3d forward = aim.rotation[e] * Eigen::Vector3d::UnitZ();
        const Eigen::Vector3d mid = 0.5 * (rig.eyes().centre(0) + rig.eyes().centre(1));
        const double yaw = 20 * 3.141592653589793 / 180, pitch = -10 * 3.141592653589793 / 180;
        const Eigen::Vector3d target =
            mid + 30 * Eigen::Vector3d(std::cos(pitch) * std::sin(yaw), std::sin(pitch),
                                       std::cos(pitch) * std::cos(yaw));
        EXPECT_GT(forward.dot((target - centre).normalized()), 1 - 1e-12);
    }
    EXPECT_NE(aim.yawDegrees[0], aim.yawDegrees[1]);  // vergence
    // Looking left and down drives eyeLookOut_L, eyeLookIn_R, eyeLookDown_*; not their opposites.
    EXPECT_GT(aim.lookWeights[4], 0.3);  // eyeLookOut_L (the left eye turns less: it converges)
    EXPECT_GT(aim.lookWeights[3], 0.5);  // eyeLookIn_R
    EXPECT_EQ(aim.lookWeights[2], 0.0);  // eyeLookIn_L
    EXPECT_EQ(aim.lookWeights[6], 0.0);  // eyeLookUp_L
}

// Summed penetration depth of the lip zone into the opposite lip, for positions `x`.
double lipPenetration(const FaceRig& rig, const std::vector<double>& x) {
    const LipContact& lips = rig.lipContact();
    double total = 0;
    for (Index v : lips.zoneVertices()) {
        const Eigen::Vector3d p = at(x, v);
        double best = INFINITY, s = 0;
        for (std::int32_t t : lips.candidates(v)) {
            const auto& tri = rig.topology().triangles()[static_cast<size_t>(t)];
            const Eigen::Vector3d a = at(x, tri[0]), b = at(x, tri[1]), c = at(x, tri[2]);
            const Eigen::Vector3d q = closestPointOnTriangle(p, a, b, c);
            if ((p - q).squaredNorm() < best) {
                best = (p - q).squaredNorm();
                s = (p - q).dot((b - a).cross(c - a).normalized());
            }
        }
        total += std::min(0.0, s);
    }
    return -total;
}

TEST(FaceRig, LipContactReducesPenetrationOfPressedLips) {
    PMSC_REQUIRE_ICT();
    const FaceRig& rig = *fixture().rig;
    const IctFace& face = fixture().face;
    // mouthClose without jawOpen, and the lower lip rolled in: the blendshapes drive one lip
    // into the other. (The ICT mesh winds outward, so the raw winding gives the sign here.)
    for (auto [control, weight] :
         {std::pair{MouthClose, 0.1}, std::pair{MouthClose, 0.2}, std::pair{MouthRollLower, 0.8}}) {
        ControlVector c = restPose();
        c[control] = weight;
        std::vector<double> blend = face.neutral.positions;
        const auto& d = face.deltas[face.expression(controlName(control))];
        for (size_t i = 0; i < blend.size(); ++i) blend[i] += weight * d[i];
        const double before = lipPenetration(rig, blend);
        const double after = lipPenetration(rig, poseAll(c));
        EXPECT_GT(before, 1.0) << controlName(control);
        EXPECT_LT(after, 0.75 * before) << controlName(control) << " " << weight;
    }
    // The response: penetration pushes out by half (C1 ramp), separation pulls with stickiness.
    EXPECT_EQ(LipContact::response(1.0, 0.0), 0.0);
    EXPECT_NEAR(LipContact::response(-1.0, 0.0), 0.5 * (1.0 - 0.5 * LipContact::kContactSoftness), 1e-12);
    EXPECT_GT(LipContact::response(-0.01, 0.0), 0.0);
    EXPECT_LT(LipContact::response(0.1, 1.0), 0.0);
    EXPECT_EQ(LipContact::response(LipContact::kStickRange, 1.0), 0.0);
    EXPECT_EQ(LipContact::response(0.1, 0.0), 0.0);
}

TEST(FaceRig, StickyLipsHoldSlightlyPartedLipsTogether) {
    PMSC_REQUIRE_ICT();
    // Inner-lip landmarks (62 upper, 66 lower) with the jaw slightly open: sticky lips keep them
    // closer than without.
    const Index upper = IctFace::multiPie68()[62], lower = IctFace::multiPie68()[66];
    ControlVector c = restPose();
    c[JawOpen] = 0.06;
    const std::vector<double> free = poseAll(c);
    c[LipStick] = 1.0;
    const std::vector<double> sticky = poseAll(c);
    EXPECT_LT((at(sticky, upper) - at(sticky, lower)).norm(),
              (at(free, upper) - at(free, lower)).norm() - 0.01);
}

TEST(FaceRig, FleshIsZeroInTheMouthBoxAndOnRigidParts) {
    PMSC_REQUIRE_ICT();
    const FaceRig& rig = *fixture().rig;
    for (Index v = 0; v < rig.pointCount(); ++v) {
        if (rig.lipContact().inMouthBox(v)) {
            ASSERT_EQ(rig.fleshWeight(v), 0.0) << v;
        }
    }
    for (const char* r : {"teeth", "eyeball_left", "eyeball_right", "eyelashes_left", "gums_and_tongue"}) {
        const VertexRegion& region = IctFace::region(r);
        for (Index v = region.first; v <= region.last; ++v) ASSERT_EQ(rig.fleshWeight(v), 0.0) << r;
    }
    // A contracted zygomaticus lifts the cheek: the flesh field is non-zero and local.
    ControlVector c = restPose();
    c[MouthSmileL] = 1.0;
    const FleshDeformer::Pose pose = rig.flesh().prepare(c, rig.jaw().transform(c));
    ASSERT_FALSE(pose.samples.empty());
    double left = 0, right = 0;  // largest weighted flesh displacement on each side of the face
    for (Index v = 0; v < rig.pointCount(); ++v) {
        const Eigen::Vector3d x(&rig.restPositions()[3 * v]);
        const double d = rig.fleshWeight(v) * rig.flesh().displacement(x, pose).norm();
        double& side = x[0] > 0 ? left : right;
        side = std::max(side, d);
    }
    EXPECT_GT(left, 0.05);
    EXPECT_LT(left, 0.3);
    EXPECT_LT(right, 0.25 * left);
}

TEST(FaceRig, BadPointIsOutOfRange) {
    PMSC_REQUIRE_ICT();
    std::vector<Index> bad = {0, fixture().rig->pointCount()};
    std::vector<double> out(6);
    EXPECT_THROW(fixture().rig->evaluate(restPose(), bad, out.data()), std::out_of_range);
}

}  // namespace
}  // namespace pmsc::face
