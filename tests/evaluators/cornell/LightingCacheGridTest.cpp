// The OpenVDB lighting cache: a file OpenVDB can read back with every voxel and the metadata,
// and a world-space lookup that returns what was stored.
#include "evaluators/cornell/LightingCacheGrid.h"

#include "pmsc/Errors.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

namespace pmsc::cornell {
namespace {

std::string tempPath(const std::string& name) {
    return (std::filesystem::temp_directory_path() /
            ("pmsc_cornell_" + std::to_string(::getpid()) + "_" + name))
        .string();
}

TEST(LightingCacheGrid, RoundTripKeepsVoxelsValuesAndMetadata) {
    const SurfaceVoxels vox = SurfaceVoxels::voxelize(CornellScene::standard(), 20.0);
    std::vector<double> values(3 * vox.size());
    for (std::size_t i = 0; i < values.size(); ++i) values[i] = 0.001 * static_cast<double>(i % 997);
    const CacheMetadata meta{42, {100.5, 488.8, 200.25}, "blend", 0.375, 0.0123};
    const LightingCacheGrid grid(vox, values, meta);
    EXPECT_EQ(grid.activeVoxelCount(), static_cast<std::int64_t>(vox.size()));

    const std::string path = tempPath("roundtrip.vdb");
    grid.write(path);
    EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
    const LightingCacheGrid back = LightingCacheGrid::read(path);
    std::filesystem::remove(path);

    EXPECT_EQ(back.activeVoxelCount(), static_cast<std::int64_t>(vox.size()));
    EXPECT_DOUBLE_EQ(back.voxelSizeMm(), 20.0);
    const CacheMetadata m = back.metadata();
    EXPECT_EQ(m.frame, 42);
    EXPECT_EQ(m.state, "blend");
    EXPECT_DOUBLE_EQ(m.weight, 0.375);
    EXPECT_DOUBLE_EQ(m.keyError, 0.0123);
    EXPECT_DOUBLE_EQ(m.lightPosition.x, 100.5);
    EXPECT_DOUBLE_EQ(m.lightPosition.y, 488.8);
    EXPECT_DOUBLE_EQ(m.lightPosition.z, 200.25);
    for (std::size_t i = 0; i < vox.size(); i += 37) {
        const Rgb v = back.valueAt(vox.ijk[i]);
        for (int c = 0; c < 3; ++c)
            EXPECT_FLOAT_EQ(static_cast<float>(v[c]), static_cast<float>(values[3 * i + c]));
    }
}

TEST(LightingCacheGrid, WorldLookupOfAConstantFieldIsThatConstant) {
    // Renormalized trilinear weights over the active, same-facing voxels: a constant cache
    // reads back as the constant anywhere on the surfaces, also at corners and edges.
    const SurfaceVoxels vox = SurfaceVoxels::voxelize(CornellScene::standard(), 15.0);
    std::vector<double> values(3 * vox.size());
    for (std::size_t i = 0; i < vox.size(); ++i) {
        values[3 * i] = 0.5;
        values[3 * i + 1] = 0.25;
        values[3 * i + 2] = 0.125;
    }
    const LightingCacheGrid grid(vox, values, CacheMetadata{});
    std::vector<double> out(3 * vox.size());
    grid.sample(vox.position, vox.normal, out.data());
    for (std::size_t i = 0; i < vox.size(); ++i) {
        ASSERT_NEAR(out[3 * i], 0.5, 1e-6) << i;
        ASSERT_NEAR(out[3 * i + 1], 0.25, 1e-6) << i;
        ASSERT_NEAR(out[3 * i + 2], 0.125, 1e-6) << i;
    }
}

TEST(LightingCacheGrid, LookupDoesNotBleedAcrossACorner) {
    // Floor voxels hold 1, red-wall voxels 0: floor points next to the wall must still read 1.
    const CornellScene scene = CornellScene::standard();
    const SurfaceVoxels vox = SurfaceVoxels::voxelize(scene, 10.0);
    std::vector<double> values(3 * vox.size(), 0.0);
    for (std::size_t i = 0; i < vox.size(); ++i)
        if (scene.quads()[static_cast<std::size_t>(vox.quad[i])].name == "floor") values[3 * i] = 1.0;
    const LightingCacheGrid grid(vox, values, CacheMetadata{});
    const Vec3 up{0, 1, 0};
    for (double x : {548.0, 545.0, 540.0}) {
        const Vec3 p{x, 0, 300};
        double out[3];
        grid.sample(std::span<const Vec3>(&p, 1), std::span<const Vec3>(&up, 1), out);
        EXPECT_NEAR(out[0], 1.0, 1e-6) << "x = " << x;
    }
}

TEST(LightingCacheGrid, ForeignOrMissingFilesAreInputErrors) {
    EXPECT_THROW(LightingCacheGrid::read(tempPath("does_not_exist.vdb")), InputError);
    const std::string junk = tempPath("junk.vdb");
    std::ofstream(junk) << "not a vdb file";
    EXPECT_THROW(LightingCacheGrid::read(junk), InputError);
    std::filesystem::remove(junk);
}

TEST(LightingCacheGrid, WriteToAMissingFolderIsAnIoError) {
    const SurfaceVoxels vox = SurfaceVoxels::voxelize(CornellScene::standard(), 40.0);
    const LightingCacheGrid grid(vox, std::vector<double>(3 * vox.size(), 1.0), CacheMetadata{});
    EXPECT_THROW(grid.write("/nonexistent-folder-pmsc/x.vdb"), IoError);
    EXPECT_THROW(LightingCacheGrid(vox, std::vector<double>(5, 1.0), CacheMetadata{}), std::invalid_argument);
}

}  // namespace
}  // namespace pmsc::cornell
