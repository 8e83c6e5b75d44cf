#include "pmsc/Learning.h"

#include "Synthetic.h"
#include "pmsc/Calibration.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/RegionMultiplier.h"
#include "pmsc/Training.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

namespace {

using pmsc::Index;

constexpr Index kPatches = 6, kPointsPerPatch = 20, kChannels = 3;

// Frames [first, first + frames) of one shot of 6 independently moving patches (the same shapes
// throughout) plus white noise; `still` last patches do not move (the motion a first training
// never saw).
pmsc::FrameSet patches(Index first, Index frames, unsigned seed, Index still) {
    const pmsc::FrameSet shot = pmsc::test::patchFrames(kPatches, kPointsPerPatch, kChannels, 400, seed);
    pmsc::FrameSet set(frames, shot.points, shot.channels);
    set.matrix() = shot.matrix().middleCols(first, frames);
    auto q = set.matrix();
    q += 0.01 * pmsc::test::gaussian(set.rows(), frames, seed + 100 + static_cast<unsigned>(first));
    const Index firstStill = (kPatches - still) * kPointsPerPatch * kChannels;
    // Still at the shot's mean pose, so that stillness adds no offset direction of its own.
    for (Index row = firstStill; row < set.rows(); ++row)
        q.row(row).setConstant(shot.matrix().row(row).mean());
    return set;
}

pmsc::FrameSet join(const pmsc::FrameSet& a, const pmsc::FrameSet& b) {
    pmsc::FrameSet all(a.frames + b.frames, a.points, a.channels);
    std::copy(a.values.begin(), a.values.end(), all.values.begin());
    std::copy(b.values.begin(), b.values.end(),
              all.values.begin() + static_cast<std::ptrdiff_t>(a.values.size()));
    return all;
}

struct Errors {
    double keyRmsMax = 0, keyRmsMean = 0, pointMax = 0;
};

Errors errorsOn(const pmsc::Model& model, const pmsc::FrameSet& frames) {
    const pmsc::PointMultiplier pm(model);
    Errors e;
    std::vector<double> keys(static_cast<size_t>(model.keyCount() * kChannels)),
        coords(static_cast<size_t>(model.basisSize())), out(static_cast<size_t>(frames.rows()));
    for (Index f = 0; f < frames.frames; ++f) {
        const double* full = frames.frame(f);
        for (Index k = 0; k < model.keyCount(); ++k)
            for (Index c = 0; c < kChannels; ++c)
                keys[static_cast<size_t>(k * kChannels + c)] =
                    full[model.keyPoints[static_cast<size_t>(k)] * kChannels + c];
        pm.project(keys.data(), coords.data());
        const double rms = pm.keyError(keys.data(), coords.data());
        e.keyRmsMax = std::max(e.keyRmsMax, rms);
        e.keyRmsMean += rms / static_cast<double>(frames.frames);
        pm.reconstruct(coords.data(), out.data());
        for (Index p = 0; p < frames.points; ++p) {
            double d = 0;
            for (Index c = 0; c < kChannels; ++c)
                d += std::pow(out[static_cast<size_t>(p * kChannels + c)] - full[p * kChannels + c], 2);
            e.pointMax = std::max(e.pointMax, std::sqrt(d));
        }
    }
    return e;
}

pmsc::TrainingOptions options(Index learnRank) {
    pmsc::TrainingOptions o;
    o.basis = 6;
    o.maxKeys = 24;
    o.block = 6;
    o.tolerance = 0.2;
    o.learnRank = learnRank;
    o.calibrationRule = pmsc::CalibrationRule::Conformal;
    o.calibrationCoverage = 0.9;
    o.keyErrorNorm = pmsc::KeyErrorNorm::Rms;  // the predicted error's own test resets it
    return o;
}

}  // namespace

