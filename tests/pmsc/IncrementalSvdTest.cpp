#include "pmsc/IncrementalSvd.h"

#include "Synthetic.h"
#include "pmsc/Subspace.h"

#include <gtest/gtest.h>

#include <Eigen/SVD>

#include <cmath>

namespace {

using pmsc::Index;

// The state `pmsc train` would store for frames `raw` ((N*C) x F): exact mean, the leading
// `rank` singular triplets of the mean-removed matrix, its exact energy.
pmsc::IncrementalSubspace stateFromScratch(const Eigen::MatrixXd& raw, Index rank) {
    pmsc::IncrementalSubspace s;
    Eigen::MatrixXd centered;
    s.mean = pmsc::removeRowMean(raw, centered);
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(centered, Eigen::ComputeThinU);
    Index r = 0;
    while (r < rank && r < svd.singularValues().size() &&
           svd.singularValues()[r] > 1e-12 * svd.singularValues()[0])
        ++r;
    s.u = svd.matrixU().leftCols(r);
    s.sigma = svd.singularValues().head(r);
    s.frames = raw.cols();
    s.totalEnergy = centered.squaredNorm();
    return s;
}

Eigen::MatrixXd join(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
    Eigen::MatrixXd all(a.rows(), a.cols() + b.cols());
    all << a, b;
    return all;
}

// Frames that move in `rank` directions about a non-zero offset, plus white noise of `noise`.
Eigen::MatrixXd frames(Index rows, Index cols, Index rank, unsigned seed, double noise) {
    Eigen::MatrixXd m = pmsc::test::lowRank(rows, cols, rank, seed, 0.8);
    for (Index i = 0; i < rows; ++i) m.row(i).array() += 3.0 * std::sin(0.41 * static_cast<double>(i));
    if (noise > 0) m += noise * pmsc::test::gaussian(rows, cols, seed + 7);
    return m;
}

}  // namespace

TEST(IncrementalSvd, LowRankUpdateEqualsTheSvdOfAllFrames) {
    // Old and new frames share a rank-6 subspace but the new ones also move in 3 directions the
    // old never did, and their mean differs: the update must find the new directions, move the
    // mean, and match the SVD of the union to rounding.
    const Eigen::MatrixXd old = frames(90, 40, 6, 11, 0.0);
    Eigen::MatrixXd fresh = frames(90, 25, 6, 11, 0.0).leftCols(25);
    fresh += pmsc::test::lowRank(90, 25, 3, 21, 0.9) + Eigen::MatrixXd::Constant(90, 25, 0.7);
    pmsc::IncrementalSubspace s = stateFromScratch(old, 10);
    ASSERT_EQ(s.rank(), 6);
    pmsc::updateSubspace(s, fresh);
    const pmsc::IncrementalSubspace exact = stateFromScratch(join(old, fresh), 20);

    EXPECT_EQ(s.frames, 65);
    EXPECT_LT((s.mean - exact.mean).norm(), 1e-12 * exact.mean.norm());
    EXPECT_NEAR(s.totalEnergy, exact.totalEnergy, 1e-12 * exact.totalEnergy);
    ASSERT_EQ(s.rank(), exact.rank());
    EXPECT_LT((s.sigma - exact.sigma).norm(), 1e-10 * exact.sigma[0]);
    EXPECT_LT(pmsc::largestPrincipalAngle(exact.u, s.u), 1e-9);
    EXPECT_LT((s.u.transpose() * s.u - Eigen::MatrixXd::Identity(s.rank(), s.rank())).norm(), 1e-12);
    EXPECT_LT(s.tailNorm(), 1e-9 * exact.sigma[0]);
    EXPECT_EQ(s.discardedEnergy, 0.0);
}

TEST(IncrementalSvd, FramesInsideTheSubspaceAddNoDirection) {
    const Eigen::MatrixXd all = frames(60, 50, 4, 31, 0.0);
    pmsc::IncrementalSubspace s = stateFromScratch(all.leftCols(30), 8);
    ASSERT_EQ(s.rank(), 4);
    pmsc::updateSubspace(s, all.rightCols(20));
    const pmsc::IncrementalSubspace exact = stateFromScratch(all, 8);
    // The mean moves within the data's affine span, so no fifth direction may appear.
    EXPECT_EQ(s.rank(), 4);
    EXPECT_LT((s.sigma - exact.sigma).norm(), 1e-10 * exact.sigma[0]);
    EXPECT_LT(pmsc::largestPrincipalAngle(exact.u, s.u), 1e-9);
}

