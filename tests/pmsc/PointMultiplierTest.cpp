#include "pmsc/PointMultiplier.h"

#include "Synthetic.h"
#include "pmsc/Calibration.h"
#include "pmsc/ModelIO.h"

#include <gtest/gtest.h>

#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <vector>

namespace {

// A hand-built model: random orthonormal basis, given keys, projector from makeProjector.
pmsc::Model makeModel(pmsc::Index n, pmsc::Index c, pmsc::Index m, std::vector<pmsc::Index> keys) {
    pmsc::Model model;
    model.points = n;
    model.channels = c;
    model.trainFrames = 10;
    const Eigen::MatrixXd g = pmsc::test::gaussian(n * c, m, 7);
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(g);
    model.basis = qr.householderQ() * Eigen::MatrixXd::Identity(n * c, m);
    model.mean = pmsc::test::gaussian(n * c, 1, 8).col(0);
    model.singularValues = Eigen::VectorXd::LinSpaced(m, static_cast<double>(m), 1.0);
    model.totalEnergy = model.singularValues.squaredNorm() * 1.01;
    model.keyPoints = std::move(keys);
    model.projector = pmsc::makeProjector(model.basis, c, model.keyPoints);
    model.epsMin = 0.1;
    model.epsMax = 0.15;
    return model;
}

std::vector<double> keyValuesOf(const pmsc::Model& model, const Eigen::VectorXd& frame) {
    std::vector<double> k;
    for (pmsc::Index p : model.keyPoints)
        for (pmsc::Index ch = 0; ch < model.channels; ++ch) k.push_back(frame[p * model.channels + ch]);
    return k;
}

}  // namespace

TEST(PointMultiplier, FrameInSubspaceIsReconstructedExactlyFromItsKeys) {
    const pmsc::Model model = makeModel(50, 3, 6, {3, 17, 29, 41});
    const pmsc::PointMultiplier pm(model);
    const Eigen::VectorXd b = pmsc::test::gaussian(6, 1, 9).col(0);
    const Eigen::VectorXd frame = model.mean + model.basis * b;
    const std::vector<double> keys = keyValuesOf(model, frame);
    Eigen::VectorXd coords(6);
    pm.project(keys.data(), coords.data());
    EXPECT_LT((coords - b).norm(), 1e-10);
    Eigen::VectorXd out(150);
    pm.reconstruct(coords.data(), out.data());
    EXPECT_LT((out - frame).cwiseAbs().maxCoeff(), 1e-10);
    EXPECT_LT(pm.keyError(keys.data(), coords.data()), 1e-10);
}

TEST(PointMultiplier, KeyRmsIsRmsOverKeysOfPerPointEuclideanError) {
    const pmsc::Model model = makeModel(40, 3, 4, {1, 5, 9, 13, 20});
    const pmsc::PointMultiplier pm(model);
    const Eigen::VectorXd b = pmsc::test::gaussian(4, 1, 10).col(0);
    Eigen::VectorXd frame = model.mean + model.basis * b;
    // Perturb out of the subspace, then check against the definition computed directly.
    frame += 0.01 * pmsc::test::gaussian(120, 1, 11).col(0);
    const std::vector<double> keys = keyValuesOf(model, frame);
    Eigen::VectorXd coords(4);
    pm.project(keys.data(), coords.data());
    const Eigen::VectorXd predicted = model.mean + model.basis * coords;
    double sum = 0;
    for (pmsc::Index p : model.keyPoints) sum += (frame - predicted).segment(p * 3, 3).squaredNorm();
    const double expected = std::sqrt(sum / 5.0);
    EXPECT_GT(expected, 1e-4);
    EXPECT_NEAR(pm.keyError(keys.data(), coords.data()), expected, 1e-12);
}

