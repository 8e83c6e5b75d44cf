// The Cornell evaluator: a point's value must not depend on its company or the thread count
// (PointEvaluator's contract), and the numbers must behave like light.
#include "evaluators/cornell/CornellEvaluator.h"
#include "pmsc/Errors.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <numeric>

namespace pmsc::cornell {
namespace {

std::shared_ptr<const CornellWorld> smallWorld() {
    static const auto world = CornellWorld::create(3000);
    return world;
}

TEST(CornellEvaluator, PointAloneEqualsPointAmongAllBitForBit) {
    const auto world = smallWorld();
    const CornellEvaluator ev(world, LightRig{}.scatteredLights(3), 24);
    const Index n = ev.pointCount();
    std::vector<double> all(static_cast<std::size_t>(3 * n));
    ev.evaluateAll(2, all.data());
    for (Index p : {Index{0}, Index{1}, n / 3, n / 2, n - 1}) {
        double one[3];
        const Index idx[1] = {p};
        ev.evaluate(2, idx, one);
        EXPECT_EQ(0, std::memcmp(one, all.data() + 3 * p, sizeof one)) << "point " << p;
    }
    // A shuffled subset, as the engine's key evaluation and fail-through chunks ask for it.
    const std::vector<Index> subset = {n - 5, 7, n / 2 + 1, 3, n / 4};
    std::vector<double> some(3 * subset.size());
    ev.evaluate(2, subset, some.data());
    for (std::size_t i = 0; i < subset.size(); ++i)
        EXPECT_EQ(0, std::memcmp(&some[3 * i], all.data() + 3 * subset[i], 3 * sizeof(double)));
}

// Training's frames come a set of lights at a time, each point's gather rays traced once for the
// set: every frame must be the one evaluateAll() gives, bit for bit, in any order (more frames
// than the light-path cache holds, a frame twice).
TEST(CornellEvaluator, FramesEvaluatedTogetherAreEachFrameAloneBitForBit) {
    const CornellEvaluator ev(smallWorld(), LightRig{}.trainingLights(), 24);
    const std::size_t n = static_cast<std::size_t>(ev.pointCount()) * 3;
    std::vector<Index> frames(20);
    std::iota(frames.begin(), frames.end(), Index{100});
    frames[3] = 7;
    frames[11] = 7;
    std::vector<double> together(frames.size() * n), alone(n);
    ev.evaluateAllFrames(frames, together.data());
    for (std::size_t k = 0; k < frames.size(); ++k) {
        ev.evaluateAll(frames[k], alone.data());
        EXPECT_EQ(0, std::memcmp(alone.data(), together.data() + k * n, n * sizeof(double)))
            << "frame " << frames[k];
    }
    const std::vector<Index> bad = {0, ev.frameCount()};
    EXPECT_THROW(ev.evaluateAllFrames(bad, together.data()), std::out_of_range);
}

// Embree on oneTBB caps the whole process's parallelism when its device is given a thread count;
// the ray tracer must not (it once did, and every Cornell run used one core of two).
TEST(CornellEvaluator, TheRayTracerLeavesTheProcesssParallelismAlone) {
    const auto before = tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism);
    const auto world = CornellWorld::create(500);
    const CornellEvaluator ev(world, LightRig{}.trainingLights(), 8);
    std::vector<double> v(static_cast<std::size_t>(3 * ev.pointCount()));
    ev.evaluateAll(0, v.data());
    EXPECT_EQ(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism), before);
    EXPECT_GE(before, static_cast<std::size_t>(tbb::info::default_concurrency()));
}

// Single rays, streams (the default) and packets of 8 trace the same rays: the irradiance agrees
// to float round-off whichever way Embree is called.
TEST(CornellEvaluator, SingleRaysStreamsAndPacketsGiveTheSameIrradiance) {
    std::vector<std::vector<double>> results;
    for (const TraceMode mode : {TraceMode::Stream, TraceMode::Single, TraceMode::Packet8}) {
        const CornellEvaluator ev(CornellWorld::create(1500, mode), LightRig{}.trainingLights(), 16);
        results.emplace_back(static_cast<std::size_t>(3 * ev.pointCount()));
        ev.evaluateAll(5, results.back().data());
    }
    double scale = 0;
    for (double v : results[0]) scale = std::max(scale, std::abs(v));
    ASSERT_GT(scale, 0);
    for (std::size_t m = 1; m < results.size(); ++m) {
        ASSERT_EQ(results[m].size(), results[0].size());
        for (std::size_t i = 0; i < results[0].size(); ++i)
            ASSERT_NEAR(results[m][i], results[0][i], 1e-6 * scale) << "mode " << m << ", value " << i;
    }
}