TEST(IncrementalSvd, ManySmallUpdatesStayOrthonormalAndExact) {
    const Eigen::MatrixXd all = frames(120, 100, 8, 41, 0.0);
    pmsc::IncrementalSubspace s = stateFromScratch(all.leftCols(10), 20);
    for (Index first = 10; first < 100; first += 9) {
        pmsc::updateSubspace(s, all.middleCols(first, std::min<Index>(9, 100 - first)));
    }
    const pmsc::IncrementalSubspace exact = stateFromScratch(all, 20);
    EXPECT_EQ(s.frames, 100);
    ASSERT_EQ(s.rank(), exact.rank());
    EXPECT_LT((s.sigma - exact.sigma).norm(), 1e-9 * exact.sigma[0]);
    EXPECT_LT(pmsc::largestPrincipalAngle(exact.u, s.u), 1e-8);
    EXPECT_LT((s.u.transpose() * s.u - Eigen::MatrixXd::Identity(s.rank(), s.rank())).norm(), 1e-11);
    EXPECT_LT((s.mean - exact.mean).norm(), 1e-12 * exact.mean.norm());
}

TEST(IncrementalSvd, TruncatedStateObeysTheWeylAndWedinBounds) {
    // Full-rank data (noise on a rank-5 signal) with the state truncated to rank 8: the update is
    // approximate, and the documented bounds must hold against the exact SVD.
    const Eigen::MatrixXd old = frames(150, 70, 5, 51, 0.02);
    const Eigen::MatrixXd fresh = frames(150, 40, 5, 52, 0.02);
    pmsc::IncrementalSubspace s = stateFromScratch(old, 8);
    pmsc::IncrementalSvdOptions options;
    options.maxRank = 8;
    pmsc::updateSubspace(s, fresh, options);
    const pmsc::IncrementalSubspace exact = stateFromScratch(join(old, fresh), 40);
    ASSERT_EQ(s.rank(), 8);
    EXPECT_GT(s.discardedEnergy, 0.0);
    EXPECT_NEAR(s.totalEnergy, exact.totalEnergy, 1e-12 * exact.totalEnergy);
    const double tail = s.tailNorm();
    EXPECT_GT(tail, 0.0);
    for (Index i = 0; i < s.rank(); ++i)
        EXPECT_LE(std::abs(s.sigma[i] - exact.sigma[i]), tail * (1 + 1e-9)) << i;
    const Index m = 5;
    const double gap = exact.sigma[m - 1] - exact.sigma[m];
    const double angle = pmsc::largestPrincipalAngle(exact.u.leftCols(m), s.u.leftCols(m));
    EXPECT_LE(std::sin(angle), tail / gap);
    EXPECT_LT(angle, 0.05);  // the signal's directions are found, the noise is what is approximate
}

TEST(IncrementalSvd, PrincipalAngleOfAKnownRotation) {
    Eigen::MatrixXd a = Eigen::MatrixXd::Zero(5, 2), b = Eigen::MatrixXd::Zero(5, 2);
    a(0, 0) = a(1, 1) = 1;
    const double theta = 0.3;
    b(0, 0) = 1;
    b(1, 1) = std::cos(theta);
    b(2, 1) = std::sin(theta);
    EXPECT_NEAR(pmsc::largestPrincipalAngle(a, b), theta, 1e-14);
    EXPECT_NEAR(pmsc::largestPrincipalAngle(a, a), 0.0, 1e-15);
    EXPECT_NEAR(pmsc::largestPrincipalAngle(-a, a), 0.0, 1e-15);  // signs do not matter
}

TEST(IncrementalSvd, RejectsBadUpdates) {
    pmsc::IncrementalSubspace s = stateFromScratch(frames(30, 10, 3, 61, 0.0), 5);
    EXPECT_THROW(pmsc::updateSubspace(s, Eigen::MatrixXd::Zero(29, 3)), std::invalid_argument);
    EXPECT_THROW(pmsc::updateSubspace(s, Eigen::MatrixXd::Zero(30, 0)), std::invalid_argument);
    pmsc::IncrementalSvdOptions bad;
    bad.maxRank = -1;
    EXPECT_THROW(pmsc::updateSubspace(s, Eigen::MatrixXd::Zero(30, 2), bad), std::invalid_argument);
    EXPECT_NO_THROW(s.validate());
    pmsc::IncrementalSubspace broken = s;
    broken.sigma[0] = -1;
    EXPECT_THROW(broken.validate(), std::invalid_argument);
}