TEST(Learning, UpdateMatchesTrainingFromScratchOnTheUnion) {
    const pmsc::FrameSet day1 = patches(0, 80, 1, 2);     // patches 4 and 5 never move
    const pmsc::FrameSet misses = patches(80, 40, 1, 0);  // everything moves
    const pmsc::FrameSet heldOut = patches(200, 60, 1, 0);
    const pmsc::Model old = pmsc::train(day1, options(12));
    ASSERT_TRUE(old.learning.has_value());
    ASSERT_TRUE(old.calibrationRecord.has_value());
    EXPECT_EQ(old.calibrationRecord->keyRms.size(), 80u);

    pmsc::LearnReport report;
    const pmsc::Model learned = pmsc::learn(old, misses, {}, &report);
    const pmsc::Model scratch = pmsc::train(join(day1, misses), options(12));

    EXPECT_EQ(learned.trainFrames, 120);
    EXPECT_EQ(learned.basisSize(), scratch.basisSize());
    EXPECT_LT((learned.mean - scratch.mean).norm(), 1e-12 * scratch.mean.norm());
    EXPECT_NEAR(learned.totalEnergy, scratch.totalEnergy, 1e-10 * scratch.totalEnergy);
    // The signal's 6 directions are found; the noise beyond rank 12 is what is approximate.
    const double angle = pmsc::largestPrincipalAngle(scratch.basis, learned.basis);
    EXPECT_LT(angle, 0.02);
    EXPECT_GT(report.largestAngle, 0.5);  // the old basis lacked two patches' directions
    EXPECT_EQ(report.newFrames, 40);
    EXPECT_EQ(learned.learning->updates, 1);
    EXPECT_EQ(learned.calibrationRecord->keyRms.size(), 120u);

    const Errors before = errorsOn(old, heldOut), after = errorsOn(learned, heldOut),
                 reference = errorsOn(scratch, heldOut);
    EXPECT_GT(before.pointMax, 10 * reference.pointMax);  // the old model cannot pose patches 4, 5
    EXPECT_LE(after.pointMax, 1.1 * reference.pointMax);
    EXPECT_LE(after.keyRmsMean, 1.1 * reference.keyRmsMean);
    // The new keys see the new patches: some lie in patches 4 and 5.
    const auto inNewPatches = std::count_if(learned.keyPoints.begin(), learned.keyPoints.end(),
                                            [](Index p) { return p >= 4 * kPointsPerPatch; });
    EXPECT_GE(inNewPatches, 2);
    EXPECT_GT(learned.epsMin, 0.0);
    EXPECT_DOUBLE_EQ(learned.epsMax, 2 * learned.epsMin);
    EXPECT_EQ(learned.tolerance, old.tolerance);
}

TEST(Learning, APredictedKeyErrorModelKeepsBothPartsScoresThroughItsFileAndItsUpdate) {
    const pmsc::FrameSet day1 = patches(0, 80, 41, 2), misses = patches(80, 40, 41, 0);
    pmsc::TrainingOptions o = options(12);
    o.calibrationRule.reset();  // the defaults: the predicted error, its leave-one-out part by `threshold`
    o.keyErrorNorm.reset();
    const pmsc::Model old = pmsc::train(day1, o);
    ASSERT_EQ(old.keyErrorNorm, pmsc::KeyErrorNorm::Predicted);
    EXPECT_EQ(old.epsMin, o.tolerance);
    EXPECT_GT(old.partEps.rms, 0.0);
    EXPECT_GT(old.partEps.loo, 0.0);
    ASSERT_TRUE(old.calibrationRecord.has_value());
    EXPECT_EQ(old.calibrationRecord->rule, pmsc::CalibrationRule::Threshold);
    EXPECT_EQ(old.calibrationRecord->keyLoo.size(), 80u);
    // The file keeps the rule and both parts' scores.
    const pmsc::Model read = pmsc::decodeModel(pmsc::encodeModel(old), "test");
    EXPECT_EQ(read.calibrationRecord->rule, pmsc::CalibrationRule::Threshold);
    EXPECT_EQ(read.calibrationRecord->keyLoo, old.calibrationRecord->keyLoo);
    EXPECT_EQ(read.partEps.loo, old.partEps.loo);

    pmsc::LearnReport report;
    const pmsc::Model learned = pmsc::learn(read, misses, {}, &report);
    EXPECT_EQ(learned.keyErrorNorm, pmsc::KeyErrorNorm::Predicted);
    EXPECT_EQ(learned.epsMin, o.tolerance);
    EXPECT_GT(learned.partEps.rms, 0.0);
    EXPECT_GT(learned.partEps.loo, 0.0);
    // Each part's threshold is at most what the stored scores alone give (and the new ones alone).
    ASSERT_EQ(learned.calibrationRecord->keyRms.size(), 120u);
    ASSERT_EQ(learned.calibrationRecord->keyLoo.size(), 120u);
    EXPECT_EQ(std::vector<double>(learned.calibrationRecord->keyLoo.begin(),
                                  learned.calibrationRecord->keyLoo.begin() + 80),
              old.calibrationRecord->keyLoo);
    pmsc::CalibrationStats stored = old.calibrationRecord->scores();
    pmsc::setPredictedThresholds(stored, o.tolerance, pmsc::CalibrationRule::Threshold, 0.9);
    const auto tail = [](const std::vector<double>& v) {
        return std::vector<double>(v.begin() + 80, v.end());
    };
    pmsc::CalibrationStats fresh;
    fresh.keyRms = tail(learned.calibrationRecord->keyRms);
    fresh.keyLoo = tail(learned.calibrationRecord->keyLoo);
    fresh.maxPointError = tail(learned.calibrationRecord->maxPointError);
    pmsc::setPredictedThresholds(fresh, o.tolerance, pmsc::CalibrationRule::Threshold, 0.9);
    EXPECT_EQ(learned.partEps.rms, std::min(stored.partEps.rms, fresh.partEps.rms));
    EXPECT_EQ(learned.partEps.loo, std::min(stored.partEps.loo, fresh.partEps.loo));
    EXPECT_EQ(learned.epsMax, std::min(stored.epsMax, fresh.epsMax));
    // The report keeps the new frames' scores, in the learned model's measure.
    EXPECT_EQ(report.calibration.keyRms.size(), 40u);
    EXPECT_EQ(report.calibration.partEps.loo, learned.partEps.loo);
    EXPECT_NO_THROW(learned.validate());
}

