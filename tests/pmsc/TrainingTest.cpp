#include "pmsc/Training.h"

#include "Synthetic.h"
#include "pmsc/Errors.h"
#include "pmsc/KeyPointSelector.h"
#include "pmsc/PointMultiplier.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <string>
#include <vector>

namespace {

bool anyWarningContains(const pmsc::TrainingReport& r, const std::string& needle) {
    for (const auto& w : r.warnings)
        if (w.find(needle) != std::string::npos) return true;
    return false;
}

template <class E, class F>
void expectThrowMentioning(F&& f, const std::string& needle) {
    try {
        f();
        ADD_FAILURE() << "no exception; expected one mentioning " << needle;
    } catch (const E& e) {
        EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
}

}  // namespace

TEST(Training, LowRankDataIsReconstructedFromKeysExactly) {
    // Rank-5 data + offset: 5 basis vectors capture everything and a handful of keys determine
    // them, so every training frame is reconstructed to rounding from its keys.
    const Eigen::MatrixXd m = pmsc::test::lowRank(60 * 3, 40, 5, 1);
    const pmsc::FrameSet frames = pmsc::test::framesFromMatrix(m, 3);
    pmsc::TrainingOptions o;
    o.maxKeys = 6;
    o.block = 4;
    pmsc::TrainingReport report;
    const pmsc::Model model = pmsc::train(frames, o, &report);
    EXPECT_EQ(model.basisSize(), 5);
    EXPECT_EQ(model.keyCount(), 6);
    EXPECT_LT(model.trainMaxPointResidual, 1e-9);
    EXPECT_NEAR(model.energyCaptured(), 1.0, 1e-10);
    const pmsc::PointMultiplier pm(model);
    std::vector<double> keys(model.keyCount() * 3), out(60 * 3);
    Eigen::VectorXd coords(model.basisSize());
    for (pmsc::Index f = 0; f < frames.frames; ++f) {
        for (pmsc::Index i = 0; i < model.keyCount(); ++i)
            for (int c = 0; c < 3; ++c) keys[i * 3 + c] = frames.frame(f)[model.keyPoints[i] * 3 + c];
        pm.project(keys.data(), coords.data());
        pm.reconstruct(coords.data(), out.data());
        for (pmsc::Index x = 0; x < 180; ++x) ASSERT_NEAR(out[x], frames.frame(f)[x], 1e-9);
    }
    EXPECT_GT(report.seconds, 0.0);
    ASSERT_FALSE(report.residualPerRound.empty());
}

TEST(Training, RejectsBadDataNamingTheValue) {
    pmsc::FrameSet frames = pmsc::test::patchFrames(4, 10, 3, 30, 2);
    pmsc::TrainingOptions o;
    o.maxKeys = 10;
    frames.frame(7)[5 * 3 + 2] = std::numeric_limits<double>::quiet_NaN();
    expectThrowMentioning<pmsc::InputError>([&] { pmsc::train(frames, o); }, "frame 7, point 5, channel 2");
    frames.frame(7)[5 * 3 + 2] = std::numeric_limits<double>::infinity();
    expectThrowMentioning<pmsc::InputError>([&] { pmsc::train(frames, o); }, "inf");

    pmsc::FrameSet one(1, 10, 3);
    expectThrowMentioning<pmsc::InputError>([&] { pmsc::train(one, o); }, "at least 2");
    pmsc::FrameSet still(5, 10, 3);
    expectThrowMentioning<pmsc::InputError>([&] { pmsc::train(still, o); }, "identical");
}

TEST(Training, RejectsBadOptionsNamingTheValue) {
    const pmsc::FrameSet frames = pmsc::test::patchFrames(4, 10, 3, 30, 3);
    auto check = [&](auto tweak, const std::string& needle) {
        pmsc::TrainingOptions o;
        o.maxKeys = 10;
        tweak(o);
        expectThrowMentioning<std::invalid_argument>([&] { pmsc::train(frames, o); }, needle);
    };
    check([](auto& o) { o.maxKeys = 41; }, "41");
    check([](auto& o) { o.maxKeys = 0; }, "max keys");
    check([](auto& o) { o.block = 0; }, "block");
    check([](auto& o) { o.energy = 1.5; }, "1.5");
    check([](auto& o) { o.energy = std::numeric_limits<double>::quiet_NaN(); }, "energy");
    check([](auto& o) { o.basis = -2; }, "-2");
    check([](auto& o) { o.maxError = -1; }, "max error");
    check(
        [](auto& o) {
            o.tolerance = 0.1;
            o.calibrationSlices = 1;
        },
        "slices");
    check([](auto& o) { o.fiducials = {3, 99}; }, "99");
    check([](auto& o) { o.fiducials = {3, 4, 3}; }, "fiducial point 3");
    check(
        [](auto& o) {
            o.fiducials = {3};
            o.gridPoints = {3};
        },
        "3");
    check([](auto& o) { o.varimaxMaxIterations = 0; }, "varimax");
}

TEST(Training, ProgressIsReportedAndCanCancel) {
    const pmsc::FrameSet frames = pmsc::test::patchFrames(4, 10, 3, 30, 4);
    pmsc::TrainingOptions o;
    o.maxKeys = 10;
    std::set<std::string> stages;
    o.progress = [&](std::string_view stage, double, double) {
        stages.insert(std::string(stage));
        return true;
    };
    pmsc::train(frames, o);
    for (const char* s : {"mean", "svd", "keys", "projector", "calibration"})
        EXPECT_TRUE(stages.count(s)) << s;
    o.progress = [&](std::string_view stage, double, double) { return stage != "keys"; };
    expectThrowMentioning<pmsc::Cancelled>([&] { pmsc::train(frames, o); }, "keys");
}

TEST(Training, TooFewKeysReduceMAndSaySo) {
    // 3 keys x 3 channels = 9 values cannot determine 12 basis vectors: M must drop to <= 9.
    const Eigen::MatrixXd m = pmsc::test::lowRank(40 * 3, 50, 12, 5, 0.9);
    const pmsc::FrameSet frames = pmsc::test::framesFromMatrix(m, 3);
    pmsc::TrainingOptions o;
    o.basis = 12;
    o.maxKeys = 3;
    o.block = 4;
    pmsc::TrainingReport report;
    const pmsc::Model model = pmsc::train(frames, o, &report);
    EXPECT_EQ(report.requestedBasis, 12);
    EXPECT_LE(model.basisSize(), 9);
    EXPECT_GE(model.basisSize(), 1);
    EXPECT_TRUE(anyWarningContains(report, "reduced M from 12 to " + std::to_string(model.basisSize())))
        << (report.warnings.empty() ? "" : report.warnings[0]);
    EXPECT_TRUE(anyWarningContains(report, "K*C = 9"));
    EXPECT_NO_THROW(model.validate());
}

TEST(Training, KeyCountTimesChannelsEqualToMWarnsThatTheMonitorIsBlind) {
    const Eigen::MatrixXd m = pmsc::test::lowRank(40 * 3, 50, 12, 6, 0.9);
    const pmsc::FrameSet frames = pmsc::test::framesFromMatrix(m, 3);
    pmsc::TrainingOptions o;
    o.basis = 6;
    o.maxKeys = 2;  // K*C = 6 = M
    o.block = 3;
    pmsc::TrainingReport report;
    const pmsc::Model model = pmsc::train(frames, o, &report);
    ASSERT_EQ(model.basisSize(), 6);
    EXPECT_TRUE(anyWarningContains(report, "blind"));
}

TEST(Training, EnergyRuleAndDefaultThresholds) {
    Eigen::VectorXd sigma;
    const Eigen::MatrixXd m = pmsc::test::lowRank(50 * 3, 60, 10, 7, 0.5, &sigma);
    const pmsc::FrameSet frames = pmsc::test::framesFromMatrix(m, 3);
    pmsc::TrainingOptions o;
    o.energy = 0.99;
    o.maxKeys = 20;
    pmsc::TrainingReport report;
    const pmsc::Model model = pmsc::train(frames, o, &report);
    // Expected M straight from the prescribed spectrum.
    double total = sigma.squaredNorm(), acc = 0;
    pmsc::Index expected = 0;
    while (acc < 0.99 * total) acc += sigma[expected] * sigma[expected], ++expected;
    EXPECT_EQ(model.basisSize(), expected);
    EXPECT_GE(model.energyCaptured(), 0.99);
    // Uncalibrated: eps_min is the largest training key RMS, eps_max 1.5x.
    double largest = 0;
    for (double e : report.calibration.keyRms) largest = std::max(largest, e);
    EXPECT_DOUBLE_EQ(model.epsMin, largest);
    EXPECT_DOUBLE_EQ(model.epsMax, 1.5 * largest);
    EXPECT_EQ(model.tolerance, 0.0);
}

TEST(Training, DeterministicForASeed) {
    const pmsc::FrameSet frames = pmsc::test::patchFrames(6, 30, 3, 80, 8);
    pmsc::TrainingOptions o;
    o.maxKeys = 24;
    o.block = 4;
    o.basis = 6;
    const pmsc::Model a = pmsc::train(frames, o);
    const pmsc::Model b = pmsc::train(frames, o);
    EXPECT_EQ(a.keyPoints, b.keyPoints);
    EXPECT_EQ((a.basis - b.basis).cwiseAbs().maxCoeff(), 0.0);
}

TEST(Training, QDeimSelectorTrainsAWellDeterminedModel) {
    const pmsc::FrameSet frames = pmsc::test::patchFrames(8, 25, 3, 100, 9);
    pmsc::TrainingOptions o;
    o.selector = pmsc::Selector::QDeim;
    o.basis = 8;
    o.maxKeys = 12;
    o.fiducials = {7};
    pmsc::TrainingReport report;
    const pmsc::Model model = pmsc::train(frames, o, &report);
    EXPECT_EQ(model.selector, pmsc::Selector::QDeim);
    EXPECT_EQ(model.keyCount(), 12);
    EXPECT_EQ(model.keyPoints.front(), 7);
    EXPECT_EQ(model.basisSize(), 8);
    EXPECT_LT(model.trainMaxPointResidual, 1e-9);  // rank-8 data, determined keys
    ASSERT_EQ(report.residualPerRound.size(), 1u);
    EXPECT_GE(report.iterations, 1);
}

TEST(Training, ToleranceCalibratesEps) {
    // Rank-6 structure plus small off-subspace noise, M = 6: held-out errors are the noise.
    const Eigen::MatrixXd m =
        pmsc::test::lowRank(50 * 3, 90, 6, 10, 0.8) + 1e-4 * pmsc::test::gaussian(150, 90, 11);
    const pmsc::FrameSet frames = pmsc::test::framesFromMatrix(m, 3);
    pmsc::TrainingOptions o;
    o.basis = 6;
    o.maxKeys = 10;
    o.tolerance = 1e-3;
    o.calibrationSlices = 3;
    pmsc::TrainingReport report;
    const pmsc::Model model = pmsc::train(frames, o, &report);
    EXPECT_EQ(model.tolerance, 1e-3);
    ASSERT_GT(report.calibration.ratio, 0.0);
    EXPECT_DOUBLE_EQ(model.epsMin, 1e-3 / report.calibration.ratio);
    EXPECT_DOUBLE_EQ(model.epsMax, report.calibration.band * model.epsMin);
    EXPECT_GE(report.calibration.band, 1.5);
    EXPECT_LE(report.calibration.band, 2.0);
    EXPECT_EQ(report.calibration.frames.size(), 90u);
    EXPECT_EQ(report.calibration.slices, 3);
}

TEST(Training, BasisMaxErrorRulePicksTheSmallestSufficientM) {
    const Eigen::MatrixXd m = pmsc::test::lowRank(40 * 3, 60, 12, 12, 0.6);
    const pmsc::FrameSet frames = pmsc::test::framesFromMatrix(m, 3);
    pmsc::TrainingOptions o;
    o.basisMaxError = 0.01;
    o.maxKeys = 20;
    const pmsc::Model model = pmsc::train(frames, o);
    // Check the rule directly on the training data: M meets the bound, M - 1 does not.
    Eigen::MatrixXd q;
    pmsc::removeRowMean(frames.matrix(), q);
    const pmsc::TruncatedSvd svd = pmsc::truncatedSvd(q, 12);
    auto err = [&](pmsc::Index k) {
        const Eigen::MatrixXd u = svd.u.leftCols(k);
        return pmsc::maxPointNorm(q - u * (u.transpose() * q), 3);
    };
    const pmsc::Index mm = model.basisSize();
    EXPECT_LE(err(mm), 0.01);
    for (pmsc::Index k = 1; k < mm; ++k) EXPECT_GT(err(k), 0.01) << k;
}

TEST(Training, TrainMaxPointResidualIsThePmErrorOfTheFinalModel) {
    // Checked against a direct recomputation for a plain run, a run whose M is reduced, and Q-DEIM.
    const pmsc::FrameSet frames = pmsc::test::patchFrames(10, 12, 3, 80, 13);
    Eigen::MatrixXd q;
    pmsc::removeRowMean(frames.matrix(), q);
    for (int variant = 0; variant < 3; ++variant) {
        pmsc::TrainingOptions o;
        o.basis = variant == 1 ? 10 : 6;
        o.maxKeys = variant == 1 ? 2 : 9;  // variant 1: K*C = 6 < M = 10
        o.block = 4;
        if (variant == 2) o.selector = pmsc::Selector::QDeim;
        const pmsc::Model model = pmsc::train(frames, o);
        Eigen::MatrixXd residual;
        const double direct = pmsc::pmResidual(q, model.basis, 3, model.keyPoints, residual);
        EXPECT_NEAR(model.trainMaxPointResidual, direct, 1e-12 * (1 + direct)) << "variant " << variant;
        EXPECT_GT(direct, 0.0);
    }
}

namespace {

/// Low-rank frames shifted so that every value is >= 0 and the smallest is 0 (light, density).
pmsc::FrameSet nonNegativeFrames(pmsc::Index channels) {
    const Eigen::MatrixXd m = pmsc::test::lowRank(40 * channels, 30, 5, 77);
    pmsc::FrameSet frames(m.cols(), 40, channels);
    frames.matrix() = m.array() - m.minCoeff();
    return frames;
}

pmsc::TrainingOptions clampOptions() {
    pmsc::TrainingOptions o;
    o.basis = 4;
    o.maxKeys = 10;
    o.block = 4;
    return o;
}

}  // namespace

TEST(Training, FramesThatAreNeverNegativeMakeAModelWhoseOutputIsClampedAtZero) {
    const pmsc::FrameSet frames = nonNegativeFrames(3);
    const pmsc::Model model = pmsc::train(frames, clampOptions());
    ASSERT_TRUE(model.nonNegative);
    // Key values far below anything training saw: PM rings negative, the output stops at 0.
    const pmsc::PointMultiplier pm(model);
    std::vector<double> keys(static_cast<size_t>(model.keyCount() * 3));
    for (size_t i = 0; i < keys.size(); ++i) keys[i] = (i % 2 == 0) ? -5.0 : 8.0;
    std::vector<double> coords(static_cast<size_t>(model.coordCount()));
    pm.project(keys.data(), coords.data());
    const Eigen::VectorXd linear =
        model.mean + model.basis * Eigen::Map<const Eigen::VectorXd>(coords.data(), 4);
    ASSERT_LT(linear.minCoeff(), -0.1);  // the case is one the clamp changes
    std::vector<double> all(static_cast<size_t>(linear.size()));
    pm.reconstruct(coords.data(), all.data());
    std::vector<pmsc::Index> some{0, 7, 39};
    std::vector<double> subset(some.size() * 3), range(9);
    pm.reconstructPoints(coords.data(), some, subset.data());
    pm.reconstructRange(coords.data(), 5, 3, range.data());
    for (pmsc::Index i = 0; i < linear.size(); ++i)
        EXPECT_NEAR(all[size_t(i)], std::max(linear[i], 0.0), 1e-12) << "row " << i;
    for (size_t i = 0; i < some.size(); ++i)
        for (pmsc::Index c = 0; c < 3; ++c)
            EXPECT_NEAR(subset[i * 3 + size_t(c)], all[size_t(some[i] * 3 + c)], 1e-12);
    for (pmsc::Index i = 0; i < 9; ++i) EXPECT_NEAR(range[size_t(i)], all[size_t(15 + i)], 1e-12);
}

TEST(Training, ANegativeValueOrNoClampKeepsTheOutputLinear) {
    pmsc::FrameSet frames = nonNegativeFrames(3);
    pmsc::TrainingOptions o = clampOptions();
    o.clampAtZero = false;
    EXPECT_FALSE(pmsc::train(frames, o).nonNegative);
    frames.values[123] = -1e-9;
    EXPECT_FALSE(pmsc::train(frames, clampOptions()).nonNegative);
}

TEST(Training, ChannelsSharingTheBasisDecideFromTheFramesNotTheirCentredChannels) {
    pmsc::TrainingOptions o = clampOptions();
    o.sharedChannels = true;
    // C = 3 (panels in registers) and C = 5 (the general panel path) clamp alike.
    for (const pmsc::Index c : {pmsc::Index(3), pmsc::Index(5)}) {
        const pmsc::Model model = pmsc::train(nonNegativeFrames(c), o);
        ASSERT_TRUE(model.nonNegative) << c;
        const pmsc::PointMultiplier pm(model, pmsc::BasisPrecision::Single);
        std::vector<double> keys(static_cast<size_t>(model.keyCount() * c));
        for (size_t i = 0; i < keys.size(); ++i) keys[i] = (i % 3 == 0) ? -6.0 : 7.0;
        std::vector<double> coords(static_cast<size_t>(model.coordCount())), out(static_cast<size_t>(40 * c)),
            range(static_cast<size_t>(3 * c));
        pm.project(keys.data(), coords.data());
        pm.reconstruct(coords.data(), out.data());
        EXPECT_EQ(*std::min_element(out.begin(), out.end()), 0.0) << c;  // clamped, and something was
        pm.reconstructRange(coords.data(), 17, 3, range.data());         // a range inside one panel
        for (size_t i = 0; i < range.size(); ++i) EXPECT_EQ(range[i], out[size_t(17 * c) + i]) << c;
    }
    o.clampAtZero = false;
    EXPECT_FALSE(pmsc::train(nonNegativeFrames(3), o).nonNegative);
}

TEST(Training, ClampAtZeroKeepsNaN) {
    std::vector<double> v{-1.0, std::nan(""), 2.0, -0.0, 0.5};
    pmsc::clampAtZero(v.data(), pmsc::Index(v.size()));
    EXPECT_EQ(v[0], 0.0);
    EXPECT_TRUE(std::isnan(v[1]));
    EXPECT_EQ(v[2], 2.0);
    EXPECT_EQ(v[4], 0.5);
}
