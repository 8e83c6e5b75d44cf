// The local change of the Cornell box: the changed scene keeps the original quads first, the
// changed world keeps the cache's points, and the cube acts like an object (it covers the floor
// under it and throws a contact shadow next to it).
#include "evaluators/cornell/CornellEvaluator.h"
#include "examples/cornell/CornellLocalChange.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pmsc::cornell {
namespace {

TEST(CornellLocalChange, WithBoxAppendsFiveQuadsOnTheFloorSixAboveItAndKeepsTheOriginalsFirst) {
    const CornellScene base = CornellScene::standard();
    const LocalChangeBox box = LocalChangeBox::againstBackWall(100);
    const CornellScene onFloor = base.withBox("cube", box.lo, box.hi);
    ASSERT_EQ(onFloor.quads().size(), base.quads().size() + 5);
    for (std::size_t q = 0; q < base.quads().size(); ++q)
        EXPECT_EQ(onFloor.quads()[q].name, base.quads()[q].name);
    const Vec3 centre = (box.lo + box.hi) * 0.5;
    for (std::size_t q = base.quads().size(); q < onFloor.quads().size(); ++q) {
        const Quad& quad = onFloor.quads()[q];
        EXPECT_NEAR(quad.area(), 100.0 * 100.0, 1e-6) << quad.name;
        const Vec3 mid = (quad.corners[0] + quad.corners[1] + quad.corners[2] + quad.corners[3]) * 0.25;
        EXPECT_GT(dot(mid - centre, quad.normal), 0) << quad.name << ": normals point out of the cube";
    }
    const CornellScene floating = base.withBox("shelf", {100, 200, 450}, {200, 250, 549});
    EXPECT_EQ(floating.quads().size(), base.quads().size() + 6);
    EXPECT_THROW(base.withBox("flat", {0, 0, 0}, {10, 0, 10}), std::invalid_argument);
}

TEST(CornellLocalChange, TheBoxStandsAgainstTheBackWallClearOfTheBlocks) {
    const CornellScene scene = CornellScene::standard();
    for (const double edge : {10.0, 100.0, 150.0}) {
        const LocalChangeBox b = LocalChangeBox::againstBackWall(edge);
        EXPECT_DOUBLE_EQ(b.lo.y, 0);
        EXPECT_DOUBLE_EQ(b.hi.y, edge);
        EXPECT_NEAR(559.2 - b.hi.z, 10, 1e-9);
        for (const double x : {b.lo.x, b.hi.x})
            for (const double z : {b.lo.z, b.hi.z}) EXPECT_FALSE(scene.insideBlock({x, 1, z})) << edge;
    }
}

// The demo's cube goes where key points would see it: given keys clustered by the green wall at
// z = 420, the chosen cube stands within half an edge of them all, 10 mm from that wall, clear of
// the blocks.
TEST(CornellLocalChange, WhereKeysSeePutsTheCubeByTheKeys) {
    const auto world = CornellWorld::create(3000);
    std::vector<Index> keys;
    for (Index p = 0; p < Index(world->voxels.size()); ++p) {
        const Vec3 x = world->voxels.position[size_t(p)];
        if (x.y < 1 && x.x > 60 && x.x < 90 && std::abs(x.z - 420) < 30) keys.push_back(p);
    }
    ASSERT_GE(keys.size(), 2u);
    Index near = -1;
    const LocalChangeBox b = LocalChangeBox::whereKeysSee(80, *world, keys, &near);
    EXPECT_EQ(near, Index(keys.size()));
    EXPECT_DOUBLE_EQ(b.lo.x, 10);
    EXPECT_DOUBLE_EQ(b.hi.x - b.lo.x, 80);
    for (const Index k : keys) {  // each within half an edge of the cube
        const Vec3 x = world->voxels.position[size_t(k)];
        const double dz = std::max({b.lo.z - x.z, 0.0, x.z - b.hi.z}), dx = std::max(x.x - b.hi.x, 0.0);
        EXPECT_LE(std::hypot(dx, dz), 40) << "key " << k;
    }
    EXPECT_FALSE(world->scene.insideBlock({b.lo.x, 1, b.lo.z}, -5));
    EXPECT_FALSE(world->scene.insideBlock({b.hi.x, 1, b.hi.z}, -5));
}

TEST(CornellLocalChange, TheChangedWorldKeepsThePointsAndTheCubeShadowsTheFloorNextToIt) {
    const auto base = CornellWorld::create(3000);
    const LocalChangeBox box = LocalChangeBox::againstBackWall(100);
    const auto changed = CornellWorld::withScene(*base, base->scene.withBox("cube", box.lo, box.hi));
    ASSERT_EQ(changed->voxels.size(), base->voxels.size());
    EXPECT_EQ(changed->voxels.ijk, base->voxels.ijk);
    const std::vector<PointLight> lights = LightRig{}.scatteredLights(2);
    const CornellEvaluator before(base, lights, 24), after(changed, lights, 24);
    const Index n = before.pointCount();
    std::vector<double> a(static_cast<std::size_t>(3 * n)), b(a.size());
    before.evaluateAll(1, a.data());
    after.evaluateAll(1, b.data());
    // Floor points under the cube see only its inside: nothing. Floor points within 40 mm of its
    // front or sides lose light (contact shadow). Ceiling points far from it barely change.
    Index under = 0, near = 0;
    double nearBefore = 0, nearAfter = 0;
    for (Index p = 0; p < n; ++p) {
        const Vec3 x = base->voxels.position[static_cast<std::size_t>(p)];
        if (base->voxels.quad[static_cast<std::size_t>(p)] != 0) continue;  // quad 0: the floor
        const bool inside = x.x > box.lo.x && x.x < box.hi.x && x.z > box.lo.z && x.z < box.hi.z;
        const double dx = std::max({box.lo.x - x.x, 0.0, x.x - box.hi.x});
        const double dz = std::max(box.lo.z - x.z, 0.0);
        if (inside) {
            ++under;
            for (int c = 0; c < 3; ++c)
                EXPECT_EQ(b[static_cast<std::size_t>(3 * p + c)], 0.0) << "point " << p;
        } else if (std::hypot(dx, dz) < 40) {
            ++near;
            for (int c = 0; c < 3; ++c) {
                nearBefore += a[static_cast<std::size_t>(3 * p + c)];
                nearAfter += b[static_cast<std::size_t>(3 * p + c)];
            }
        }
    }
    EXPECT_GT(under, 0);
    ASSERT_GT(near, 0);
    EXPECT_LT(nearAfter, 0.9 * nearBefore) << "no contact shadow next to the cube";
    EXPECT_THROW(CornellWorld::withScene(*base, CornellScene{}), std::invalid_argument);
}

}  // namespace
}  // namespace pmsc::cornell
