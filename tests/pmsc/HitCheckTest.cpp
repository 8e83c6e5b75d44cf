// The check of a hit one part of the predicted error alone certifies (HitCheck.h) and the points
// it reads near the keys (KeyNeighbours.h) and over what training saw move (Sentinels.h).
#include "pmsc/HitCheck.h"
#include "pmsc/KeyNeighbours.h"
#include "pmsc/Learning.h"
#include "pmsc/ModelIO.h"
#include "pmsc/Sentinels.h"
#include "pmsc/Training.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <stdexcept>
#include <vector>

namespace {

using pmsc::Index;
using pmsc::Model;

/// A 30 x 30 sheet in the unit square (3 channels: positions) waving in three smooth modes, or,
/// with `light`, values far larger than the sheet's extent (not a shape).
pmsc::FrameSet sheetFrames(Index frames, bool light = false) {
    constexpr Index side = 30;
    pmsc::FrameSet set(frames, side * side, 3);
    for (Index f = 0; f < frames; ++f) {
        const double a = std::sin(0.31 * double(f)), b = std::cos(0.17 * double(f) + 1),
                     c = std::sin(0.07 * double(f) + 2);
        for (Index p = 0; p < side * side; ++p) {
            const double x = double(p % side) / double(side - 1), y = double(p / side) / double(side - 1);
            double* v = set.frame(f) + 3 * p;
            v[0] = x + 0.02 * c * x * y;
            v[1] = y;
            v[2] = 0.1 * a * std::sin(3.14159 * x) + 0.1 * b * std::cos(3.14159 * y) + 0.05 * c * x;
            if (light) {
                for (int ch = 0; ch < 3; ++ch) v[ch] = 10 * (a * x + b * y + c) + double(ch);
            }
        }
    }
    return set;
}

/// The same sheet, bent a little and turned about z through +-2 radians: a shape whose frames are
/// surfaces (each point keeps its distance to its neighbours) but whose mean folds the sheet together.
pmsc::FrameSet turningSheetFrames(Index frames) {
    constexpr Index side = 30;
    pmsc::FrameSet set(frames, side * side, 3);
    for (Index f = 0; f < frames; ++f) {
        const double angle = 2 * std::sin(0.37 * double(f)), bend = 0.1 * std::cos(0.23 * double(f));
        for (Index p = 0; p < side * side; ++p) {
            const double x = double(p % side) / double(side - 1), y = double(p / side) / double(side - 1);
            double* v = set.frame(f) + 3 * p;
            v[0] = std::cos(angle) * x - std::sin(angle) * y;
            v[1] = std::sin(angle) * x + std::cos(angle) * y;
            v[2] = bend * std::sin(3.14159 * x);
        }
    }
    return set;
}

Model trainSheet(bool light = false, double tolerance = 0.01, Index regions = 0, Index sentinels = 0) {
    pmsc::TrainingOptions o;
    o.regions.count = regions;
    o.sentinels = sentinels;
    o.basis = 3;
    o.maxKeys = 12;
    o.tolerance = tolerance;
    return pmsc::train(sheetFrames(60, light), o);
}

/// The key values of frame 60 of the sheet, a frame no model here trained on (K*C values).
std::vector<double> unseenKeys(const Model& m) {
    const pmsc::FrameSet frames = sheetFrames(61);
    const Index c = m.channels;
    std::vector<double> keys(size_t(m.keyCount() * c));
    for (Index i = 0; i < m.keyCount(); ++i)
        for (Index ch = 0; ch < c; ++ch)
            keys[size_t(i * c + ch)] = frames.frame(60)[m.keyPoints[size_t(i)] * c + ch];
    return keys;
}

TEST(KeyNeighbours, AreTheNearestPointsThatAreNotKeysNearestFirst) {
    Eigen::MatrixXd line = Eigen::MatrixXd::Zero(10, 3);
    for (Index i = 0; i < 10; ++i) line(i, 0) = double(i);
    const std::vector<Index> keys = {0, 5, 6};
    const pmsc::KeyNeighbours near = pmsc::nearestToKeys(line, keys, 2, true);
    EXPECT_EQ(near.perKey, 2);
    EXPECT_TRUE(near.fromMean);
    // Key 5: 4 at 1, then 3 and 7 at 2 (the lower index first); key 6: 7, then 4 and 8 at 2.
    EXPECT_EQ(near.points, (std::vector<Index>{1, 2, 4, 3, 7, 4}));
}

TEST(KeyNeighbours, RejectBadArguments) {
    const Eigen::MatrixXd points = Eigen::MatrixXd::Random(5, 3);
    const std::vector<Index> keys = {0, 1};
    EXPECT_THROW(pmsc::nearestToKeys(points, keys, 0, true), std::invalid_argument);
    EXPECT_THROW(pmsc::nearestToKeys(points, keys, 4, true), std::invalid_argument);  // only 3 non-key points
    EXPECT_THROW(pmsc::nearestToKeys(points, std::vector<Index>{7}, 1, true), std::invalid_argument);
    EXPECT_THROW(pmsc::nearestToKeys(Eigen::MatrixXd::Zero(5, 2), keys, 1, true), std::invalid_argument);
}

TEST(KeyNeighbours, TrainingKeepsThemForAShapeWithAPredictedKeyErrorOnly) {
    const Model shape = trainSheet();
    ASSERT_EQ(shape.keyErrorNorm, pmsc::KeyErrorNorm::Predicted);
    ASSERT_TRUE(shape.keyNeighbours.has_value());
    EXPECT_EQ(shape.keyNeighbours->perKey, pmsc::kNeighboursPerKey);
    EXPECT_TRUE(shape.keyNeighbours->fromMean);
    EXPECT_NO_THROW(shape.validate());
    // Key 0's neighbours are the points of the mean nearest it, none of them a key.
    const Eigen::MatrixXd mean =
        Eigen::Map<const Eigen::MatrixXd>(shape.mean.data(), 3, shape.points).transpose();
    const std::set<Index> keys(shape.keyPoints.begin(), shape.keyPoints.end());
    const auto first = shape.keyNeighbours->of(0);
    const double farthest = (mean.row(first.back()) - mean.row(shape.keyPoints[0])).norm();
    for (const Index p : first) EXPECT_EQ(keys.count(p), 0u);
    Index closer = 0;
    for (Index p = 0; p < shape.points; ++p)
        if (!keys.count(p) && (mean.row(p) - mean.row(shape.keyPoints[0])).norm() < farthest - 1e-12)
            ++closer;
    EXPECT_LE(closer, pmsc::kNeighboursPerKey);

    EXPECT_FALSE(trainSheet(true).keyNeighbours.has_value()) << "light is not a shape";
    EXPECT_FALSE(trainSheet(false, 0).keyNeighbours.has_value())
        << "no tolerance: the key RMS, nothing to check";
}

/// A model whose predicted error's parts always disagree (the RMS part certifies every frame, the
/// leave-one-out part none), so every hit is checked.
Model disagreeing() {
    Model m = trainSheet();
    m.partEps.rms = 1e6;
    m.partEps.loo = 1e-12;
    return m;
}

TEST(HitCheck, ChecksOnlyHitsWhosePartsDisagree) {
    const Model m = disagreeing();
    const pmsc::PointMultiplier pm(m);
    const pmsc::HitCheck check(m, pm);
    EXPECT_TRUE(check.available());
    EXPECT_TRUE(check.needed({pmsc::CacheState::Hit, 0}, {1, 1}));
    EXPECT_FALSE(check.needed({pmsc::CacheState::Blend, 0.5}, {1, 1}));
    EXPECT_FALSE(check.needed({pmsc::CacheState::Hit, 0}, {1, 1e-13})) << "both parts certify";
    Model rms = m;
    rms.keyErrorNorm = pmsc::KeyErrorNorm::Rms;
    const pmsc::PointMultiplier pmRms(rms);
    EXPECT_FALSE(pmsc::HitCheck(rms, pmRms).available());
    Model bare = m;
    bare.keyNeighbours.reset();
    const pmsc::PointMultiplier pmBare(bare);
    EXPECT_FALSE(pmsc::HitCheck(bare, pmBare).available()) << "nothing to check at";
}

TEST(HitCheck, ReadsTheNeighboursOfTheKeysWithTheLargestResidualsAndHoldsPmToTheTolerance) {
    const Model m = disagreeing();
    const pmsc::PointMultiplier pm(m);
    const pmsc::HitCheck check(m, pm);
    const Index c = m.channels;
    std::vector<double> keys = unseenKeys(m), coords(size_t(m.coordCount()));
    // Key 5 off by far more than the fit can absorb: its neighbours are among the points checked.
    keys[size_t(5 * c + 2)] += 1.0;
    pm.project(keys.data(), coords.data());
    const std::vector<Index> points = check.points(keys.data(), coords.data(), {1, 1});
    EXPECT_TRUE(std::is_sorted(points.begin(), points.end()));
    EXPECT_EQ(std::adjacent_find(points.begin(), points.end()), points.end());
    EXPECT_LE(Index(points.size()), pmsc::kCheckedKeys * pmsc::kNeighboursPerKey);
    for (const Index p : m.keyNeighbours->of(5))
        EXPECT_TRUE(std::binary_search(points.begin(), points.end(), p)) << p;

    // PM's own values pass; one value 0.95 T away fails; one 0.85 T away passes.
    std::vector<double> values(points.size() * size_t(c));
    pm.reconstructPoints(coords.data(), points, values.data());
    EXPECT_TRUE(check.passes(coords.data(), points, values.data()));
    values[1] += 0.85 * m.tolerance;
    EXPECT_TRUE(check.passes(coords.data(), points, values.data()));
    values[1] += 0.10 * m.tolerance;
    EXPECT_FALSE(check.passes(coords.data(), points, values.data()));
    values[1] = std::nan("");
    EXPECT_FALSE(check.passes(coords.data(), points, values.data()));
}

TEST(HitCheck, HoldsPmCloserAtTheRegionKeysThanAtTheNeighbours) {
    Model m = trainSheet(false, 0.01, 8);
    ASSERT_TRUE(m.regions.has_value());
    ASSERT_FALSE(m.regions->extraKeyPoints.empty()) << "regions holding few keys get keys of their own";
    m.partEps = {1e6, 1e-12};
    const pmsc::PointMultiplier pm(m);
    const pmsc::HitCheck check(m, pm);
    const Index c = m.channels;
    std::vector<double> keys = unseenKeys(m), coords(size_t(m.coordCount()));
    pm.project(keys.data(), coords.data());
    const std::vector<Index> points = check.points(keys.data(), coords.data(), {1, 1});
    std::vector<double> values(points.size() * size_t(c));
    pm.reconstructPoints(coords.data(), points, values.data());
    const auto& regionKeys = m.regions->extraKeyPoints;
    size_t regionKey = points.size(), neighbour = points.size();
    for (size_t i = 0; i < points.size(); ++i) {
        const bool isRegionKey =
            std::find(regionKeys.begin(), regionKeys.end(), points[i]) != regionKeys.end();
        (isRegionKey ? regionKey : neighbour) = i;
    }
    ASSERT_LT(regionKey, points.size());
    ASSERT_LT(neighbour, points.size());
    std::vector<double> off = values;
    off[neighbour * size_t(c)] += (pmsc::kConfirmedShare + 0.05) * m.tolerance;
    EXPECT_TRUE(check.passes(coords.data(), points, off.data())) << "within kNeighbourShare at a neighbour";
    off = values;
    off[regionKey * size_t(c)] += (pmsc::kConfirmedShare + 0.05) * m.tolerance;
    EXPECT_FALSE(check.passes(coords.data(), points, off.data())) << "over kConfirmedShare at a region key";
}

TEST(Sentinels, FarthestPointSamplingOfTheMovingPointsThatAreNotKeys) {
    // Points 0..9 on a line; 9 does not move, 4 is a key. The first is the point that moves most
    // (7), then the farthest from the chosen ones, the lower index on ties.
    Eigen::MatrixXd line = Eigen::MatrixXd::Zero(10, 3);
    for (Index i = 0; i < 10; ++i) line(i, 0) = double(i);
    Eigen::VectorXd motion = Eigen::VectorXd::Ones(10);
    motion[7] = 2;
    motion[9] = 0;
    const std::vector<Index> keys = {4};
    constexpr auto mean = pmsc::SentinelSource::Mean;
    const pmsc::Sentinels s = pmsc::farthestPointSentinels(line, motion, keys, 3, mean);
    EXPECT_EQ(s.points, (std::vector<Index>{7, 0, 3}));
    EXPECT_DOUBLE_EQ(s.coveringRadius, 2.0) << "point 5 is 2 from 3 and from 7";
    EXPECT_EQ(s.source, mean);
    EXPECT_EQ(pmsc::farthestPointSentinels(line, motion, keys, 100, mean).points.size(), 8u)
        << "at most the moving points that are not keys";
    EXPECT_TRUE(pmsc::farthestPointSentinels(line, Eigen::VectorXd::Zero(10), keys, 3, mean).points.empty());
    EXPECT_THROW(pmsc::farthestPointSentinels(line, Eigen::VectorXd::Ones(9), keys, 3, mean),
                 std::invalid_argument);
    EXPECT_THROW(pmsc::farthestPointSentinels(line, motion, std::vector<Index>{10}, 3, mean),
                 std::invalid_argument);
}

TEST(Sentinels, WithoutPositionsOneIsDrawnInEachEqualRunOfTheMovingPoints) {
    // 100 points; 0-9 do not move, 50 is a key: 89 moving points, 10 runs of 8 or 9.
    Eigen::VectorXd motion = Eigen::VectorXd::Ones(100);
    motion.head(10).setZero();
    const std::vector<Index> keys = {50};
    const pmsc::Sentinels s = pmsc::pointOrderSentinels(motion, keys, 10, 7);
    EXPECT_EQ(s.source, pmsc::SentinelSource::PointOrder);
    ASSERT_EQ(s.points.size(), 10u);
    std::vector<Index> pool;
    for (Index p = 10; p < 100; ++p)
        if (p != 50) pool.push_back(p);
    for (Index r = 0; r < 10; ++r) {
        const Index p = s.points[size_t(r)];
        const Index begin = pool[size_t(r * 89 / 10)], last = pool[size_t((r + 1) * 89 / 10 - 1)];
        EXPECT_GE(p, begin) << "run " << r;
        EXPECT_LE(p, last) << "run " << r;
        EXPECT_NE(p, 50) << "a key's error is a fit";
    }
    EXPECT_DOUBLE_EQ(s.coveringRadius, 9.0) << "the longest run";
    EXPECT_EQ(pmsc::pointOrderSentinels(motion, keys, 10, 7).points, s.points)
        << "the same seed, the same draw";
    EXPECT_NE(pmsc::pointOrderSentinels(motion, keys, 10, 8).points, s.points);
    EXPECT_EQ(pmsc::pointOrderSentinels(motion, keys, 1000, 7).points.size(), 89u)
        << "at most the moving points";
    EXPECT_THROW(pmsc::pointOrderSentinels(motion, std::vector<Index>{100}, 3, 7), std::invalid_argument);
}

TEST(Sentinels, TrainingSpreadsThemOverAShapeWithAPredictedKeyError) {
    const Model m = trainSheet(false, 0.01, 0, 40);
    ASSERT_TRUE(m.sentinels.has_value());
    EXPECT_EQ(m.sentinels->points.size(), 40u);
    EXPECT_EQ(trainSheet(false, 0.01, 0, 1000).sentinels->points.size(), size_t(900 / pmsc::kSentinelSpacing))
        << "at most one point in kSentinelSpacing";
    EXPECT_EQ(pmsc::sentinelCount(1024, 26719), 1024);
    EXPECT_EQ(pmsc::sentinelCount(1024, 2592), 162);
    EXPECT_GT(m.sentinels->coveringRadius, 0.0);
    EXPECT_NO_THROW(m.validate());
    const std::set<Index> keys(m.keyPoints.begin(), m.keyPoints.end());
    for (const Index p : m.sentinels->points) EXPECT_EQ(keys.count(p), 0u) << "a key's error is a fit";
    // Every point of the sheet's mean that is not a key is within the covering radius of a
    // sentinel (a key's error is the key error, a fit: the covering leaves keys out, and which
    // points are keys depends on the machine's rounding).
    const Eigen::MatrixXd mean = Eigen::Map<const Eigen::MatrixXd>(m.mean.data(), 3, m.points).transpose();
    for (Index p = 0; p < m.points; ++p) {
        if (keys.count(p) != 0) continue;
        double nearest = 1e300;
        for (const Index s : m.sentinels->points)
            nearest = std::min(nearest, (mean.row(p) - mean.row(s)).norm());
        EXPECT_LE(nearest, m.sentinels->coveringRadius + 1e-12) << p;
    }
    // The model file keeps them.
    const Model back = pmsc::decodeModel(pmsc::encodeModel(m), "sentinels");
    ASSERT_TRUE(back.sentinels.has_value());
    EXPECT_EQ(back.sentinels->points, m.sentinels->points);
    EXPECT_DOUBLE_EQ(back.sentinels->coveringRadius, m.sentinels->coveringRadius);

    const Model light = trainSheet(true, 0.01, 0, 20);
    ASSERT_TRUE(light.sentinels.has_value()) << "light without positions: drawn in point order";
    EXPECT_EQ(light.sentinels->source, pmsc::SentinelSource::PointOrder);
    EXPECT_EQ(light.sentinels->points.size(), size_t(pmsc::kPointOrderFactor * 20)) << "a draw: more of them";
    EXPECT_FALSE(trainSheet(false, 0, 0, 40).sentinels.has_value()) << "no tolerance: nothing to check";
    EXPECT_FALSE(trainSheet(false, 0.01, 0, 0).sentinels.has_value()) << "--sentinels 0";
}

TEST(Sentinels, AFrameIsTheShapeOfDataThatDeformAsASurfaceDoes) {
    // frame f = mean + basis * coefficients.col(f): here the basis is the centred frames and the
    // coefficients the identity, so every frame is as near the mean and the first one is taken.
    const auto shapeOf = [](const pmsc::FrameSet& frames) {
        const Eigen::MatrixXd x = frames.matrix();
        const Eigen::VectorXd mean = x.rowwise().mean();
        const Eigen::MatrixXd centred = x.colwise() - mean;
        return pmsc::frameShape(mean, centred, Eigen::MatrixXd::Identity(frames.frames, frames.frames));
    };
    const pmsc::FrameSet turning = turningSheetFrames(40);
    const Eigen::MatrixXd shape = shapeOf(turning);
    ASSERT_EQ(shape.rows(), 900);
    ASSERT_EQ(shape.cols(), 3);
    const Eigen::MatrixXd first = Eigen::Map<const Eigen::MatrixXd>(turning.frame(0), 3, 900).transpose();
    EXPECT_LT((shape - first).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_EQ(shapeOf(sheetFrames(40, true)).size(), 0)
        << "light: neighbours in one frame are not in the next";
    // Stretched: the sheet's x axis scaled by 1 to 3 over the frames is no surface either.
    pmsc::FrameSet stretched = turningSheetFrames(40);
    for (Index f = 0; f < 40; ++f)
        for (Index p = 0; p < 900; ++p) stretched.frame(f)[3 * p] *= 2 + std::sin(0.5 * double(f));
    EXPECT_EQ(shapeOf(stretched).size(), 0);
    EXPECT_THROW(
        pmsc::frameShape(Eigen::VectorXd::Zero(9), Eigen::MatrixXd::Zero(8, 2), Eigen::MatrixXd::Zero(2, 4)),
        std::invalid_argument);
    EXPECT_EQ(
        pmsc::frameShape(Eigen::VectorXd::Zero(9), Eigen::MatrixXd::Zero(9, 2), Eigen::MatrixXd::Zero(2, 0))
            .size(),
        0)
        << "no frames";
}

/// Options of a learnable model with 40 sentinels and no regions.
pmsc::TrainingOptions learnableWithSentinels(Index basis, Index keys) {
    pmsc::TrainingOptions o;
    o.basis = basis;
    o.maxKeys = keys;
    o.tolerance = 0.01;
    o.regions.count = 0;
    o.sentinels = 40;
    o.learnable = true;
    return o;
}

TEST(Sentinels, TrainingSpreadsThemOverATrainingFrameWhenTheMeanIsNoShape) {
    const Model m = pmsc::train(turningSheetFrames(60), learnableWithSentinels(6, 24));
    ASSERT_TRUE(m.sentinels.has_value());
    EXPECT_EQ(m.sentinels->source, pmsc::SentinelSource::Frame);
    EXPECT_EQ(m.sentinels->points.size(), 40u) << "a covering, not a draw: as many as asked";
    // 40 farthest-point samples of a unit sheet are about 0.1-0.2 apart; over the mean, which folds
    // the turning sheet towards its centre, they would be much closer.
    EXPECT_GT(m.sentinels->coveringRadius, 0.08);
    EXPECT_LT(m.sentinels->coveringRadius, 0.3);
    EXPECT_NO_THROW(m.validate());
    const Model learned = pmsc::learn(m, turningSheetFrames(90));
    ASSERT_TRUE(learned.sentinels.has_value());
    EXPECT_EQ(learned.sentinels->source, pmsc::SentinelSource::Frame) << "chosen again from a new frame";
    EXPECT_EQ(learned.sentinels->points.size(), 40u);
    EXPECT_NO_THROW(learned.validate());
    // A model whose mean was a shape, learned with frames that turn the sheet: the learned mean
    // folds the sheet, so learn chooses as training would, from a new frame.
    const Model flat = pmsc::train(sheetFrames(60), learnableWithSentinels(3, 12));
    ASSERT_TRUE(flat.sentinels.has_value());
    ASSERT_EQ(flat.sentinels->source, pmsc::SentinelSource::Mean);
    const Model turned = pmsc::learn(flat, turningSheetFrames(90));
    ASSERT_TRUE(turned.sentinels.has_value());
    EXPECT_EQ(turned.sentinels->source, pmsc::SentinelSource::Frame);
    EXPECT_NO_THROW(turned.validate());
}

TEST(Sentinels, LearnChoosesThemAgainFromTheLearnedMeanAndBasis) {
    const Model m = pmsc::train(sheetFrames(60), learnableWithSentinels(3, 12));
    ASSERT_TRUE(m.sentinels.has_value());
    const Model learned = pmsc::learn(m, sheetFrames(90));
    ASSERT_TRUE(learned.sentinels.has_value());
    EXPECT_EQ(learned.sentinels->points.size(), m.sentinels->points.size());
    EXPECT_EQ(learned.sentinels->source, pmsc::SentinelSource::Mean);
    const std::set<Index> keys(learned.keyPoints.begin(), learned.keyPoints.end());
    for (const Index p : learned.sentinels->points) EXPECT_EQ(keys.count(p), 0u) << p;
    EXPECT_NO_THROW(learned.validate());
}

/// The light sheet's points where they lie: the unit square at z = 0 (what train --positions takes).
Eigen::MatrixXd sheetPositions() {
    constexpr Index side = 30;
    Eigen::MatrixXd at = Eigen::MatrixXd::Zero(side * side, 3);
    for (Index p = 0; p < side * side; ++p) {
        at(p, 0) = double(p % side) / double(side - 1);
        at(p, 1) = double(p / side) / double(side - 1);
    }
    return at;
}

/// Light sheet frames [first, first + frames) plus, with `corner`, a ripple in the corner x, y >
/// 0.6 that frames without it never show.
pmsc::FrameSet lightSheetFrames(Index first, Index frames, bool corner) {
    const pmsc::FrameSet all = sheetFrames(first + frames, true);
    pmsc::FrameSet set(frames, all.points, 3);
    std::copy(all.frame(first), all.frame(first) + set.values.size(), set.values.begin());
    if (!corner) return set;
    const Eigen::MatrixXd at = sheetPositions();
    for (Index f = 0; f < frames; ++f)
        for (Index p = 0; p < set.points; ++p)
            if (at(p, 0) > 0.6 && at(p, 1) > 0.6)
                for (Index ch = 0; ch < 3; ++ch)
                    set.frame(f)[3 * p + ch] += 5 * std::sin(0.9 * double(first + f)) *
                                                std::sin(9 * at(p, 0)) * std::cos(7 * at(p, 1));
    return set;
}

TEST(Sentinels, LearnChoosesThemAgainFromTheGivenPositionsOrKeepsTheOldOnesLessTheNewKeys) {
    pmsc::TrainingOptions o = learnableWithSentinels(3, 12);
    o.regions.positions = sheetPositions();
    const Model m = pmsc::train(lightSheetFrames(0, 60, false), o);
    ASSERT_TRUE(m.sentinels.has_value());
    ASSERT_EQ(m.sentinels->source, pmsc::SentinelSource::Given);
    const pmsc::FrameSet corner = lightSheetFrames(60, 60, true);

    // Without the positions: the old sentinels less those that became keys, a valid model that
    // reads back from its file, and a warning.
    pmsc::LearnReport report;
    const Model kept = pmsc::learn(m, corner, {}, &report);
    ASSERT_TRUE(kept.sentinels.has_value());
    const std::set<Index> keys(kept.keyPoints.begin(), kept.keyPoints.end());
    Index lost = 0;
    for (const Index p : m.sentinels->points) lost += keys.count(p) ? 1 : 0;
    ASSERT_GT(lost, 0) << "the case this test is for: sentinels that became keys";
    EXPECT_EQ(kept.sentinels->points.size() + size_t(lost), m.sentinels->points.size());
    for (const Index p : kept.sentinels->points) EXPECT_EQ(keys.count(p), 0u) << p;
    EXPECT_GT(kept.sentinels->coveringRadius, m.sentinels->coveringRadius);
    EXPECT_NO_THROW(kept.validate());
    EXPECT_NO_THROW(pmsc::decodeModel(pmsc::encodeModel(kept), "kept"));
    EXPECT_TRUE(std::any_of(report.warnings.begin(), report.warnings.end(), [](const std::string& w) {
        return w.find("--positions") != std::string::npos && w.find("sentinels") != std::string::npos;
    }));

    // With them: chosen again as training would from the learned model's motion, and the key
    // neighbours with them.
    pmsc::LearnOptions given;
    given.positions = sheetPositions();
    const Model again = pmsc::learn(m, corner, given);
    ASSERT_TRUE(again.sentinels.has_value());
    const pmsc::Sentinels expected =
        pmsc::farthestPointSentinels(given.positions, pmsc::basisMotion(again), again.keyPoints,
                                     Index(m.sentinels->points.size()), pmsc::SentinelSource::Given);
    EXPECT_EQ(again.sentinels->points, expected.points);
    EXPECT_EQ(again.sentinels->neighbours, expected.neighbours);
    EXPECT_DOUBLE_EQ(again.sentinels->coveringRadius, expected.coveringRadius);
    if (m.keyNeighbours) {
        ASSERT_TRUE(again.keyNeighbours.has_value());
        EXPECT_FALSE(again.keyNeighbours->fromMean);
        EXPECT_EQ(
            again.keyNeighbours->points,
            pmsc::nearestToKeys(given.positions, again.keyPoints, m.keyNeighbours->perKey, false).points);
    }
    EXPECT_NO_THROW(again.validate());

    // Positions that are not the model's points, or for a model that took nothing from positions.
    pmsc::LearnOptions wrong;
    wrong.positions = Eigen::MatrixXd::Zero(m.points + 1, 3);
    EXPECT_THROW(pmsc::learn(m, corner, wrong), pmsc::InputError);
    wrong.positions = sheetPositions();
    wrong.positions(7, 1) = std::nan("");
    EXPECT_THROW(pmsc::learn(m, corner, wrong), pmsc::InputError);
    const Model fromMean = pmsc::train(sheetFrames(60), learnableWithSentinels(3, 12));
    EXPECT_THROW(pmsc::learn(fromMean, sheetFrames(90), given), pmsc::InputError);
}

TEST(Sentinels, WithoutPointsKeepsEachOnesNearestAndBoundsTheCoveringRadius) {
    // 400 points spread in the unit cube, all moving; 40 farthest-point sentinels.
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> unit(0, 1);
    Eigen::MatrixXd at(400, 3);
    for (Index p = 0; p < at.rows(); ++p)
        for (Index k = 0; k < 3; ++k) at(p, k) = unit(rng);
    const Eigen::VectorXd motion = Eigen::VectorXd::Ones(at.rows());
    const pmsc::Sentinels s =
        pmsc::farthestPointSentinels(at, motion, std::vector<Index>{}, 40, pmsc::SentinelSource::Given);
    ASSERT_EQ(s.perSentinel, pmsc::kSentinelNeighbours);
    EXPECT_EQ(pmsc::withoutPoints(s, std::vector<Index>{}).points, s.points) << "nothing removed";

    // Remove sentinel 3 and every one of its neighbours but the farthest, and two more.
    std::vector<Index> removed = {s.points[3], s.points[20], s.points[31]};
    for (Index k = 0; k + 1 < s.perSentinel; ++k)
        removed.push_back(s.points[size_t(s.neighbours[size_t(3 * 6 + k)])]);
    const pmsc::Sentinels out = pmsc::withoutPoints(s, removed);
    std::vector<Index> keptPoints;
    for (const Index p : s.points)
        if (std::find(removed.begin(), removed.end(), p) == removed.end()) keptPoints.push_back(p);
    ASSERT_EQ(out.points, keptPoints);
    ASSERT_GT(out.perSentinel, 0);
    EXPECT_LT(out.perSentinel, s.perSentinel) << "some kept sentinel lost a neighbour";
    ASSERT_EQ(out.neighbours.size(), out.points.size() * size_t(out.perSentinel));
    // Each list: the nearest kept sentinels, nearest first, at their distances.
    const auto count = static_cast<Index>(out.points.size());
    for (Index i = 0; i < count; ++i) {
        std::vector<double> all;
        for (Index j = 0; j < count; ++j)
            if (j != i) all.push_back((at.row(out.points[size_t(i)]) - at.row(out.points[size_t(j)])).norm());
        std::sort(all.begin(), all.end());
        for (Index k = 0; k < out.perSentinel; ++k) {
            const size_t n = size_t(i * out.perSentinel + k);
            const Index j = out.neighbours[n];
            ASSERT_NE(j, i);
            EXPECT_NEAR(out.neighbourDistances[n],
                        (at.row(out.points[size_t(i)]) - at.row(out.points[size_t(j)])).norm(), 1e-12);
            EXPECT_NEAR(out.neighbourDistances[n], all[size_t(k)], 1e-12);
        }
    }
    // The covering radius bounds every point's distance to its nearest kept sentinel.
    double farthest = 0;
    for (Index p = 0; p < at.rows(); ++p) {
        double nearest = std::numeric_limits<double>::infinity();
        for (const Index q : out.points) nearest = std::min(nearest, (at.row(p) - at.row(q)).norm());
        farthest = std::max(farthest, nearest);
    }
    EXPECT_GT(farthest, s.coveringRadius) << "the case this test is for: the radius grew";
    EXPECT_GE(out.coveringRadius, farthest);

    // Two pairs, each the other's only neighbour: a removed pair reaches no kept sentinel, nothing
    // bounds the radius, and the slope check goes (each sentinel's own check stays).
    pmsc::Sentinels pairs;
    pairs.points = {10, 11, 20, 21};
    pairs.coveringRadius = 1;
    pairs.perSentinel = 1;
    pairs.neighbours = {1, 0, 3, 2};
    pairs.neighbourDistances = {1, 1, 1, 1};
    const pmsc::Sentinels lone = pmsc::withoutPoints(pairs, std::vector<Index>{10, 11});
    EXPECT_EQ(lone.points, (std::vector<Index>{20, 21}));
    EXPECT_EQ(lone.perSentinel, 0);
    EXPECT_TRUE(lone.neighbours.empty());
}

TEST(Sentinels, EveryHitComputesThemAndTheyHoldPmWithinTheirShareOfTheTolerance) {
    Model m = trainSheet(false, 0.01, 0, 40);
    const pmsc::PointMultiplier pm(m);
    const pmsc::HitCheck check(m, pm);
    ASSERT_TRUE(check.available());
    const pmsc::PredictedParts agree{0, 0};
    ASSERT_FALSE(pmsc::partsDisagree(agree, m.partEps));
    EXPECT_TRUE(check.needed({pmsc::CacheState::Hit, 0}, agree)) << "a hit both parts certify is checked too";
    EXPECT_FALSE(check.needed({pmsc::CacheState::Blend, 0.5}, agree));
    const Index c = m.channels;
    std::vector<double> keys = unseenKeys(m), coords(size_t(m.coordCount()));
    pm.project(keys.data(), coords.data());
    const std::vector<Index> points = check.points(keys.data(), coords.data(), agree);
    std::vector<Index> sorted = m.sentinels->points;
    std::sort(sorted.begin(), sorted.end());
    EXPECT_EQ(points, sorted) << "parts that agree: the sentinels alone";
    const std::vector<Index> both = check.points(keys.data(), coords.data(), {1e9, 0});
    EXPECT_GT(both.size(), points.size()) << "parts that disagree: the key neighbours too";
    for (const Index p : points) EXPECT_TRUE(std::binary_search(both.begin(), both.end(), p));

    std::vector<double> values(points.size() * size_t(c));
    pm.reconstructPoints(coords.data(), points, values.data());
    EXPECT_TRUE(check.passes(coords.data(), points, values.data()));
    // The same error at every sentinel: no slope, so the share alone decides.
    for (size_t i = 0; i < points.size(); ++i)
        values[i * size_t(c)] += (pmsc::kSentinelShare - 0.05) * m.tolerance;
    EXPECT_TRUE(check.passes(coords.data(), points, values.data()));
    values[2 * size_t(c)] += 0.1 * m.tolerance;
    EXPECT_FALSE(check.passes(coords.data(), points, values.data())) << "over kSentinelShare at a sentinel";
}

TEST(Sentinels, EachKeepsItsNearestSentinelsInTheModelFile) {
    Model m = trainSheet(false, 0.01, 0, 40);
    const pmsc::Sentinels& s = *m.sentinels;
    ASSERT_EQ(s.perSentinel, pmsc::kSentinelNeighbours);
    ASSERT_EQ(s.neighbours.size(), s.points.size() * size_t(s.perSentinel));
    const Eigen::MatrixXd mean = Eigen::Map<const Eigen::MatrixXd>(m.mean.data(), 3, m.points).transpose();
    auto distance = [&](Index a, Index b) {
        return (mean.row(s.points[size_t(a)]) - mean.row(s.points[size_t(b)])).norm();
    };
    const auto count = static_cast<Index>(s.points.size());
    for (Index i = 0; i < count; ++i) {
        std::vector<double> all;
        for (Index j = 0; j < count; ++j)
            if (j != i) all.push_back(distance(i, j));
        std::sort(all.begin(), all.end());
        for (Index k = 0; k < s.perSentinel; ++k) {
            const size_t at = size_t(i * s.perSentinel + k);
            EXPECT_NE(s.neighbours[at], i);
            EXPECT_NEAR(s.neighbourDistances[at], distance(i, s.neighbours[at]), 1e-12);
            EXPECT_NEAR(s.neighbourDistances[at], all[size_t(k)], 1e-12) << "the k-th nearest, nearest first";
            EXPECT_GE(s.neighbourDistances[at], s.coveringRadius - 1e-12)
                << "farthest-point samples are at least the covering radius apart";
        }
    }
    const Model back = pmsc::decodeModel(pmsc::encodeModel(m), "neighbours");
    EXPECT_EQ(back.sentinels->perSentinel, s.perSentinel);
    EXPECT_EQ(back.sentinels->neighbours, s.neighbours);
    EXPECT_EQ(back.sentinels->neighbourDistances, s.neighbourDistances);

    Model self = m;
    self.sentinels->neighbours[0] = 0;
    EXPECT_THROW(self.validate(), std::invalid_argument) << "a sentinel is not its own neighbour";
    Model shorter = m;
    shorter.sentinels->neighbourDistances.pop_back();
    EXPECT_THROW(shorter.validate(), std::invalid_argument);

    // Point order: the nearest runs (a sentinel in each, ascending), the distance between the runs
    // in points: runs apart times a run's length, whatever points the draw took inside them.
    const Model light = trainSheet(true, 0.01, 0, 20);
    const pmsc::Sentinels& o = *light.sentinels;
    ASSERT_EQ(o.perSentinel, pmsc::kSentinelNeighbours);
    ASSERT_EQ(o.neighbours.size(), o.points.size() * size_t(o.perSentinel));
    ASSERT_TRUE(std::is_sorted(o.points.begin(), o.points.end()));
    const auto runs = static_cast<Index>(o.points.size());
    for (Index i = 0; i < runs; ++i) {
        std::vector<Index> all;
        for (Index j = 0; j < runs; ++j)
            if (j != i) all.push_back(std::abs(j - i));
        std::sort(all.begin(), all.end());
        for (Index k = 0; k < o.perSentinel; ++k) {
            const size_t at = size_t(i * o.perSentinel + k);
            const Index apart = std::abs(o.neighbours[at] - i);
            EXPECT_EQ(apart, all[size_t(k)]) << "the k-th nearest run, nearest first";
            EXPECT_DOUBLE_EQ(o.neighbourDistances[at], double(apart) * o.coveringRadius);
        }
    }
    EXPECT_NO_THROW(light.validate());
}

TEST(Sentinels, TheSlopeCheckRefusesASentinelWellOverItsNeighbours) {
    Model m = trainSheet(false, 0.01, 0, 40);
    const pmsc::PointMultiplier pm(m);
    const pmsc::HitCheck check(m, pm);
    const pmsc::Sentinels& s = *m.sentinels;
    const Index c = m.channels;
    std::vector<double> keys = unseenKeys(m), coords(size_t(m.coordCount()));
    pm.project(keys.data(), coords.data());
    const std::vector<Index> points = check.points(keys.data(), coords.data(), {0, 0});
    std::vector<double> exact(points.size() * size_t(c));
    pm.reconstructPoints(coords.data(), points, exact.data());
    // The sentinel whose nearest sentinel is nearest: the steepest slope an error of its own makes.
    Index steep = 0;
    for (Index i = 1; i < static_cast<Index>(s.points.size()); ++i)
        if (s.neighbourDistances[size_t(i * s.perSentinel)] <
            s.neighbourDistances[size_t(steep * s.perSentinel)])
            steep = i;
    const double ratio = s.coveringRadius / s.neighbourDistances[size_t(steep * s.perSentinel)];
    ASSERT_GT(ratio, 0.7) << "the test needs a sentinel whose nearest is within 1/0.7 of the covering radius";
    const size_t row =
        size_t(std::lower_bound(points.begin(), points.end(), s.points[size_t(steep)]) - points.begin());
    auto withError = [&](double share) {
        std::vector<double> v = exact;
        v[row * size_t(c)] += share * m.tolerance;
        return v;
    };
    // e + 0.5 r e / d with e = 0.75 T and r / d > 0.7: over T.
    std::vector<double> v = withError(0.75);
    EXPECT_FALSE(check.passes(coords.data(), points, v.data()));
    EXPECT_EQ(check.offPoints(coords.data(), points, v.data()), std::vector<Index>{s.points[size_t(steep)]});
    // e = 0.6 T: at most 0.6 + 0.3 T.
    v = withError(0.6);
    EXPECT_TRUE(check.passes(coords.data(), points, v.data()))
        << "under 2/3 T a sentinel passes whatever its slope";
    // A check of this sentinel alone (a local frame's): no computed neighbour, no slope.
    const std::vector<Index> alone{s.points[size_t(steep)]};
    std::vector<double> one(static_cast<size_t>(c), 0.0);
    pm.reconstructPoints(coords.data(), alone, one.data());
    one[0] += 0.75 * m.tolerance;
    EXPECT_TRUE(check.passes(coords.data(), alone, one.data()));
}

/// The sheet trained with 40 sentinels, a one-part key error (the key RMS) and no regions; with
/// `shared`, its light version with the channels sharing the basis.
Model sheetWithSentinels(bool shared) {
    pmsc::TrainingOptions o;
    o.regions.count = 0;
    o.sentinels = 40;
    o.basis = 3;
    o.maxKeys = 12;
    o.tolerance = 0.01;
    o.keyErrorNorm = pmsc::KeyErrorNorm::Rms;
    o.sharedChannels = shared;
    return pmsc::train(sheetFrames(60, shared), o);
}

TEST(Sentinels, ModelsWhoseKeyErrorHasOnePartOrWhoseChannelsShareTheBasisCheckEveryHitAtThem) {
    const Model rms = sheetWithSentinels(false);
    ASSERT_TRUE(rms.sentinels.has_value());
    EXPECT_EQ(rms.sentinels->source, pmsc::SentinelSource::Mean);
    const Model shared = sheetWithSentinels(true);
    ASSERT_TRUE(shared.sentinels.has_value());
    EXPECT_EQ(shared.sentinels->source, pmsc::SentinelSource::PointOrder) << "shared channels: no mean shape";
    for (const Model* m : {&rms, &shared}) {
        const pmsc::PointMultiplier pm(*m);
        const pmsc::HitCheck check(*m, pm);
        ASSERT_TRUE(check.available());
        EXPECT_TRUE(check.needed({pmsc::CacheState::Hit, 0}, {1e9, 0}));
        std::vector<double> keys = unseenKeys(*m), coords(size_t(m->coordCount()));
        pm.project(keys.data(), coords.data());
        const std::vector<Index> points = check.points(keys.data(), coords.data(), {1e9, 0});
        EXPECT_EQ(points.size(), m->sentinels->points.size()) << "one part: the sentinels alone";
        std::vector<double> values(points.size() * size_t(m->channels));
        pm.reconstructPoints(coords.data(), points, values.data());
        EXPECT_TRUE(check.passes(coords.data(), points, values.data()));
        values[1] += 0.9 * m->tolerance;
        EXPECT_FALSE(check.passes(coords.data(), points, values.data()));
    }
}

// The check reconstructs PM at the sentinels from their rows gathered once; the sums are
// PointMultiplier::reconstructPoints' own, in its order, so with a tolerance of 1e-300 a check of
// values PM computed passes only when every value is reproduced to the last bit: all the sentinels,
// in another order, some of them, and sentinels among other points, with and without shared channels,
// and clamped at 0.
TEST(Sentinels, TheCheckReconstructsPmAtThemToTheLastBit) {
    Model separate = sheetWithSentinels(false), shared = sheetWithSentinels(true);
    Model clamped = separate;  // clamped at 0 as a light's model is: the check reads what a hit hands back
    clamped.nonNegative = true;
    for (Model* m : {&separate, &shared, &clamped}) {
        m->tolerance = 1e-300;
        const pmsc::PointMultiplier pm(*m);
        const pmsc::HitCheck check(*m, pm);
        std::vector<double> keys = unseenKeys(*m), coords(size_t(m->coordCount()));
        pm.project(keys.data(), coords.data());
        std::vector<Index> all(check.sentinels().begin(), check.sentinels().end());
        std::vector<Index> some, mixed = {0, 1, m->keyPoints[0]};
        for (size_t i = 0; i < all.size(); i += 3) some.push_back(all[i]);
        mixed.insert(mixed.end(), some.begin(), some.end());
        std::sort(mixed.begin(), mixed.end());
        mixed.erase(std::unique(mixed.begin(), mixed.end()), mixed.end());
        std::vector<Index> reversed(all.rbegin(), all.rend());  // the C API passes the model's order
        for (const std::vector<Index>* points : {&all, &reversed, &some, &mixed}) {
            std::vector<double> values(points->size() * size_t(m->channels));
            pm.reconstructPoints(coords.data(), *points, values.data());
            if (m == &clamped && points == &all) {
                EXPECT_EQ(*std::min_element(values.begin(), values.end()), 0.0) << "some value clamped";
            }
            EXPECT_TRUE(check.offPoints(coords.data(), *points, values.data()).empty())
                << points->size() << " points, shared " << m->sharedChannels;
            const size_t last = values.size() - 1;
            values[last] = values[last] == 0 ? 1e-100 : std::nextafter(values[last], 1e300);  // over 0.8 T
            // One bit off is off (and its sentinel neighbours with it, by the slope check).
            const std::vector<Index> off = check.offPoints(coords.data(), *points, values.data());
            EXPECT_NE(std::find(off.begin(), off.end(), points->back()), off.end());
        }
    }
}

}  // namespace