TEST(CornellEvaluator, ThreadCountDoesNotChangeAnyBit) {
    const auto world = smallWorld();
    const CornellEvaluator ev(world, LightRig{}.trainingLights(), 16);
    std::vector<double> one(static_cast<std::size_t>(3 * ev.pointCount())), two(one.size());
    tbb::task_arena(1).execute([&] { ev.evaluateAll(77, one.data()); });
    tbb::task_arena(2).execute([&] { ev.evaluateAll(77, two.data()); });
    EXPECT_EQ(0, std::memcmp(one.data(), two.data(), one.size() * sizeof(double)));
}

// The engine evaluates a frame's keys and sentinels in pieces on every thread at once: threads that
// start a frame together may each build its light paths, and frames past the 16-frame cache evict
// others meanwhile; every piece must still be what one caller with nothing cached computes.
TEST(CornellEvaluator, PiecesOfOneFrameOnManyThreadsEqualOneCallerBitForBit) {
    const auto lights = LightRig{}.trainingLights();
    const CornellEvaluator shared(smallWorld(), lights, 16);
    const Index n = shared.pointCount();
    constexpr Index kPieces = 8, kFrames = 24;
    std::vector<double> together(static_cast<std::size_t>(3 * n * kFrames));
    tbb::task_arena(4).execute([&] {
        tbb::parallel_for(Index{0}, kFrames * kPieces, [&](Index task) {
            const Index frame = 40 + task / kPieces, piece = task % kPieces;
            std::vector<Index> points;
            for (Index p = piece; p < n; p += kPieces) points.push_back(p);
            std::vector<double> values(3 * points.size());
            shared.evaluate(frame, points, values.data());
            double* out = together.data() + 3 * n * (frame - 40);
            for (std::size_t i = 0; i < points.size(); ++i)
                std::memcpy(out + 3 * points[i], &values[3 * i], 3 * sizeof(double));
        });
    });
    std::vector<double> one(static_cast<std::size_t>(3 * n));
    for (Index f = 0; f < kFrames; ++f) {
        const CornellEvaluator alone(smallWorld(), lights, 16);  // one frame, nothing cached before
        alone.evaluateAll(40 + f, one.data());
        EXPECT_EQ(0, std::memcmp(one.data(), together.data() + 3 * n * f, one.size() * sizeof(double)))
            << "frame " << 40 + f;
    }
}

TEST(CornellEvaluator, IrradianceIsFiniteNonNegativeAndLit) {
    const auto world = smallWorld();
    const CornellEvaluator ev(world, LightRig{}.trainingLights(), 16);
    std::vector<double> v(static_cast<std::size_t>(3 * ev.pointCount()));
    ev.evaluateAll(0, v.data());
    double sum = 0;
    for (double x : v) {
        ASSERT_TRUE(std::isfinite(x));
        ASSERT_GE(x, 0.0);
        sum += x;
    }
    EXPECT_GT(sum / static_cast<double>(v.size()), 0.01);
}

TEST(CornellEvaluator, DirectLightFollowsTheInverseSquareLaw) {
    const auto world = smallWorld();
    const Vec3 floorPoint{278, 0, 100};
    const Vec3 up{0, 1, 0};
    double e[3][3];
    const double heights[3] = {50, 100, 200};
    for (int i = 0; i < 3; ++i) {
        const PointLight light{{278, heights[i], 100}, {1e4, 2e4, 3e4}};
        directIrradiance(*world->tracer, light, std::span<const Vec3>(&floorPoint, 1),
                         std::span<const Vec3>(&up, 1), e[i]);
    }
    for (int i = 0; i < 3; ++i)
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(e[i][c] * heights[i] * heights[i], 1e4 * (c + 1), 1e-6 * 1e4 * (c + 1));
}

