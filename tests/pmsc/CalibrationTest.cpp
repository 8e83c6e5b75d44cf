#include "pmsc/Calibration.h"

#include "Synthetic.h"
#include "pmsc/Model.h"

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
    d.ratio =
        pmsc::maxPointNorm(pointErr, c) / (keyErr.norm() / std::sqrt(static_cast<double>(d.keys.size())));
    return d;
}

}  // namespace

TEST(Calibration, RecoversTheKnownErrorRatioAndSetsEps) {
    const KnownRatio d = knownRatioData();
    const double tolerance = 0.002;
    const pmsc::CalibrationStats s = pmsc::calibrate(d.q, 3, d.keys, 4, tolerance, 5);
    EXPECT_NEAR(s.ratio, d.ratio, 1e-3 * d.ratio);
    EXPECT_NEAR(s.epsMin, tolerance / s.ratio, 1e-15);
    EXPECT_DOUBLE_EQ(s.band, 1.5) << "one ratio for every frame: the narrowest band";
    EXPECT_DOUBLE_EQ(s.epsMax, 1.5 * s.epsMin);
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

namespace {
pmsc::CalibrationStats scores(std::vector<double> e, std::vector<double> bigE) {
    pmsc::CalibrationStats s;
    s.keyRms = std::move(e);
    s.maxPointError = std::move(bigE);
    return s;
}
}  // namespace

// The threshold rule is the held-out frames' own best threshold, between the max rule's eps and the
// conformal quantile's; the max rule's where no held-out frame crossed T.
TEST(Calibration, ThresholdRuleIsTheHeldOutBestThresholdBetweenMaxAndConformal) {
    // T = 5: frames over T at e = 3 and e = 6; the largest e below 3 is 2. Ratios, sorted:
    // 0.75, 0.8, 1, 1, 3.33, 3.33. Coverage 0.5: the 4th, 1, so the conformal eps is 5.
    pmsc::CalibrationStats s = scores({1, 2, 3, 4, 5, 6}, {1, 2, 10, 3, 4, 20});
    pmsc::setThresholds(s, 5.0, pmsc::CalibrationRule::Threshold, 0.5);
    EXPECT_DOUBLE_EQ(s.epsMin, 2.0);
    EXPECT_DOUBLE_EQ(s.ratio, 2.5);
    EXPECT_NEAR(s.maxRatio, 10.0 / 3.0, 1e-12);
    pmsc::CalibrationStats max = scores({1, 2, 3, 4, 5, 6}, {1, 2, 10, 3, 4, 20});
    pmsc::setThresholds(max, 5.0, pmsc::CalibrationRule::MaxRatio, 0.9);
    EXPECT_DOUBLE_EQ(max.epsMin, 1.5) << "T / the largest ratio";
    // Coverage 0.9 of 6 frames has no quantile (the largest ratio, eps 1.5): the conformal cap binds.
    s = scores({1, 2, 3, 4, 5, 6}, {1, 2, 10, 3, 4, 20});
    pmsc::setThresholds(s, 5.0, pmsc::CalibrationRule::Threshold, 0.9);
    EXPECT_DOUBLE_EQ(s.epsMin, 1.5);
    // No held-out frame over T: the linear bound extrapolates, as the max rule does.
    s = scores({1, 2}, {1, 3});
    pmsc::setThresholds(s, 5.0, pmsc::CalibrationRule::Threshold, 0.5);
    EXPECT_DOUBLE_EQ(s.epsMin, 5.0 / 1.5);
    // The lowest crossing below every other frame: the max rule's eps, the floor.
    s = scores({1, 0.5}, {0.5, 10});
    pmsc::setThresholds(s, 5.0, pmsc::CalibrationRule::Threshold, 0.5);
    EXPECT_DOUBLE_EQ(s.epsMin, 0.25);
    EXPECT_STREQ(pmsc::toString(pmsc::CalibrationRule::Threshold), "threshold");
    EXPECT_EQ(pmsc::calibrationRuleNamed("threshold"), pmsc::CalibrationRule::Threshold);
    EXPECT_EQ(pmsc::calibrationRuleNamed("max"), pmsc::CalibrationRule::MaxRatio);
    EXPECT_FALSE(pmsc::calibrationRuleNamed("median").has_value());
    EXPECT_THROW(pmsc::setThresholds(s, 5.0, pmsc::CalibrationRule::Threshold, 1.0), std::invalid_argument);
}

TEST(Calibration, PredictedErrorHitsWhereEitherPartDoesAndNoHeldOutHitIsOverTheTolerance) {
    // 300 held-out frames whose point error each part sees differently: E = a * rms for some
    // frames, E = b * loo for the others, plus frames over T.
    const Eigen::MatrixXd g = pmsc::test::gaussian(300, 3, 71).cwiseAbs();
    std::vector<double> rms, loo, big;
    for (pmsc::Index f = 0; f < 300; ++f) {
        rms.push_back(0.2 + g(f, 0));
        loo.push_back(0.2 + g(f, 1));
        big.push_back(f % 2 == 0 ? 3 * rms.back() * (0.8 + 0.2 * g(f, 2))
                                 : 2 * loo.back() * (0.9 + 0.1 * g(f, 2)));
    }
    const double t = 4.0;
    pmsc::CalibrationStats s = scores(rms, big);
    s.keyLoo = loo;
    pmsc::setPredictedThresholds(s, t, pmsc::CalibrationRule::Threshold, 0.9);
    pmsc::CalibrationStats r = scores(rms, big), l = scores(loo, big);
    pmsc::setThresholds(r, t, pmsc::CalibrationRule::MaxRatio, 0.9);
    pmsc::setThresholds(l, t, pmsc::CalibrationRule::Threshold, 0.9);
    EXPECT_EQ(s.partEps.rms, r.epsMin) << "the RMS part by the largest ratio whatever the rule";
    EXPECT_EQ(s.partEps.loo, l.epsMin) << "the leave-one-out part by the rule";
    EXPECT_EQ(s.epsMin, t);
    EXPECT_EQ(s.epsMax, std::min(r.band, l.band) * t);
    ASSERT_EQ(s.parts.size(), 2u);
    EXPECT_EQ(s.parts[0].keyRms, rms);
    EXPECT_EQ(s.parts[1].keyRms, loo);
    int hits = 0, rmsHits = 0, looHits = 0, overT = 0;
    for (std::size_t f = 0; f < rms.size(); ++f) {
        const bool either = rms[f] <= r.epsMin || loo[f] <= l.epsMin;
        EXPECT_EQ(s.keyRms[f] <= t, either) << "frame " << f;
        hits += s.keyRms[f] <= t;
        rmsHits += rms[f] <= r.epsMin;
        looHits += loo[f] <= l.epsMin;
        overT += big[f] > t;
        if (s.keyRms[f] <= t) {
            EXPECT_LE(big[f], t) << "a held-out hit over the tolerance, frame " << f;
        }
    }
    EXPECT_GT(overT, 0) << "the data must cross T for the check above to mean anything";
    EXPECT_GT(hits, std::max(rmsHits, looHits)) << "each part finds hits the other misses";
    // The parts must be scored on the same frames.
    pmsc::CalibrationStats bad = scores(rms, big);
    bad.keyLoo = {1.0};
    EXPECT_THROW(pmsc::setPredictedThresholds(bad, t, pmsc::CalibrationRule::Threshold, 0.9),
                 std::invalid_argument);
}

TEST(Calibration, PredictedErrorThroughCalibrateScoresBothPartsOnTheSameFolds) {
    const KnownRatio d = knownRatioData();
    const pmsc::CalibrationStats rms = pmsc::calibrate(d.q, 3, d.keys, 4, 0.002, 5);
    const pmsc::CalibrationStats loo =
        pmsc::calibrate(d.q, 3, d.keys, 4, 0.002, 5, {}, nullptr, pmsc::CalibrationRule::Threshold, 0.9,
                        pmsc::KeyErrorNorm::LeaveOneOut);
    const pmsc::CalibrationStats s =
        pmsc::calibrate(d.q, 3, d.keys, 4, 0.002, 5, {}, nullptr, pmsc::CalibrationRule::Threshold, 0.9,
                        pmsc::KeyErrorNorm::Predicted);
    ASSERT_EQ(s.parts.size(), 2u);
    EXPECT_EQ(s.parts[0].keyRms, rms.keyRms);
    EXPECT_EQ(s.parts[1].keyRms, loo.keyRms);
    EXPECT_DOUBLE_EQ(s.partEps.rms, rms.epsMin);
    EXPECT_DOUBLE_EQ(s.partEps.loo, loo.epsMin);
    EXPECT_EQ(s.epsMin, 0.002);
}

TEST(Calibration, BlendBandSpansTheRuleRatioToTheMedianWithinOneAndAHalfAndTwo) {
    EXPECT_DOUBLE_EQ(pmsc::blendBand({1, 1, 1.8, 1.9}, 1.8), 1.5);  // median 1.8: clamped up
    EXPECT_DOUBLE_EQ(pmsc::blendBand({1, 1, 1, 1.7, 1.75}, 1.75), 1.75);
    EXPECT_DOUBLE_EQ(pmsc::blendBand({1, 1, 1, 5}, 5), 2.0);
    EXPECT_DOUBLE_EQ(pmsc::blendBand({}, 5), 2.0);
    pmsc::CalibrationStats s = scores({1, 1, 1, 1, 1}, {1, 1, 1, 1.7, 1.75});
    pmsc::setThresholds(s, 3.5, pmsc::CalibrationRule::MaxRatio, 0.9);
    EXPECT_DOUBLE_EQ(s.epsMin, 2.0);
    EXPECT_DOUBLE_EQ(s.band, 1.75);
    EXPECT_DOUBLE_EQ(s.epsMax, 3.5);
}

TEST(Calibration, ConformalQuantileIsTheRankOfNPlusOneTimesCoverage) {
    std::vector<double> v;
    for (int i = 19; i >= 1; --i) v.push_back(i);        // 1..19, unsorted
    EXPECT_EQ(pmsc::conformalQuantile(v, 0.9), 18.0);    // ceil(20 * 0.9) = 18
    EXPECT_EQ(pmsc::conformalQuantile(v, 0.5), 10.0);    // ceil(20 * 0.5) = 10
    EXPECT_EQ(pmsc::conformalQuantile(v, 0.951), 19.0);  // ceil(19.02) = 20 > n: the largest
    EXPECT_EQ(pmsc::conformalQuantile({}, 0.9), 0.0);
}

namespace {

// Held-out scores whose ratio E/e is log-normal: most frames near 3, a tail up to ~4x that, as
// held-out training frames show on the ICT face.
pmsc::CalibrationStats lognormalScores(size_t n, unsigned seed) {
    const Eigen::MatrixXd z = pmsc::test::gaussian(static_cast<pmsc::Index>(n), 2, seed);
    pmsc::CalibrationStats s;
    for (size_t i = 0; i < n; ++i) {
        const double e = 0.01 + 0.05 * std::abs(z(static_cast<pmsc::Index>(i), 0));
        const double ratio = 3.0 * std::exp(0.35 * z(static_cast<pmsc::Index>(i), 1));
        s.keyRms.push_back(e);
        s.maxPointError.push_back(ratio * e);
    }
    return s;
}

}  // namespace

TEST(Calibration, ConformalRuleKeepsItsCoverageOnFreshFramesAndWastesFewerHits) {
    const double tolerance = 0.2, coverage = 0.9;
    pmsc::CalibrationStats conformal = lognormalScores(400, 71);
    pmsc::CalibrationStats max = conformal;
    pmsc::setThresholds(conformal, tolerance, pmsc::CalibrationRule::Conformal, coverage);
    pmsc::setThresholds(max, tolerance, pmsc::CalibrationRule::MaxRatio, 0);
    EXPECT_EQ(conformal.usableFrames, 400);
    EXPECT_EQ(conformal.maxRatio, max.ratio);
    EXPECT_LT(conformal.ratio, max.ratio);
    EXPECT_NEAR(conformal.epsMin, tolerance / conformal.ratio, 1e-15);
    EXPECT_DOUBLE_EQ(conformal.epsMax, conformal.band * conformal.epsMin);
    EXPECT_GT(conformal.epsMin, max.epsMin);

    // Fresh frames from the same distribution: the bound E <= r e fails on about 1 - coverage of
    // them (split-conformal: at most alpha in expectation, here one draw of 20,000 frames).
    const pmsc::CalibrationStats fresh = lognormalScores(20000, 72);
    size_t outside = 0, hits = 0, badHits = 0;
    for (size_t i = 0; i < fresh.keyRms.size(); ++i) {
        outside += fresh.maxPointError[i] > conformal.ratio * fresh.keyRms[i];
        if (fresh.keyRms[i] <= conformal.epsMin) {
            ++hits;
            badHits += fresh.maxPointError[i] > tolerance;
        }
    }
    const double rate = static_cast<double>(outside) / static_cast<double>(fresh.keyRms.size());
    EXPECT_LT(rate, 1 - coverage + 0.03);
    EXPECT_GT(rate, 1 - coverage - 0.05);  // and not so cautious that the quantile is the max
    EXPECT_LE(static_cast<double>(badHits), (1 - coverage) * static_cast<double>(fresh.keyRms.size()));
    EXPECT_GT(hits, 0u);
}

TEST(Calibration, ConformalRuleWithTooFewFramesFallsBackToTheLargestRatio) {
    pmsc::CalibrationStats s = lognormalScores(10, 73);
    pmsc::setThresholds(s, 0.2, pmsc::CalibrationRule::Conformal, 0.95);  // ceil(11 * 0.95) = 11 > 10
    EXPECT_EQ(s.ratio, s.maxRatio);
    EXPECT_FALSE(s.notes.empty());
}

TEST(Calibration, ConformalRuleThroughCalibrateAndBadCoverage) {
    const KnownRatio d = knownRatioData();
    // Every held-out ratio is the same constant: both rules agree.
    const pmsc::CalibrationStats s =
        pmsc::calibrate(d.q, 3, d.keys, 4, 0.002, 5, {}, nullptr, pmsc::CalibrationRule::Conformal, 0.9);
    EXPECT_NEAR(s.ratio, d.ratio, 1e-3 * d.ratio);
    EXPECT_EQ(s.rule, pmsc::CalibrationRule::Conformal);
    EXPECT_EQ(s.coverage, 0.9);
    EXPECT_THROW(
        pmsc::calibrate(d.q, 3, d.keys, 4, 0.002, 5, {}, nullptr, pmsc::CalibrationRule::Conformal, 1.0),
        std::invalid_argument);
    pmsc::CalibrationStats t = lognormalScores(50, 74);
    EXPECT_THROW(pmsc::setThresholds(t, 0.2, pmsc::CalibrationRule::Conformal, 0.0), std::invalid_argument);
    EXPECT_THROW(pmsc::setThresholds(t, -1, pmsc::CalibrationRule::MaxRatio, 0.0), std::invalid_argument);
}
