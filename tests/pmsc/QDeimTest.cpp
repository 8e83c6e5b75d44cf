#include "pmsc/QDeim.h"

#include "Synthetic.h"
#include "pmsc/Model.h"

#include <gtest/gtest.h>

#include <Eigen/QR>
#include <Eigen/SVD>

#include <algorithm>
#include <random>
#include <set>

namespace {

Eigen::MatrixXd orthonormalBasis(pmsc::Index rows, pmsc::Index cols, unsigned seed) {
    // A smooth-ish, decaying basis like a real subspace: QR of a low-rank product plus noise.
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(pmsc::test::lowRank(rows, cols + 5, cols + 5, seed, 0.8) +
                                             0.05 * pmsc::test::gaussian(rows, cols + 5, seed + 1));
    return (qr.householderQ() * Eigen::MatrixXd::Identity(rows, cols + 5)).leftCols(cols);
}

double keyCondition(const Eigen::MatrixXd& basis, pmsc::Index channels,
                    const std::vector<pmsc::Index>& keys) {
    const Eigen::VectorXd s =
        Eigen::JacobiSVD<Eigen::MatrixXd>(pmsc::gatherKeyRows(basis, channels, keys)).singularValues();
    return s[0] / s[s.size() - 1];
}

}  // namespace

TEST(QDeim, SingleChannelPicksArePivotsOfColumnPivotedQrOfBTranspose) {
    const Eigen::MatrixXd b = orthonormalBasis(60, 7, 51);
    const pmsc::QDeimSelection sel = pmsc::selectKeysQDeim(b, 1, 7, {});
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(b.transpose());
    std::vector<pmsc::Index> expected;
    for (int i = 0; i < 7; ++i) expected.push_back(qr.colsPermutation().indices()[i]);
    EXPECT_EQ(sel.keys, expected);
    EXPECT_EQ(sel.passes, 1);
}

TEST(QDeim, KeysAreBetterConditionedThanRandomKeys) {
    const pmsc::Index n = 400, c = 3, m = 24, k = 12;  // K*C = 36 >= M
    const Eigen::MatrixXd b = orthonormalBasis(n * c, m, 52);
    const pmsc::QDeimSelection sel = pmsc::selectKeysQDeim(b, c, k, {});
    ASSERT_EQ(static_cast<pmsc::Index>(sel.keys.size()), k);
    const double qdeim = keyCondition(b, c, sel.keys);
    // Median over random key sets of the same size.
    std::mt19937_64 rng(53);
    std::vector<double> randomConds;
    std::vector<pmsc::Index> all(static_cast<size_t>(n));
    for (pmsc::Index i = 0; i < n; ++i) all[static_cast<size_t>(i)] = i;
    for (int trial = 0; trial < 31; ++trial) {
        std::shuffle(all.begin(), all.end(), rng);
        randomConds.push_back(keyCondition(b, c, std::vector<pmsc::Index>(all.begin(), all.begin() + k)));
    }
    std::nth_element(randomConds.begin(), randomConds.begin() + 15, randomConds.end());
    EXPECT_LT(qdeim, randomConds[15]);
    // And the Drmac-Gugercin style bound holds comfortably: ||pinv(B_K)|| is modest.
    const Eigen::VectorXd s =
        Eigen::JacobiSVD<Eigen::MatrixXd>(pmsc::gatherKeyRows(b, c, sel.keys)).singularValues();
    EXPECT_GT(s[s.size() - 1], 0.05);
}

TEST(QDeim, ExtendsBeyondOnePassWithoutDuplicates) {
    const pmsc::Index n = 100, c = 3, m = 6;
    const Eigen::MatrixXd b = orthonormalBasis(n * c, m, 54);
    // One pass yields at most M = 6 pivot rows, so at most 6 points; ask for 20.
    const pmsc::QDeimSelection sel = pmsc::selectKeysQDeim(b, c, 20, {});
    EXPECT_EQ(sel.keys.size(), 20u);
    EXPECT_GE(sel.passes, 4);
    EXPECT_EQ(std::set<pmsc::Index>(sel.keys.begin(), sel.keys.end()).size(), sel.keys.size());
    // The first pass alone already determines the basis; later passes only add rows.
    const pmsc::QDeimSelection one = pmsc::selectKeysQDeim(b, c, 2, {});
    EXPECT_EQ(std::vector<pmsc::Index>(sel.keys.begin(), sel.keys.begin() + 2), one.keys);
    // Adding rows never worsens the smallest singular value.
    const auto smin = [&](const std::vector<pmsc::Index>& keys) {
        const Eigen::VectorXd s =
            Eigen::JacobiSVD<Eigen::MatrixXd>(pmsc::gatherKeyRows(b, c, keys)).singularValues();
        return s[s.size() - 1];
    };
    EXPECT_GE(smin(sel.keys), smin(std::vector<pmsc::Index>(sel.keys.begin(), sel.keys.begin() + 6)) - 1e-12);
    // All points: nothing left afterwards.
    EXPECT_EQ(pmsc::selectKeysQDeim(b, c, n, {}).keys.size(), static_cast<size_t>(n));
}

TEST(QDeim, SeedsAreForcedFirstAndTheRestAvoidTheirSpan) {
    const pmsc::Index n = 80, c = 3, m = 9;
    const Eigen::MatrixXd b = orthonormalBasis(n * c, m, 55);
    const pmsc::QDeimSelection free = pmsc::selectKeysQDeim(b, c, 6, {});
    // Seed the first free pick and one other point; they must lead and never repeat.
    const std::vector<pmsc::Index> seeds = {free.keys[0], 17 == free.keys[0] ? 18 : 17};
    const pmsc::QDeimSelection sel = pmsc::selectKeysQDeim(b, c, 6, seeds);
    ASSERT_EQ(sel.keys.size(), 6u);
    EXPECT_EQ(sel.keys[0], seeds[0]);
    EXPECT_EQ(sel.keys[1], seeds[1]);
    EXPECT_EQ(std::set<pmsc::Index>(sel.keys.begin(), sel.keys.end()).size(), 6u);
    // With seeds spanning 6 of the 9 dimensions, 1 more point (3 rows) completes the basis.
    EXPECT_LT(keyCondition(b, c, sel.keys), 1e6);
    EXPECT_THROW(pmsc::selectKeysQDeim(b, c, 6, {3, 3}), std::invalid_argument);
    EXPECT_THROW(pmsc::selectKeysQDeim(b, c, 6, {80}), std::invalid_argument);
    EXPECT_THROW(pmsc::selectKeysQDeim(b, c, 1, {1, 2}), std::invalid_argument);
    EXPECT_THROW(pmsc::selectKeysQDeim(b, c, 81, {}), std::invalid_argument);
}
