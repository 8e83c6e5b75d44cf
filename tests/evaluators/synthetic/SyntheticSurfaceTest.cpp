#include "evaluators/synthetic/SyntheticSurface.h"

#include <gtest/gtest.h>

#include <numeric>

namespace {

using pmsc::Index;
using pmsc::synthetic::SurfaceOptions;
using pmsc::synthetic::SyntheticSurface;

TEST(SyntheticSurface, AnySubsetEqualsTheFullFrameBitForBit) {
    SurfaceOptions o;
    o.grid = 9;
    o.frames = 30;
    o.novelFrames = 10;
    const SyntheticSurface s(o);
    std::vector<double> full(81 * 3);
    for (Index f : {0, 19, 25, 29}) {
        s.evaluateAll(f, full.data());
        const std::vector<Index> points = {80, 3, 40, 0};
        std::vector<double> some(points.size() * 3);
        s.evaluate(f, points, some.data());
        for (std::size_t i = 0; i < points.size(); ++i)
            for (int c = 0; c < 3; ++c) EXPECT_EQ(some[i * 3 + c], full[points[i] * 3 + c]);
    }
}

TEST(SyntheticSurface, SameSeedSameShotOtherSeedOtherMotionSameRestPose) {
    SurfaceOptions o;
    o.grid = 8;
    o.frames = 50;
    const auto a = pmsc::evaluateFrames(SyntheticSurface(o), 0, 50);
    const auto b = pmsc::evaluateFrames(SyntheticSurface(o), 0, 50);
    EXPECT_EQ(a.values, b.values);
    o.seed = 2;
    const auto c = pmsc::evaluateFrames(SyntheticSurface(o), 0, 50);
    EXPECT_NE(a.values, c.values);
}

TEST(SyntheticSurface, NovelMotionOnlyInTheLastFrames) {
    SurfaceOptions o;
    o.grid = 8;
    o.frames = 40;
    o.seed = 3;
    const auto plain = pmsc::evaluateFrames(SyntheticSurface(o), 0, 40);
    o.novelFrames = 10;
    const SyntheticSurface novel(o);
    const auto withNovel = pmsc::evaluateFrames(novel, 0, 40);
    for (Index f = 0; f < 40; ++f) {
        const bool same = std::equal(plain.frame(f), plain.frame(f) + plain.rows(), withNovel.frame(f));
        EXPECT_EQ(same, f < 30) << "frame " << f;
    }
    EXPECT_EQ(novel.controls(29).novel, 0);
    EXPECT_GT(novel.controls(30).novel, 0);
    EXPECT_EQ(novel.controls(39).novel, 1);
}

TEST(SyntheticSurface, RejectsBadOptionsAndIndices) {
    SurfaceOptions o;
    o.grid = 1;
    EXPECT_THROW(SyntheticSurface{o}, std::invalid_argument);
    o.grid = 4;
    o.frames = 5;
    o.novelFrames = 6;
    EXPECT_THROW(SyntheticSurface{o}, std::invalid_argument);
    o.novelFrames = 0;
    const SyntheticSurface s(o);
    std::vector<double> out(3);
    const std::vector<Index> bad = {16};
    EXPECT_THROW(s.evaluate(0, bad, out.data()), std::out_of_range);
    const std::vector<Index> ok = {15};
    EXPECT_THROW(s.evaluate(5, ok, out.data()), std::out_of_range);
}

}  // namespace