TEST(Learning, TrainingResolvesTheKeyErrorFromTheOptions) {
    pmsc::TrainingOptions o;
    EXPECT_EQ(pmsc::resolvedKeyErrorNorm(o), pmsc::KeyErrorNorm::Rms) << "no tolerance: nothing to predict";
    EXPECT_EQ(pmsc::resolvedCalibrationRule(o), pmsc::CalibrationRule::MaxRatio);
    o.tolerance = 0.1;
    EXPECT_EQ(pmsc::resolvedKeyErrorNorm(o), pmsc::KeyErrorNorm::Predicted);
    EXPECT_EQ(pmsc::resolvedCalibrationRule(o), pmsc::CalibrationRule::Threshold);
    o.sharedChannels = true;
    EXPECT_EQ(pmsc::resolvedKeyErrorNorm(o), pmsc::KeyErrorNorm::Rms);
    o.sharedChannels = false;
    o.keyErrorNorm = pmsc::KeyErrorNorm::Rms;
    EXPECT_EQ(pmsc::resolvedCalibrationRule(o), pmsc::CalibrationRule::MaxRatio);
    o.calibrationRule = pmsc::CalibrationRule::Conformal;
    EXPECT_EQ(pmsc::resolvedCalibrationRule(o), pmsc::CalibrationRule::Conformal);
    // Asked for without a tolerance, the predicted error is refused with a reason.
    pmsc::TrainingOptions untuned;
    untuned.keyErrorNorm = pmsc::KeyErrorNorm::Predicted;
    EXPECT_THROW(pmsc::train(patches(0, 20, 51, 0), untuned), std::invalid_argument);
}

TEST(Learning, RepeatedUpdatesAgreeWithOneUpdateOfEverything) {
    const pmsc::FrameSet day1 = patches(0, 60, 11, 2), a = patches(60, 30, 11, 0), b = patches(90, 30, 11, 0);
    const pmsc::Model old = pmsc::train(day1, options(200));  // rank 200 keeps every direction seen
    const pmsc::Model twice = pmsc::learn(pmsc::learn(old, a), b);
    const pmsc::Model once = pmsc::learn(old, join(a, b));
    EXPECT_EQ(twice.trainFrames, 120);
    EXPECT_EQ(twice.learning->updates, 2);
    EXPECT_LT(pmsc::largestPrincipalAngle(once.basis, twice.basis), 1e-8);
    EXPECT_LT((once.mean - twice.mean).norm(), 1e-12 * once.mean.norm());
    EXPECT_NEAR(once.singularValues[0], twice.singularValues[0], 1e-10 * once.singularValues[0]);
}