TEST(CornellEvaluator, IndirectLightFallsOffWithLightDistance) {
    // A light in front of the open box, moving away along -z: the light entering the opening
    // falls as 1/r^2 and so does everything it bounces into.
    const auto world = smallWorld();
    std::vector<PointLight> lights;
    for (double z : {-1500.0, -3000.0, -6000.0}) lights.push_back({{278, 274, z}, {1e7, 1e7, 1e7}});
    const CornellEvaluator ev(world, lights, 32);
    std::vector<double> v(static_cast<std::size_t>(3 * ev.pointCount()));
    double mean[3];
    for (Index f = 0; f < 3; ++f) {
        ev.evaluateAll(f, v.data());
        mean[f] = std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
    }
    EXPECT_GT(mean[0], mean[1]);
    EXPECT_GT(mean[1], mean[2]);
    EXPECT_GT(mean[0] / mean[1], 2.0);
    EXPECT_LT(mean[0] / mean[1], 6.0);
    EXPECT_GT(mean[1] / mean[2], 2.5);
    EXPECT_LT(mean[1] / mean[2], 5.5);
}

TEST(CornellEvaluator, IndirectLightIsLinearInTheLightsIntensity) {
    const auto world = smallWorld();
    const Vec3 pos{300, 480, 250};
    const CornellEvaluator ev(world, {{pos, {1e5, 1e5, 1e5}}, {pos, {4e5, 2e5, 1e5}}}, 16);
    std::vector<double> a(static_cast<std::size_t>(3 * ev.pointCount())), b(a.size());
    ev.evaluateAll(0, a.data());
    ev.evaluateAll(1, b.data());
    for (std::size_t i = 0; i < a.size(); i += 3) {
        EXPECT_NEAR(b[i], 4 * a[i], 1e-9 * (1 + b[i]));
        EXPECT_NEAR(b[i + 1], 2 * a[i + 1], 1e-9 * (1 + b[i]));
        EXPECT_NEAR(b[i + 2], a[i + 2], 1e-9 * (1 + b[i]));
    }
}

TEST(CornellEvaluator, EstimatesAgreeAcrossSampleCounts) {
    // The MIS estimator is unbiased: its mean over all points must not depend on the sample
    // count (a wrong MIS weight or pdf shows up as a few percent here), and the per-point
    // noise must fall as samples grow.
    const auto world = smallWorld();
    const auto lights = LightRig{}.scatteredLights(2);
    std::vector<double> ref(static_cast<std::size_t>(3 * world->voxels.size())), v(ref.size());
    CornellEvaluator(world, lights, 1024).evaluateAll(1, ref.data());
    const double refMean = std::accumulate(ref.begin(), ref.end(), 0.0);
    double lastNoise = 1e30;
    for (int s : {8, 32, 128}) {
        CornellEvaluator(world, lights, s).evaluateAll(1, v.data());
        EXPECT_NEAR(std::accumulate(v.begin(), v.end(), 0.0) / refMean, 1.0, 0.02) << s << " samples";
        double e2 = 0, r2 = 0;
        for (std::size_t i = 0; i < v.size(); ++i) {
            e2 += (v[i] - ref[i]) * (v[i] - ref[i]);
            r2 += ref[i] * ref[i];
        }
        const double noise = std::sqrt(e2 / r2);
        EXPECT_LT(noise, 0.7 * lastNoise) << s << " samples";
        lastNoise = noise;
    }
}

TEST(CornellEvaluator, GatherPointsSitOnTheSurfaceEmbreeTraces) {
    // A ray leaving a gather point along its normal must never hit a back face right away: that
    // would mean the point lies behind the traced surface (the measured red wall is not planar,
    // and a point on the other diagonal's triangles sat up to a millimetre behind it).
    const auto world = smallWorld();
    const auto& vox = world->voxels;
    std::vector<Ray> rays(vox.size());
    std::vector<Hit> hits(vox.size());
    for (std::size_t i = 0; i < vox.size(); ++i) {
        const Vec3 o = vox.position[i] + vox.normal[i] * 0.01;
        rays[i] = Ray{{float(o.x), float(o.y), float(o.z)},
                      {float(vox.normal[i].x), float(vox.normal[i].y), float(vox.normal[i].z)},
                      0.0f,
                      1e30f};
    }
    world->tracer->intersect(rays, hits);
    for (std::size_t i = 0; i < vox.size(); ++i) {
        if (hits[i].quad < 0) continue;
        const Quad& q = world->scene.quads()[static_cast<std::size_t>(hits[i].quad)];
        EXPECT_LT(dot(q.normal, vox.normal[i]), 0.0)
            << "voxel " << i << " on " << world->scene.quads()[vox.quad[i]].name << " hits the back of "
            << q.name << " at t = " << hits[i].t;
    }
}

