#include "pmsc/Subspace.h"

#include "Synthetic.h"

#include <gtest/gtest.h>

#include <Eigen/SVD>

#include <cmath>
#include <vector>

using Route = pmsc::SvdOptions::Route;

namespace {

pmsc::SvdOptions route(Route r) {
    pmsc::SvdOptions o;
    o.route = r;
    return o;
}

// Subspace distance: ||(I - U U^T) Ref||, zero iff span(Ref) is inside span(U).
double outside(const Eigen::MatrixXd& u, const Eigen::MatrixXd& ref) {
    return (ref - u * (u.transpose() * ref)).norm();
}

}  // namespace

class SubspaceRoutes : public ::testing::TestWithParam<Route> {};

TEST_P(SubspaceRoutes, RecoversLowRankDataExactly) {
    Eigen::VectorXd sigma;
    const Eigen::MatrixXd q = pmsc::test::lowRank(300, 80, 6, 31, 0.6, &sigma);
    // Ask for more than the rank: the extra directions are numerically zero and must be dropped.
    const pmsc::TruncatedSvd s = pmsc::truncatedSvd(q, 12, route(GetParam()));
    ASSERT_EQ(s.sigma.size(), 6);
    EXPECT_LT((s.sigma - sigma).cwiseAbs().maxCoeff(), 1e-10 * sigma[0]);
    const Eigen::MatrixXd rebuilt = s.u * s.sigma.asDiagonal() * s.v.transpose();
    EXPECT_LT((rebuilt - q).cwiseAbs().maxCoeff(), 1e-10);
    EXPECT_EQ(s.gramRoute, GetParam() == Route::Gram);
}

TEST_P(SubspaceRoutes, OrthonormalAndMatchesJacobiSvdOnSmallData) {
    // Full-rank data with a decaying spectrum plus noise: compare the leading 8 triplets.
    Eigen::MatrixXd q = pmsc::test::lowRank(200, 60, 20, 32, 0.75) + 1e-3 * pmsc::test::gaussian(200, 60, 33);
    const pmsc::TruncatedSvd s = pmsc::truncatedSvd(q, 8, route(GetParam()));
    ASSERT_EQ(s.sigma.size(), 8);
    EXPECT_LT((s.u.transpose() * s.u - Eigen::MatrixXd::Identity(8, 8)).norm(), 1e-10);
    EXPECT_LT((s.v.transpose() * s.v - Eigen::MatrixXd::Identity(8, 8)).norm(), 1e-10);
    Eigen::JacobiSVD<Eigen::MatrixXd> ref(q, Eigen::ComputeThinU | Eigen::ComputeThinV);
    for (int i = 0; i < 8; ++i) {
        EXPECT_NEAR(s.sigma[i], ref.singularValues()[i], 1e-9 * ref.singularValues()[0]) << i;
        // Singular vectors up to sign.
        const double d =
            std::min((s.u.col(i) - ref.matrixU().col(i)).norm(), (s.u.col(i) + ref.matrixU().col(i)).norm());
        EXPECT_LT(d, 1e-6) << i;
    }
    for (int i = 1; i < 8; ++i) EXPECT_GE(s.sigma[i - 1], s.sigma[i]);
}

INSTANTIATE_TEST_SUITE_P(BothRoutes, SubspaceRoutes, ::testing::Values(Route::Gram, Route::Randomized),
                         [](const auto& info) { return info.param == Route::Gram ? "Gram" : "Randomized"; });

TEST(Subspace, AutoRoutePicksTheCheaperAlgorithm) {
    const Eigen::MatrixXd q = pmsc::test::lowRank(2000, 200, 10, 34);
    // Wide sketch relative to F: Gram. Narrow sketch (rank 4 + 10 of 200 columns): randomized.
    EXPECT_TRUE(pmsc::truncatedSvd(q, 100).gramRoute);
    EXPECT_FALSE(pmsc::truncatedSvd(q, 4).gramRoute);
    // Wide matrices never take the Gram route (Q^T Q would be the large side).
    EXPECT_FALSE(pmsc::truncatedSvd(Eigen::MatrixXd(q.transpose()), 100).gramRoute);
    EXPECT_THROW(pmsc::truncatedSvd(Eigen::MatrixXd(q.transpose()), 5, route(Route::Gram)),
                 std::invalid_argument);
}