TEST(Learning, APlainModelCanLearnButSaysWhatItLacks) {
    const pmsc::FrameSet day1 = patches(0, 60, 21, 2), misses = patches(60, 30, 21, 0),
                         heldOut = patches(200, 30, 21, 0);
    pmsc::TrainingOptions o = options(0);
    o.calibrationRule = pmsc::CalibrationRule::MaxRatio;
    const pmsc::Model old = pmsc::train(day1, o);
    EXPECT_FALSE(old.learning.has_value());
    EXPECT_FALSE(old.calibrationRecord.has_value());
    pmsc::LearnReport report;
    const pmsc::Model learned = pmsc::learn(old, misses, {}, &report);
    EXPECT_EQ(report.rankBefore, old.basisSize());
    EXPECT_GE(report.warnings.size(), 2u);  // no learning state, no stored scores
    EXPECT_GT(learned.epsMin, 0.0);
    EXPECT_LT(errorsOn(learned, heldOut).pointMax, 0.5 * errorsOn(old, heldOut).pointMax);
}

TEST(Learning, RejectsFramesThatDoNotFitTheModel) {
    const pmsc::Model old = pmsc::train(patches(0, 40, 31, 0), options(8));
    EXPECT_THROW(pmsc::learn(old, pmsc::FrameSet(3, old.points + 1, kChannels)), pmsc::InputError);
    EXPECT_THROW(pmsc::learn(old, pmsc::FrameSet(3, old.points, 1)), pmsc::InputError);
    pmsc::FrameSet bad = patches(40, 5, 31, 0);
    bad.values[17] = std::nan("");
    EXPECT_THROW(pmsc::learn(old, bad), pmsc::InputError);
    pmsc::LearnOptions tooSmall;
    tooSmall.maxRank = 3;
    EXPECT_THROW(pmsc::learn(old, patches(50, 5, 31, 0), tooSmall), std::invalid_argument);
}

TEST(Learning, TheEnergyRuleChoosesMAgainAsTrainingWould) {
    // Trained by the energy rule on frames where two patches never move, the model has fewer basis
    // vectors than training on the union would choose; learn chooses M by the same rule on all
    // frames seen, and keeps M when asked for a basis size.
    const pmsc::FrameSet day1 = patches(0, 80, 41, 2), misses = patches(80, 40, 41, 0);
    pmsc::TrainingOptions o = options(20);
    o.basis = 0;
    o.energy = 0.99;
    const pmsc::Model old = pmsc::train(day1, o);
    ASSERT_TRUE(old.learning.has_value());
    EXPECT_EQ(old.learning->basisEnergy, 0.99);
    const pmsc::Model scratch = pmsc::train(join(day1, misses), o);
    ASSERT_GT(scratch.basisSize(), old.basisSize());
    const pmsc::Model learned = pmsc::learn(old, misses);
    EXPECT_EQ(learned.basisSize(), scratch.basisSize());
    EXPECT_EQ(learned.learning->basisEnergy, 0.99);
    EXPECT_LT(pmsc::largestPrincipalAngle(scratch.basis, learned.basis), 0.02);

    pmsc::LearnOptions fixed;
    fixed.basis = old.basisSize();
    const pmsc::Model kept = pmsc::learn(old, misses, fixed);
    EXPECT_EQ(kept.basisSize(), old.basisSize());
    EXPECT_EQ(kept.learning->basisEnergy, 0.0);  // M was given: later updates keep it
    pmsc::LearnOptions lower;
    lower.energy = 0.9;
    EXPECT_LT(pmsc::learn(old, misses, lower).basisSize(), learned.basisSize());
    lower.energy = 1.5;
    EXPECT_THROW(pmsc::learn(old, misses, lower), std::invalid_argument);
    lower.energy = 0.9;
    lower.basis = 3;
    EXPECT_THROW(pmsc::learn(old, misses, lower), std::invalid_argument);
}

