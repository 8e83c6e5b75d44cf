#include "pmsc/SoftCache.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

using pmsc::CacheState;
using pmsc::SoftCachePolicy;

TEST(SoftCache, HitAtAndBelowEpsMin) {
    const SoftCachePolicy policy(0.1, 0.15);
    for (double e : {0.0, 0.05, std::nextafter(0.1, 0.0), 0.1}) {
        const auto d = policy.decide(e);
        EXPECT_EQ(d.state, CacheState::Hit) << e;
        EXPECT_EQ(d.weight, 0.0) << e;
    }
}

TEST(SoftCache, MissAtAndAboveEpsMax) {
    const SoftCachePolicy policy(0.1, 0.15);
    for (double e : {0.15, std::nextafter(0.15, 1.0), 0.2, 1e300}) {
        const auto d = policy.decide(e);
        EXPECT_EQ(d.state, CacheState::Miss) << e;
        EXPECT_EQ(d.weight, 1.0) << e;
    }
}

TEST(SoftCache, BlendJustInsideBothThresholdsAndLinearBetween) {
    const SoftCachePolicy policy(0.1, 0.15);
    const auto justAbove = policy.decide(std::nextafter(0.1, 1.0));
    EXPECT_EQ(justAbove.state, CacheState::Blend);
    EXPECT_GT(justAbove.weight, 0.0);
    EXPECT_LT(justAbove.weight, 1e-12);
    const auto justBelow = policy.decide(std::nextafter(0.15, 0.0));
    EXPECT_EQ(justBelow.state, CacheState::Blend);
    EXPECT_LT(justBelow.weight, 1.0);
    EXPECT_GT(justBelow.weight, 1.0 - 1e-12);
    const auto mid = policy.decide(0.125);
    EXPECT_EQ(mid.state, CacheState::Blend);
    EXPECT_NEAR(mid.weight, 0.5, 1e-12);
    EXPECT_NEAR(policy.decide(0.11).weight, 0.2, 1e-12);
}

TEST(SoftCache, EqualThresholdsAreAHardSwitch) {
    const SoftCachePolicy policy(0.2, 0.2);
    EXPECT_EQ(policy.decide(0.2).state, CacheState::Hit);
    EXPECT_EQ(policy.decide(std::nextafter(0.2, 1.0)).state, CacheState::Miss);
    EXPECT_EQ(policy.decide(std::nextafter(0.2, 0.0)).state, CacheState::Hit);
    const SoftCachePolicy zero(0.0, 0.0);
    EXPECT_EQ(zero.decide(0.0).state, CacheState::Hit);
    EXPECT_EQ(zero.decide(1e-300).state, CacheState::Miss);
}

TEST(SoftCache, NonFiniteErrorIsAMiss) {
    const SoftCachePolicy policy(0.1, 0.15);
    for (double e : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
                     -std::numeric_limits<double>::infinity()}) {
        const auto d = policy.decide(e);
        EXPECT_EQ(d.state, CacheState::Miss);
        EXPECT_EQ(d.weight, 1.0);
    }
}

TEST(SoftCache, RejectsInvalidThresholds) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    EXPECT_THROW(SoftCachePolicy(0.2, 0.1), std::invalid_argument);
    EXPECT_THROW(SoftCachePolicy(-0.1, 0.1), std::invalid_argument);
    EXPECT_THROW(SoftCachePolicy(nan, 0.1), std::invalid_argument);
    EXPECT_THROW(SoftCachePolicy(0.1, nan), std::invalid_argument);
    EXPECT_THROW(SoftCachePolicy(0.1, inf), std::invalid_argument);
    EXPECT_NO_THROW(SoftCachePolicy(0.0, 0.0));
}

TEST(SoftCache, StateNames) {
    EXPECT_EQ(pmsc::toString(CacheState::Hit), "hit");
    EXPECT_EQ(pmsc::toString(CacheState::Blend), "blend");
    EXPECT_EQ(pmsc::toString(CacheState::Miss), "miss");
}

TEST(SoftCache, AlwaysMissFailsThroughEveryErrorEvenZero) {
    const SoftCachePolicy policy = SoftCachePolicy::alwaysMiss();
    for (double e : {0.0, 1e-300, 0.5, 1e300}) {
        const auto d = policy.decide(e);
        EXPECT_EQ(d.state, pmsc::CacheState::Miss) << e;
        EXPECT_EQ(d.weight, 1.0) << e;
    }
}

TEST(SoftCache, ABlendedPointIsNeverHandedBackOverTheTolerance) {
    // Two points of 3 channels: PM 0.5 away from the full value (under T = 1) and 4 away (over).
    const std::vector<double> pm = {0.5, 0, 0, 4, 0, 0};
    const std::vector<double> full(6, 0.0);
    std::vector<double> out(6);
    pmsc::blendPoints(0.25, 1.0, 3, pm.data(), full.data(), out.data(), 2);
    EXPECT_DOUBLE_EQ(out[0], 0.75 * 0.5);  // under T: the frame's weight alone
    EXPECT_LE(out[3], 1.0);                // over T: the weight raised to 1 - T / e
    EXPECT_GT(out[3], 1.0 - 1e-6);         // and no further
    EXPECT_DOUBLE_EQ(pmsc::guardedWeight(0.25, 4.0, 1.0), 1.0 - (1.0 - 1e-9) * 0.25);
    EXPECT_EQ(pmsc::guardedWeight(0.9, 4.0, 1.0), 0.9);    // a weight already high enough stays
    EXPECT_EQ(pmsc::guardedWeight(0.25, 4.0, 0.0), 0.25);  // no tolerance: the weight alone
    EXPECT_DOUBLE_EQ(pmsc::blendedError(0.25, 4.0, 1.0), out[3]);
    EXPECT_DOUBLE_EQ(pmsc::blendedError(0.25, 0.5, 1.0), out[0]);
    // In place, into the full buffer (the engine's Blender) and into PM's (the feathered blend).
    std::vector<double> inFull = full, inPm = pm;
    pmsc::blendPoints(0.25, 1.0, 3, pm.data(), inFull.data(), inFull.data(), 2);
    pmsc::blendPoints(0.25, 1.0, 3, inPm.data(), full.data(), inPm.data(), 2);
    EXPECT_EQ(inFull, out);
    EXPECT_EQ(inPm, out);
}