TEST(Subspace, RandomizedRouteIsDeterministicForASeed) {
    const Eigen::MatrixXd q = pmsc::test::lowRank(500, 100, 30, 35, 0.5);
    const pmsc::SvdOptions o = route(Route::Randomized);
    const pmsc::TruncatedSvd a = pmsc::truncatedSvd(q, 5, o);
    const pmsc::TruncatedSvd b = pmsc::truncatedSvd(q, 5, o);
    EXPECT_EQ((a.u - b.u).cwiseAbs().maxCoeff(), 0.0);
    pmsc::SvdOptions other = o;
    other.seed += 1;
    const pmsc::TruncatedSvd c = pmsc::truncatedSvd(q, 5, other);
    // A different sketch, the same leading subspace (the spectrum decays fast enough that the
    // sketch error (sigma_16 / sigma_3)^(2q+1) is negligible).
    EXPECT_LT(outside(c.u.leftCols(3), a.u.leftCols(3)), 1e-6);
}

TEST(Subspace, LeftVectorsLimitsTheGramRouteAndCanBeCompletedLater) {
    const Eigen::MatrixXd q = pmsc::test::lowRank(300, 50, 10, 36);
    pmsc::SvdOptions o = route(Route::Gram);
    o.leftVectors = 3;
    pmsc::TruncatedSvd s = pmsc::truncatedSvd(q, 8, o);
    EXPECT_EQ(s.u.cols(), 3);
    EXPECT_EQ(s.sigma.size(), 8);
    EXPECT_EQ(s.v.cols(), 8);
    pmsc::formLeftVectors(q, s, 6);
    ASSERT_EQ(s.u.cols(), 6);
    const pmsc::TruncatedSvd full = pmsc::truncatedSvd(q, 8, route(Route::Gram));
    EXPECT_LT((s.u - full.u.leftCols(6)).cwiseAbs().maxCoeff(), 1e-12);
    pmsc::formLeftVectors(q, s, 100);  // capped by the singular values there are
    EXPECT_EQ(s.u.cols(), 8);
    // The randomized route forms all of U regardless (it is cheap there).
    pmsc::SvdOptions r = route(Route::Randomized);
    r.leftVectors = 3;
    EXPECT_EQ(pmsc::truncatedSvd(q, 8, r).u.cols(), 8);
}

TEST(Subspace, RemoveRowMeanAndPointNorms) {
    Eigen::MatrixXd raw(6, 3);  // 2 points x 3 channels, 3 frames
    raw << 1, 2, 3, 0, 0, 0, 4, 4, 4, 1, 1, 1, -1, 0, 1, 2, 2, 5;
    Eigen::MatrixXd centered;
    const Eigen::VectorXd mean = pmsc::removeRowMean(raw, centered);
    EXPECT_NEAR(mean[0], 2.0, 1e-15);
    EXPECT_NEAR(mean[5], 3.0, 1e-15);
    EXPECT_LT(centered.rowwise().sum().cwiseAbs().maxCoeff(), 1e-14);
    // Point 1 of frame 2: (1, 1, 5) - (1, 0, 3) = (0, 1, 2) -> norm sqrt(5), the largest.
    EXPECT_NEAR(pmsc::maxPointNorm(centered, 3), std::sqrt(5.0), 1e-14);
    const Eigen::VectorXd perFrame = pmsc::maxPointNormPerColumn(centered, 3);
    EXPECT_NEAR(perFrame[0], std::sqrt(1.0 + 0 + 1.0), 1e-14);  // point 0: (-1,0,0); point 1: (0,-1,-1)
}

