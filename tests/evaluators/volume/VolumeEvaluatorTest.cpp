// The full calculation per voxel: physics against closed forms, the march's convergence, the
// determinism the engine relies on, the colour control, the light rig and the spec's errors.
#include "evaluators/volume/VolumeEvaluator.h"
#include "pmsc/Errors.h"
#include "tests/common/MissingData.h"
#include "tests/evaluators/volume/VdbFixtures.h"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <numeric>

namespace pmsc::volume {
namespace {

std::shared_ptr<const VolumeWorld> boxWorld(const std::string& dir, float density, MediumSettings m) {
    test::writeDensityBox(dir + "/box.vdb", "density", 0.5, 0.05, density);
    return VolumeWorld::create(DensityVolume::read(dir + "/box.vdb"), m, dir + "/box.vdb");
}

TEST(VolumeEvaluator, ThinMediumGivesTheUnshadowedClosedFormWithAllOctaves) {
    const std::string dir = test::tempDir("thin");
    MediumSettings m;
    m.sigmaT = 1e-9;  // no extinction: every T = 1
    const auto world = boxWorld(dir, 1.0f, m);
    VolumeLight l;
    l.position = {3, 0, 0};
    l.radius = 1e-6;
    l.intensity = {2.0, 1.0, 0.5};
    const VolumeEvaluator ev(world, {l});
    const Index point = 123;
    double rgb[3];
    ev.evaluate(0, std::span<const Index>(&point, 1), rgb);
    const Vec3 p = world->density.voxelPositions()[123];
    const double d2 = std::pow(scene::length(l.position - p), 2);
    for (int c = 0; c < 3; ++c) {
        double sum = 1, w = 1;
        for (int k = 0; k < m.octaves; ++k) sum += (w *= m.octaveScattering * m.albedo[c]);
        EXPECT_NEAR(rgb[c], l.intensity[c] / (4 * M_PI * d2) * sum, 1e-9 * rgb[c]) << c;
    }
    std::filesystem::remove_all(dir);
}

TEST(VolumeEvaluator, SingleScatteringInAConstantBoxIsBeersLaw) {
    const std::string dir = test::tempDir("beer");
    MediumSettings m;
    m.sigmaT = 1.5;
    m.octaves = 0;
    const auto world = boxWorld(dir, 1.0f, m);
    VolumeLight l;
    l.position = {4, 0, 0};
    l.radius = 1e-6;
    l.intensity = {1, 1, 1};
    const VolumeEvaluator ev(world, {l});
    std::vector<double> all(3 * static_cast<std::size_t>(ev.pointCount()));
    ev.evaluateAll(0, all.data());
    for (std::size_t i = 0; i < world->density.voxelCount(); i += 37) {
        const Vec3 p = world->density.voxelPositions()[i];
        if (std::abs(p.y) > 0.4 || std::abs(p.z) > 0.4) continue;  // shadow rays leave through the +x face
        // To the box's +x face along the ray, with the last voxel's ramp (half a voxel of density).
        const double d = scene::length(l.position - p);
        const double path = (0.5 + 0.5 * 0.05 - p.x) * d / (l.position.x - p.x);
        const double d2 = d * d;
        EXPECT_NEAR(all[3 * i], std::exp(-1.5 * path) / (4 * M_PI * d2), 0.01 * all[3 * i]) << p.x;
    }
    std::filesystem::remove_all(dir);
}

class SmokeTest : public ::testing::Test {
protected:
    static void SetUpTestSuite() {
        const std::string mesh = test::testMesh();
        if (mesh.empty()) return;
        FogOptions fog;
        fog.targetVoxels = 6000;
        world_ = VolumeWorld::create(DensityVolume::fromMesh(mesh, fog), MediumSettings{}, mesh);
    }
    static void TearDownTestSuite() { world_.reset(); }
    void SetUp() override {
        if (!world_) {
            PMSC_MISSING_DATA("assimp-testmodels not installed");
        }
    }
    static std::shared_ptr<const VolumeWorld> world_;
};
std::shared_ptr<const VolumeWorld> SmokeTest::world_;

TEST_F(SmokeTest, AVoxelsValueIsBitIdenticalAloneAmongAllAndAtAnyThreadCount) {
    const VolumeRig rig;
    const VolumeEvaluator ev(world_, rig.path(*world_, 3));
    const std::size_t n = static_cast<std::size_t>(ev.pointCount());
    std::vector<double> one(3 * n), two(3 * n);
    tbb::task_arena(1).execute([&] { ev.evaluateAll(2, one.data()); });
    tbb::task_arena(2).execute([&] { ev.evaluateAll(2, two.data()); });
    EXPECT_EQ(one, two);
    std::vector<Index> some{static_cast<Index>(n - 1), 0, 17, static_cast<Index>(n / 2)};
    std::vector<double> alone(3 * some.size());
    ev.evaluate(2, some, alone.data());
    for (std::size_t i = 0; i < some.size(); ++i)
        for (int c = 0; c < 3; ++c)
            EXPECT_EQ(alone[3 * i + c], one[3 * static_cast<std::size_t>(some[i]) + c]);
    EXPECT_THROW(ev.evaluate(3, some, alone.data()), std::out_of_range);
    const Index bad = static_cast<Index>(n);
    EXPECT_THROW(ev.evaluate(0, std::span<const Index>(&bad, 1), alone.data()), std::out_of_range);
}

TEST_F(SmokeTest, OneVoxelStepIsWithinHalfAPercentOfAFourTimesFinerMarch) {
    MediumSettings fine = world_->medium;
    fine.stepVoxels = 0.25;
    const VolumeRig rig;
    const auto lights = rig.between(*world_, 2);
    const VolumeEvaluator coarse(world_, lights),
        finer(VolumeWorld::create(world_->density, fine, "fine"), lights);
    const std::size_t n = world_->density.voxelCount();
    std::vector<double> a(3 * n), b(3 * n);
    for (Index f = 0; f < 2; ++f) {
        coarse.evaluateAll(f, a.data());
        finer.evaluateAll(f, b.data());
        double e2 = 0, r2 = 0;
        for (std::size_t i = 0; i < a.size(); ++i) {
            e2 += (a[i] - b[i]) * (a[i] - b[i]);
            r2 += b[i] * b[i];
        }
        EXPECT_LT(std::sqrt(e2 / r2), 0.005) << f;
    }
}

TEST_F(SmokeTest, TheSideFacingTheLightIsBrighterAndMultipleScatteringLightsTheShadow) {
    const VolumeRig rig;
    const VolumeLight l = rig.light(*world_, 0, 0, 6500);  // on +x
    MediumSettings single = world_->medium;
    single.octaves = 0;
    const VolumeEvaluator ms(world_, {l}), ss(VolumeWorld::create(world_->density, single, "ss"), {l});
    const std::size_t n = world_->density.voxelCount();
    std::vector<double> a(3 * n), b(3 * n);
    ms.evaluateAll(0, a.data());
    ss.evaluateAll(0, b.data());
    double lit = 0, shade = 0, shadeSingle = 0;
    std::size_t nl = 0, ns = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const double x = world_->density.voxelPositions()[i].x - world_->centre.x;
        if (x > 0.5) lit += a[3 * i + 1], ++nl;
        if (x < -0.5) shade += a[3 * i + 1], shadeSingle += b[3 * i + 1], ++ns;
        for (int c = 0; c < 3; ++c) EXPECT_GE(a[3 * i + c], b[3 * i + c]);
    }
    ASSERT_GT(nl, 0u);
    ASSERT_GT(ns, 0u);
    EXPECT_GT(lit / nl, 2 * shade / ns);
    EXPECT_GT(shade, 1.5 * shadeSingle);  // the octaves carry light into the shadow
}

TEST_F(SmokeTest, RecolouringAFrameEqualsCalculatingItInTheOtherColour) {
    const VolumeRig rig;
    const VolumeLight warm = rig.light(*world_, 30, 40, 4000), cool = rig.light(*world_, 30, 40, 6500);
    const VolumeEvaluator ev(world_, {warm, cool});
    const std::size_t n = world_->density.voxelCount();
    std::vector<double> a(3 * n), b(3 * n);
    ev.evaluateAll(0, a.data());
    ev.evaluateAll(1, b.data());
    recolour(warm, cool, a.data(), static_cast<Index>(n));
    for (std::size_t i = 0; i < a.size(); ++i) ASSERT_NEAR(a[i], b[i], 1e-12 * std::abs(b[i]) + 1e-300) << i;
    EXPECT_THROW(recolour(warm, rig.light(*world_, 31, 40, 6500), a.data(), 1), std::invalid_argument);
}

TEST(VolumeLightColour, KelvinGivesWarmAndColdLightOfEqualLuminance) {
    const Rgb warm = kelvinToRgb(3000), cold = kelvinToRgb(8000);
    EXPECT_GT(warm[0], 1.5 * warm[2]);
    EXPECT_GT(cold[2], cold[0]);
    for (const Rgb& c : {warm, cold}) EXPECT_NEAR(0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2], 1.0, 1e-12);
    EXPECT_THROW(kelvinToRgb(100), std::invalid_argument);
}