TEST(Learning, NewFramesAreHeldOutInSlicesOfTheTrainingsSize) {
    // 80 training frames in 5 slices: with 40 new frames a slice of all 120 is 24 frames, so the
    // new frames are 2 slices; 10 new frames are one slice, scored by the old state alone.
    const pmsc::Model old = pmsc::train(patches(0, 80, 51, 2), options(12));
    ASSERT_EQ(old.calibrationRecord->slices, 5);
    pmsc::LearnReport report;
    pmsc::learn(old, patches(80, 40, 51, 0), {}, &report);
    EXPECT_EQ(report.calibration.slices, 2);
    EXPECT_EQ(report.calibration.keyRms.size(), 40u);
    pmsc::learn(old, patches(80, 10, 51, 0), {}, &report);
    EXPECT_EQ(report.calibration.slices, 1);
    EXPECT_EQ(report.calibration.keyRms.size(), 10u);
    EXPECT_GT(report.calibrationRatioNew, 0.0);
    pmsc::LearnOptions four;
    four.slices = 4;
    pmsc::learn(old, patches(80, 40, 51, 0), four, &report);
    EXPECT_EQ(report.calibration.slices, 4);
    four.slices = 1;
    EXPECT_THROW(pmsc::learn(old, patches(80, 40, 51, 0), four), std::invalid_argument);
}

TEST(Learning, NewFramesWithANegativeValueLiftTheClampAtZero) {
    // Patches offset to be >= 0: the model clamps its output; new frames below 0 lift it.
    pmsc::FrameSet day1 = patches(0, 60, 41, 0), more = patches(60, 20, 41, 0);
    const double low = std::min(day1.matrix().minCoeff(), more.matrix().minCoeff());
    day1.matrix().array() -= low;
    more.matrix().array() -= low;
    const pmsc::Model old = pmsc::train(day1, options(12));
    ASSERT_TRUE(old.nonNegative);
    EXPECT_TRUE(pmsc::learn(old, more).nonNegative);
    more.values[5] = -0.25;
    pmsc::LearnReport report;
    const pmsc::Model learned = pmsc::learn(old, more, {}, &report);
    EXPECT_FALSE(learned.nonNegative);
    EXPECT_TRUE(std::any_of(report.warnings.begin(), report.warnings.end(), [](const std::string& w) {
        return w.find("no longer clamped") != std::string::npos;
    }));
}

TEST(Learning, ScoresOfFramesSpanningSeveralSlabsAreThoseOfTheWholeFrames) {
    // 18,000 points of one channel: learn scores the new frames in slabs of about 8,200 points,
    // so the keys and the largest point errors fall in three of them. Uncalibrated (no tolerance),
    // the learned eps_min is the largest key error on the new frames and the report their largest
    // point error: both must be what PM gives on the whole frames.
    const pmsc::FrameSet shot = pmsc::test::patchFrames(6, 3000, 1, 120, 7);
    pmsc::FrameSet day1(80, shot.points, 1), fresh(40, shot.points, 1);
    day1.matrix() = shot.matrix().leftCols(80);
    fresh.matrix() = shot.matrix().rightCols(40);
    fresh.matrix() += 0.05 * pmsc::test::gaussian(fresh.rows(), 40, 8);  // what the old basis lacks
    pmsc::TrainingOptions o;
    o.basis = 6;
    o.maxKeys = 24;
    o.keyErrorNorm = pmsc::KeyErrorNorm::Rms;
    o.learnRank = 12;
    const pmsc::Model old = pmsc::train(day1, o);
    ASSERT_EQ(old.tolerance, 0.0);
    pmsc::LearnOptions lo;
    lo.basis = 6;
    pmsc::LearnReport report;
    const pmsc::Model learned = pmsc::learn(old, fresh, lo, &report);
    ASSERT_GT(*std::max_element(learned.keyPoints.begin(), learned.keyPoints.end()), 2 * 8192);

    const pmsc::PointMultiplier pm(learned);
    std::vector<double> keys(learned.keyPoints.size()), coords(static_cast<size_t>(learned.basisSize())),
        out(static_cast<size_t>(fresh.rows()));
    double keyMax = 0, pointMax = 0;
    for (Index f = 0; f < fresh.frames; ++f) {
        const double* full = fresh.frame(f);
        for (size_t k = 0; k < keys.size(); ++k) keys[k] = full[learned.keyPoints[k]];
        pm.project(keys.data(), coords.data());
        keyMax = std::max(keyMax, pm.keyError(keys.data(), coords.data()));
        pm.reconstruct(coords.data(), out.data());
        for (Index p = 0; p < fresh.points; ++p)
            pointMax = std::max(pointMax, std::abs(out[size_t(p)] - full[p]));
    }
    ASSERT_GT(keyMax, old.epsMin);  // so the learned threshold is the new frames' own
    EXPECT_NEAR(learned.epsMin, keyMax, 1e-9 * keyMax);
    EXPECT_NEAR(report.newFramesMaxPointError, pointMax, 1e-9 * pointMax);
}

