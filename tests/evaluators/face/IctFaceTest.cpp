#include "evaluators/face/IctFace.h"
#include "pmsc/Errors.h"
#include "tests/common/FaceTestData.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace pmsc::face {
namespace {

namespace fs = std::filesystem;

// A copy of the ICT folder made of symbolic links, where a test can break one file.
class LinkedFolder {
public:
    LinkedFolder() {
        std::string pattern = (fs::temp_directory_path() / "pmsc-ict-XXXXXX").string();
        if (!::mkdtemp(pattern.data())) throw std::runtime_error("mkdtemp failed");
        path_ = pattern;
        for (const auto& e : fs::directory_iterator(test::ictFolder())) {
            fs::create_symlink(e.path(), path_ / e.path().filename());
        }
    }
    ~LinkedFolder() {
        std::error_code ignored;
        fs::remove_all(path_, ignored);
    }
    std::string file(const std::string& name) const { return (path_ / name).string(); }
    std::string str() const { return path_.string(); }

private:
    fs::path path_;
};

std::string messageOf(const std::string& folder) {
    try {
        loadIctFace(folder);
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

TEST(IctFace, LoadsTheWholeModel) {
    PMSC_REQUIRE_ICT();
    const IctFace& face = test::fixture().face;
    EXPECT_EQ(face.vertexCount(), 26719);
    EXPECT_EQ(face.neutral.polygonCount(), 26384);
    ASSERT_EQ(face.deltas.size(), 57u);
    // Head bounding-box diagonal (the paper's error unit), from the neutral mesh.
    EXPECT_NEAR(face.boundingBoxDiagonal(), 47.52, 0.01);
    // jawOpen moves the chin landmark (Multi-PIE 8) by several units.
    const auto& jaw = face.deltas[face.expression("jawOpen")];
    const Index chin = IctFace::multiPie68()[8];
    EXPECT_GT(std::abs(jaw[3 * chin + 1]), 2.0);
}

TEST(IctFace, MissingExpressionIsNamed) {
    PMSC_REQUIRE_ICT();
    LinkedFolder folder;
    fs::remove(folder.file("mouthPucker.obj"));
    const std::string msg = messageOf(folder.str());
    EXPECT_NE(msg.find("mouthPucker.obj"), std::string::npos) << msg;
}

TEST(IctFace, ShortExpressionIsNamed) {
    PMSC_REQUIRE_ICT();
    LinkedFolder folder;
    fs::remove(folder.file("eyeBlink_L.obj"));
    std::ofstream(folder.file("eyeBlink_L.obj")) << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    const std::string msg = messageOf(folder.str());
    EXPECT_NE(msg.find("eyeBlink_L.obj"), std::string::npos) << msg;
    EXPECT_NE(msg.find("3 vertices"), std::string::npos) << msg;
}

TEST(IctFace, MismatchedTopologyIsNamed) {
    PMSC_REQUIRE_ICT();
    LinkedFolder folder;
    // Same vertices, one face fewer: not the same topology.
    std::ifstream in(test::ictFolder() + "/jawLeft.obj");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    text.erase(text.rfind("\nf "));
    text += "\n";
    fs::remove(folder.file("jawLeft.obj"));
    std::ofstream(folder.file("jawLeft.obj")) << text;
    const std::string msg = messageOf(folder.str());
    EXPECT_NE(msg.find("jawLeft.obj"), std::string::npos) << msg;
    EXPECT_NE(msg.find("faces"), std::string::npos) << msg;
}

TEST(IctFace, WrongNeutralIsNamed) {
    const std::string dir = (fs::temp_directory_path() / "pmsc-ict-tiny").string();
    fs::create_directories(dir);
    std::ofstream(dir + "/generic_neutral_mesh.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    const std::string msg = messageOf(dir);
    EXPECT_NE(msg.find("generic_neutral_mesh.obj"), std::string::npos) << msg;
    EXPECT_NE(msg.find("26719"), std::string::npos) << msg;
    fs::remove_all(dir);
}

TEST(IctFace, RegionsFollowTheUpstreamTable) {
    EXPECT_EQ(IctFace::region("face").size(), 9409);
    EXPECT_EQ(IctFace::region("teeth_upper").size() + IctFace::region("teeth_lower").size(),
              IctFace::region("teeth").size());
    EXPECT_EQ(IctFace::region("eyelashes_right").last, 26718);
    EXPECT_THROW(IctFace::region("tail"), std::out_of_range);
    for (Index v : IctFace::multiPie68()) EXPECT_TRUE(IctFace::region("face").contains(v));
}

}  // namespace
}  // namespace pmsc::face