// The largest-key norm, over more keys than one block of the key basis (256 rows), so keys whose
// channels straddle a block boundary count whole; and the KEYERROR section keeps the norm.
TEST(PointMultiplier, LargestKeyErrorIsTheLargestKeysEuclideanError) {
    std::vector<pmsc::Index> keys(100);
    std::iota(keys.begin(), keys.end(), pmsc::Index(0));
    pmsc::Model model = makeModel(150, 3, 5, keys);
    model.keyErrorNorm = pmsc::KeyErrorNorm::Largest;
    const pmsc::PointMultiplier pm(model);
    Eigen::VectorXd frame = model.mean + model.basis * pmsc::test::gaussian(5, 1, 12).col(0);
    frame += 0.01 * pmsc::test::gaussian(450, 1, 13).col(0);
    frame.segment(85 * 3, 3) += Eigen::Vector3d(0.3, -0.2, 0.1);  // key 85: rows 255..257, across the block
    const std::vector<double> k = keyValuesOf(model, frame);
    Eigen::VectorXd coords(5);
    pm.project(k.data(), coords.data());
    const Eigen::VectorXd residual = frame - (model.mean + model.basis * coords);
    double largest = 0;
    for (pmsc::Index p : model.keyPoints) largest = std::max(largest, residual.segment(p * 3, 3).norm());
    EXPECT_NEAR(pm.keyError(k.data(), coords.data()), largest, 1e-12);
    EXPECT_NEAR(
        pmsc::keyErrorOfResidual(pmsc::gatherKeyRows(residual, 3, keys), 3, pmsc::KeyErrorNorm::Largest),
        largest, 1e-12);

    const pmsc::Model back = pmsc::decodeModel(pmsc::encodeModel(model), "test");
    EXPECT_EQ(back.keyErrorNorm, pmsc::KeyErrorNorm::Largest);
    model.keyErrorNorm = pmsc::KeyErrorNorm::Rms;
    EXPECT_EQ(pmsc::modelFormatVersion(model), 1u) << "an RMS model needs no section";
    EXPECT_EQ(pmsc::decodeModel(pmsc::encodeModel(model), "test").keyErrorNorm, pmsc::KeyErrorNorm::Rms);
}

// What key row j would miss were it left out of the fit: solve the least squares without that
// row, predict it. Brute force, for the PRESS identity r_j / (1 - h_jj) the model computes.
Eigen::VectorXd leaveOneOutResiduals(const Eigen::MatrixXd& bk, const Eigen::VectorXd& k) {
    Eigen::VectorXd r(bk.rows());
    for (pmsc::Index j = 0; j < bk.rows(); ++j) {
        Eigen::MatrixXd a(bk.rows() - 1, bk.cols());
        Eigen::VectorXd y(bk.rows() - 1);
        for (pmsc::Index i = 0, o = 0; i < bk.rows(); ++i) {
            if (i == j) continue;
            a.row(o) = bk.row(i);
            y[o++] = k[i];
        }
        const Eigen::VectorXd b = a.colPivHouseholderQr().solve(y);
        r[j] = k[j] - bk.row(j).dot(b);
    }
    return r;
}

TEST(PointMultiplier, LeaveOneOutKeyErrorIsWhatEachKeyRowMissesWhenLeftOut) {
    // 12 keys x 3 channels = 36 rows for a 6-vector basis: every row has leverage below 1.
    const std::vector<pmsc::Index> keys{2, 5, 9, 13, 17, 22, 26, 31, 35, 38, 44, 47};
    pmsc::Model model = makeModel(50, 3, 6, keys);
    model.keyErrorNorm = pmsc::KeyErrorNorm::LeaveOneOut;
    const pmsc::PointMultiplier pm(model);
    Eigen::VectorXd frame = model.mean + model.basis * pmsc::test::gaussian(6, 1, 21).col(0);
    frame += 0.05 * pmsc::test::gaussian(150, 1, 22).col(0);
    const std::vector<double> k = keyValuesOf(model, frame);
    Eigen::VectorXd coords(6);
    pm.project(k.data(), coords.data());
    const Eigen::MatrixXd bk = pmsc::gatherKeyRows(model.basis, 3, keys);
    const Eigen::VectorXd centred =
        Eigen::Map<const Eigen::VectorXd>(k.data(), 36) - pmsc::gatherKeyRows(model.mean, 3, keys).col(0);
    const Eigen::VectorXd loo = leaveOneOutResiduals(bk, centred);
    double largest = 0, plain = 0;
    for (pmsc::Index key = 0; key < 12; ++key) {
        largest = std::max(largest, loo.segment(key * 3, 3).norm());
        plain = std::max(plain, (centred - bk * coords).segment(key * 3, 3).norm());
    }
    EXPECT_GT(largest, plain) << "leaving a row out can only raise what it misses";
    EXPECT_NEAR(pm.keyError(k.data(), coords.data()), largest, 1e-10 * largest);
    // The calibration's measure is the same number.
    const Eigen::VectorXd scale = pmsc::leaveOneOutScale(bk, model.projector);
    EXPECT_NEAR(pmsc::keyErrorOfResidual(centred - bk * coords, 3, pmsc::KeyErrorNorm::LeaveOneOut, &scale),
                largest, 1e-10 * largest);
    EXPECT_THROW(pmsc::keyErrorOfResidual(centred - bk * coords, 3, pmsc::KeyErrorNorm::LeaveOneOut),
                 std::invalid_argument)
        << "the leave-one-out error needs the rows' scale";
    // The KEYERROR section keeps it; a norm this version does not know is refused.
    EXPECT_EQ(pmsc::decodeModel(pmsc::encodeModel(model), "test").keyErrorNorm,
              pmsc::KeyErrorNorm::LeaveOneOut);
}

