#include "pmsc/KeyPointSelector.h"

#include "Synthetic.h"
#include "pmsc/Model.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <set>
#include <string>

namespace {

// Mean-removed training matrix of a frame set.
Eigen::MatrixXd centered(const pmsc::FrameSet& frames) {
    Eigen::MatrixXd q;
    pmsc::removeRowMean(frames.matrix(), q);
    return q;
}

template <class F>
void expectInvalidMentioning(F&& f, const std::string& needle) {
    try {
        f();
        ADD_FAILURE() << "no exception; expected one mentioning " << needle;
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
}

void expectUnique(const std::vector<pmsc::Index>& keys) {
    std::set<pmsc::Index> s(keys.begin(), keys.end());
    EXPECT_EQ(s.size(), keys.size());
}

}  // namespace

TEST(Teleconnection, PairIsLargestLoadingThenMostNegativeInnerProduct) {
    // 5 points x 2 channels. Point 2 has the largest loading (3,4) -> norm 5. Inner products with
    // (3,4): p0 (1,0) -> 3, p1 (-1,-1) -> -7, p3 (0,-2) -> -8, p4 (2,2) -> 14. Most negative: p3.
    Eigen::VectorXd v(10);
    v << 1, 0, -1, -1, 3, 4, 0, -2, 2, 2;
    pmsc::KeySet keys(5);
    EXPECT_EQ(pmsc::addTeleconnectionPair(v, 2, keys, 10), 2);
    EXPECT_EQ(keys.keys(), (std::vector<pmsc::Index>{2, 3}));
    // Again on the same vector: 2 and 3 are keys, so the next best are taken, never a duplicate.
    // Largest non-key loading: p4 (2,2); most negative with it: p1 (-1,-1) -> -4.
    EXPECT_EQ(pmsc::addTeleconnectionPair(v, 2, keys, 10), 2);
    EXPECT_EQ(keys.keys(), (std::vector<pmsc::Index>{2, 3, 4, 1}));
    // Only p0 is left: one key, then nothing.
    EXPECT_EQ(pmsc::addTeleconnectionPair(v, 2, keys, 10), 1);
    EXPECT_EQ(pmsc::addTeleconnectionPair(v, 2, keys, 10), 0);
    expectUnique(keys.keys());
}

TEST(Teleconnection, WithoutNegativeInnerProductTheSecondIsTheNextLargest) {
    Eigen::VectorXd v(4);  // C = 1, all loadings positive
    v << 0.1, 0.9, 0.5, 0.5;
    pmsc::KeySet keys(4);
    pmsc::addTeleconnectionPair(v, 1, keys, 10);
    // Largest: p1; no negative product; next largest: p2 and p3 tie -> the lower index.
    EXPECT_EQ(keys.keys(), (std::vector<pmsc::Index>{1, 2}));
}

TEST(Teleconnection, RespectsTheBudget) {
    Eigen::VectorXd v(4);
    v << 0.1, 0.9, -0.5, 0.5;
    pmsc::KeySet keys(4);
    EXPECT_EQ(pmsc::addTeleconnectionPair(v, 1, keys, 1), 1);
    EXPECT_EQ(keys.keys(), (std::vector<pmsc::Index>{1}));
    EXPECT_EQ(pmsc::addTeleconnectionPair(v, 1, keys, 1), 0);
}

TEST(Teleconnection, SeedsAreValidatedNamingTheIndex) {
    pmsc::KeySet keys(10);
    expectInvalidMentioning([&] { pmsc::seedKeys(keys, {1, 10}, {}); }, "fiducial point 10");
    pmsc::KeySet a(10);
    expectInvalidMentioning([&] { pmsc::seedKeys(a, {1, -1}, {}); }, "fiducial point -1");
    pmsc::KeySet b(10);
    expectInvalidMentioning([&] { pmsc::seedKeys(b, {4, 2, 4}, {}); }, "fiducial point 4");
    pmsc::KeySet c(10);
    expectInvalidMentioning([&] { pmsc::seedKeys(c, {4}, {5, 4}); }, "grid point 4");
    pmsc::KeySet d(10);
    pmsc::seedKeys(d, {7, 3}, {0, 9});
    EXPECT_EQ(d.keys(), (std::vector<pmsc::Index>{7, 3, 0, 9}));
}

TEST(Teleconnection, KeysLandInEveryIndependentlyDrivenPatch) {
    // 8 disjoint patches, each moved by its own signal: the subspace is 8-dimensional and each
    // varimax-rotated vector is one patch, so the first picks of the first block cover all 8.
    std::vector<pmsc::Index> patchOf;
    const pmsc::FrameSet frames = pmsc::test::patchFrames(8, 25, 3, 120, 41, &patchOf);
    const Eigen::MatrixXd q = centered(frames);
    const pmsc::TruncatedSvd svd = pmsc::truncatedSvd(q, 8);
    const Eigen::MatrixXd basis = svd.u.leftCols(8);
    pmsc::TeleconnectionOptions o;
    o.maxKeys = 16;
    o.block = 8;
    const pmsc::KeySelection sel = pmsc::selectKeysTeleconnection(q, basis, svd.u, svd.sigma, 3, o);
    ASSERT_EQ(sel.keys.size(), 16u);
    expectUnique(sel.keys);
    std::vector<int> perPatch(8, 0);
    for (pmsc::Index k : sel.keys) ++perPatch[static_cast<size_t>(patchOf[static_cast<size_t>(k)])];
    for (int p = 0; p < 8; ++p) EXPECT_GE(perPatch[static_cast<size_t>(p)], 1) << "patch " << p;
    // The data is exactly rank 8 and every patch has a key: PM is exact on the training set.
    EXPECT_LT(sel.residualPerRound.back(), 1e-9);
    // The patch structure is also visible in the first 8 picks alone (one per rotated vector).
    std::set<pmsc::Index> firstPatches;
    for (size_t i = 0; i < sel.keys.size(); i += 2)
        firstPatches.insert(patchOf[static_cast<size_t>(sel.keys[i])]);
    EXPECT_EQ(firstPatches.size(), 8u);
}

TEST(Teleconnection, FiducialsComeFirstAndForcedDuplicatesAreSkipped) {
    std::vector<pmsc::Index> patchOf;
    const pmsc::FrameSet frames = pmsc::test::patchFrames(6, 20, 3, 100, 42, &patchOf);
    const Eigen::MatrixXd q = centered(frames);
    const pmsc::TruncatedSvd svd = pmsc::truncatedSvd(q, 6);
    const Eigen::MatrixXd basis = svd.u.leftCols(6);
    pmsc::TeleconnectionOptions o;
    o.maxKeys = 20;
    o.block = 6;
    const pmsc::KeySelection plain = pmsc::selectKeysTeleconnection(q, basis, svd.u, svd.sigma, 3, o);
    // Force duplicates: make the first two keys the plain selection would pick fiducials. The
    // selection must skip them as candidates, never repeat them, and still fill the budget.
    o.fiducials = {plain.keys[0], plain.keys[1]};
    o.gridPoints = {plain.keys[2]};
    const pmsc::KeySelection seeded = pmsc::selectKeysTeleconnection(q, basis, svd.u, svd.sigma, 3, o);
    ASSERT_EQ(seeded.keys.size(), 20u);
    EXPECT_EQ(seeded.keys[0], plain.keys[0]);
    EXPECT_EQ(seeded.keys[1], plain.keys[1]);
    EXPECT_EQ(seeded.keys[2], plain.keys[2]);
    expectUnique(seeded.keys);
    // A repeated fiducial is an error naming it, not a silent drop.
    o.fiducials = {5, 5};
    o.gridPoints = {};
    expectInvalidMentioning([&] { pmsc::selectKeysTeleconnection(q, basis, svd.u, svd.sigma, 3, o); },
                            "fiducial point 5");
}

TEST(Teleconnection, StopsAtMaxErrorAndRecordsEachRound) {
    const pmsc::FrameSet frames = pmsc::test::patchFrames(10, 15, 3, 150, 43);
    const Eigen::MatrixXd q = centered(frames);
    const pmsc::TruncatedSvd svd = pmsc::truncatedSvd(q, 10);
    const Eigen::MatrixXd basis = svd.u.leftCols(10);
    pmsc::TeleconnectionOptions o;
    o.maxKeys = 150;
    o.block = 2;  // small blocks: several rounds
    o.maxError = 1e-6;
    std::vector<pmsc::Index> keysAfterRound;
    o.onRound = [&](pmsc::Index, pmsc::Index k, double) { keysAfterRound.push_back(k); };
    const pmsc::KeySelection sel = pmsc::selectKeysTeleconnection(q, basis, svd.u, svd.sigma, 3, o);
    ASSERT_EQ(static_cast<size_t>(sel.rounds), sel.residualPerRound.size());
    ASSERT_EQ(keysAfterRound.size(), sel.residualPerRound.size());
    EXPECT_GT(sel.rounds, 1);
    EXPECT_LE(sel.residualPerRound.back(), 1e-6);
    for (size_t i = 0; i + 1 < sel.residualPerRound.size(); ++i) EXPECT_GT(sel.residualPerRound[i], 1e-6);
    EXPECT_LT(static_cast<pmsc::Index>(sel.keys.size()), o.maxKeys);  // stopped early, on the bound
    for (size_t i = 1; i < keysAfterRound.size(); ++i) EXPECT_GT(keysAfterRound[i], keysAfterRound[i - 1]);
}

TEST(Teleconnection, FrameSpaceResidualBlocksAgreeWithTheExplicitSvd) {
    // The Gram shortcut for residual blocks must choose the same keys as the randomized SVD of
    // the explicit residual on data whose residual spectrum is well separated.
    const pmsc::FrameSet frames = pmsc::test::patchFrames(12, 20, 3, 200, 44);
    const Eigen::MatrixXd q = centered(frames);
    pmsc::SvdOptions gramRoute;
    gramRoute.route = pmsc::SvdOptions::Route::Gram;
    const pmsc::TruncatedSvd svd = pmsc::truncatedSvd(q, 12, gramRoute);
    const Eigen::MatrixXd basis = svd.u.leftCols(12);
    pmsc::TeleconnectionOptions o;
    o.maxKeys = 12;
    o.block = 3;
    const pmsc::KeySelection a = pmsc::selectKeysTeleconnection(q, basis, svd.u, svd.sigma, 3, o);
    const pmsc::KeySelection b = pmsc::selectKeysTeleconnection(q, basis, svd.u, svd.sigma, 3, o, &svd.gram);
    EXPECT_EQ(a.keys, b.keys);
    ASSERT_EQ(a.residualPerRound.size(), b.residualPerRound.size());
    for (size_t i = 0; i < a.residualPerRound.size(); ++i)
        EXPECT_NEAR(a.residualPerRound[i], b.residualPerRound[i], 1e-9 * (1 + a.residualPerRound[i]));
}

TEST(Teleconnection, RejectsBadBudgetAndBlock) {
    const pmsc::FrameSet frames = pmsc::test::patchFrames(2, 5, 3, 20, 45);
    const Eigen::MatrixXd q = centered(frames);
    const pmsc::TruncatedSvd svd = pmsc::truncatedSvd(q, 2);
    pmsc::TeleconnectionOptions o;
    o.maxKeys = 11;
    expectInvalidMentioning([&] { pmsc::selectKeysTeleconnection(q, svd.u, svd.u, svd.sigma, 3, o); }, "11");
    o.maxKeys = 4;
    o.block = 0;
    expectInvalidMentioning([&] { pmsc::selectKeysTeleconnection(q, svd.u, svd.u, svd.sigma, 3, o); },
                            "block");
    o.block = 2;
    o.fiducials = {0, 1, 2, 3, 4};
    expectInvalidMentioning([&] { pmsc::selectKeysTeleconnection(q, svd.u, svd.u, svd.sigma, 3, o); },
                            "budget");
}

TEST(Determinacy, TooFewKeyValuesOrDependentKeysReduceM) {
    const Eigen::MatrixXd basis = pmsc::test::lowRank(30 * 3, 8, 8, 46);  // 90 x 8, rank 8
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(basis);
    Eigen::MatrixXd b = qr.householderQ() * Eigen::MatrixXd::Identity(90, 8);
    // Two keys: K*C = 6 < M = 8.
    EXPECT_EQ(pmsc::determinedBasisSize(b, 3, {4, 11}), 6);
    // Enough keys: everything determined.
    EXPECT_EQ(pmsc::determinedBasisSize(b, 3, {4, 11, 20}), 8);
    // Make key 20's rows and key 11's rows identical in the basis beyond column 3: the key system
    // is rank deficient, so the trailing columns cannot all be determined.
    Eigen::MatrixXd dependent = b;
    dependent.block(20 * 3, 0, 3, 8) = dependent.block(11 * 3, 0, 3, 8);
    EXPECT_LT(pmsc::determinedBasisSize(dependent, 3, {4, 11, 20}), 8);
    // Keys whose basis rows are zero determine nothing.
    Eigen::MatrixXd zero = b;
    zero.middleRows(0, 3).setZero();
    EXPECT_EQ(pmsc::determinedBasisSize(zero, 3, {0}), 0);
}

TEST(Determinacy, BlockwiseMaxResidualMatchesTheExplicitResidual) {
    // More rows than one block (96 points) and a ragged last block.
    const Eigen::MatrixXd q = pmsc::test::lowRank(250 * 3, 40, 12, 48, 0.8);
    const pmsc::TruncatedSvd svd = pmsc::truncatedSvd(q, 5);
    const std::vector<pmsc::Index> keys = {3, 77, 140, 201, 249};
    Eigen::MatrixXd residual, coords;
    const double explicitWorst = pmsc::pmResidual(q, svd.u, 3, keys, residual, &coords);
    EXPECT_GT(explicitWorst, 1e-3);
    EXPECT_NEAR(pmsc::maxPointResidual(q, svd.u, coords, 3), explicitWorst, 1e-13);
}

TEST(Determinacy, PmResidualIsTheProjectionErrorWhenAllPointsAreKeys) {
    const Eigen::MatrixXd q = pmsc::test::lowRank(20 * 3, 15, 6, 47);
    const pmsc::TruncatedSvd svd = pmsc::truncatedSvd(q, 4);
    std::vector<pmsc::Index> all(20);
    for (int i = 0; i < 20; ++i) all[static_cast<size_t>(i)] = i;
    Eigen::MatrixXd residual;
    const double worst = pmsc::pmResidual(q, svd.u, 3, all, residual);
    const Eigen::MatrixXd direct = q - svd.u * (svd.u.transpose() * q);
    EXPECT_LT((residual - direct).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_NEAR(worst, pmsc::maxPointNorm(direct, 3), 1e-12);
}
