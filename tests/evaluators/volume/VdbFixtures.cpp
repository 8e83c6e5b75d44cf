#include "tests/evaluators/volume/VdbFixtures.h"

#include "tests/common/MissingData.h"

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <unistd.h>
#include <cstdlib>
#include <filesystem>

namespace pmsc::volume::test {

void writeDensityBox(const std::string& path, const std::string& name, double half, double voxel,
                     float density) {
    openvdb::initialize();
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(voxel));
    const int n = static_cast<int>(std::lround(half / voxel));
    grid->denseFill(openvdb::CoordBBox(openvdb::Coord(-n), openvdb::Coord(n)), density, true);
    grid->setName(name);
    openvdb::io::File(path).write({grid});
}

void writeFloatGrids(const std::string& path, const std::vector<std::string>& names, double half,
                     double voxel) {
    openvdb::initialize();
    openvdb::GridPtrVec grids;
    const int n = static_cast<int>(std::lround(half / voxel));
    for (const std::string& name : names) {
        auto grid = openvdb::FloatGrid::create(0.0f);
        grid->setTransform(openvdb::math::Transform::createLinearTransform(voxel));
        grid->denseFill(openvdb::CoordBBox(openvdb::Coord(-n), openvdb::Coord(n)), 1.0f, true);
        grid->setName(name);
        grids.push_back(grid);
    }
    openvdb::io::File(path).write(grids);
}

void writeEmptyFloatGrid(const std::string& path, const std::string& name) {
    openvdb::initialize();
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setName(name);
    openvdb::io::File(path).write({grid});
}

void writeVectorOnly(const std::string& path) {
    openvdb::initialize();
    auto grid = openvdb::Vec3SGrid::create(openvdb::Vec3s(0));
    grid->tree().setValue(openvdb::Coord(1, 2, 3), openvdb::Vec3s(1, 0, 0));
    grid->setName("velocity");
    openvdb::io::File(path).write({grid});
}

std::string testMesh() {
    const std::string p = std::string(PMSC_ASSIMP_MODELS_DIR) + "/OBJ/WusonOBJ.obj";
    if (std::filesystem::exists(p)) return p;
    // CI installs assimp-testmodels: a missing mesh there is a failure, not a skip.
    if (pmsc::test::underCi()) ADD_FAILURE() << "missing " << p << " (apt-get install assimp-testmodels)";
    return "";
}

std::string tempDir(const std::string& tag) {
    const auto d =
        std::filesystem::temp_directory_path() / ("pmsc_volume_" + tag + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(d);
    std::filesystem::create_directories(d);
    return d.string();
}

}  // namespace pmsc::volume::test
