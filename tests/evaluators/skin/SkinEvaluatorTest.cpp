// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// The skin:ASSET evaluator: posing checked against hand-computed linear blend skinning and morph
// targets on small glTF files written here, then subset == full bit for bit and thread safety on
// real animated characters from Debian's assimp-testmodels.
#include "evaluators/SkinEvaluator.h"
#include "pmsc/Errors.h"
#include "pmsc/ObjIO.h"
#include "tests/common/MissingData.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

namespace fs = std::filesystem;
using pmsc::Index;
using pmsc::evaluators::SkinEvaluator;
using pmsc::evaluators::SkinOptions;

namespace {

#ifndef PMSC_ASSIMP_TESTMODELS
#define PMSC_ASSIMP_TESTMODELS ""
#endif

std::string testModel(const std::string& relative) {
    const std::string dir = PMSC_ASSIMP_TESTMODELS;
    if (dir.empty()) return {};
    const std::string path = dir + "/" + relative;
    return fs::exists(path) ? path : std::string();
}

#define REQUIRE_MODEL(var, rel)                               \
    const std::string var = testModel(rel);                   \
    if (var.empty())                                          \
    PMSC_MISSING_DATA("assimp-testmodels not installed (" rel \
                      " not found); install the Debian package assimp-testmodels")

// A fresh folder per test, removed when the test ends.
struct ScratchDir {
    fs::path path =
        fs::temp_directory_path() / ("pmsc-skin-test-" + std::to_string(::getpid()) + "-" +
                                     ::testing::UnitTest::GetInstance()->current_test_info()->name());
    ScratchDir() {
        fs::remove_all(path);
        fs::create_directories(path);
    }
    ~ScratchDir() {
        std::error_code ec;
        fs::remove_all(path, ec);
    }
};

// --- a tiny glTF writer: a buffer of little-endian floats/shorts, base64 data URI -----------------

std::string base64(const std::string& bytes) {
    static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    std::size_t i = 0;
    for (; i + 2 < bytes.size(); i += 3) {
        const auto b = (std::uint32_t(std::uint8_t(bytes[i])) << 16) |
                       (std::uint32_t(std::uint8_t(bytes[i + 1])) << 8) |
                       std::uint32_t(std::uint8_t(bytes[i + 2]));
        for (int k = 3; k >= 0; --k) out += table[(b >> (6 * k)) & 63];
    }
    if (i + 1 == bytes.size()) {
        const auto b = std::uint32_t(std::uint8_t(bytes[i])) << 16;
        out += table[(b >> 18) & 63];
        out += table[(b >> 12) & 63];
        out += "==";
    } else if (i + 2 == bytes.size()) {
        const auto b =
            (std::uint32_t(std::uint8_t(bytes[i])) << 16) | (std::uint32_t(std::uint8_t(bytes[i + 1])) << 8);
        out += table[(b >> 18) & 63];
        out += table[(b >> 12) & 63];
        out += table[(b >> 6) & 63];
        out += '=';
    }
    return out;
}

struct GltfBuffer {
    std::string bytes;
    std::string views, accessors;
    int count = 0;
    template <class T>
    int add(const std::vector<T>& v, int componentType, const char* type, int elements,
            const std::string& minmax = "") {
        while (bytes.size() % 4) bytes += '\0';
        const std::size_t offset = bytes.size();
        bytes.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
        if (count) {
            views += ",";
            accessors += ",";
        }
        views += "{\"buffer\":0,\"byteOffset\":" + std::to_string(offset) +
                 ",\"byteLength\":" + std::to_string(v.size() * sizeof(T)) + "}";
        accessors += "{\"bufferView\":" + std::to_string(count) +
                     ",\"componentType\":" + std::to_string(componentType) +
                     ",\"count\":" + std::to_string(elements) + ",\"type\":\"" + type + "\"" + minmax + "}";
        return count++;
    }
    std::string json(const std::string& rest) const {
        return "{\"asset\":{\"version\":\"2.0\"}," + rest +
               ",\"buffers\":[{\"byteLength\":" + std::to_string(bytes.size()) +
               ",\"uri\":\"data:application/octet-stream;base64," + base64(bytes) + "\"}],\"bufferViews\":[" +
               views + "],\"accessors\":[" + accessors + "]}";
    }
};

// Two joints: joint 0 at the origin, joint 1 at (0,1,0) rotating about z from 0 to 90 degrees over
// one second (LINEAR). Vertex 0 follows joint 0, vertex 1 and 3 joint 1, vertex 2 half and half.
std::string writeTwoJointRig(const fs::path& dir) {
    GltfBuffer b;
    const std::vector<float> positions{1, 0, 0, 1, 2, 0, 1, 1, 0, 0, 2, 0};
    const int pos = b.add(positions, 5126, "VEC3", 4, ",\"min\":[0,0,0],\"max\":[1,2,0]");
    const std::vector<std::uint16_t> joints{0, 1, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 1, 0, 0, 0};
    const int jts = b.add(joints, 5123, "VEC4", 4);
    const std::vector<float> weights{1, 0, 0, 0, 1, 0, 0, 0, 0.5f, 0.5f, 0, 0, 1, 0, 0, 0};
    const int wts = b.add(weights, 5126, "VEC4", 4);
    const std::vector<std::uint16_t> indices{0, 1, 2, 1, 3, 2};
    const int idx = b.add(indices, 5123, "SCALAR", 6);
    // glTF matrices are column-major: identity, and the inverse of translate(0,1,0).
    const std::vector<float> ibm{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0,  0, 1,
                                 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, -1, 0, 1};
    const int inv = b.add(ibm, 5126, "MAT4", 2);
    const std::vector<float> times{0, 1};
    const int in = b.add(times, 5126, "SCALAR", 2, ",\"min\":[0],\"max\":[1]");
    const float s = static_cast<float>(std::sqrt(0.5));
    const std::vector<float> rotations{0, 0, 0, 1, 0, 0, s, s};
    const int out = b.add(rotations, 5126, "VEC4", 2);
    const std::string json = b.json(
        "\"scene\":0,\"scenes\":[{\"nodes\":[0,1]}],"
        "\"nodes\":[{\"mesh\":0,\"skin\":0},{\"children\":[2]},{\"translation\":[0,1,0]}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":" +
        std::to_string(pos) + ",\"JOINTS_0\":" + std::to_string(jts) +
        ",\"WEIGHTS_0\":" + std::to_string(wts) + "},\"indices\":" + std::to_string(idx) +
        "}]}],"
        "\"skins\":[{\"inverseBindMatrices\":" +
        std::to_string(inv) +
        ",\"joints\":[1,2]}],"
        "\"animations\":[{\"channels\":[{\"sampler\":0,\"target\":{\"node\":2,\"path\":\"rotation\"}}],"
        "\"samplers\":[{\"input\":" +
        std::to_string(in) + ",\"output\":" + std::to_string(out) + ",\"interpolation\":\"LINEAR\"}]}]");
    const fs::path path = dir / "two-joint-rig.gltf";
    std::ofstream(path) << json;
    return path.string();
}

// One triangle on a node translated by (2,0,0) with one morph target that lifts every vertex by
// (0,0,1); its weight goes 0 -> 1 over one second.
std::string writeMorphTriangle(const fs::path& dir) {
    GltfBuffer b;
    const std::vector<float> positions{0, 0, 0, 1, 0, 0, 0, 1, 0};
    const int pos = b.add(positions, 5126, "VEC3", 3, ",\"min\":[0,0,0],\"max\":[1,1,0]");
    const std::vector<float> lift{0, 0, 1, 0, 0, 1, 0, 0, 1};
    const int target = b.add(lift, 5126, "VEC3", 3, ",\"min\":[0,0,1],\"max\":[0,0,1]");
    const std::vector<float> times{0, 1};
    const int in = b.add(times, 5126, "SCALAR", 2, ",\"min\":[0],\"max\":[1]");
    const std::vector<float> w{0, 1};
    const int out = b.add(w, 5126, "SCALAR", 2);
    const std::string json = b.json(
        "\"scene\":0,\"scenes\":[{\"nodes\":[0]}],"
        "\"nodes\":[{\"mesh\":0,\"name\":\"lifted\",\"translation\":[2,0,0]}],"
        "\"meshes\":[{\"weights\":[0],\"primitives\":[{\"attributes\":{\"POSITION\":" +
        std::to_string(pos) + "},\"targets\":[{\"POSITION\":" + std::to_string(target) +
        "}]}]}],"
        "\"animations\":[{\"channels\":[{\"sampler\":0,\"target\":{\"node\":0,\"path\":\"weights\"}}],"
        "\"samplers\":[{\"input\":" +
        std::to_string(in) + ",\"output\":" + std::to_string(out) + ",\"interpolation\":\"LINEAR\"}]}]");
    const fs::path path = dir / "morph-triangle.gltf";
    std::ofstream(path) << json;
    return path.string();
}

std::vector<double> evaluateAll(const SkinEvaluator& e, Index frame) {
    std::vector<double> out(static_cast<std::size_t>(e.pointCount() * 3));
    e.evaluateAll(frame, out.data());
    return out;
}

}  // namespace