// Learn says when its region bases were capped by their share of key values, as training does:
// a region of white noise wants every direction and gets 0.4 of its key values.
TEST(Learning, SaysAsTrainingDoesWhenRegionBasesAreCapped) {
    auto noise = [](Index frames, unsigned seed) {
        pmsc::FrameSet set(frames, kPatches * kPointsPerPatch, kChannels);
        set.matrix() = pmsc::test::gaussian(set.rows(), frames, seed);
        return set;
    };
    pmsc::TrainingOptions o = options(40);
    o.basis = 40;
    o.maxKeys = 60;
    o.regions.count = 6;
    pmsc::TrainingReport trained;
    const pmsc::Model old = pmsc::train(noise(120, 3), o, &trained);
    ASSERT_TRUE(old.regions.has_value());
    const auto capped = [](const std::vector<std::string>& notes) {
        return std::count_if(notes.begin(), notes.end(), [](const std::string& n) {
            return n.find("local bases were capped by their share of key values") != std::string::npos;
        });
    };
    ASSERT_EQ(capped(trained.warnings), 1);
    pmsc::LearnReport report;
    const pmsc::Model learned = pmsc::learn(old, noise(60, 4), pmsc::LearnOptions{}, &report);
    ASSERT_TRUE(learned.regions.has_value());
    EXPECT_EQ(capped(report.warnings), 1);
}

namespace {

// The patches laid out on a line, 10 units apart, so that regions follow them.
Eigen::MatrixXd patchPositions() {
    Eigen::MatrixXd pos = Eigen::MatrixXd::Zero(kPatches * kPointsPerPatch, 3);
    for (Index p = 0; p < pos.rows(); ++p)
        pos(p, 0) = 10.0 * double(p / kPointsPerPatch) + 0.1 * double(p % kPointsPerPatch);
    return pos;
}

}  // namespace