TEST(PointMultiplier, PredictedKeyErrorIsTheToleranceTimesTheSmallerPartOverItsThreshold) {
    const std::vector<pmsc::Index> keys{2, 5, 9, 13, 17, 22, 26, 31, 35, 38, 44, 47};
    pmsc::Model model = makeModel(50, 3, 6, keys);
    model.keyErrorNorm = pmsc::KeyErrorNorm::Predicted;
    model.tolerance = 0.4;
    Eigen::VectorXd frame = model.mean + model.basis * pmsc::test::gaussian(6, 1, 21).col(0);
    frame += 0.05 * pmsc::test::gaussian(150, 1, 22).col(0);
    const std::vector<double> k = keyValuesOf(model, frame);
    const Eigen::MatrixXd bk = pmsc::gatherKeyRows(model.basis, 3, keys);
    const Eigen::VectorXd centred =
        Eigen::Map<const Eigen::VectorXd>(k.data(), 36) - pmsc::gatherKeyRows(model.mean, 3, keys).col(0);
    const Eigen::VectorXd loo = leaveOneOutResiduals(bk, centred);
    Eigen::VectorXd coords(6);
    double rms2 = 0, largestLoo = 0;
    {
        const pmsc::PointMultiplier pm(model);
        pm.project(k.data(), coords.data());
        const Eigen::VectorXd r = centred - bk * coords;
        for (pmsc::Index key = 0; key < 12; ++key) {
            rms2 += r.segment(key * 3, 3).squaredNorm();
            largestLoo = std::max(largestLoo, loo.segment(key * 3, 3).norm());
        }
    }
    const double rms = std::sqrt(rms2 / 12);
    // Each part in turn the smaller over its threshold, then a part whose threshold is 0.
    for (const pmsc::PredictedParts eps :
         {pmsc::PredictedParts{rms, 10 * largestLoo}, pmsc::PredictedParts{10 * rms, largestLoo / 2},
          pmsc::PredictedParts{0, largestLoo}}) {
        model.partEps = eps;
        const pmsc::PointMultiplier pm(model);
        const double rmsOver = eps.rms > 0 ? rms / eps.rms : std::numeric_limits<double>::infinity();
        const double expected = 0.4 * std::min(rmsOver, largestLoo / eps.loo);
        EXPECT_NEAR(pm.keyError(k.data(), coords.data()), expected, 1e-10 * expected);
        pmsc::PredictedParts parts;
        pm.keyError(k.data(), coords.data(), &parts);  // the raw parts it was combined from
        EXPECT_NEAR(parts.rms, rms, 1e-12 * rms);
        EXPECT_NEAR(parts.loo, largestLoo, 1e-12 * largestLoo);
    }
    // Disagreeing parts: exactly one at or under its threshold.
    EXPECT_TRUE(pmsc::partsDisagree({1, 3}, {2, 2}));
    EXPECT_TRUE(pmsc::partsDisagree({3, 2}, {2, 2}));
    EXPECT_FALSE(pmsc::partsDisagree({1, 1}, {2, 2}));
    EXPECT_FALSE(pmsc::partsDisagree({3, 3}, {2, 2}));
    EXPECT_FALSE(pmsc::partsDisagree({std::nan(""), 1}, {2, 2}));
    EXPECT_NEAR(pmsc::predictedPointError({rms, largestLoo}, {rms, largestLoo / 10}, 0.4), 0.4, 1e-15)
        << "a frame at its RMS part's threshold is predicted at the tolerance";
    EXPECT_EQ(pmsc::predictedPointError({0, 0}, {0, 0}, 0.4), 0) << "no error: certified by any threshold";
    EXPECT_TRUE(std::isinf(pmsc::predictedPointError({1e-12, 1e-12}, {0, 0}, 0.4)));
    EXPECT_TRUE(std::isnan(pmsc::predictedPointError({std::nan(""), 0}, {1, 1}, 0.4)));
    EXPECT_THROW(pmsc::keyErrorOfResidual(centred, 3, pmsc::KeyErrorNorm::Predicted), std::invalid_argument);
    // A key value that is not finite is a miss, as for every measure.
    std::vector<double> bad = k;
    bad[4] = std::numeric_limits<double>::quiet_NaN();
    EXPECT_TRUE(std::isnan(pmsc::PointMultiplier(model).keyError(bad.data(), coords.data())));
}