// ------------------------------------------------------------------------------------------------

TEST(SkinEvaluator, LinearBlendSkinningMatchesHandComputedPoses) {
    const ScratchDir scratch;
    const fs::path& dir = scratch.path;
    SkinOptions o;
    o.path = writeTwoJointRig(dir);
    o.fps = 4;  // frames at 0, 0.25, ..., 1 s
    SkinEvaluator e(o);
    ASSERT_EQ(e.pointCount(), 4);
    ASSERT_EQ(e.channelCount(), 3);
    ASSERT_EQ(e.frameCount(), 5);
    EXPECT_EQ(e.boneCount(), 2);
    EXPECT_EQ(e.triangles().size(), 6u);

    for (Index f = 0; f < e.frameCount(); ++f) {
        // Slerp from identity to a quarter turn: the angle grows linearly with time.
        const double theta = M_PI / 2 * static_cast<double>(f) / 4.0;
        const double c = std::cos(theta), s = std::sin(theta);
        auto joint1 = [&](double x, double y) {  // T(0,1,0) Rz(theta) T(0,-1,0)
            const double ry = y - 1;
            return std::array<double, 2>{c * x - s * ry, s * x + c * ry + 1};
        };
        const auto p = evaluateAll(e, f);
        const double tol = 2e-7;  // the file stores floats
        EXPECT_NEAR(p[0], 1, tol);
        EXPECT_NEAR(p[1], 0, tol);
        const auto v1 = joint1(1, 2);
        EXPECT_NEAR(p[3], v1[0], tol) << "frame " << f;
        EXPECT_NEAR(p[4], v1[1], tol) << "frame " << f;
        const auto v2 = joint1(1, 1);
        EXPECT_NEAR(p[6], 0.5 * 1 + 0.5 * v2[0], tol) << "frame " << f;
        EXPECT_NEAR(p[7], 0.5 * 1 + 0.5 * v2[1], tol) << "frame " << f;
        const auto v3 = joint1(0, 2);
        EXPECT_NEAR(p[9], v3[0], tol);
        EXPECT_NEAR(p[10], v3[1], tol);
        for (int i = 0; i < 4; ++i) EXPECT_NEAR(p[3 * i + 2], 0, tol);
    }
}