TEST(Subspace, BasisSizeForEnergy) {
    const Eigen::Vector4d sigma(4, 2, 1, 1);  // energies 16, 4, 1, 1 of total 22
    EXPECT_EQ(pmsc::basisSizeForEnergy(sigma, 22, 0.5), 1);
    EXPECT_EQ(pmsc::basisSizeForEnergy(sigma, 22, 16.0 / 22.0), 1);
    EXPECT_EQ(pmsc::basisSizeForEnergy(sigma, 22, 0.9), 2);
    EXPECT_EQ(pmsc::basisSizeForEnergy(sigma, 22, 1.0), 4);
    EXPECT_EQ(pmsc::basisSizeForEnergy(sigma, 44, 1.0), 4);  // not reachable: capped
    EXPECT_THROW(pmsc::basisSizeForEnergy(sigma, 22, 0.0), std::invalid_argument);
    EXPECT_THROW(pmsc::basisSizeForEnergy(sigma, 22, 1.5), std::invalid_argument);
}

TEST(Subspace, BasisSizeForMaxErrorMatchesDirectProjection) {
    const Eigen::MatrixXd q = pmsc::test::lowRank(40 * 3, 30, 8, 37, 0.5);
    const pmsc::TruncatedSvd s = pmsc::truncatedSvd(q, 8);
    std::vector<double> errors;
    const pmsc::Index m = pmsc::basisSizeForMaxError(q, s, 3, 0.05, 8, &errors);
    ASSERT_EQ(errors.size(), 8u);
    for (int k = 1; k <= 8; ++k) {
        const Eigen::MatrixXd u = s.u.leftCols(k);
        const double direct = pmsc::maxPointNorm(q - u * (u.transpose() * q), 3);
        EXPECT_NEAR(errors[static_cast<size_t>(k - 1)], direct, 1e-10) << k;
    }
    // The rule: the smallest M meeting the bound.
    pmsc::Index expected = 9;
    for (int k = 1; k <= 8; ++k)
        if (errors[static_cast<size_t>(k - 1)] <= 0.05) {
            expected = k;
            break;
        }
    EXPECT_EQ(m, expected);
    EXPECT_GT(m, 1);
    EXPECT_LE(m, 8);
    EXPECT_EQ(pmsc::basisSizeForMaxError(q, s, 3, 1e-30, 3), 4);  // unreachable within 3 -> maxM + 1
}

TEST(Subspace, SvdFromGramOfAResidualMatchesTheExplicitSvd) {
    // The identity key selection relies on: R = Q - U C with U orthonormal gives
    // R^T R = G - W^T C - C^T W + C^T C, W = U^T Q.
    const Eigen::MatrixXd q = pmsc::test::lowRank(400, 60, 25, 38, 0.85);
    const pmsc::TruncatedSvd s = pmsc::truncatedSvd(q, 10);
    const Eigen::MatrixXd c = pmsc::test::gaussian(10, 60, 39);
    const Eigen::MatrixXd r = q - s.u * c;
    const Eigen::MatrixXd g = pmsc::gramMatrix(q);
    const Eigen::MatrixXd w = s.u.transpose() * q;
    const Eigen::MatrixXd rtr = g - w.transpose() * c - c.transpose() * w + c.transpose() * c;
    const pmsc::TruncatedSvd fromGram = pmsc::svdFromGram(r, rtr, 5);
    Eigen::JacobiSVD<Eigen::MatrixXd> ref(r, Eigen::ComputeThinU);
    for (int i = 0; i < 5; ++i)
        EXPECT_NEAR(fromGram.sigma[i], ref.singularValues()[i], 1e-9 * ref.singularValues()[0]);
    EXPECT_LT(outside(fromGram.u, ref.matrixU().leftCols(5)), 1e-6);
}

TEST(Subspace, RejectsBadArguments) {
    const Eigen::MatrixXd q = pmsc::test::gaussian(10, 5, 40);
    EXPECT_THROW(pmsc::truncatedSvd(q, 0), std::invalid_argument);
    EXPECT_THROW(pmsc::truncatedSvd(Eigen::MatrixXd(0, 5), 2), std::invalid_argument);
    pmsc::SvdOptions o;
    o.powerIterations = -1;
    EXPECT_THROW(pmsc::truncatedSvd(q, 2, o), std::invalid_argument);
}