TEST(PointMultiplier, LeaveOneOutKeyErrorOfSharedChannelsLeavesAKeyOutOfEachChannelsFit) {
    // The channels share the K x M key basis: one leverage per key, each channel its own fit.
    const std::vector<pmsc::Index> keys{1, 4, 8, 11, 15, 19, 23, 27, 30, 34};
    pmsc::Model model = makeModel(40, 1, 4, keys);  // an N x M basis
    model.channels = 3;
    model.sharedChannels = true;
    model.mean = pmsc::test::gaussian(120, 1, 30).col(0);
    model.projector = pmsc::makeProjector(model.basis, 1, keys);
    model.keyErrorNorm = pmsc::KeyErrorNorm::LeaveOneOut;
    const pmsc::PointMultiplier pm(model);
    Eigen::VectorXd frame = model.mean + 0.1 * pmsc::test::gaussian(120, 1, 31).col(0);
    const std::vector<double> k = keyValuesOf(model, frame);
    std::vector<double> coords(static_cast<size_t>(model.coordCount()));
    pm.project(k.data(), coords.data());
    const Eigen::MatrixXd bk = pmsc::gatherKeyRows(model.basis, 1, keys);
    Eigen::MatrixXd loo(10, 3);
    for (pmsc::Index ch = 0; ch < 3; ++ch) {
        Eigen::VectorXd y(10);
        for (pmsc::Index i = 0; i < 10; ++i)
            y[i] = k[size_t(i * 3 + ch)] - model.mean[keys[size_t(i)] * 3 + ch];
        loo.col(ch) = leaveOneOutResiduals(bk, y);
    }
    const double largest = loo.rowwise().norm().maxCoeff();
    EXPECT_NEAR(pm.keyError(k.data(), coords.data()), largest, 1e-10 * largest);
}

TEST(PointMultiplier, KeyRmsIsNaNForNonFiniteKeyValue) {
    const pmsc::Model model = makeModel(20, 3, 3, {0, 4, 8});
    const pmsc::PointMultiplier pm(model);
    std::vector<double> keys(9, 1.0);
    Eigen::VectorXd coords(3);
    pm.project(keys.data(), coords.data());
    EXPECT_TRUE(std::isfinite(pm.keyError(keys.data(), coords.data())));
    keys[4] = std::numeric_limits<double>::infinity();
    EXPECT_TRUE(std::isnan(pm.keyError(keys.data(), coords.data())));
    keys[4] = std::numeric_limits<double>::quiet_NaN();
    EXPECT_TRUE(std::isnan(pm.keyError(keys.data(), coords.data())));
}