double angleDeg(const Vec3& a, const Vec3& b) {
    return std::acos(std::clamp(scene::dot(a, b) / (scene::length(a) * scene::length(b)), -1.0, 1.0)) * 180 /
           M_PI;
}

TEST(VolumeRig, ForMediumRefinesTheGridWhereTheLightingChangesFasterThanTheSmokes) {
    const std::string mesh = test::testMesh();
    if (mesh.empty()) {
        PMSC_MISSING_DATA("assimp-testmodels not installed");
    }
    FogOptions fog;
    fog.targetVoxels = 6000;
    fog.densityScale = 0.05;  // thin: light reaches every voxel almost unshadowed
    const auto thin = VolumeWorld::create(DensityVolume::fromMesh(mesh, fog), MediumSettings{}, mesh);
    fog.densityScale = 3;  // dense and uniform: sharp, moving shadows
    fog.noiseFloor = 1;
    const auto dense = VolumeWorld::create(DensityVolume::fromMesh(mesh, fog), MediumSettings{}, mesh);

    const VolumeRig base;
    EXPECT_LT(base.cellInterpolationError(*thin), VolumeRig::kCellErrorGoal);
    EXPECT_GT(base.cellInterpolationError(*dense), VolumeRig::kCellErrorGoal);
    const VolumeRig forThin = VolumeRig::forMedium(*thin);
    EXPECT_EQ(forThin.azimuths, base.azimuths);
    EXPECT_EQ(forThin.elevations, base.elevations);
    const VolumeRig forDense = VolumeRig::forMedium(*dense);
    EXPECT_GT(forDense.azimuths, base.azimuths);
    EXPECT_GT(forDense.elevations.size(), base.elevations.size());
    EXPECT_EQ(forDense.elevations.front(), base.elevations.front());  // the same band, finer
    EXPECT_EQ(forDense.elevations.back(), base.elevations.back());
    EXPECT_TRUE(forDense.cellInterpolationError(*dense) <= VolumeRig::kCellErrorGoal ||
                forDense.azimuths == 2 * base.azimuths);
    EXPECT_LT(forDense.cellInterpolationError(*dense), base.cellInterpolationError(*dense));
    // A spiral, or colours and distance asked for, pass through.
    VolumeRig spiral;
    spiral.spiral = 40;
    EXPECT_EQ(VolumeRig::forMedium(*dense, spiral).spiral, 40);
    VolumeRig warm;
    warm.kelvinLow = warm.kelvinHigh = 3000;
    EXPECT_EQ(VolumeRig::forMedium(*dense, warm).kelvinHigh, 3000);
}