TEST(SkinEvaluator, MorphTargetsBlendByAnimatedWeights) {
    const ScratchDir scratch;
    const fs::path& dir = scratch.path;
    SkinOptions o;
    o.path = writeMorphTriangle(dir);
    o.fps = 4;
    SkinEvaluator e(o);
    ASSERT_EQ(e.pointCount(), 3);
    EXPECT_EQ(e.morphTargetCount(), 1);
    ASSERT_EQ(e.frameCount(), 5);
    const double base[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    for (Index f = 0; f < 5; ++f) {
        const double w = static_cast<double>(f) / 4.0;
        const auto p = evaluateAll(e, f);
        for (int v = 0; v < 3; ++v) {
            EXPECT_NEAR(p[3 * v + 0], base[3 * v] + 2, 1e-7) << "the node's translation moves it";
            EXPECT_NEAR(p[3 * v + 1], base[3 * v + 1], 1e-7);
            EXPECT_NEAR(p[3 * v + 2], w, 1e-7) << "frame " << f;
        }
    }
}

TEST(SkinEvaluator, FramesOutsideTheAnimationAndBadPointsThrow) {
    const ScratchDir scratch;
    const fs::path& dir = scratch.path;
    SkinOptions o;
    o.path = writeTwoJointRig(dir);
    SkinEvaluator e(o);
    EXPECT_EQ(e.frameCount(), 25);  // one second at the default 24 fps, both ends included
    std::vector<double> out(3);
    const Index bad[] = {4};
    EXPECT_THROW(e.evaluate(0, bad, out.data()), std::out_of_range);
    const Index ok[] = {0};
    EXPECT_THROW(e.evaluate(25, ok, out.data()), std::out_of_range);
    EXPECT_THROW(e.evaluate(-1, ok, out.data()), std::out_of_range);
}

TEST(SkinEvaluator, UnreadableAssetsAreInputErrorsOnOneLine) {
    const ScratchDir scratch;
    const fs::path& dir = scratch.path;
    auto message = [](const std::string& path) {
        try {
            SkinOptions o;
            o.path = path;
            SkinEvaluator e(o);
        } catch (const pmsc::InputError& e) {
            return std::string(e.what());
        }
        return std::string("no error");
    };
    const std::string missing = message((dir / "nope.gltf").string());
    EXPECT_NE(missing.find("Assimp cannot read it"), std::string::npos) << missing;
    EXPECT_NE(missing.find("nope.gltf"), std::string::npos) << missing;

    const fs::path garbage = dir / "garbage.fbx";
    std::ofstream(garbage) << "this is not a mesh\n\nat all\n";
    const std::string g = message(garbage.string());
    EXPECT_NE(g.find("Assimp cannot read it"), std::string::npos) << g;
    EXPECT_EQ(g.find('\n'), std::string::npos) << g;

    // A static mesh (no animation): nothing to pose.
    const fs::path still = dir / "still.obj";
    std::ofstream(still) << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    const std::string s = message(still.string());
    EXPECT_NE(s.find("has no animation"), std::string::npos) << s;

    // An animated node and no mesh at all: nothing to evaluate.
    GltfBuffer b;
    const int in = b.add(std::vector<float>{0, 1}, 5126, "SCALAR", 2, ",\"min\":[0],\"max\":[1]");
    const int out = b.add(std::vector<float>{0, 0, 0, 1, 0, 0}, 5126, "VEC3", 2);
    const fs::path empty = dir / "no-vertices.gltf";
    std::ofstream(empty) << b.json(
        "\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"name\":\"empty\"}],"
        "\"animations\":[{\"channels\":[{\"sampler\":0,\"target\":{\"node\":0,\"path\":\"translation\"}}],"
        "\"samplers\":[{\"input\":" +
        std::to_string(in) + ",\"output\":" + std::to_string(out) + "}]}]");
    const std::string e = message(empty.string());
    EXPECT_NE(e.find("has no vertices"), std::string::npos) << e;
    EXPECT_EQ(e.find('\n'), std::string::npos) << e;
}

TEST(SkinEvaluator, ParsesOptionsFromTheEndOfTheSpec) {
    auto o = pmsc::evaluators::parseSkinArgs("/a/b.fbx:fps=30:animation=Walk");
    EXPECT_EQ(o.path, "/a/b.fbx");
    EXPECT_EQ(o.fps, 30);
    EXPECT_EQ(o.animation, "Walk");
    o = pmsc::evaluators::parseSkinArgs("C:/odd:path.gltf");
    EXPECT_EQ(o.path, "C:/odd:path.gltf");
    EXPECT_EQ(o.fps, 24);
    EXPECT_THROW(pmsc::evaluators::parseSkinArgs("a.gltf:fps=0"), pmsc::InputError);
    EXPECT_THROW(pmsc::evaluators::parseSkinArgs("a.gltf:fps=x"), pmsc::InputError);
    EXPECT_THROW(pmsc::evaluators::parseSkinArgs("a.gltf:speed=2"), pmsc::InputError);
    EXPECT_THROW(pmsc::evaluators::parseSkinArgs(""), pmsc::InputError);
    o = pmsc::evaluators::parseSkinArgs("clip.bvh:fps=30:body=tubes:space=root");
    EXPECT_EQ(o.path, "clip.bvh");
    EXPECT_TRUE(o.tubes);
    EXPECT_TRUE(o.rootSpace);
    EXPECT_FALSE(pmsc::evaluators::parseSkinArgs("clip.bvh").tubes);
    EXPECT_FALSE(pmsc::evaluators::parseSkinArgs("clip.bvh").rootSpace);
    EXPECT_THROW(pmsc::evaluators::parseSkinArgs("clip.bvh:body=sticks"), pmsc::InputError);
    EXPECT_THROW(pmsc::evaluators::parseSkinArgs("clip.bvh:space=world"), pmsc::InputError);
}

// --- real characters --------------------------------------------------------------------------------

namespace {

// Random subsets in random order, at several frames: every value equal to the full pose's bit for bit.
void expectSubsetsMatchFullPose(const SkinEvaluator& e) {
    std::mt19937_64 rng(6);
    const Index n = e.pointCount();
    const Index frames = e.frameCount();
    for (Index f : {Index(0), frames / 3, frames - 1}) {
        const auto full = evaluateAll(e, f);
        for (Index size : {Index(1), Index(17), n / 3, n}) {
            std::vector<Index> pts(static_cast<std::size_t>(n));
            std::iota(pts.begin(), pts.end(), Index(0));
            std::shuffle(pts.begin(), pts.end(), rng);
            pts.resize(static_cast<std::size_t>(size));
            std::vector<double> sub(pts.size() * 3);
            e.evaluate(f, pts, sub.data());
            for (std::size_t i = 0; i < pts.size(); ++i)
                ASSERT_EQ(0, std::memcmp(&sub[3 * i], &full[static_cast<std::size_t>(3 * pts[i])],
                                         3 * sizeof(double)))
                    << e.name() << " frame " << f << " point " << pts[i] << " (subset of " << size << ")";
        }
    }
}

double largestMove(const SkinEvaluator& e) {
    const auto a = evaluateAll(e, 0);
    double most = 0;
    for (Index f = 1; f < e.frameCount(); f += std::max<Index>(1, e.frameCount() / 8)) {
        const auto b = evaluateAll(e, f);
        for (std::size_t i = 0; i < a.size(); ++i) most = std::max(most, std::abs(a[i] - b[i]));
    }
    return most;
}

}  // namespace

TEST(SkinEvaluatorOnTestModels, WusonWalkSubsetEqualsFullBitForBit) {
    REQUIRE_MODEL(path, "X/Testwuson.X");
    auto e = pmsc::evaluators::makeSkinEvaluator(path + ":animation=Wuson_Walk");
    EXPECT_EQ(e->animationName(), "Wuson_Walk");
    EXPECT_EQ(e->pointCount(), 11196);
    EXPECT_EQ(e->frameCount(), 87);  // 17280 ticks at 4800/s = 3.6 s at 24 fps, both ends
    EXPECT_GT(e->boneCount(), 30);
    EXPECT_GT(largestMove(*e), 0.1) << "the walk must move the character";
    expectSubsetsMatchFullPose(*e);
}

TEST(SkinEvaluatorOnTestModels, ThreeMeshCharacterSubsetEqualsFullBitForBit) {
    REQUIRE_MODEL(path, "X/BCN_Epileptic.X");
    auto e = pmsc::evaluators::makeSkinEvaluator(path);
    ASSERT_EQ(e->meshOffsets().size(), 4u);  // three meshes concatenated in scene order
    EXPECT_EQ(e->meshOffsets().back(), e->pointCount());
    EXPECT_GT(largestMove(*e), 0.1);
    expectSubsetsMatchFullPose(*e);
}

TEST(SkinEvaluatorOnTestModels, FbxAndMorphAssetsSubsetEqualsFullBitForBit) {
    REQUIRE_MODEL(fbx, "FBX/animation_with_skeleton.fbx");
    auto skinned = pmsc::evaluators::makeSkinEvaluator(fbx);
    EXPECT_GT(largestMove(*skinned), 0.01);
    expectSubsetsMatchFullPose(*skinned);

    REQUIRE_MODEL(cube, "glTF2/glTF-Sample-Models/AnimatedMorphCube-glTF/AnimatedMorphCube.gltf");
    auto morph = pmsc::evaluators::makeSkinEvaluator(cube);
    EXPECT_EQ(morph->morphTargetCount(), 2);
    EXPECT_GT(largestMove(*morph), 0.001) << "the morph weights must move the cube";
    expectSubsetsMatchFullPose(*morph);
}

TEST(SkinEvaluatorOnTestModels, ConcurrentEvaluationEqualsSerial) {
    REQUIRE_MODEL(path, "X/Testwuson.X");
    auto e = pmsc::evaluators::makeSkinEvaluator(path + ":animation=Wuson_Run");
    const Index frames = e->frameCount();
    std::vector<std::vector<double>> serial;
    for (Index f = 0; f < frames; ++f) serial.push_back(evaluateAll(*e, f));
    std::vector<std::vector<double>> parallel(static_cast<std::size_t>(frames));
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&, t] {
            for (Index f = t; f < frames; f += 4) parallel[static_cast<std::size_t>(f)] = evaluateAll(*e, f);
        });
    for (auto& t : threads) t.join();
    for (Index f = 0; f < frames; ++f)
        ASSERT_EQ(serial[static_cast<std::size_t>(f)], parallel[static_cast<std::size_t>(f)]) << f;
}