TEST(PointMultiplier, PointsAndRangeAgreeWithFullReconstruction) {
    const pmsc::Model model = makeModel(60, 3, 5, {2, 30, 58});
    const pmsc::PointMultiplier pm(model);
    const Eigen::VectorXd coords = pmsc::test::gaussian(5, 1, 12).col(0);
    Eigen::VectorXd all(180);
    pm.reconstruct(coords.data(), all.data());
    const std::vector<pmsc::Index> subset = {59, 0, 17, 17, 33};
    std::vector<double> some(subset.size() * 3);
    pm.reconstructPoints(coords.data(), subset, some.data());
    for (size_t i = 0; i < subset.size(); ++i)
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(some[i * 3 + c], all[subset[i] * 3 + c], 1e-13);
    std::vector<double> chunk(7 * 3);
    pm.reconstructRange(coords.data(), 20, 7, chunk.data());
    for (int i = 0; i < 21; ++i) EXPECT_NEAR(chunk[i], all[60 + i], 1e-13);
    // Against the definition mean + B b.
    EXPECT_LT((all - (model.mean + model.basis * coords)).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(PointMultiplier, WithoutABasisCopyItProjectsMeasuresAndReconstructsPointsButNotFrames) {
    const pmsc::Model model = makeModel(60, 3, 5, {2, 30, 58});
    const pmsc::PointMultiplier copy(model), none(model, pmsc::BasisPrecision::None);
    const Eigen::VectorXd keys = pmsc::test::gaussian(9, 1, 14).col(0);
    Eigen::VectorXd a(5), b(5);
    copy.project(keys.data(), a.data());
    none.project(keys.data(), b.data());
    EXPECT_TRUE(a == b);
    EXPECT_EQ(copy.keyError(keys.data(), a.data()), none.keyError(keys.data(), b.data()));
    const std::vector<pmsc::Index> subset = {59, 0, 17};
    std::vector<double> x(9), y(9);
    copy.reconstructPoints(a.data(), subset, x.data());
    none.reconstructPoints(b.data(), subset, y.data());
    EXPECT_EQ(x, y);
    Eigen::VectorXd all(180);
    EXPECT_THROW(none.reconstruct(b.data(), all.data()), std::logic_error);
    EXPECT_THROW(none.reconstructRange(b.data(), 0, 7, all.data()), std::logic_error);
}

TEST(PointMultiplier, LargestErrorAtPointsIsTheLargestEuclideanErrorOfTheirReconstruction) {
    const pmsc::Model model = makeModel(60, 3, 5, {2, 30, 58});
    const pmsc::PointMultiplier pm(model);
    const Eigen::VectorXd coords = pmsc::test::gaussian(5, 1, 31).col(0);
    const std::vector<pmsc::Index> points{4, 11, 40};
    std::vector<double> values(9);
    pm.reconstructPoints(coords.data(), points, values.data());
    EXPECT_EQ(pm.largestErrorAt(coords.data(), points, values.data()), 0.0);
    values[3] += 3;  // point 11 off by (3, 4, 0): error 5
    values[4] += 4;
    values[7] += 1;  // point 40 off by 1
    EXPECT_NEAR(pm.largestErrorAt(coords.data(), points, values.data()), 5.0, 1e-12);
    values[8] = std::nan("");
    EXPECT_TRUE(std::isnan(pm.largestErrorAt(coords.data(), points, values.data())));
}

TEST(PointMultiplier, UnderdeterminedKeysGiveMinimumNormCoordinates) {
    // K*C = 3 < M = 5: the projector must still be the pseudo-inverse (minimum-norm solution).
    const pmsc::Model model = makeModel(30, 3, 5, {7});
    const Eigen::MatrixXd bk = pmsc::gatherKeyRows(model.basis, 3, model.keyPoints);
    const Eigen::MatrixXd pinv = bk.completeOrthogonalDecomposition().pseudoInverse();
    EXPECT_LT((model.projector - pinv).norm(), 1e-12);
    EXPECT_LT((bk * model.projector - Eigen::MatrixXd::Identity(3, 3)).norm(), 1e-10);
}

TEST(Model, ValidateNamesTheProblem) {
    pmsc::Model model = makeModel(20, 3, 3, {0, 4, 8});
    EXPECT_NO_THROW(model.validate());
    auto expectThrowContaining = [](const pmsc::Model& m, const std::string& needle) {
        try {
            m.validate();
            ADD_FAILURE() << "no throw, expected " << needle;
        } catch (const std::invalid_argument& e) {
            EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
        }
    };
    pmsc::Model bad = model;
    bad.keyPoints = {0, 4, 4};
    expectThrowContaining(bad, "repeated");
    bad = model;
    bad.keyPoints = {0, 4, 20};
    expectThrowContaining(bad, "outside");
    bad = model;
    bad.epsMin = 0.2;
    expectThrowContaining(bad, "eps_min");
    bad = model;
    bad.mean.resize(5);
    expectThrowContaining(bad, "mean");
    bad = model;
    bad.projector.resize(3, 6);
    expectThrowContaining(bad, "projector");
    bad = model;
    bad.basis(3, 1) = std::numeric_limits<double>::quiet_NaN();
    expectThrowContaining(bad, "NaN");
}

TEST(Model, EnergyCaptured) {
    pmsc::Model model = makeModel(20, 3, 3, {0, 4, 8});
    model.singularValues = Eigen::Vector3d(3, 2, 1);
    model.totalEnergy = 28;
    EXPECT_NEAR(model.energyCaptured(), 14.0 / 28.0, 1e-15);
}

TEST(KeyError, NamesRoundTripAndOthersAreRefused) {
    for (const auto norm :
         {pmsc::KeyErrorNorm::Rms, pmsc::KeyErrorNorm::Largest, pmsc::KeyErrorNorm::LeaveOneOut})
        EXPECT_EQ(pmsc::keyErrorNormNamed(pmsc::toString(norm)), norm);
    EXPECT_EQ(std::string(pmsc::toString(pmsc::KeyErrorNorm::LeaveOneOut)), "loo");
    EXPECT_EQ(pmsc::keyErrorNormNamed("RMS"), std::nullopt);
    EXPECT_EQ(pmsc::keyErrorNormNamed(""), std::nullopt);
}