TEST(VolumeRig, SpiralCoversTheBandEvenlyCyclesColoursAndBetweenFindsItsHoles) {
    const std::string dir = test::tempDir("spiral");
    const auto world = boxWorld(dir, 1.0f, {});
    VolumeRig rig;
    rig.spiral = 60;
    rig.colours = 3;
    rig.elevations = {10, 70};
    const auto lights = rig.training(*world);
    const auto dirs = rig.trainingDirections();
    ASSERT_EQ(lights.size(), 60u);
    ASSERT_EQ(dirs.size(), 60u);
    std::map<double, int> perKelvin;
    std::vector<double> spacing;
    for (std::size_t i = 0; i < lights.size(); ++i) {
        const Vec3 d = lights[i].position - world->centre;
        EXPECT_LT(angleDeg(d, dirs[i]), 1e-6) << i;
        const double elevation = std::asin(d.y / scene::length(d)) * 180 / M_PI;
        EXPECT_GE(elevation, 10.0) << i;
        EXPECT_LE(elevation, 70.0) << i;
        ++perKelvin[lights[i].kelvin];
        double nearest = 1e9;
        for (std::size_t j = 0; j < dirs.size(); ++j)
            if (j != i) nearest = std::min(nearest, angleDeg(dirs[i], dirs[j]));
        spacing.push_back(nearest);
    }
    EXPECT_EQ(perKelvin.size(), 3u);
    for (const auto& [k, count] : perKelvin) EXPECT_EQ(count, 20) << k;
    EXPECT_TRUE(perKelvin.count(0.5 * (rig.kelvinLow + rig.kelvinHigh)));
    std::sort(spacing.begin(), spacing.end());
    // Even in area: no position much closer to its neighbour than the median spacing.
    EXPECT_GT(spacing.front(), 0.5 * spacing[spacing.size() / 2]);
    // The holes: every validation light at least 0.6 x the median spacing from every training
    // position (a random direction in the band is closer than that about half the time).
    for (const VolumeLight& l : rig.between(*world, 8)) {
        double nearest = 1e9;
        for (const Vec3& d : dirs) nearest = std::min(nearest, angleDeg(l.position - world->centre, d));
        EXPECT_GT(nearest, 0.6 * spacing[spacing.size() / 2]);
        EXPECT_GT(l.kelvin, rig.kelvinLow);
        EXPECT_LT(l.kelvin, rig.kelvinHigh);
    }
    // The grid's directions follow training() (one per frame, twice with colour pairs).
    VolumeRig grid;
    grid.colourPairs = true;
    EXPECT_EQ(grid.trainingDirections().size(), grid.training(*world).size());
    std::filesystem::remove_all(dir);
}

