#include "pmsc/Varimax.h"

#include "Synthetic.h"
#include "pmsc/Communicator.h"

#include <gtest/gtest.h>

#include <Eigen/LU>
#include <Eigen/QR>

#include <cmath>
#include <utility>
#include <vector>

namespace {

// Reference values from an independent implementation: R's stats::varimax, R 4.2.2 Patched
// (2022-11-10 r83330), Debian 12 package r-base-core, run once by hand; the numbers are frozen
// here (R is not a build or test dependency). The exact script:
//
//   x <- matrix(c(0.80, 0.30, 0.10,  0.75, 0.35, -0.05,  0.70, 0.25, 0.20,  0.20, 0.85, 0.15,
//                 0.25, 0.80, -0.10, 0.30, 0.70, 0.05,   0.10, 0.20, 0.90,  -0.05, 0.15, 0.85,
//                 0.15, 0.05, 0.75,  0.40, 0.40, 0.40), ncol = 3, byrow = TRUE)
//   a <- 0.6; b <- 0.4
//   rz <- matrix(c(cos(a), -sin(a), 0, sin(a), cos(a), 0, 0, 0, 1), 3, byrow = TRUE)
//   rx <- matrix(c(1, 0, 0, 0, cos(b), -sin(b), 0, sin(b), cos(b)), 3, byrow = TRUE)
//   x2 <- x %*% rz %*% rx
//   options(digits = 17)
//   for (norm in c(FALSE, TRUE)) {
//     v <- stats::varimax(x2, normalize = norm, eps = 1e-14)
//     write.table(format(unclass(v$rotmat), digits = 17), quote = FALSE)
//     write.table(format(unclass(v$loadings), digits = 17), quote = FALSE)
//   }
//
// x2 (the input, as printed by R):
const double kInput[10][3] = {
    {0.8296612339462533514, -0.1490589594539108720, 0.1715915600876040115},
    {0.8166265768705212036, -0.1434589808173999670, 0.0063682628375228006},
    {0.7188955487855336335, -0.0961193315356324018, 0.2577794872395582915},
    {0.6450132253677157701, 0.6005554953624888670, -0.0910551266577120655},
    {0.6580478824434479179, 0.4391881798025178973, -0.2942562270087849541},
    {0.6428504158494282583, 0.3955789790732723299, -0.1129628884083828111},
    {0.1954620561699749182, 0.4505063806685757344, 0.7866629427999681790},
    {0.0434295902637713768, 0.4710367651306304748, 0.7236976140521620415},
    {0.1520324659062035066, 0.2520624551540006086, 0.7077080245498256206},
    {0.5559912353218855463, 0.2518130505447450096, 0.3278169211932073779},
};
// v$loadings with normalize = FALSE
const double kRotatedRaw[10][3] = {
    {0.808989753589095195, 0.270206756802989612, 0.111910174541304128},
    {0.758366159305023824, 0.333632981931767325, -0.032707824572483106},
    {0.709019073044664050, 0.214727301049416064, 0.209007512407852425},
    {0.224628185383866918, 0.829395435884810572, 0.215975436715836688},
    {0.269963377214565647, 0.798858232999093643, -0.038017082114128686},
    {0.319249673355416763, 0.685617713280959662, 0.102508523049781891},
    {0.117203581107523186, 0.122699783913990446, 0.911706138842463321},
    {-0.034727991864199365, 0.080832258699838511, 0.860093083645347534},
    {0.161186277265124522, -0.015688263711204020, 0.749181461598682819},
    {0.415808719657349946, 0.355396956885597359, 0.425201260220818944},
};
// v$loadings with normalize = TRUE (Kaiser normalisation)
const double kRotatedKaiser[10][3] = {
    {0.810592176884779692, 0.267290945423339810, 0.107218810233521714},
    {0.759806889496932314, 0.329801650200450103, -0.037740723337757166},
    {0.710672032150955646, 0.213055034725602555, 0.205067829989259515},
    {0.229178488128415569, 0.830024321111247909, 0.208654851232809913},
    {0.273565418261774107, 0.797255591065033964, -0.045227032257317661},
    {0.322768063245415515, 0.684906437780902988, 0.096041391259590894},
    {0.120663965082663735, 0.129396319391557990, 0.910327853060889369},
    {-0.031624109443213630, 0.087832664963910623, 0.859526229190977875},
    {0.163485199721232599, -0.010484801351421200, 0.748774103727372742},
    {0.418807863061097463, 0.356813487357238279, 0.421051195317343141},
};

Eigen::MatrixXd fromArray(const double (&a)[10][3]) {
    Eigen::MatrixXd m(10, 3);
    for (int i = 0; i < 10; ++i)
        for (int j = 0; j < 3; ++j) m(i, j) = a[i][j];
    return m;
}

// Each reference column must match one of ours up to sign (column order and sign are arbitrary
// for a rotation criterion). R stops on its own proxy criterion, which leaves ~1e-8 differences
// between runs from different starts, hence the tolerance.
void expectSameUpToSignAndOrder(const Eigen::MatrixXd& ours, const Eigen::MatrixXd& reference, double tol) {
    ASSERT_EQ(ours.rows(), reference.rows());
    ASSERT_EQ(ours.cols(), reference.cols());
    std::vector<bool> used(static_cast<size_t>(ours.cols()), false);
    for (Eigen::Index j = 0; j < reference.cols(); ++j) {
        double best = 1e300;
        Eigen::Index bestCol = -1;
        for (Eigen::Index k = 0; k < ours.cols(); ++k) {
            if (used[static_cast<size_t>(k)]) continue;
            const double d = std::min((ours.col(k) - reference.col(j)).cwiseAbs().maxCoeff(),
                                      (ours.col(k) + reference.col(j)).cwiseAbs().maxCoeff());
            if (d < best) best = d, bestCol = k;
        }
        ASSERT_GE(bestCol, 0);
        used[static_cast<size_t>(bestCol)] = true;
        EXPECT_LT(best, tol) << "reference column " << j;
    }
}

pmsc::VarimaxOptions tight(bool normalize) {
    pmsc::VarimaxOptions o;
    o.normalize = normalize;
    o.tolerance = 1e-15;
    o.maxIterations = 1000;
    return o;
}

}  // namespace

