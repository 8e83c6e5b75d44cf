#include "app/Replay.h"
#include "evaluators/EvaluatorRegistry.h"
#include "evaluators/ReplayEvaluator.h"
#include "pmsc/Errors.h"
#include "pmsc/Training.h"

#include <gtest/gtest.h>

#include <Eigen/QR>

#include <cmath>

namespace {

using pmsc::Index;

/// A model of 3 points x 1 channel with M = 1: basis e = (1, 1, 1)/sqrt 3, key = point 0 and
/// point 1, mean 0. A frame a*(1,1,1) is reproduced exactly; (1, 0, 0) is not.
pmsc::Model tinyModel(double epsMin, double epsMax) {
    pmsc::Model m;
    m.points = 3;
    m.channels = 1;
    m.trainFrames = 2;
    m.mean = Eigen::VectorXd::Zero(3);
    m.basis = Eigen::VectorXd::Constant(3, 1 / std::sqrt(3.0));
    m.singularValues = Eigen::VectorXd::Constant(1, 1.0);
    m.totalEnergy = 1;
    m.keyPoints = {0, 1};
    m.projector = pmsc::makeProjector(m.basis, 1, m.keyPoints);
    m.epsMin = epsMin;
    m.epsMax = epsMax;
    return m;
}

pmsc::evaluators::ReplayEvaluator recording(std::vector<double> values, Index frames) {
    pmsc::FrameFile file{pmsc::FrameSet(frames, 3, 1), pmsc::NpyDtype::Float64};
    file.frames.values.assign(values.begin(), values.end());
    return pmsc::evaluators::ReplayEvaluator(std::move(file), "test");
}

TEST(ReplayFrame, HitBlendAndMissProduceTheSoftCachedFrame) {
    // Frame 0 lies in the subspace; frames 1-2 have key residual 0.5 * sqrt(2)/sqrt(2) = 0.5
    // ((1,0) projected onto (1,1)/sqrt2 leaves (0.5,-0.5): RMS over 2 keys = 0.5).
    const auto rec = recording({2, 2, 2, 1, 0, 0, 1, 0, 0}, 3);
    const pmsc::Model model = tinyModel(0.25, 0.75);
    const pmsc::PointMultiplier pm(model);
    pmsc::app::ReplayScratch scratch(model);
    std::vector<double> out(3);

    auto row = pmsc::app::replayFrame(pm, pmsc::SoftCachePolicy(0.25, 0.75), rec, 0, scratch, out.data());
    EXPECT_EQ(row.decision.state, pmsc::CacheState::Hit);
    EXPECT_NEAR(row.keyRms, 0, 1e-12);
    EXPECT_NEAR(row.pmMaxPointError, 0, 1e-12);
    EXPECT_NEAR(out[2], 2, 1e-12);

    row = pmsc::app::replayFrame(pm, pmsc::SoftCachePolicy(0.25, 0.75), rec, 1, scratch, out.data());
    EXPECT_NEAR(row.keyRms, 0.5, 1e-12);
    EXPECT_EQ(row.decision.state, pmsc::CacheState::Blend);
    EXPECT_NEAR(row.decision.weight, 0.5, 1e-12);
    // PM gives (0.5, 0.5, 0.5); the recording (1, 0, 0); the blend is halfway.
    EXPECT_NEAR(out[0], 0.75, 1e-12);
    EXPECT_NEAR(out[1], 0.25, 1e-12);
    EXPECT_NEAR(out[2], 0.25, 1e-12);
    EXPECT_NEAR(row.pmMaxPointError, 0.5, 1e-12);
    EXPECT_NEAR(row.softMaxPointError, 0.25, 1e-12);

    row = pmsc::app::replayFrame(pm, pmsc::SoftCachePolicy(0.1, 0.2), rec, 2, scratch, out.data());
    EXPECT_EQ(row.decision.state, pmsc::CacheState::Miss);
    EXPECT_EQ(out, (std::vector<double>{1, 0, 0}));
    EXPECT_EQ(row.softMaxPointError, 0);
}

TEST(Replay, ReportCountsStatesAndUsesTheOverride) {
    const auto rec = recording({2, 2, 2, 1, 0, 0, 1, 0, 0}, 3);
    const pmsc::Model model = tinyModel(0.25, 0.75);
    pmsc::app::ReplayOptions options;
    options.threads = 1;
    auto result = pmsc::app::replay(model, rec, options);
    auto report = pmsc::app::replayReport(model, result);
    EXPECT_DOUBLE_EQ(report["summary"]["hit_rate"].get<double>(), 1.0 / 3);
    EXPECT_DOUBLE_EQ(report["summary"]["blend_rate"].get<double>(), 2.0 / 3);
    EXPECT_EQ(report["frames"][1]["state"], "blend");
    options.eps = std::make_pair(0.0, 0.0);
    result = pmsc::app::replay(model, rec, options);
    report = pmsc::app::replayReport(model, result);
    // Frame 0's key error is zero up to rounding, so only frames 1 and 2 are certain misses.
    EXPECT_EQ(report["frames"][1]["state"], "miss");
    EXPECT_EQ(report["frames"][2]["state"], "miss");
    EXPECT_EQ(report["summary"]["eps_max"], 0.0);
}

/// 40 points x 3 channels, M = 2, four regions of 10 points with two keys each, whose local bases
/// are the rows of the global basis (a frame in the subspace hits everywhere), no feather bands.
pmsc::Model regionModel() {
    pmsc::Model m;
    m.points = 40;
    m.channels = 3;
    m.trainFrames = 2;
    Eigen::MatrixXd g(120, 2);
    for (Index i = 0; i < g.size(); ++i) g.data()[i] = std::sin(0.7 * double(i) + 0.2);
    m.basis = Eigen::HouseholderQR<Eigen::MatrixXd>(g).householderQ() * Eigen::MatrixXd::Identity(120, 2);
    m.mean = Eigen::VectorXd::Zero(120);
    m.singularValues = Eigen::Vector2d(2, 1);
    m.totalEnergy = 5;
    for (Index r = 0; r < 4; ++r) m.keyPoints.insert(m.keyPoints.end(), {10 * r + 2, 10 * r + 7});
    m.projector = pmsc::makeProjector(m.basis, 3, m.keyPoints);
    m.epsMin = 1e-9;
    m.epsMax = 2e-9;
    pmsc::LocalRegions lr;
    for (Index r = 0; r < 4; ++r) {
        pmsc::Region reg;
        for (Index p = 10 * r; p < 10 * r + 10; ++p) reg.points.push_back(p);
        reg.keys = {2 * r, 2 * r + 1};
        reg.basis = m.basis.middleRows(30 * r, 30);
        reg.keyBasis = pmsc::gatherKeyRows(m.basis, 3, {10 * r + 2, 10 * r + 7});
        reg.projector = Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd>(reg.keyBasis).pseudoInverse();
        reg.epsMin = 1e-9;
        reg.epsMax = 2e-9;
        lr.regions.push_back(std::move(reg));
    }
    lr.featherStart.assign(41, 0);
    m.regions = std::move(lr);
    m.validate();
    return m;
}

/// Two frames of regionModel()'s 40 points: frame 0 in the subspace (a hit); frame 1 the same plus
/// a displacement of region 0's points (up to 0.1).
pmsc::FrameFile hitThenRegion0Moved(const pmsc::Model& model) {
    pmsc::FrameFile file{pmsc::FrameSet(2, 40, 3), pmsc::NpyDtype::Float64};
    auto& values = file.frames.values;
    for (Index x = 0; x < 120; ++x) {
        values[x] = 0.5 * model.basis(x, 0) - 0.25 * model.basis(x, 1);
        values[120 + x] = values[x] + (x < 30 ? 0.1 * std::cos(double(x)) : 0.0);
    }
    return file;
}

TEST(Replay, ModelWithRegionsReportsLocalFramesAndWholeFrameFlagRestoresTheOldRoute) {
    const pmsc::Model model = regionModel();
    const pmsc::evaluators::ReplayEvaluator rec(hitThenRegion0Moved(model), "test");
    pmsc::app::ReplayOptions options;
    options.threads = 2;
    auto report = pmsc::app::replayReport(model, pmsc::app::replay(model, rec, options));
    EXPECT_EQ(report["summary"]["regions"], 4);
    EXPECT_EQ(report["summary"]["local_frames"], 1);
    EXPECT_EQ(report["frames"][0]["regions"], "hhhh");
    EXPECT_EQ(report["frames"][1]["regions"], "mhhh");
    EXPECT_EQ(report["frames"][1]["local"], true);
    EXPECT_DOUBLE_EQ(report["frames"][1]["points_evaluated_fraction"].get<double>(), 0.25);
    EXPECT_LT(report["frames"][1]["soft_max_point_error"].get<double>(),
              1e-12);  // region 0 read, the rest exact
    EXPECT_GT(report["frames"][1]["pm_max_point_error"].get<double>(), 0.01);
    // The local frame's PM column (the sink reconstructs it with the engine's point multiplier) is
    // the whole frame's PM, to the bit, as replayFrame() computes it with a multiplier of its own.
    {
        const pmsc::PointMultiplier own(model);
        pmsc::app::ReplayScratch scratch(model);
        std::vector<double> out(120);
        const pmsc::app::ReplayFrame direct = pmsc::app::replayFrame(
            own, pmsc::SoftCachePolicy(model.epsMin, model.epsMax), rec, 1, scratch, out.data());
        EXPECT_EQ(report["frames"][1]["pm_max_point_error"].get<double>(), direct.pmMaxPointError);
    }
    EXPECT_EQ(report["summary"]["region_states"][0]["misses"], 1);
    options.localFailThrough = false;  // --whole-frame-fail-through
    report = pmsc::app::replayReport(model, pmsc::app::replay(model, rec, options));
    EXPECT_EQ(report["summary"]["local_frames"], 0);
    EXPECT_EQ(report["frames"][1]["local"], false);
    EXPECT_DOUBLE_EQ(report["frames"][1]["points_evaluated_fraction"].get<double>(), 1.0);
    // A version-1 model's report has none of it.
    pmsc::Model v1 = model;
    v1.regions.reset();
    report = pmsc::app::replayReport(v1, pmsc::app::replay(v1, rec, options));
    EXPECT_FALSE(report["summary"].contains("regions"));
    EXPECT_FALSE(report["frames"][1].contains("local"));
}

TEST(Replay, ModelWithSentinelsReportsThePointsItsCheckComputes) {
    // The region model without its regions, with two sentinels: frame 0 (in the subspace) is a
    // checked hit that computes 2 of 40 points; frame 1 misses and is computed whole. Without the
    // sentinels (a version-1 model) the report has no such field.
    pmsc::Model model = regionModel();
    model.regions.reset();
    pmsc::Sentinels s;
    s.points = {0, 20};
    s.coveringRadius = 10;
    s.source = pmsc::SentinelSource::PointOrder;
    model.sentinels = std::move(s);
    model.tolerance = 0.01;  // frame 1 is off by up to 0.1: its sentinel 0 would refuse it as a hit
    model.validate();
    const pmsc::evaluators::ReplayEvaluator rec(hitThenRegion0Moved(model), "test");
    pmsc::app::ReplayOptions options;
    options.threads = 2;
    auto report = pmsc::app::replayReport(model, pmsc::app::replay(model, rec, options));
    EXPECT_EQ(report["frames"][0]["state"], "hit");
    EXPECT_DOUBLE_EQ(report["frames"][0]["points_evaluated_fraction"].get<double>(), 2.0 / 40.0);
    EXPECT_DOUBLE_EQ(report["frames"][1]["points_evaluated_fraction"].get<double>(), 1.0);
    EXPECT_DOUBLE_EQ(report["summary"]["points_evaluated_fraction"].get<double>(), (2.0 / 40.0 + 1.0) / 2);
    EXPECT_FALSE(report["summary"].contains("regions"));
    model.sentinels.reset();
    report = pmsc::app::replayReport(model, pmsc::app::replay(model, rec, options));
    EXPECT_FALSE(report["frames"][0].contains("points_evaluated_fraction"));
    EXPECT_FALSE(report["summary"].contains("points_evaluated_fraction"));
}

TEST(Replay, CancelFlagStopsWithCancelled) {
    const auto rec = recording({2, 2, 2, 1, 0, 0, 1, 0, 0}, 3);
    const pmsc::Model model = tinyModel(0.25, 0.75);
    std::atomic<bool> cancel{true};
    pmsc::app::ReplayOptions options;
    options.cancel = &cancel;
    EXPECT_THROW(pmsc::app::replay(model, rec, options), pmsc::Cancelled);
}

TEST(EvaluatorRegistry, ReplaySpecAndUnknownNames) {
    EXPECT_THROW(pmsc::evaluators::makeEvaluator("nosuch:x"), std::invalid_argument);
    EXPECT_THROW(pmsc::evaluators::makeEvaluator("replay"), std::invalid_argument);
    EXPECT_THROW(pmsc::evaluators::makeEvaluator("replay:/no/such/file.npy"), pmsc::InputError);
    try {
        pmsc::evaluators::makeEvaluator("nosuch");
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("known: replay"), std::string::npos) << e.what();
    }
}

TEST(ReplayEvaluator, SubsetsReadTheRecordedValues) {
    const auto rec = recording({0, 1, 2, 10, 11, 12}, 2);
    std::vector<double> out(2);
    const std::vector<Index> points = {2, 0};
    rec.evaluate(1, points, out.data());
    EXPECT_EQ(out, (std::vector<double>{12, 10}));
    EXPECT_THROW(rec.evaluate(2, points, out.data()), std::out_of_range);
    const std::vector<Index> bad = {3};
    EXPECT_THROW(rec.evaluate(0, bad, out.data()), std::out_of_range);
}

}  // namespace
