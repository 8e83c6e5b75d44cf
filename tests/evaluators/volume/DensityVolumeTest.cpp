// The density grid: bad inputs (one line each), the ray march against an analytic integral, the
// smoke made from a mesh, and the cache grid's topology and file round trip.
#include "evaluators/volume/DensityVolume.h"
#include "pmsc/Errors.h"
#include "tests/common/MissingData.h"
#include "tests/evaluators/volume/VdbFixtures.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

namespace pmsc::volume {
namespace {

std::string errorOf(const std::function<void()>& f) {
    try {
        f();
    } catch (const InputError& e) {
        return e.what();
    }
    return "(no InputError)";
}

TEST(DensityVolume, BadInputsAreOneLineInputErrorsNamingTheFile) {
    const std::string dir = test::tempDir("bad");
    const std::string missing = dir + "/missing.vdb";
    std::string e = errorOf([&] { DensityVolume::read(missing); });
    EXPECT_NE(e.find(missing), std::string::npos) << e;
    EXPECT_NE(e.find("no such file"), std::string::npos) << e;

    const std::string vectors = dir + "/vectors.vdb";
    test::writeVectorOnly(vectors);
    e = errorOf([&] { DensityVolume::read(vectors); });
    EXPECT_NE(e.find("has no float grid"), std::string::npos) << e;
    e = errorOf([&] { DensityVolume::read(vectors, "velocity"); });
    EXPECT_NE(e.find("not a float grid"), std::string::npos) << e;

    const std::string box = dir + "/box.vdb";
    test::writeDensityBox(box, "smoke", 0.5, 0.1, 1.0f);
    e = errorOf([&] { DensityVolume::read(box, "density"); });
    EXPECT_NE(e.find("no grid named 'density' (grids: smoke)"), std::string::npos) << e;

    const std::string text = dir + "/text.vdb";
    std::ofstream(text) << "not a vdb\n";
    e = errorOf([&] { DensityVolume::read(text); });
    EXPECT_NE(e.find("not a readable OpenVDB file"), std::string::npos) << e;
    for (const std::string& msg :
         {errorOf([&] { DensityVolume::read(text); }), errorOf([&] { DensityVolume::read(missing); })})
        EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
    std::filesystem::remove_all(dir);
}

TEST(DensityVolume, WithoutAGridNameTheOnlyFloatGridIsReadAndSeveralAreOneErrorListingThem) {
    const std::string dir = test::tempDir("grids");
    // vdb_tool names its fog volume after the operations and the mesh.
    const std::string one = dir + "/one.vdb";
    test::writeFloatGrids(one, {"ls2fog_mesh2ls_Spider_binary"}, 0.2, 0.1);
    EXPECT_EQ(DensityVolume::read(one).gridName(), "ls2fog_mesh2ls_Spider_binary");

    const std::string two = dir + "/two.vdb";
    test::writeFloatGrids(two, {"temperature", "smoke"}, 0.2, 0.1);
    std::string e = errorOf([&] { DensityVolume::read(two); });
    EXPECT_NE(e.find("2 float grids ("), std::string::npos) << e;  // in the file's order
    EXPECT_NE(e.find("'temperature'"), std::string::npos) << e;
    EXPECT_NE(e.find("'smoke'"), std::string::npos) << e;
    EXPECT_NE(e.find("and none named 'density'"), std::string::npos) << e;
    EXPECT_NE(e.find("--grid NAME"), std::string::npos) << e;
    EXPECT_NE(e.find(two), std::string::npos) << e;
    EXPECT_EQ(e.find('\n'), std::string::npos) << e;
    EXPECT_EQ(DensityVolume::read(two, "smoke").gridName(), "smoke");

    const std::string three = dir + "/three.vdb";
    test::writeFloatGrids(three, {"temperature", "density", "smoke"}, 0.2, 0.1);
    EXPECT_EQ(DensityVolume::read(three).gridName(), "density");

    const std::string empty = dir + "/empty.vdb";
    test::writeEmptyFloatGrid(empty, "density");
    e = errorOf([&] { DensityVolume::read(empty); });
    EXPECT_NE(e.find("the grid has no active voxels"), std::string::npos) << e;
    EXPECT_NE(e.find(empty), std::string::npos) << e;
    std::filesystem::remove_all(dir);
}

TEST(DensityVolume, MarchIntegratesAConstantBoxExactlyAndSkipsEmptySpace) {
    const std::string dir = test::tempDir("box");
    test::writeDensityBox(dir + "/box.vdb", "smoke", 1.0, 0.05, 2.0f);
    const DensityVolume v = DensityVolume::read(dir + "/box.vdb");  // the only float grid
    EXPECT_EQ(v.gridName(), "smoke");
    EXPECT_EQ(v.voxelCount(), 41u * 41u * 41u);
    DensityVolume::Tracer tracer(v);
    // From the centre to a point 10 m away along +x: density 2 over 1 m of box, then the
    // trilinear ramp of the last voxel (half a voxel of density on average) and nothing.
    const double inside = tracer.densityIntegral({0, 0, 0}, {10, 0, 0}, 1.0);
    EXPECT_NEAR(inside, 2.0 * (1.0 + 0.5 * 0.05), 0.01);
    // A finer step changes it by less than the midpoint rule's error on a linear ramp (none).
    EXPECT_NEAR(tracer.densityIntegral({0, 0, 0}, {10, 0, 0}, 0.25), inside, 1e-3);
    // A segment entirely outside the box sees nothing; one that crosses it sees 2 x its width.
    EXPECT_EQ(tracer.densityIntegral({3, 0, 0}, {3, 5, 0}, 1.0), 0.0);
    EXPECT_NEAR(tracer.densityIntegral({-5, 0.2, 0.1}, {5, 0.2, 0.1}, 1.0), 2.0 * (2.0 + 0.05), 0.01);
    EXPECT_NEAR(tracer.density({0.3, 0.2, -0.1}), 2.0, 1e-6);
    std::filesystem::remove_all(dir);
}

// The tracer reads a stencil inside one leaf from the leaf's buffer and any other through the
// accessor; both must give BoxSampler's value to the bit (the evaluator's frames, and so the
// models trained on them, do not depend on which path a sample took).
TEST(DensityVolume, TrilinearDensityIsBoxSamplersToTheBit) {
    const std::string dir = test::tempDir("noise");
    const double voxel = 0.1;
    test::writeNoiseDensity(dir + "/noise.vdb", voxel, 7);
    const DensityVolume v = DensityVolume::read(dir + "/noise.vdb");
    DensityVolume::Tracer tracer(v);
    std::mt19937 rng(11);
    // Random points over the random leaves; points near the leaves' faces along every axis (index
    // coordinates just inside a leaf, straddling two, and just past a face, at -8, 0 and 8, so
    // negative ones too); points across the border between the leaves and the two tiles (index 7
    // to 25 along x or y); and fixed points on the inactive tile's border.
    std::uniform_real_distribution<double> inside(-11.5, 11.5), acrossTiles(7.0, 25.0), jitter(-0.01, 0.01);
    std::uniform_int_distribution<int> face(-1, 1), side(0, 2);
    const double nearFace[3] = {-1.01, -0.5, 0.01};
    std::vector<double> xyz;
    for (int p = 0; p < 6000; ++p) {
        double index[3] = {inside(rng), inside(rng), inside(rng)};
        if (p % 3 == 1)
            for (double& c : index) c = 8.0 * face(rng) + nearFace[side(rng)] + jitter(rng);
        if (p % 3 == 2) index[p % 2] = acrossTiles(rng);
        for (const double c : index) xyz.push_back(c * voxel);
    }
    for (const double c : {3.3, 15.5, 4.2, 3.3, 16.01, 4.2, 3.3, 23.5, 4.2, 7.999, 8.0, 0.0, 15.5, 3.3, 4.2})
        xyz.push_back(c * voxel);
    const std::vector<double> expected = test::boxSamplerDensities(dir + "/noise.vdb", xyz);
    ASSERT_EQ(expected.size(), xyz.size() / 3);
    int nonZero = 0;
    for (std::size_t p = 0; p < expected.size(); ++p) {
        const double got = tracer.density({xyz[3 * p], xyz[3 * p + 1], xyz[3 * p + 2]});
        ASSERT_EQ(got, expected[p]) << "at point " << p;
        nonZero += got != 0;
    }
    EXPECT_GT(nonZero, 4000);  // the points sample the grid, not its background
    std::filesystem::remove_all(dir);
}

TEST(DensityVolume, SmokeFromTheMeshHasTheWantedVoxelsAndVaryingDensity) {
    const std::string mesh = test::testMesh();
    if (mesh.empty()) {
        PMSC_MISSING_DATA("assimp-testmodels not installed");
    }
    FogOptions fog;
    fog.targetVoxels = 8000;
    const DensityVolume v = DensityVolume::fromMesh(mesh, fog);
    EXPECT_NEAR(static_cast<double>(v.voxelCount()), 8000, 8000 * 0.06);
    double lo = 1e9, hi = 0;
    for (std::size_t i = 0; i < v.voxelCount(); ++i) {
        lo = std::min(lo, v.densityAt(i));
        hi = std::max(hi, v.densityAt(i));
    }
    EXPECT_GT(lo, 0.0);  // inactive where it is zero
    EXPECT_LE(hi, 1.0);
    EXPECT_GT(hi, 3 * lo);  // noise: heterogeneous
    const auto [a, b] = v.worldBounds();
    EXPECT_NEAR(std::max({b.x - a.x, b.y - a.y, b.z - a.z}), fog.sizeMetres, 0.1 * fog.sizeMetres);

    const std::string dir = test::tempDir("mesh");
    v.write(dir + "/density.vdb");
    const DensityVolume back = DensityVolume::read(dir + "/density.vdb");
    ASSERT_EQ(back.voxelCount(), v.voxelCount());
    EXPECT_EQ(back.gridName(), "density");
    for (std::size_t i = 0; i < v.voxelCount(); i += 97) EXPECT_EQ(back.densityAt(i), v.densityAt(i));

    EXPECT_NE(errorOf([&] { DensityVolume::fromMesh(dir + "/nope.obj", fog); }).find("no such file"),
              std::string::npos);
    std::filesystem::remove_all(dir);
}

TEST(ScatterCache, SharesTheDensityTopologyAndRoundTripsThroughAFile) {
    const std::string dir = test::tempDir("cache");
    test::writeDensityBox(dir + "/box.vdb", "density", 0.3, 0.1, 1.0f);
    const DensityVolume v = DensityVolume::read(dir + "/box.vdb");
    std::vector<double> values(3 * v.voxelCount());
    for (std::size_t i = 0; i < v.voxelCount(); ++i) {
        const Vec3 p = v.voxelPositions()[i];
        values[3 * i] = p.x + 1;
        values[3 * i + 1] = p.y + 2;
        values[3 * i + 2] = p.z + 3;
    }
    ScatterCacheInfo info;
    info.frame = 7;
    info.lightKelvin = 4200;
    info.state = "hit";
    const ScatterCache cache(v, values, info);
    EXPECT_EQ(cache.activeVoxelCount(), static_cast<std::int64_t>(v.voxelCount()));
    cache.write(dir + "/cache.vdb");
    const ScatterCache back = ScatterCache::read(dir + "/cache.vdb");
    EXPECT_EQ(back.activeVoxelCount(), cache.activeVoxelCount());
    EXPECT_EQ(back.info().frame, 7);
    EXPECT_EQ(back.info().state, "hit");
    EXPECT_EQ(back.info().lightKelvin, 4200);
    ScatterCache::Sampler s(back);
    for (std::size_t i = 0; i < v.voxelCount(); i += 5) {
        const Vec3 p = v.voxelPositions()[i];
        const Rgb r = s.at(p);
        EXPECT_NEAR(r[0], p.x + 1, 1e-5);
        EXPECT_NEAR(r[2], p.z + 3, 1e-5);
    }
    // Between voxels: trilinear (the values are linear in position); at the edge, renormalized.
    EXPECT_NEAR(s.at({0.05, 0.0, 0.0})[0], 1.05, 1e-5);
    EXPECT_NEAR(s.at({0.32, 0.0, 0.0})[0], 1.3, 1e-5);
    EXPECT_THROW(ScatterCache(v, std::span<const double>(values.data(), 3), info), std::invalid_argument);
    EXPECT_THROW(ScatterCache::read(dir + "/box.vdb"), InputError);  // no "inscatter" grid
    std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace pmsc::volume