TEST(IncrementalSvd, UpdateInSpanEqualsTheIncrementalUpdate) {
    // What learn's cross-fitting relies on: the old state updated with any subset of the new
    // frames, computed in the span of the update of all of them, is the incremental update of that
    // subset (low-rank old frames: both are also the SVD of the union; the new frames move in 3
    // directions the old never did, about another mean).
    const Eigen::MatrixXd old = frames(90, 40, 6, 71, 0.0);
    Eigen::MatrixXd fresh = frames(90, 30, 6, 71, 0.0);
    fresh += pmsc::test::lowRank(90, 30, 3, 73, 0.9) + Eigen::MatrixXd::Constant(90, 30, 0.5);
    const pmsc::IncrementalSubspace before = stateFromScratch(old, 12);
    const pmsc::UpdateSpan span = pmsc::spanOfUpdate(before, fresh);
    // The 3 new directions and the offset of the means, nothing else.
    EXPECT_GE(span.coords.rows(), before.rank() + 3);
    EXPECT_LE(span.coords.rows(), before.rank() + 4);
    for (const bool all : {true, false}) {
        std::vector<Index> columns;
        for (Index j = 0; j < 30; ++j)
            if (all || j < 12 || j >= 18) columns.push_back(j);  // a fold: slice [12, 18) held out
        Eigen::MatrixXd chosen(90, static_cast<Index>(columns.size()));
        for (Index j = 0; j < chosen.cols(); ++j) chosen.col(j) = fresh.col(columns[static_cast<size_t>(j)]);
        pmsc::IncrementalSubspace incremental = before;
        pmsc::updateSubspace(incremental, chosen);
        const pmsc::IncrementalSubspace projected = pmsc::updateInSpan(before, span, fresh, columns);
        EXPECT_EQ(projected.frames, incremental.frames);
        EXPECT_LT((projected.mean - incremental.mean).norm(), 1e-12 * incremental.mean.norm());
        EXPECT_NEAR(projected.totalEnergy, incremental.totalEnergy, 1e-12 * incremental.totalEnergy);
        ASSERT_EQ(projected.rank(), incremental.rank());
        EXPECT_LT((projected.sigma - incremental.sigma).norm(), 1e-10 * incremental.sigma[0]);
        EXPECT_LT(pmsc::largestPrincipalAngle(incremental.u, projected.u), 1e-9);
        const Index r = projected.rank();
        EXPECT_LT((projected.u.transpose() * projected.u - Eigen::MatrixXd::Identity(r, r)).norm(), 1e-12);
        const pmsc::IncrementalSubspace exact = stateFromScratch(join(old, chosen), 20);
        EXPECT_LT(pmsc::largestPrincipalAngle(exact.u, projected.u), 1e-9);
    }
    // Truncated to the fold's basis size, the leading directions are the same.
    pmsc::IncrementalSvdOptions five;
    five.maxRank = 5;
    pmsc::IncrementalSubspace incremental = before;
    pmsc::updateSubspace(incremental, fresh.leftCols(20), five);
    std::vector<Index> first20(20);
    for (Index j = 0; j < 20; ++j) first20[static_cast<size_t>(j)] = j;
    const pmsc::IncrementalSubspace projected = pmsc::updateInSpan(before, span, fresh, first20, five);
    ASSERT_EQ(projected.rank(), 5);
    EXPECT_LT(pmsc::largestPrincipalAngle(incremental.u, projected.u), 1e-9);
    EXPECT_NEAR(projected.discardedEnergy, incremental.discardedEnergy, 1e-10 * incremental.totalEnergy);
}

TEST(IncrementalSvd, UpdateInSpanRejectsBadColumns) {
    const pmsc::IncrementalSubspace s = stateFromScratch(frames(30, 10, 3, 81, 0.0), 5);
    const Eigen::MatrixXd fresh = frames(30, 6, 3, 82, 0.0);
    const pmsc::UpdateSpan span = pmsc::spanOfUpdate(s, fresh);
    EXPECT_THROW(pmsc::updateInSpan(s, span, fresh, {}), std::invalid_argument);
    EXPECT_THROW(pmsc::updateInSpan(s, span, fresh, {0, 6}), std::invalid_argument);
    EXPECT_THROW(pmsc::updateInSpan(s, span, fresh, {-1}), std::invalid_argument);
    EXPECT_THROW(pmsc::updateInSpan(s, span, fresh.leftCols(5), {0}), std::invalid_argument);
    EXPECT_THROW(pmsc::spanOfUpdate(s, Eigen::MatrixXd::Zero(29, 3)), std::invalid_argument);
}
