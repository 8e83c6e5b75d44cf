// The cache's points: a one-voxel shell over the box's surfaces, each voxel's gather point on a
// surface inside (or at the edge of) the voxel, never inside a block.
#include "evaluators/cornell/SurfaceVoxels.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

namespace pmsc::cornell {
namespace {

TEST(SurfaceVoxels, VoxelSizeIsDerivedFromTheRequestedCount) {
    const CornellScene scene = CornellScene::standard();
    for (std::size_t target : {2000u, 20000u}) {
        const SurfaceVoxels v = SurfaceVoxels::voxelizeToCount(scene, target);
        EXPECT_NEAR(static_cast<double>(v.size()), static_cast<double>(target), 0.02 * target);
        // A one-voxel shell over the surfaces: about one voxel per voxel-size squared of area.
        const double perArea =
            static_cast<double>(v.size()) * v.voxelSizeMm * v.voxelSizeMm / scene.totalArea();
        EXPECT_GT(perArea, 0.85);
        EXPECT_LT(perArea, 1.3);
    }
    EXPECT_THROW(SurfaceVoxels::voxelizeToCount(scene, 3), std::invalid_argument);
}

TEST(SurfaceVoxels, GatherPointsLieOnTheirSurfaceNearTheVoxel) {
    const CornellScene scene = CornellScene::standard();
    const SurfaceVoxels v = SurfaceVoxels::voxelize(scene, 12.0);
    ASSERT_GT(v.size(), 1000u);
    ASSERT_TRUE(std::is_sorted(v.ijk.begin(), v.ijk.end()));
    ASSERT_EQ(std::adjacent_find(v.ijk.begin(), v.ijk.end()), v.ijk.end());
    const double h = v.voxelSizeMm;
    for (std::size_t i = 0; i < v.size(); ++i) {
        const Quad& q = scene.quads()[static_cast<std::size_t>(v.quad[i])];
        const Vec3 p = v.position[i];
        EXPECT_LT(length(q.closestPoint(p) - p), 1e-6);
        const Vec3 centre{v.ijk[i][0] * h, v.ijk[i][1] * h, v.ijk[i][2] * h};
        EXPECT_LE(length(p - centre), 0.5 * std::sqrt(3.0) * h + 1e-9);
        EXPECT_NEAR(length(v.normal[i]), 1.0, 1e-12);
        EXPECT_FALSE(scene.insideBlock(p, 1e-6)) << "point " << i;
    }
}

TEST(SurfaceVoxels, NormalsFaceTheLitSide) {
    const CornellScene scene = CornellScene::standard();
    for (const Quad& q : scene.quads()) {
        const Vec3 n = q.normal;
        const bool ok = q.name == "floor"     ? n.y > 0.99
                        : q.name == "ceiling" ? n.y < -0.99
                        : q.name == "left"    ? n.x < -0.99  // red wall at x = 556 faces -x
                        : q.name == "right"   ? n.x > 0.99   // green wall at x = 0 faces +x
                        : q.name == "back"    ? n.z < -0.99
                        : q.name.find("top") != std::string::npos
                            ? n.y > 0.99
                            : std::abs(n.y) < 1e-9;  // block sides are vertical
        EXPECT_TRUE(ok) << q.name;
    }
}

}  // namespace
}  // namespace pmsc::cornell