TEST(SkinEvaluatorOnTestModels, AssetWithoutAnimationIsRejected) {
    REQUIRE_MODEL(path, "IQM/mrfixit.iqm");
    try {
        pmsc::evaluators::makeSkinEvaluator(path);
        FAIL() << "expected an InputError";
    } catch (const pmsc::InputError& e) {
        EXPECT_NE(std::string(e.what()).find("has no animation"), std::string::npos) << e.what();
    }
}

// A CMU motion-capture clip dressed in tubes: every bone of length > 0 gets 8 rings of 12 points.
// Root space is one rigid motion of the scene-space pose per frame (the root joint's, undone), which
// takes away where the character walks.
TEST(SkinEvaluatorOnTestModels, MotionCaptureDressedInTubesFollowsTheSkeletonInRootSpace) {
    REQUIRE_MODEL(path, "BVH/01_01.bvh");
    auto scene = pmsc::evaluators::makeSkinEvaluator(path + ":fps=30:body=tubes");
    auto root = pmsc::evaluators::makeSkinEvaluator(path + ":fps=30:body=tubes:space=root");
    EXPECT_EQ(scene->pointCount(), 27 * 96);  // the CMU skeleton's bones with a length
    EXPECT_EQ(root->pointCount(), scene->pointCount());
    EXPECT_EQ(scene->frameCount(), 688);  // 2752 frames at 120 Hz = 22.93 s at 30 fps
    EXPECT_EQ(static_cast<Index>(scene->triangles().size()), 27 * 7 * 12 * 2 * 3);
    const Index n = scene->pointCount();
    auto centroid = [&](const std::vector<double>& p) {
        return Eigen::Map<const Eigen::Matrix3Xd>(p.data(), 3, n).rowwise().mean().eval();
    };
    const Eigen::Vector3d sceneStart = centroid(evaluateAll(*scene, 0)),
                          rootStart = centroid(evaluateAll(*root, 0));
    double sceneTravel = 0, rootTravel = 0;
    for (Index f = 1; f < scene->frameCount(); f += 40) {
        const auto a = evaluateAll(*scene, f), b = evaluateAll(*root, f);
        const Eigen::Map<const Eigen::Matrix3Xd> pa(a.data(), 3, n), pb(b.data(), 3, n);
        const Eigen::Matrix4d rigid = Eigen::umeyama(pa, pb, /*with_scaling=*/false);
        const Eigen::Matrix3Xd moved =
            (rigid.topLeftCorner<3, 3>() * pa).colwise() + rigid.topRightCorner<3, 1>();
        EXPECT_LT((moved - pb).cwiseAbs().maxCoeff(), 1e-9) << "frame " << f << ": not one rigid motion";
        sceneTravel = std::max(sceneTravel, (centroid(a) - sceneStart).norm());
        rootTravel = std::max(rootTravel, (centroid(b) - rootStart).norm());
    }
    EXPECT_GT(sceneTravel, 10.0) << "the clip walks";
    EXPECT_LT(rootTravel, 0.25 * sceneTravel) << "root space keeps the body where it stands";
    expectSubsetsMatchFullPose(*root);
    // Without body=tubes the clip is Assimp's display mesh (one pyramid per bone).
    EXPECT_NE(pmsc::evaluators::makeSkinEvaluator(path)->pointCount(), n);
}

