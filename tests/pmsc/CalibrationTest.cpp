#include "pmsc/Calibration.h"

#include "pmsc/Model.h"
#include "Synthetic.h"

#include <gtest/gtest.h>

#include <Eigen/QR>

#include <algorithm>
#include <cmath>

namespace {

// Data where the calibration's answer is known: frames = U_true b_t + alpha_t w, with w a fixed
// direction orthogonal to U_true and much weaker than the subspace. Under PM with basis U_true
// and keys K, frame t has point error |alpha_t| max_p ||(w - U P w_K)_p|| and key RMS
// |alpha_t| ||(I - U_K P) w_K|| / sqrt(K): their ratio is the same constant r* for every frame.
struct KnownRatio {
    Eigen::MatrixXd q;
    std::vector<pmsc::Index> keys;
    double ratio = 0;
};

KnownRatio knownRatioData() {
    const pmsc::Index n = 60, c = 3, f = 100, m = 4;
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(pmsc::test::gaussian(n * c, m + 1, 61));
    const Eigen::MatrixXd all = qr.householderQ() * Eigen::MatrixXd::Identity(n * c, m + 1);
    const Eigen::MatrixXd u = all.leftCols(m);
    const Eigen::VectorXd w = all.col(m);
    Eigen::MatrixXd b = 3.0 * pmsc::test::gaussian(m, f, 62);
    Eigen::VectorXd alpha = 1e-3 * pmsc::test::gaussian(f, 1, 63).col(0);
    KnownRatio d;
    d.q = u * b + w * alpha.transpose();
    d.keys = {2, 9, 15, 33, 41, 57};
    const Eigen::MatrixXd p = pmsc::makeProjector(u, c, d.keys);
    const Eigen::MatrixXd wk = pmsc::gatherKeyRows(w, c, d.keys);
    const Eigen::VectorXd pointErr = w - u * (p * wk);
    const Eigen::VectorXd keyErr = wk - pmsc::gatherKeyRows(u, c, d.keys) * (p * wk);
    d.ratio = pmsc::maxPointNorm(pointErr, c) / (keyErr.norm() / std::sqrt(static_cast<double>(d.keys.size())));
    return d;
}

}  // namespace

TEST(Calibration, RecoversTheKnownErrorRatioAndSetsEps) {
    const KnownRatio d = knownRatioData();
    const double tolerance = 0.002;
    const pmsc::CalibrationStats s = pmsc::calibrate(d.q, 3, d.keys, 4, tolerance, 5);
    EXPECT_NEAR(s.ratio, d.ratio, 1e-3 * d.ratio);
    EXPECT_NEAR(s.epsMin, tolerance / s.ratio, 1e-15);
    EXPECT_DOUBLE_EQ(s.epsMax, 2 * s.epsMin);
    ASSERT_EQ(s.frames.size(), 100u);
    ASSERT_EQ(s.keyRms.size(), 100u);
    for (size_t i = 0; i < s.frames.size(); ++i) EXPECT_EQ(s.frames[i], static_cast<pmsc::Index>(i));
    // The guarantee eps_min is built for: every held-out frame under eps_min had error <= T.
    for (size_t i = 0; i < s.keyRms.size(); ++i)
        if (s.keyRms[i] <= s.epsMin) {
            EXPECT_LE(s.maxPointError[i], tolerance * (1 + 1e-12));
        }
    EXPECT_EQ(s.blindFrames, 0);
}

TEST(Calibration, FrameSpaceFoldsAgreeWithExplicitFolds) {
    const KnownRatio d = knownRatioData();
    Eigen::MatrixXd centered;
    pmsc::removeRowMean(d.q, centered);
    const Eigen::MatrixXd gram = pmsc::gramMatrix(centered);
    const pmsc::CalibrationStats a = pmsc::calibrate(centered, 3, d.keys, 4, 0.002, 4);
    const pmsc::CalibrationStats b = pmsc::calibrate(centered, 3, d.keys, 4, 0.002, 4, {}, &gram);
    ASSERT_EQ(a.keyRms.size(), b.keyRms.size());
    for (size_t i = 0; i < a.keyRms.size(); ++i) {
        EXPECT_NEAR(a.keyRms[i], b.keyRms[i], 1e-7 * (1e-3 + a.keyRms[i]));
        EXPECT_NEAR(a.maxPointError[i], b.maxPointError[i], 1e-7 * (1e-3 + a.maxPointError[i]));
    }
    EXPECT_NEAR(a.ratio, b.ratio, 1e-6 * a.ratio);
}

TEST(Calibration, BlindKeysAreReported) {
    // K*C == M: the key residual is identically zero, so no threshold can bound the error (the
    // data has rank 5, so M = 3 leaves real point errors).
    const KnownRatio d = knownRatioData();
    const std::vector<pmsc::Index> keys = {2};  // 3 values for M = 3
    const pmsc::CalibrationStats s = pmsc::calibrate(d.q, 3, keys, 3, 0.002, 5);
    EXPECT_GT(s.blindFrames, 0);
    EXPECT_FALSE(s.notes.empty());
    EXPECT_EQ(s.epsMin, 0.0);
}

TEST(Calibration, UncalibratedRuleUsesTrainingKeyRms) {
    const KnownRatio d = knownRatioData();
    Eigen::MatrixXd centered;
    pmsc::removeRowMean(d.q, centered);
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(centered);
    const pmsc::TruncatedSvd svd = pmsc::truncatedSvd(centered, 4);
    const Eigen::MatrixXd p = pmsc::makeProjector(svd.u, 3, d.keys);
    const pmsc::CalibrationStats s = pmsc::thresholdsFromTraining(centered, svd.u, 3, d.keys, p);
    const Eigen::VectorXd e = pmsc::keyRmsPerFrame(centered, svd.u, 3, d.keys, p);
    EXPECT_DOUBLE_EQ(s.epsMin, e.maxCoeff());
    EXPECT_DOUBLE_EQ(s.epsMax, 1.5 * e.maxCoeff());
    EXPECT_GT(s.epsMin, 0.0);
}

TEST(Calibration, RejectsBadArguments) {
    const KnownRatio d = knownRatioData();
    EXPECT_THROW(pmsc::calibrate(d.q, 3, d.keys, 4, 0.0, 5), std::invalid_argument);
    EXPECT_THROW(pmsc::calibrate(d.q, 3, d.keys, 4, std::nan(""), 5), std::invalid_argument);
    EXPECT_THROW(pmsc::calibrate(d.q, 3, d.keys, 4, 0.1, 1), std::invalid_argument);
    EXPECT_THROW(pmsc::calibrate(d.q, 3, d.keys, 4, 0.1, 101), std::invalid_argument);
}
