// The ICT-style rig generator on a tiny mesh written by the test, where the jaw hinge is known.
#include "examples/synthetic/IctFrames.h"
#include "pmsc/Errors.h"
#include "tests/common/TempDir.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <vector>

namespace {

using pmsc::Index;
using pmsc::test::TempDir;

constexpr double kPivotY = -1.0, kPivotZ = 2.0, kAngle = 0.3;

/// 40 "jaw" points (z < 0, rotated about the x axis through (y, z) = (kPivotY, kPivotZ) in jawOpen),
/// 10 "brow" points moved only by a smile shape, 10 still points.
struct Mesh {
    std::vector<Eigen::Vector3d> neutral, jawOpen, smile;
    Mesh() {
        for (int i = 0; i < 60; ++i) {
            const Eigen::Vector3d p(0.1 * (i % 7) - 0.3, -3.0 + 0.05 * i,
                                    i < 40 ? -1.0 - 0.02 * i : 1.0 + 0.01 * i);
            neutral.push_back(p);
            Eigen::Vector3d j = p, s = p;
            if (i < 40) {
                const double y = p.y() - kPivotY, z = p.z() - kPivotZ;
                j.y() = kPivotY + std::cos(kAngle) * y - std::sin(kAngle) * z;
                j.z() = kPivotZ + std::sin(kAngle) * y + std::cos(kAngle) * z;
            } else if (i < 50) {
                s.y() += 0.3;
            }
            jawOpen.push_back(j);
            smile.push_back(s);
        }
    }
};

void writeObj(const std::string& path, const std::vector<Eigen::Vector3d>& v) {
    std::ofstream out(path);
    out.precision(17);
    out << "# test mesh\n";
    for (const auto& p : v) out << "v " << p.x() << " " << p.y() << " " << p.z() << "\n";
    out << "f 1 2 3\n";
}

/// The test mesh written as an ICT folder (neutral, jawOpen, smile) and read back as a rig.
pmsc::synthetic::IctRig loadRig(TempDir& dir, const Mesh& mesh) {
    writeObj(dir.file("generic_neutral_mesh.obj"), mesh.neutral);
    writeObj(dir.file("jawOpen.obj"), mesh.jawOpen);
    writeObj(dir.file("smile.obj"), mesh.smile);
    return pmsc::synthetic::loadIctRig(dir.path().string());
}

TEST(IctFrames, FitsTheJawHingeOfAKnownRotation) {
    TempDir dir;
    const Mesh mesh;
    const auto rig = loadRig(dir, mesh);
    EXPECT_EQ(rig.points, 60);
    ASSERT_EQ(rig.shapes.size(), 1u);  // jawOpen is the hinge, not a blendshape
    EXPECT_EQ(rig.shapes[0].name, "smile");
    EXPECT_EQ(rig.shapes[0].vertices.size(), 10u);
    // jawOpen is an exact rigid rotation, so the fit recovers it to rounding.
    EXPECT_NEAR(rig.jawAngle, kAngle, 1e-12);
    EXPECT_NEAR(rig.jawPivotYZ[0], kPivotY, 1e-9);
    EXPECT_NEAR(rig.jawPivotYZ[1], kPivotZ, 1e-9);
    EXPECT_EQ(rig.jawVertices.size(), 40u);
    for (double w : rig.jawWeights) EXPECT_NEAR(w, 1.0, 1e-9);
}

TEST(IctFrames, PosesDeterministicallyAndHoldsExcludedShapes) {
    TempDir dir;
    const Mesh mesh;
    const auto rig = loadRig(dir, mesh);
    const auto a = pmsc::synthetic::poseIctFrames(rig, 80, 3);
    EXPECT_EQ(a.values, pmsc::synthetic::poseIctFrames(rig, 80, 3).values);
    EXPECT_NE(a.values, pmsc::synthetic::poseIctFrames(rig, 80, 4).values);
    bool smiled = false;
    for (Index f = 0; f < 80; ++f) smiled = smiled || a.frame(f)[3 * 45 + 1] != mesh.neutral[45].y();
    EXPECT_TRUE(smiled);
    const auto held = pmsc::synthetic::poseIctFrames(rig, 80, 3, {"smile"});
    for (Index f = 0; f < 80; ++f)
        for (Index p = 40; p < 60; ++p)
            for (int c = 0; c < 3; ++c) EXPECT_EQ(held.frame(f)[3 * p + c], mesh.neutral[p][c]);
    // The jaw moves only by rotation about the hinge: distances to the axis are kept.
    for (Index f = 0; f < 80; ++f)
        for (Index p = 0; p < 40; ++p) {
            const double y = held.frame(f)[3 * p + 1] - rig.jawPivotYZ[0],
                         z = held.frame(f)[3 * p + 2] - rig.jawPivotYZ[1];
            const double y0 = mesh.neutral[p].y() - rig.jawPivotYZ[0],
                         z0 = mesh.neutral[p].z() - rig.jawPivotYZ[1];
            EXPECT_NEAR(std::hypot(y, z), std::hypot(y0, z0), 1e-12);
        }
    EXPECT_THROW(pmsc::synthetic::poseIctFrames(rig, 5, 1, {"mouthPucker"}), pmsc::InputError);
}

TEST(IctFrames, AHeldShapeTakesItsWeightInEveryFrameAndLeavesTheOtherCurves) {
    TempDir dir;
    const Mesh mesh;
    const auto rig = loadRig(dir, mesh);
    const auto still = pmsc::synthetic::poseIctFrames(rig, 30, 3, {"smile"});
    const auto held = pmsc::synthetic::poseIctFrames(rig, 30, 3, {}, {{"smile", 0.5}});
    for (Index f = 0; f < 30; ++f) {
        for (Index p = 40; p < 60; ++p)  // the smile's points: neutral + half its delta
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(held.frame(f)[3 * p + c],
                            mesh.neutral[p][c] + 0.5 * (mesh.smile[p][c] - mesh.neutral[p][c]), 1e-12);
        for (Index p = 0; p < 40; ++p)  // the jaw's curve is the same as without the smile
            for (int c = 0; c < 3; ++c) EXPECT_EQ(held.frame(f)[3 * p + c], still.frame(f)[3 * p + c]);
    }
    EXPECT_THROW(pmsc::synthetic::poseIctFrames(rig, 5, 1, {}, {{"smile", 1.5}}), pmsc::InputError);
    EXPECT_THROW(pmsc::synthetic::poseIctFrames(rig, 5, 1, {}, {{"frown", 0.5}}), pmsc::InputError);
}

TEST(IctFrames, BadFoldersAndMeshesNameTheFile) {
    TempDir dir;
    EXPECT_THROW(pmsc::synthetic::loadIctRig(dir.file("none")), pmsc::InputError);
    EXPECT_THROW(pmsc::synthetic::loadIctRig(dir.path().string()), pmsc::InputError);  // no neutral mesh
    const Mesh mesh;
    writeObj(dir.file("generic_neutral_mesh.obj"), mesh.neutral);
    EXPECT_THROW(pmsc::synthetic::loadIctRig(dir.path().string()), pmsc::InputError);  // no jawOpen
    auto shorter = mesh.jawOpen;
    shorter.pop_back();
    writeObj(dir.file("jawOpen.obj"), shorter);
    try {
        pmsc::synthetic::loadIctRig(dir.path().string());
        ADD_FAILURE();
    } catch (const pmsc::InputError& e) {
        EXPECT_NE(std::string(e.what()).find("jawOpen.obj: 59 vertices, the neutral mesh has 60"),
                  std::string::npos)
            << e.what();
    }
}

}  // namespace

TEST(IctFrames, SegmentsAreTheTakesFirstFramesWithEachHoldOneAfterAnother) {
    TempDir dir;
    const Mesh mesh;
    const auto rig = loadRig(dir, mesh);
    const auto segments = pmsc::synthetic::poseIctSegments(rig, 12, 3, {"smile"}, {{{"smile", 0.5}}, {}});
    const auto held = pmsc::synthetic::poseIctFrames(rig, 12, 3, {}, {{"smile", 0.5}});
    const auto still = pmsc::synthetic::poseIctFrames(rig, 12, 3, {"smile"});
    ASSERT_EQ(segments.frames, 24);
    std::vector<double> both(held.values.begin(), held.values.end());
    both.insert(both.end(), still.values.begin(), still.values.end());
    EXPECT_EQ(std::vector<double>(segments.values.begin(), segments.values.end()), both);
    EXPECT_THROW(pmsc::synthetic::poseIctSegments(rig, 5, 1, {}, {}), pmsc::InputError);
    EXPECT_THROW(pmsc::synthetic::poseIctSegments(rig, 5, 1, {}, {{}, {{"frown", 0.5}}}), pmsc::InputError);
}