TEST(CornellEvaluator, EverySurfaceReceivesIndirectLight) {
    const auto world = smallWorld();
    const CornellEvaluator ev(world, {{{278, 488.8, 279.6}, {1.6e5, 1.6e5, 1.6e5}}}, 32);
    std::vector<double> v(static_cast<std::size_t>(3 * ev.pointCount()));
    ev.evaluateAll(0, v.data());
    const auto& quads = world->scene.quads();
    std::vector<double> sum(quads.size(), 0.0), count(quads.size(), 0.0);
    double all = 0;
    for (std::size_t p = 0; p < world->voxels.size(); ++p) {
        const double lum = v[3 * p] + v[3 * p + 1] + v[3 * p + 2];
        sum[static_cast<std::size_t>(world->voxels.quad[p])] += lum;
        count[static_cast<std::size_t>(world->voxels.quad[p])] += 1;
        all += lum;
    }
    all /= static_cast<double>(world->voxels.size());
    for (std::size_t q = 0; q < 5; ++q)  // the five walls
        EXPECT_GT(sum[q] / count[q], 0.2 * all) << quads[q].name;
}

TEST(CornellEvaluator, RejectsBadFramesAndPoints) {
    const CornellEvaluator ev(smallWorld(), LightRig{}.scatteredLights(2), 4);
    double out[3];
    const Index bad[1] = {ev.pointCount()};
    const Index good[1] = {0};
    EXPECT_THROW(ev.evaluate(0, bad, out), std::out_of_range);
    EXPECT_THROW(ev.evaluate(2, good, out), std::out_of_range);
    EXPECT_THROW(CornellEvaluator(smallWorld(), {}, 4), std::invalid_argument);
    EXPECT_THROW(CornellEvaluator(smallWorld(), LightRig{}.scatteredLights(1), 0), std::invalid_argument);
}

TEST(CornellEvaluator, CommandLineSpecSetsPointsSamplesAndLights) {
    const auto all = makeCornellEvaluator("points=2000,samples=4");
    EXPECT_EQ(all->frameCount(), 144 + 16 + 60);
    EXPECT_NEAR(static_cast<double>(all->pointCount()), 2000, 40);
    EXPECT_EQ(all->samplesPerPoint(), 4);
    EXPECT_EQ(makeCornellEvaluator("points=2000,lights=path")->frameCount(), 60);
    EXPECT_EQ(makeCornellEvaluator("points=2000,lights=scattered")->frameCount(), 16);
    EXPECT_THROW(makeCornellEvaluator("points=ten"), InputError);
    EXPECT_THROW(makeCornellEvaluator("samples=1"), InputError);
    EXPECT_THROW(makeCornellEvaluator("lights=moon"), InputError);
    EXPECT_THROW(makeCornellEvaluator("colour=red"), InputError);
}

TEST(CornellEvaluator, OffersAVdbFrameWriterForTheRenderFarm) {
    const auto ev = makeCornellEvaluator("points=2000,samples=4,lights=path");
    const auto writers = ev->frameWriters();
    ASSERT_EQ(writers.size(), 1u);
    EXPECT_EQ(writers[0]->extension(), ".vdb");
    std::vector<double> v(static_cast<std::size_t>(3 * ev->pointCount()));
    ev->evaluateAll(5, v.data());
    const std::string path = (std::filesystem::temp_directory_path() /
                              ("pmsc_cornell_writer_" + std::to_string(::getpid()) + ".vdb"))
                                 .string();
    EXPECT_FALSE(writers[0]->isValid(path));
    writers[0]->write(path, 5, v.data());
    EXPECT_TRUE(writers[0]->isValid(path));
    std::filesystem::remove(path);
}

}  // namespace
}  // namespace pmsc::cornell