TEST(Varimax, MatchesRStatsVarimaxWithoutNormalisation) {
    const Eigen::MatrixXd x = fromArray(kInput);
    const pmsc::VarimaxResult r = pmsc::varimax(x, tight(false));
    expectSameUpToSignAndOrder(r.rotated, fromArray(kRotatedRaw), 1e-6);
    EXPECT_LT((x * r.rotation - r.rotated).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(Varimax, MatchesRStatsVarimaxWithKaiserNormalisation) {
    const Eigen::MatrixXd x = fromArray(kInput);
    const pmsc::VarimaxResult r = pmsc::varimax(x, tight(true));
    expectSameUpToSignAndOrder(r.rotated, fromArray(kRotatedKaiser), 1e-6);
    // Normalisation rotates the normalised rows; the returned rotation still maps x to rotated.
    EXPECT_LT((x * r.rotation - r.rotated).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(Varimax, RotationIsOrthogonalAndObjectiveNeverDecreases) {
    // An orthonormal 2000 x 12 block, as key selection feeds it.
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(pmsc::test::gaussian(2000, 12, 21));
    const Eigen::MatrixXd block = qr.householderQ() * Eigen::MatrixXd::Identity(2000, 12);
    for (bool normalize : {false, true}) {
        pmsc::VarimaxOptions o;
        o.normalize = normalize;
        o.tolerance = 1e-12;
        const pmsc::VarimaxResult r = pmsc::varimax(block, o);
        EXPECT_LT((r.rotation.transpose() * r.rotation - Eigen::MatrixXd::Identity(12, 12)).norm(), 1e-12);
        EXPECT_NEAR(std::abs(r.rotation.determinant()), 1.0, 1e-12);
        ASSERT_EQ(r.objective.size(), static_cast<size_t>(r.iterations) + 1);
        ASSERT_GE(r.iterations, 2);
        for (size_t i = 1; i < r.objective.size(); ++i)
            EXPECT_GE(r.objective[i], r.objective[i - 1] * (1 - 1e-13) - 1e-300) << "step " << i;
        EXPECT_GT(r.objective.back(), r.objective.front());
        if (!normalize) {
            EXPECT_NEAR(r.objective.back(), pmsc::varimaxCriterion(r.rotated), 1e-12);
        }
        // An orthogonal rotation keeps the block orthonormal.
        if (!normalize) {
            EXPECT_LT((r.rotated.transpose() * r.rotated - Eigen::MatrixXd::Identity(12, 12)).norm(), 1e-10);
        }
    }
}

TEST(Varimax, TallBlocksSumOnEveryCoreToTheSameRotationEveryRun) {
    // 50,000 rows: four blocks of the gradient's row split, summed on whichever core takes them.
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(pmsc::test::gaussian(50000, 8, 23));
    const Eigen::MatrixXd block = qr.householderQ() * Eigen::MatrixXd::Identity(50000, 8);
    const pmsc::VarimaxResult a = pmsc::varimax(block, tight(false));
    const pmsc::VarimaxResult b = pmsc::varimax(block, tight(false));
    ASSERT_GE(a.iterations, 2);
    EXPECT_EQ(a.iterations, b.iterations);
    EXPECT_TRUE(a.rotation == b.rotation) << "the block sums must not depend on which core took a block";
    // Every block counted once: the criterion the gradient reports is the rotated block's.
    EXPECT_NEAR(a.objective.back(), pmsc::varimaxCriterion(a.rotated), 1e-12 * std::abs(a.objective.back()));
    // The rows reversed fall into other blocks and sum in another order: the same rotation.
    const pmsc::VarimaxResult r = pmsc::varimax(block.colwise().reverse(), tight(false));
    EXPECT_LT((r.rotation - a.rotation).cwiseAbs().maxCoeff(), 1e-8);
}

TEST(Varimax, ABlockHandedOverIsRotatedAsACopyOfItIs) {
    // Key selection hands each block over (rotated where it lies); the result is the copy's.
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(pmsc::test::gaussian(40000, 6, 29));
    const Eigen::MatrixXd block = qr.householderQ() * Eigen::MatrixXd::Identity(40000, 6);
    pmsc::SingleProcess one;
    for (const bool normalize : {false, true}) {
        const pmsc::VarimaxResult copied = pmsc::varimax(block, tight(normalize), one);
        Eigen::MatrixXd owned = block;
        const pmsc::VarimaxResult moved = pmsc::varimax(std::move(owned), tight(normalize), one);
        EXPECT_TRUE(copied.rotation == moved.rotation);
        EXPECT_TRUE(copied.rotated == moved.rotated);
        EXPECT_EQ(copied.objective, moved.objective);
    }
}

TEST(Varimax, RecoversLocalizedVectorsHiddenByARotation) {
    // Three vectors with disjoint supports (the "local" basis the paper wants), mixed by a rotation.
    Eigen::MatrixXd local = Eigen::MatrixXd::Zero(30, 3);
    for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 10; ++i) local(j * 10 + i, j) = std::sin(0.3 * (i + 1)) + 0.2 * j;
    for (int j = 0; j < 3; ++j) local.col(j).normalize();
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(pmsc::test::gaussian(3, 3, 22));
    const Eigen::MatrixXd mix = qr.householderQ();
    const pmsc::VarimaxResult r = pmsc::varimax(local * mix, tight(false));
    expectSameUpToSignAndOrder(r.rotated, local, 1e-7);
}

TEST(Varimax, StopsAtTheIterationCap) {
    const Eigen::MatrixXd x = fromArray(kInput);
    pmsc::VarimaxOptions o;
    o.tolerance = 0;  // never satisfied by a positive gain
    o.maxIterations = 3;
    const pmsc::VarimaxResult r = pmsc::varimax(x, o);
    EXPECT_EQ(r.iterations, 3);
    EXPECT_EQ(r.objective.size(), 4u);
}

TEST(Varimax, SingleColumnIsReturnedUnrotated) {
    const Eigen::MatrixXd x = fromArray(kInput).leftCols(1);
    const pmsc::VarimaxResult r = pmsc::varimax(x);
    EXPECT_EQ(r.rotated, x);
    EXPECT_EQ(r.rotation, Eigen::MatrixXd::Identity(1, 1));
    EXPECT_TRUE(r.converged);
}

TEST(Varimax, RejectsBadOptions) {
    pmsc::VarimaxOptions o;
    o.tolerance = -1;
    EXPECT_THROW(pmsc::varimax(fromArray(kInput), o), std::invalid_argument);
    o.tolerance = 1e-8;
    o.maxIterations = -1;
    EXPECT_THROW(pmsc::varimax(fromArray(kInput), o), std::invalid_argument);
}
