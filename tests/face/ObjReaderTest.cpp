#include "examples/face/ObjReader.h"
#include "pmsc/Errors.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace pmsc::face {
namespace {

std::string writeTemp(const std::string& name, const std::string& text) {
    const std::string path = (std::filesystem::temp_directory_path() / ("pmsc-objreader-" + name)).string();
    std::ofstream(path, std::ios::binary) << text;
    return path;
}

TEST(ObjReader, ReadsPositionsAndPolygonsSkippingTextureAndNormalIndices) {
    const std::string path = writeTemp("ok.obj",
                                       "# comment\nv 0 0 0\nv 1 0 0\r\nv 1 1 0\nv 0 1 0.5\nvt 0 0\n"
                                       "f 1/1 2/2 3/3 4/4\nf 1 3 -1\n");
    Index faces = 0;
    const ObjMesh mesh = readObj(path, ObjContent::PositionsAndPolygons, &faces);
    EXPECT_EQ(mesh.vertexCount(), 4);
    EXPECT_EQ(mesh.polygonCount(), 2);
    EXPECT_EQ(faces, 2);
    EXPECT_EQ(mesh.positions[11], 0.5);
    EXPECT_EQ(mesh.polygonVertices, (std::vector<std::int32_t>{0, 1, 2, 3, 0, 2, 3}));
    const ObjMesh positionsOnly = readObj(path, ObjContent::Positions, &faces);
    EXPECT_EQ(positionsOnly.polygonCount(), 0);
    EXPECT_EQ(faces, 2);  // counted even when not parsed
    std::remove(path.c_str());
}

TEST(ObjReader, MalformedLinesNameTheFileAndLine) {
    const std::string path = writeTemp("bad.obj", "v 0 0 0\nv 1 x 0\n");
    try {
        readObj(path, ObjContent::Positions);
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find(path + ":2:"), std::string::npos) << e.what();
    }
    std::remove(path.c_str());
}

TEST(ObjReader, FaceIndexOutOfRangeAndMissingFileAreInputErrors) {
    const std::string path = writeTemp("range.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 7\n");
    EXPECT_THROW(readObj(path, ObjContent::PositionsAndPolygons), InputError);
    std::remove(path.c_str());
    try {
        readObj("/nonexistent/pmsc/face.obj", ObjContent::Positions);
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("/nonexistent/pmsc/face.obj"), std::string::npos);
    }
}

}  // namespace
}  // namespace pmsc::face
