// The project's one percentile and largest-point-error definitions (pmsc/Metrics.h).
#include "pmsc/Metrics.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <stdexcept>
#include <vector>

namespace {

// Every report (`pmsc replay`, the face demo) uses nearest rank, so the first sample's p50 is
// 2 (a value it has), not 2.5 as linear interpolation gives, and its p99 and p99.5 are its
// largest value, not 3.97 and 3.985.
TEST(Percentiles, NearestRankGivesAValueOfTheSample) {
    const auto p = pmsc::percentiles({4, 1, 3, 2});
    EXPECT_EQ(p.p50, 2);  // ceil(0.5 * 4) = 2nd smallest
    EXPECT_EQ(p.p99, 4);  // ceil(3.96) = 4th
    EXPECT_EQ(p.p995, 4);
    EXPECT_EQ(p.max, 4);
    std::vector<double> ramp(201);
    for (std::size_t i = 0; i < ramp.size(); ++i) ramp[i] = static_cast<double>(i);
    const auto q = pmsc::percentiles(ramp);
    EXPECT_EQ(q.p50, 100);   // 101st of 201
    EXPECT_EQ(q.p99, 198);   // ceil(198.99) = 199th
    EXPECT_EQ(q.p995, 199);  // ceil(199.995) = 200th
    EXPECT_EQ(q.max, 200);
    // 1000 frames: p99.5 is the 995th smallest, so exactly 5 frames lie above it.
    std::vector<double> errors(1000);
    for (std::size_t i = 0; i < errors.size(); ++i) errors[i] = static_cast<double>((i * 7919) % 1000);
    const double p995 = pmsc::percentile(errors, 0.995);
    EXPECT_EQ(p995, 994);
    EXPECT_EQ(std::count_if(errors.begin(), errors.end(), [&](double e) { return e > p995; }), 5);
    const auto one = pmsc::percentiles({7});
    EXPECT_EQ(one.p50, 7);
    EXPECT_EQ(one.max, 7);
    EXPECT_EQ(pmsc::percentiles({}).max, 0);
    EXPECT_EQ(pmsc::percentile({}, 0.5), 0);
    EXPECT_EQ(pmsc::percentile({3, 1, 2}, 0), 1);
    EXPECT_EQ(pmsc::percentile({3, 1, 2}, 1), 3);
    EXPECT_THROW(pmsc::percentile({1}, 1.5), std::invalid_argument);
}

TEST(MaxPointError, LargestEuclideanDistanceOverChannelsAndWhere) {
    const std::vector<double> a{0, 0, 0, 1, 1, 1, 5, 5};
    const std::vector<double> b{0, 0, 0, 1, 4, 5, 5, 5};  // C = 2: point 2 is (3, 4) away
    pmsc::Index where = -1;
    EXPECT_DOUBLE_EQ(pmsc::maxPointError(a.data(), b.data(), 4, 2, &where), 5.0);
    EXPECT_EQ(where, 2);
    EXPECT_DOUBLE_EQ(pmsc::maxPointError(a.data(), b.data(), 2, 4, &where), 5.0);
    EXPECT_EQ(where, 1);
    EXPECT_DOUBLE_EQ(pmsc::maxPointError(a.data(), a.data(), 4, 2, &where), 0.0);
    EXPECT_EQ(where, 0);
}

}  // namespace