TEST(VolumeSpec, GridOptionAndBadOptionsAreOneLineInputErrors) {
    const std::string dir = test::tempDir("spec");
    test::writeDensityBox(dir + "/box.vdb", "smoke", 0.2, 0.1, 1.0f);
    const auto ev = makeVolumeEvaluator(dir + "/box.vdb:grid=smoke:lights=path");
    EXPECT_EQ(ev->frameCount(), 48);
    EXPECT_EQ(ev->pointCount(), 125);
    {
        const auto world = VolumeWorld::create(DensityVolume::read(dir + "/box.vdb"), {}, "box");
        EXPECT_EQ(makeVolumeEvaluator(dir + "/box.vdb")->frameCount(),
                  static_cast<Index>(VolumeRig::forMedium(*world).training(*world).size()) + 16 + 48);
    }
    auto message = [&](const std::string& spec) {
        try {
            makeVolumeEvaluator(spec);
        } catch (const InputError& e) {
            return std::string(e.what());
        }
        return std::string("(no InputError)");
    };
    EXPECT_NE(message(dir + "/box.vdb:grid=density").find("no grid named 'density'"), std::string::npos);
    EXPECT_NE(message(dir + "/box.vdb:samples=0").find("samples='0'"), std::string::npos);
    EXPECT_NE(message(dir + "/box.vdb:lights=some").find("lights='some'"), std::string::npos);
    EXPECT_NE(message(dir + "/box.vdb:colour=red").find("unknown option 'colour'"), std::string::npos);
    EXPECT_NE(message(dir + "/none.vdb").find("no such file"), std::string::npos);
    std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace pmsc::volume