// --- .obj frames --------------------------------------------------------------------------------------

TEST(ObjFrameWriter, RoundTripsValuesExactlyAndRejectsDamagedFiles) {
    const ScratchDir scratch;
    const fs::path& dir = scratch.path;
    const std::vector<std::int64_t> tris{0, 1, 2, 1, 3, 2};
    const auto topology = std::make_shared<const pmsc::ObjMesh>(pmsc::triangleMesh(tris));
    pmsc::ObjFrameWriter w(4, topology);
    EXPECT_EQ(w.extension(), ".obj");
    const std::vector<double> v{0.1, -2.5e-17, 3, 1.0 / 3, 2, 1e300, -0.0, 5, 6, 7, 8, 9.000000000000002};
    const std::string path = (dir / "f.obj").string();
    w.write(path, 7, v.data());
    EXPECT_TRUE(w.isValid(path));

    std::ifstream in(path);
    std::string line, tag;
    std::getline(in, line);
    EXPECT_EQ(line, "# pmsc frame 7: 4 points, 2 polygons");
    std::vector<double> back;
    for (int i = 0; i < 4; ++i) {
        double x, y, z;
        in >> tag >> x >> y >> z;
        back.insert(back.end(), {x, y, z});
    }
    EXPECT_EQ(0, std::memcmp(back.data(), v.data(), v.size() * sizeof(double)));

    // Truncated (a farm node died mid-copy), wrong vertex count, garbage: all invalid.
    std::string text;
    {
        std::ifstream all(path);
        text.assign(std::istreambuf_iterator<char>(all), {});
    }
    std::ofstream(path, std::ios::trunc) << text.substr(0, text.size() / 2);
    EXPECT_FALSE(w.isValid(path));
    pmsc::ObjFrameWriter five(5, topology);
    w.write(path, 7, v.data());
    EXPECT_FALSE(five.isValid(path));
    std::ofstream(path, std::ios::trunc) << "v 1 2 nan\n";
    EXPECT_FALSE(w.isValid(path));
    EXPECT_FALSE(w.isValid((dir / "missing.obj").string()));
    EXPECT_THROW(w.write((dir / "no-such-dir" / "x.obj").string(), 0, v.data()), pmsc::IoError);
}
