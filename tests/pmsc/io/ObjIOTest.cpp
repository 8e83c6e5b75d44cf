// The project's one OBJ reader and writer (pmsc/ObjIO.h), which the face rig, the skin
// evaluator and the synthetic ICT frames share.
#include "pmsc/Errors.h"
#include "pmsc/ObjIO.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace pmsc {
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

// One writer serves every evaluator and writes each coordinate as the shortest exact decimal,
// so `pmsc run --format obj` frames read back bit for bit whichever evaluator posed them
// (a "%.6g" writer fails this test).
TEST(ObjWriter, CoordinatesReadBackExactlyAndPolygonsAsWritten) {
    ObjMesh quad;
    quad.positions = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    quad.polygonStart = {0, 4, 7};
    quad.polygonVertices = {0, 1, 2, 3, 0, 2, 3};
    const std::vector<double> posed{
        0.1 + 1e-9, 1.0 / 3, -2.5e-17, 123456.789012345,   1e300, -0.0, 9.000000000000002, 5,
        6,          7,       8,        0.30000000000000004};
    const std::string path = writeTemp("exact.obj", "");
    writeObj(path, quad, posed, "posed");
    Index faces = 0;
    const ObjMesh back = readObj(path, ObjContent::PositionsAndPolygons, &faces);
    ASSERT_EQ(back.positions.size(), posed.size());
    for (std::size_t i = 0; i < posed.size(); ++i) EXPECT_EQ(back.positions[i], posed[i]) << i;
    EXPECT_EQ(back.polygonStart, quad.polygonStart);
    EXPECT_EQ(back.polygonVertices, quad.polygonVertices);
    EXPECT_EQ(faces, 2);
    std::remove(path.c_str());
}

TEST(ObjWriter, TriangleMeshChecksItsIndices) {
    const std::vector<std::int64_t> tris{0, 1, 2, 2, 1, 3};
    const ObjMesh mesh = triangleMesh(tris);
    EXPECT_EQ(mesh.polygonCount(), 2);
    EXPECT_EQ(mesh.polygonStart, (std::vector<std::int32_t>{0, 3, 6}));
    const std::vector<std::int64_t> ragged{0, 1};
    EXPECT_THROW(triangleMesh(ragged), std::invalid_argument);
    const std::vector<std::int64_t> negative{0, -1, 2};
    EXPECT_THROW(triangleMesh(negative), std::invalid_argument);
}

}  // namespace
}  // namespace pmsc
