#include "tests/evaluators/volume/VdbFixtures.h"

#include "tests/common/MissingData.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Interpolation.h>

#include <gtest/gtest.h>

#include <unistd.h>
#include <cstdlib>
#include <filesystem>
#include <random>

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

void writeNoiseDensity(const std::string& path, double voxel, unsigned seed) {
    openvdb::initialize();
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(voxel));
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> value(0.0f, 2.0f);
    auto acc = grid->getAccessor();
    for (int i = -12; i < 12; ++i)
        for (int j = -12; j < 12; ++j)
            for (int k = -12; k < 12; ++k) {
                const openvdb::Coord ijk(i, j, k);
                if (rng() % 4 == 0)
                    acc.setValueOff(ijk, value(rng));  // inactive, but its value is still sampled
                else
                    acc.setValueOn(ijk, value(rng));
            }
    grid->tree().addTile(1, openvdb::Coord(16, 0, 0), 0.75f, true);
    grid->tree().addTile(1, openvdb::Coord(0, 16, 0), 1.25f, false);
    grid->setName("density");
    openvdb::io::File(path).write({grid});
}

std::vector<double> boxSamplerDensities(const std::string& path, const std::vector<double>& xyz) {
    openvdb::initialize();
    openvdb::io::File file(path);
    file.open();
    const auto grid = openvdb::gridPtrCast<openvdb::FloatGrid>(file.readGrid("density"));
    file.close();
    std::vector<double> out;
    for (std::size_t p = 0; p + 2 < xyz.size(); p += 3) {
        const openvdb::Vec3d index = grid->worldToIndex(openvdb::Vec3d(xyz[p], xyz[p + 1], xyz[p + 2]));
        out.push_back(openvdb::tools::BoxSampler::sample(grid->tree(), index));
    }
    return out;
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