// Learn keeps a model's regions: the partition and feather, every key a region read that is still
// read, and thresholds calibrated on the new frames: a region that never moved in training (its
// ratio from noise alone) moves in the new frames and gets its ratio from their held-out scores, and on
// held-out frames every region it calls a hit is within T.
TEST(Learning, AModelWithRegionsKeepsThemAndCalibratesWhatTheNewFramesMove) {
    const pmsc::FrameSet day1 = patches(0, 120, 5, 2);     // patches 4 and 5 never move
    const pmsc::FrameSet misses = patches(120, 80, 5, 0);  // everything moves
    const pmsc::FrameSet heldOut = patches(260, 80, 5, 0);
    pmsc::TrainingOptions o = options(12);
    o.regions.count = 6;
    o.regions.positions = patchPositions();
    const pmsc::Model old = pmsc::train(day1, o);
    ASSERT_TRUE(old.regions.has_value());
    pmsc::LearnReport report;
    pmsc::LearnOptions lo;
    lo.positions = patchPositions();  // as train had them: the learned keys near a region join it
    const pmsc::Model learned = pmsc::learn(old, misses, lo, &report);
    ASSERT_TRUE(learned.regions.has_value());
    const pmsc::LocalRegions &was = *old.regions, &now = *learned.regions;
    ASSERT_EQ(now.regionCount(), was.regionCount());
    EXPECT_EQ(now.featherStart, was.featherStart);
    EXPECT_EQ(now.featherRegion, was.featherRegion);
    EXPECT_EQ(now.featherWidth, was.featherWidth);
    EXPECT_EQ(report.regionKeys, Index(now.extraKeyPoints.size()));

    const Index firstStill = 4 * kPointsPerPatch;
    Index stillRegions = 0;
    for (Index r = 0; r < now.regionCount(); ++r) {
        const pmsc::Region &a = was.regions[size_t(r)], &b = now.regions[size_t(r)];
        EXPECT_EQ(b.points, a.points);
        std::vector<Index> read;
        for (const Index key : b.keys) read.push_back(now.keyPoint(learned, key));
        std::sort(read.begin(), read.end());
        for (const Index key : a.keys) {
            const Index p = was.keyPoint(old, key);
            const bool stillRead = key >= old.keyCount() ||
                                   std::count(learned.keyPoints.begin(), learned.keyPoints.end(), p) > 0;
            if (stillRead) EXPECT_TRUE(std::binary_search(read.begin(), read.end(), p)) << "region " << r;
        }
        EXPECT_GE(b.ratio, a.ratio);
        std::vector<Index> readBefore;  // distinct points: a region key may sit at a model key
        for (const Index key : a.keys) readBefore.push_back(was.keyPoint(old, key));
        std::sort(readBefore.begin(), readBefore.end());
        readBefore.erase(std::unique(readBefore.begin(), readBefore.end()), readBefore.end());
        EXPECT_GE(Index(read.size()), std::min<Index>(12, Index(readBefore.size()))) << "region " << r;
        if (a.points.front() >= firstStill) {
            ++stillRegions;
            // Its motion is new: the new frames' held-out scores set its ratio, not training's noise.
            EXPECT_GT(b.ratio, a.ratio) << "region " << r;
        }
    }
    EXPECT_GE(stillRegions, 1);
    // Every learned key within the key radius of a region (4.5% of the positions' diagonal) is one of its
    // keys.
    const Eigen::MatrixXd pos = patchPositions();
    const double reach =
        pmsc::RegionOptions{}.keyRadius * (pos.colwise().maxCoeff() - pos.colwise().minCoeff()).norm();
    Index nearKeys = 0;
    for (Index r = 0; r < now.regionCount(); ++r) {
        const pmsc::Region& g = now.regions[size_t(r)];
        for (Index j = 0; j < learned.keyCount(); ++j) {
            double nearest = 1e300;
            for (const Index p : g.points)
                nearest = std::min(nearest, (pos.row(learned.keyPoints[size_t(j)]) - pos.row(p)).norm());
            if (nearest > reach || nearest == 0) continue;
            ++nearKeys;
            EXPECT_TRUE(std::binary_search(g.keys.begin(), g.keys.end(), j))
                << "region " << r << ", key " << j;
        }
    }
    EXPECT_GT(nearKeys, 0);

    // Held out: every region hit is within T, and the regions that were still hit some frames.
    const pmsc::RegionMultiplier rm(learned);
    std::vector<double> keys(size_t(learned.keyCount() * kChannels)),
        regionKeys(now.extraKeyPoints.size() * kChannels), coords(size_t(rm.coordsSize())),
        frame(size_t(heldOut.rows()));
    Index stillHits = 0;
    for (Index f = 0; f < heldOut.frames; ++f) {
        const double* full = heldOut.frame(f);
        for (Index k = 0; k < learned.keyCount(); ++k)
            for (Index c = 0; c < kChannels; ++c)
                keys[size_t(k * kChannels + c)] = full[learned.keyPoints[size_t(k)] * kChannels + c];
        for (size_t e = 0; e < now.extraKeyPoints.size(); ++e)
            for (Index c = 0; c < kChannels; ++c)
                regionKeys[e * kChannels + size_t(c)] = full[now.extraKeyPoints[e] * kChannels + c];
        for (Index r = 0; r < now.regionCount(); ++r) {
            double* rc = coords.data() + rm.coordsOffset(r);
            const double keyError = rm.project(r, keys.data(), regionKeys.data(), rc);
            if (keyError > now.regions[size_t(r)].epsMin) continue;
            rm.reconstruct(r, rc, frame.data());
            double largest = 0;
            for (const Index p : now.regions[size_t(r)].points) {
                double d = 0;
                for (Index c = 0; c < kChannels; ++c)
                    d += std::pow(frame[size_t(p * kChannels + c)] - full[p * kChannels + c], 2);
                largest = std::max(largest, std::sqrt(d));
            }
            EXPECT_LE(largest, learned.tolerance) << "frame " << f << ", region " << r;
            stillHits += now.regions[size_t(r)].points.front() >= firstStill;
        }
    }
    EXPECT_GT(stillHits, 0);

    // The regions go through the model file.
    const pmsc::Model read = pmsc::decodeModel(pmsc::encodeModel(learned), "learned");
    ASSERT_TRUE(read.regions.has_value());
    EXPECT_EQ(read.regions->extraKeyPoints, now.extraKeyPoints);
    EXPECT_EQ(read.regions->regions.back().epsMin, now.regions.back().epsMin);
}
