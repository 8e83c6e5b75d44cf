// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// The point light cache (`pmsc run --format vdb` of an exec child with positions): its voxel size
// from the points' spacing, a round trip of the values at the points (a point alone in its voxel
// gets its own value back, points sharing one their mean), and the bad inputs.
#include "evaluators/scene/PointCacheGrid.h"
#include "pmsc/Errors.h"
#include "tests/common/TempDir.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>

namespace pmsc::scene {
namespace {

/// A 20 x 20 lattice of spacing 2 in the plane z = 5, offset so no point is on a voxel boundary.
std::vector<double> lattice() {
    std::vector<double> p;
    for (int i = 0; i < 20; ++i)
        for (int j = 0; j < 20; ++j) {
            p.push_back(0.3 + 2.0 * i);
            p.push_back(-7.1 + 2.0 * j);
            p.push_back(5.0);
        }
    return p;
}

TEST(PointCacheGrid, TheVoxelIsHalfTheMedianSpacing) {
    EXPECT_DOUBLE_EQ(PointCacheGrid::cellSizeFor(lattice()), 1.0);
    // Points on a sphere, at random: the median nearest-neighbour distance, halved.
    std::mt19937 rng(3);
    std::normal_distribution<double> g;
    std::vector<double> sphere;
    for (int i = 0; i < 4000; ++i) {
        double x = g(rng), y = g(rng), z = g(rng);
        const double r = std::sqrt(x * x + y * y + z * z);
        sphere.insert(sphere.end(), {x / r, y / r, z / r});
    }
    const double h = PointCacheGrid::cellSizeFor(sphere);
    // 4000 points on 4 pi: a Poisson sheet's median nearest distance is sqrt(ln 2 / (pi density)).
    const double expected = std::sqrt(std::log(2.0) / (M_PI * 4000 / (4 * M_PI))) / 2;
    EXPECT_NEAR(h, expected, 0.15 * expected);
    EXPECT_EQ(PointCacheGrid::cellSizeFor(std::vector<double>{1, 2, 3}), 1.0);  // one point
    EXPECT_THROW(PointCacheGrid::cellSizeFor(std::vector<double>{1, 2, NAN}), InputError);
}

TEST(PointCacheGrid, ValuesComeBackAtTheirPointsAndSharedVoxelsHoldTheMean) {
    std::vector<double> p = lattice();
    // Two more points, each sharing the voxel of the first lattice point.
    p.insert(p.end(), {0.35, -7.05, 5.0, 0.25, -7.15, 5.0});
    const size_t n = p.size() / 3;
    std::vector<double> rgb(3 * n);
    for (size_t i = 0; i < rgb.size(); ++i) rgb[i] = 0.25 * double(i % 97) + 1;
    const double h = PointCacheGrid::cellSizeFor(p);
    const test::TempDir dir;
    const std::string path = dir.file("rgb.vdb");
    PointCacheGrid::write(path, p, rgb, 3, h, 7);
    EXPECT_EQ(PointCacheGrid::pointCount(path), std::int64_t(n));
    Index channels = 0;
    const std::vector<double> back = PointCacheGrid::sample(path, p, channels);
    ASSERT_EQ(channels, 3);
    ASSERT_EQ(back.size(), rgb.size());
    for (size_t i = 1; i < 400; ++i)
        for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(float(back[3 * i + c]), float(rgb[3 * i + c])) << i;
    for (const size_t i : {size_t(0), size_t(400), size_t(401)})
        for (int c = 0; c < 3; ++c)
            EXPECT_FLOAT_EQ(float(back[3 * i + c]), float((rgb[c] + rgb[1200 + c] + rgb[1203 + c]) / 3)) << i;

    // One channel: a FloatGrid.
    std::vector<double> one(n, 2.5);
    PointCacheGrid::write(path, p, one, 1, h, 0);
    EXPECT_EQ(PointCacheGrid::sample(path, p, channels), one);
    EXPECT_EQ(channels, 1);

    // A place with no voxel, other channel counts, a missing and a foreign file.
    EXPECT_THROW(PointCacheGrid::sample(path, std::vector<double>{100, 100, 100}, channels), InputError);
    EXPECT_THROW(PointCacheGrid::write(path, p, std::vector<double>(2 * n), 2, h, 0), std::invalid_argument);
    EXPECT_THROW(PointCacheGrid::write(path, p, one, 1, 0.0, 0), std::invalid_argument);
    std::filesystem::remove(path);
    EXPECT_THROW(PointCacheGrid::pointCount(path), InputError);
    std::ofstream(path) << "not a vdb";
    EXPECT_THROW(PointCacheGrid::pointCount(path), InputError);
    EXPECT_THROW(PointCacheGrid::sample(path, p, channels), InputError);
    EXPECT_THROW(PointCacheGrid::write(dir.file("no-such-dir/x.vdb"), p, one, 1, h, 0), IoError);
}

}  // namespace
}  // namespace pmsc::scene
