// The `pmsc` program end to end: success paths and every kind of bad input, through the real
// binary (exit codes, the one stderr line, and no output file left behind).
#include "SyntheticShot.h"
#include "evaluators/synthetic/SyntheticSurface.h"
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"
#include "pmsc/SoftCache.h"
#include "tests/common/CliRunner.h"

#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <limits>
#include <sstream>

namespace {

using pmsc::test::runPmsc;
using pmsc::test::RunResult;
using pmsc::test::TempDir;
namespace fs = std::filesystem;

using Shot = pmsc::test::SyntheticShot;

/// One shot and one trained model for the whole suite (training is the slow part).
class Cli : public ::testing::Test {
protected:
    static void SetUpTestSuite() {
        shot_ = new Shot;
        modelDir_ = new TempDir;
        model_ = modelDir_->file("model.pmsc");
        const RunResult r = runPmsc(*modelDir_, {"train", "--frames", shot_->train, "--out", model_,
                                                 "--max-keys", "24", "--tolerance", "0.02"});
        ASSERT_EQ(r.exitCode, 0) << r.err;
    }
    static void TearDownTestSuite() {
        delete modelDir_;
        delete shot_;
    }

    /// Expects the failure contract: the exit code, exactly one stderr line "pmsc: ..." holding
    /// every fragment, and no file in `dir` except `allowed`.
    static void expectFailure(const RunResult& r, int code, std::initializer_list<std::string> fragments) {
        EXPECT_EQ(r.exitCode, code) << r.err;
        const auto lines = r.errLines();
        ASSERT_EQ(lines.size(), 1u) << r.err;
        EXPECT_EQ(lines[0].rfind("pmsc: ", 0), 0u) << lines[0];
        for (const auto& f : fragments) EXPECT_NE(lines[0].find(f), std::string::npos) << lines[0];
    }
    /// Everything in `dir` except the captured stdout/stderr files.
    static std::vector<std::string> outputs(const TempDir& dir) {
        std::vector<std::string> names;
        for (const auto& n : dir.entries())
            if (n != "stdout.txt" && n != "stderr.txt") names.push_back(n);
        return names;
    }

    static Shot* shot_;
    static TempDir* modelDir_;
    static std::string model_;
};

Shot* Cli::shot_ = nullptr;
TempDir* Cli::modelDir_ = nullptr;
std::string Cli::model_;

TEST_F(Cli, EvaluatorsListsEveryCalculationOnePerLine) {
    TempDir dir;
    const RunResult r = runPmsc(dir, {"evaluators"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    std::vector<std::string> names;
    std::istringstream lines(r.out);
    for (std::string line; std::getline(lines, line);) names.push_back(line.substr(0, line.find(' ')));
    const std::vector<std::string> expected = {"replay", "skin",         "synthetic", "cornell",
                                               "face",   "face-control", "volume",    "exec"};
    EXPECT_EQ(names, expected) << r.out;
    EXPECT_NE(r.out.find("volume:FILE.vdb[:grid=NAME]"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("synthetic[:grid=G]"), std::string::npos) << r.out;
    expectFailure(runPmsc(dir, {"evaluators", "--bogus"}), 2, {"evaluators", "--bogus"});
}

TEST_F(Cli, SyntheticSpecOptionsAreCheckedWithOneLine) {
    TempDir dir;
    expectFailure(runPmsc(dir, {"export-frames", "synthetic:grid=1", "--out", dir.file("f.npy")}), 2,
                  {"synthetic", "grid='1'"});
    expectFailure(runPmsc(dir, {"export-frames", "synthetic:colour=red", "--out", dir.file("f.npy")}), 2,
                  {"synthetic", "unknown option 'colour'"});
    expectFailure(runPmsc(dir, {"export-frames", "synthetic:frames=5:novel=6", "--out", dir.file("f.npy")}),
                  2, {"novel=6 exceeds frames=5"});
    EXPECT_TRUE(outputs(dir).empty());
}

// The Cornell gather's frames share their gather rays, so export-frames asks for them in groups
// (PointEvaluator::framesSharingWork): the file must hold each frame as it is alone, whatever group
// or step put it there.
TEST_F(Cli, ExportFramesInGroupsWritesEachFrameAsItIsAlone) {
    TempDir dir;
    const std::string spec = "cornell:points=1000,samples=4,lights=scattered";
    for (const auto& [frames, file] :
         {std::pair{"0-15", "all.npy"}, {"1-15:2", "odd.npy"}, {"7-7", "one.npy"}})
        ASSERT_EQ(
            runPmsc(dir, {"export-frames", spec, "--frames", frames, "--out", dir.file(file), "--quiet"})
                .exitCode,
            0);
    const pmsc::FrameSet all = pmsc::readFrames(dir.file("all.npy")).frames;
    const pmsc::FrameSet odd = pmsc::readFrames(dir.file("odd.npy")).frames;
    const pmsc::FrameSet one = pmsc::readFrames(dir.file("one.npy")).frames;
    ASSERT_EQ(all.frames, 16);
    ASSERT_EQ(odd.frames, 8);
    const auto bytes = static_cast<std::size_t>(all.rows()) * sizeof(double);
    for (pmsc::Index k = 0; k < 8; ++k)
        EXPECT_EQ(0, std::memcmp(odd.frame(k), all.frame(2 * k + 1), bytes)) << "frame " << 2 * k + 1;
    EXPECT_EQ(0, std::memcmp(one.frame(0), all.frame(7), bytes));
    EXPECT_NE(0, std::memcmp(all.frame(6), all.frame(7), bytes));
}

TEST_F(Cli, TrainWritesAModelAndASummary) {
    TempDir dir;
    const auto model = dir.file("m.pmsc");
    const RunResult r = runPmsc(dir, {"train", "--frames", shot_->train, "--out", model, "--basis", "8",
                                      "--max-keys", "16", "--selector", "qdeim"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(r.err, "");  // short run, not a terminal: no progress lines
    EXPECT_NE(r.out.find("trained " + model + " from 240 frames x 144 points x 3 channels"),
              std::string::npos)
        << r.out;
    EXPECT_NE(r.out.find("M = 8"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("Q-DEIM"), std::string::npos) << r.out;
    const pmsc::Model m = pmsc::readModel(model);
    EXPECT_EQ(m.basisSize(), 8);
    EXPECT_LE(m.keyCount(), 16);
    EXPECT_EQ(m.selector, pmsc::Selector::QDeim);
    EXPECT_EQ(outputs(dir), std::vector<std::string>{"m.pmsc"});
}

// --regions: auto by default (the synthetic surface deforms whole, so it gets no regions, and the
// summary says why), a count learns that many, 0 learns none; a bad value is one line.
TEST_F(Cli, TrainRegionsAreChosenUnlessToldAndBadValuesFail) {
    TempDir dir;
    const auto train = [&](const std::string& name, std::initializer_list<std::string> more) {
        std::vector<std::string> args{"train",      "--frames", shot_->train,  "--out", dir.file(name),
                                      "--max-keys", "24",       "--tolerance", "0.02"};
        args.insert(args.end(), more);
        return runPmsc(dir, args);
    };
    RunResult r = train("auto.pmsc", {});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("regions     none: a motion moves"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("the data pose whole"), std::string::npos) << r.out;
    EXPECT_FALSE(pmsc::readModel(dir.file("auto.pmsc")).regions.has_value());

    r = train("three.pmsc", {"--regions", "3", "--feather", "0.05"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const pmsc::Model three = pmsc::readModel(dir.file("three.pmsc"));
    ASSERT_TRUE(three.regions.has_value());
    EXPECT_LE(three.regions->regionCount(), 3);

    r = train("off.pmsc", {"--regions", "0"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(r.out.find("regions "), std::string::npos) << r.out;
    EXPECT_FALSE(pmsc::readModel(dir.file("off.pmsc")).regions.has_value());
    // No regions combine with shared channels (which have none); a count does not.
    r = train("shared.pmsc", {"--regions", "0", "--shared-channels"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_FALSE(pmsc::readModel(dir.file("shared.pmsc")).regions.has_value());

    TempDir bad;
    const auto fails = [&](std::initializer_list<std::string> more,
                           std::initializer_list<std::string> fragments) {
        std::vector<std::string> args{"train", "--frames", shot_->train, "--out", bad.file("m.pmsc")};
        args.insert(args.end(), more);
        expectFailure(runPmsc(bad, args), 2, fragments);
    };
    fails({"--regions", "many"}, {"--regions", "'many' is not auto or a region count"});
    fails({"--regions", "-1"}, {"--regions", "'-1' is not auto or a region count"});
    fails({"--regions", "auto", "--region-stride", "0"}, {"--region-stride", "out of range"});
    fails({"--regions", "2", "--shared-channels"}, {"--regions does not combine with --shared-channels"});
    EXPECT_TRUE(outputs(bad).empty());
}

TEST_F(Cli, FramesThatAreNeverNegativeTrainAClampedModelUnlessNoClamp) {
    TempDir dir;
    pmsc::FrameSet light = pmsc::readFrames(shot_->train).frames;
    light.matrix().array() -= light.matrix().minCoeff();
    const auto frames = dir.file("light.npy");
    pmsc::writeFrames(frames, light, pmsc::NpyDtype::Float64);
    RunResult r =
        runPmsc(dir, {"train", "--frames", frames, "--out", dir.file("m.pmsc"), "--max-keys", "24"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("output      clamped at 0"), std::string::npos) << r.out;
    EXPECT_TRUE(pmsc::readModel(dir.file("m.pmsc")).nonNegative);
    r = runPmsc(dir, {"inspect", "--json", dir.file("m.pmsc")});
    EXPECT_NE(r.out.find("\"non_negative\": true"), std::string::npos) << r.out;
    r = runPmsc(dir, {"train", "--frames", frames, "--out", dir.file("linear.pmsc"), "--max-keys", "24",
                      "--no-clamp", "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_FALSE(pmsc::readModel(dir.file("linear.pmsc")).nonNegative);
    r = runPmsc(dir, {"inspect", dir.file("linear.pmsc")});
    EXPECT_EQ(r.out.find("clamped at 0"), std::string::npos) << r.out;
    // The shot itself has negative values: no clamp.
    r = runPmsc(
        dir, {"train", "--frames", shot_->train, "--out", dir.file("s.pmsc"), "--max-keys", "24", "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_FALSE(pmsc::readModel(dir.file("s.pmsc")).nonNegative);
}

TEST_F(Cli, TrainTakesPositionsForItsSentinelsAndBadOnesFail) {
    TempDir dir;
    // Positions from a table of one frame (1, N, 3): the training's first frame.
    const pmsc::FrameSet train = pmsc::readFrames(shot_->train).frames;
    pmsc::FrameSet table(1, train.points, 3);
    std::copy(train.frame(0), train.frame(0) + train.points * 3, table.frame(0));
    const auto positions = dir.file("positions.npy");
    pmsc::writeFrames(positions, table, pmsc::NpyDtype::Float64);
    RunResult r =
        runPmsc(dir, {"train", "--frames", shot_->train, "--out", dir.file("m.pmsc"), "--max-keys", "24",
                      "--tolerance", "0.02", "--positions", positions, "--sentinels", "5", "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const pmsc::Model m = pmsc::readModel(dir.file("m.pmsc"));
    ASSERT_TRUE(m.sentinels.has_value());
    EXPECT_EQ(m.sentinels->points.size(), 5u);
    EXPECT_EQ(m.sentinels->source, pmsc::SentinelSource::Given);
    r = runPmsc(dir, {"inspect", dir.file("m.pmsc")});
    EXPECT_NE(r.out.find("sentinels     5 (from the positions given to train)"), std::string::npos) << r.out;
    // Channels that share the basis take positions for their sentinels too.
    r = runPmsc(dir, {"train", "--frames", shot_->train, "--out", dir.file("shared.pmsc"), "--max-keys", "24",
                      "--tolerance", "0.02", "--positions", positions, "--sentinels", "5",
                      "--shared-channels", "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const pmsc::Model shared = pmsc::readModel(dir.file("shared.pmsc"));
    ASSERT_TRUE(shared.sentinels.has_value());
    EXPECT_EQ(shared.sentinels->points.size(), 5u);
    EXPECT_EQ(shared.sentinels->source, pmsc::SentinelSource::Given);

    TempDir bad;
    pmsc::FrameSet shortTable(1, train.points - 1, 3);
    const auto wrong = bad.file("wrong.npy");
    pmsc::writeFrames(wrong, shortTable, pmsc::NpyDtype::Float64);
    const auto fails = [&](std::initializer_list<std::string> more,
                           std::initializer_list<std::string> fragments) {
        std::vector<std::string> args{"train",       "--frames", shot_->train, "--out", bad.file("m.pmsc"),
                                      "--tolerance", "0.02"};
        args.insert(args.end(), more);
        expectFailure(runPmsc(bad, args), 2, fragments);
    };
    fails({"--positions", wrong}, {"--positions", "expected " + std::to_string(train.points) + " rows"});
    fails({"--positions", bad.file("none.npy")}, {"none.npy"});
    fails({"--positions", positions, "--targets", shot_->train},
          {"--positions does not apply to a cross model"});
    fails({"--sentinels", "-1"}, {"--sentinels"});
    std::filesystem::remove(wrong);
    EXPECT_TRUE(outputs(bad).empty());
}

TEST_F(Cli, TrainSpreadsTheSentinelsOverATrainingFrameOfAShapeWhoseMeanIsNone) {
    // A 20 x 20 sheet turned about z through +-2 radians: each frame is the sheet, the mean folds it.
    TempDir dir;
    constexpr pmsc::Index side = 20, frames = 48;
    pmsc::FrameSet turning(frames, side * side, 3);
    for (pmsc::Index f = 0; f < frames; ++f) {
        const double angle = 2 * std::sin(0.37 * double(f)), bend = 0.1 * std::cos(0.23 * double(f));
        for (pmsc::Index p = 0; p < side * side; ++p) {
            const double x = double(p % side) / double(side - 1), y = double(p / side) / double(side - 1);
            double* v = turning.frame(f) + 3 * p;
            v[0] = std::cos(angle) * x - std::sin(angle) * y;
            v[1] = std::sin(angle) * x + std::cos(angle) * y;
            v[2] = bend * std::sin(3.14159 * x);
        }
    }
    const auto framesFile = dir.file("turning.npy");
    pmsc::writeFrames(framesFile, turning, pmsc::NpyDtype::Float64);
    RunResult r = runPmsc(dir, {"train", "--frames", framesFile, "--out", dir.file("t.pmsc"), "--max-keys",
                                "24", "--basis", "6", "--tolerance", "0.01", "--sentinels", "20"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("spread over the training frame nearest the mean"), std::string::npos) << r.out;
    r = runPmsc(dir, {"inspect", dir.file("t.pmsc")});
    EXPECT_NE(r.out.find("sentinels     20 (from the training frame nearest the mean)"), std::string::npos)
        << r.out;
    r = runPmsc(dir, {"inspect", "--json", dir.file("t.pmsc")});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(nlohmann::json::parse(r.out).at("sentinels").at("positions"), "frame");
}

TEST_F(Cli, TrainSeedsFiducials) {
    TempDir dir;
    const auto model = dir.file("m.pmsc");
    const RunResult r = runPmsc(dir, {"train", "--frames", shot_->train, "--out", model, "--fiducials",
                                      "5,77,140", "--max-keys", "12", "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const pmsc::Model m = pmsc::readModel(model);
    for (pmsc::Index f : {5, 77, 140})
        EXPECT_NE(std::find(m.keyPoints.begin(), m.keyPoints.end(), f), m.keyPoints.end()) << f;
}

TEST_F(Cli, ReplayReportHasEveryFieldAndTheOutputMatchesTheInput) {
    TempDir dir;
    const auto report = dir.file("report.json"), out = dir.file("out.npy");
    const RunResult r = runPmsc(
        dir, {"replay", "--model", model_, "--frames", shot_->test32, "--out", out, "--report", report});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("replayed 60 frames"), std::string::npos) << r.out;
    // eps in the model's own key error (trained with a tolerance: the predicted point error).
    EXPECT_NE(r.out.find("] predicted point error (calibrated for tolerance 0.02)"), std::string::npos)
        << r.out;
    const auto json = nlohmann::json::parse(pmsc::test::readBytes(report));
    const auto& s = json.at("summary");
    for (const char* key :
         {"frames", "points", "channels", "key_points", "basis", "eps_min", "eps_max", "hit_rate",
          "blend_rate", "miss_rate", "pm_max_point_error", "soft_max_point_error", "seconds",
          "points_evaluated_fraction"})  // the model has sentinels
        EXPECT_TRUE(s.contains(key)) << key;
    EXPECT_EQ(s.size(), 14u);
    EXPECT_EQ(s.at("frames"), 60);
    EXPECT_EQ(s.at("points"), 144);
    EXPECT_EQ(s.at("channels"), 3);
    EXPECT_NEAR(
        s.at("hit_rate").get<double>() + s.at("blend_rate").get<double>() + s.at("miss_rate").get<double>(),
        1.0, 1e-12);
    for (const char* which : {"pm_max_point_error", "soft_max_point_error"}) {
        const auto& p = s.at(which);
        EXPECT_EQ(p.size(), 4u);
        EXPECT_LE(p.at("p50").get<double>(), p.at("p99").get<double>());
        EXPECT_LE(p.at("p99").get<double>(), p.at("p995").get<double>());
        EXPECT_LE(p.at("p995").get<double>(), p.at("max").get<double>());
    }
    const pmsc::Model model = pmsc::readModel(model_);
    EXPECT_EQ(s.at("eps_min").get<double>(), model.epsMin);
    EXPECT_EQ(s.at("eps_max").get<double>(), model.epsMax);
    const auto& frames = json.at("frames");
    ASSERT_EQ(frames.size(), 60u);
    double worstSoft = 0;
    for (std::size_t i = 0; i < frames.size(); ++i) {
        const auto& f = frames[i];
        EXPECT_EQ(f.size(), 7u);
        EXPECT_EQ(f.at("frame"), static_cast<int>(i));
        const double evaluated = f.at("points_evaluated_fraction");
        EXPECT_TRUE(evaluated > 0 && evaluated <= 1) << evaluated;  // the sentinels at least
        const std::string state = f.at("state");
        const double w = f.at("weight"), key = f.at("key_rms");
        if (state == "hit") {
            EXPECT_LE(key, model.epsMin);
            EXPECT_EQ(w, 0.0);
            EXPECT_EQ(f.at("soft_max_point_error"), f.at("pm_max_point_error"));
        } else if (state == "miss") {
            EXPECT_GE(key, model.epsMax);
            EXPECT_EQ(w, 1.0);
            EXPECT_EQ(f.at("soft_max_point_error").get<double>(), 0.0);  // the recorded frame itself
        } else {
            ASSERT_EQ(state, "blend");
            EXPECT_NEAR(w, (key - model.epsMin) / (model.epsMax - model.epsMin), 1e-12);
            // (1 - w) PM's error, w raised where PM is over the tolerance.
            EXPECT_NEAR(f.at("soft_max_point_error").get<double>(),
                        pmsc::blendedError(w, f.at("pm_max_point_error").get<double>(), model.tolerance),
                        1e-6 * (1 + f.at("pm_max_point_error").get<double>()));
        }
        worstSoft = std::max(worstSoft, f.at("soft_max_point_error").get<double>());
    }
    EXPECT_EQ(s.at("soft_max_point_error").at("max").get<double>(), worstSoft);
    // The last 20 frames carry motion training never saw: the soft cache must not call them hits
    // once the motion is under way (it ramps in over the first 10).
    for (std::size_t i = 50; i < 60; ++i) EXPECT_NE(frames[i].at("state"), "hit") << "frame " << i;

    const auto written = pmsc::readFrames(out);
    EXPECT_EQ(written.dtype, pmsc::NpyDtype::Float32);  // same dtype as --frames
    EXPECT_EQ(written.frames.frames, 60);
    EXPECT_EQ(written.frames.points, 144);
    EXPECT_EQ(written.frames.channels, 3);
    const auto recorded = pmsc::readFrames(shot_->test32);
    for (std::size_t i = 50; i < 60; ++i) {
        if (frames[i].at("state") != "miss") continue;
        for (pmsc::Index v = 0; v < 432; ++v) {
            EXPECT_EQ(written.frames.frame(static_cast<pmsc::Index>(i))[v],
                      recorded.frames.frame(static_cast<pmsc::Index>(i))[v]);
        }
    }
    EXPECT_EQ(outputs(dir), (std::vector<std::string>{"out.npy", "report.json"}));
}

TEST_F(Cli, ReplayIsIdenticalForAnyThreadCount) {
    TempDir dir;
    std::vector<std::string> outs, frames;
    for (const char* threads : {"1", "2", "3"}) {
        const auto out = dir.file(std::string("out") + threads + ".npy");
        const auto report = dir.file(std::string("report") + threads + ".json");
        const RunResult r = runPmsc(dir, {"replay", "--model", model_, "--frames", shot_->test, "--threads",
                                          threads, "--out", out, "--report", report});
        ASSERT_EQ(r.exitCode, 0) << r.err;
        outs.push_back(pmsc::test::readBytes(out));
        frames.push_back(nlohmann::json::parse(pmsc::test::readBytes(report)).at("frames").dump());
    }
    EXPECT_EQ(outs[0], outs[1]);
    EXPECT_EQ(outs[0], outs[2]);
    EXPECT_EQ(frames[0], frames[1]);
    EXPECT_EQ(frames[0], frames[2]);
}

TEST_F(Cli, ReplayEpsOverridesTheModel) {
    TempDir dir;
    const auto report = dir.file("r.json");
    RunResult r = runPmsc(
        dir, {"replay", "--model", model_, "--frames", shot_->test, "--eps", "0,0", "--report", report});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    auto s = nlohmann::json::parse(pmsc::test::readBytes(report)).at("summary");
    EXPECT_EQ(s.at("eps_max").get<double>(), 0.0);
    EXPECT_EQ(s.at("miss_rate").get<double>(), 1.0);  // every key error > 0: all miss
    r = runPmsc(dir,
                {"replay", "--model", model_, "--frames", shot_->test, "--eps=1e9,1e9", "--report", report});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    // Every frame is a hit by the key error; the hit check (its sentinels) may still refuse one,
    // which then is a blend of weight 0: computed whole, PM wherever it is within T.
    const auto all = nlohmann::json::parse(pmsc::test::readBytes(report));
    EXPECT_EQ(all.at("summary").at("miss_rate").get<double>(), 0.0);
    for (const auto& f : all.at("frames")) {
        if (f.at("state") != "hit") {
            EXPECT_EQ(f.at("state"), "blend") << f.dump();
            EXPECT_EQ(f.at("weight").get<double>(), 0.0) << f.dump();
        }
    }
}

TEST_F(Cli, InspectTextAndJson) {
    TempDir dir;
    RunResult r = runPmsc(dir, {"inspect", model_});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const pmsc::Model m = pmsc::readModel(model_);
    EXPECT_NE(r.out.find("N = 144, channels C = 3"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("K = " + std::to_string(m.keyCount())), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("eps"), std::string::npos);
    r = runPmsc(dir, {"inspect", "--json", model_});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j.at("points"), 144);
    EXPECT_EQ(j.at("basis"), m.basisSize());
    EXPECT_EQ(j.at("key_indices").get<std::vector<long long>>(),
              std::vector<long long>(m.keyPoints.begin(), m.keyPoints.end()));
    EXPECT_EQ(j.at("singular_values").size(), static_cast<std::size_t>(m.basisSize()));
    EXPECT_EQ(j.at("eps_min").get<double>(), m.epsMin);
    EXPECT_EQ(j.at("tolerance").get<double>(), 0.02);
    EXPECT_NEAR(j.at("energy_captured").get<double>(), m.energyCaptured(), 1e-15);
}

TEST_F(Cli, DemoRunsEndToEnd) {
    TempDir dir;
    const auto out = dir.file("demo");
    const RunResult r =
        runPmsc(dir, {"demo", "synthetic", "--out", out, "--grid", "12", "--train-frames", "240",
                      "--test-frames", "60", "--novel-frames", "20", "--max-keys", "24"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    for (const char* f : {"train.npy", "test.npy", "model.pmsc", "report.json", "out.npy"})
        EXPECT_TRUE(fs::exists(fs::path(out) / f)) << f;
    for (const char* text : {"pmsc train", "pmsc replay", "hit", "blend", "miss", "p99.5", "eps", "faster"})
        EXPECT_NE(r.out.find(text), std::string::npos) << text << "\n" << r.out;
    EXPECT_EQ(fs::directory_iterator(out) == fs::directory_iterator(), false);
    std::size_t files = 0;
    for ([[maybe_unused]] const auto& e : fs::directory_iterator(out)) ++files;
    EXPECT_EQ(files, 5u);  // no temporary file left
}

TEST_F(Cli, HelpForEveryCommand) {
    TempDir dir;
    for (const std::string command : {"train", "replay", "inspect", "demo synthetic"}) {
        std::vector<std::string> args;
        for (std::size_t start = 0;;) {
            const auto space = command.find(' ', start);
            args.push_back(command.substr(start, space - start));
            if (space == std::string::npos) break;
            start = space + 1;
        }
        args.push_back("--help");
        const RunResult r = runPmsc(dir, args);
        EXPECT_EQ(r.exitCode, 0);
        EXPECT_NE(r.out.find("usage: pmsc " + command + " "), std::string::npos) << r.out;
        EXPECT_EQ(r.err, "");
    }
    RunResult r = runPmsc(dir, {"--help"});
    EXPECT_EQ(r.exitCode, 0);
    EXPECT_NE(r.out.find("replay"), std::string::npos);
    r = runPmsc(dir, {});
    EXPECT_EQ(r.exitCode, 2);
}

// ---- bad input: exit 2, one line, nothing written ----------------------------------------------

TEST_F(Cli, MissingFramesFile) {
    TempDir dir;
    const RunResult r =
        runPmsc(dir, {"train", "--frames", dir.file("nope.npy"), "--out", dir.file("m.pmsc")});
    expectFailure(r, 2, {dir.file("nope.npy"), "no such file"});
    EXPECT_TRUE(outputs(dir).empty());
}

TEST_F(Cli, TruncatedFrames) {
    TempDir dir;
    const std::string bytes = pmsc::test::readBytes(shot_->train);
    pmsc::test::writeBytes(dir.file("cut.npy"), bytes.substr(0, bytes.size() - 100));
    const RunResult r = runPmsc(dir, {"train", "--frames", dir.file("cut.npy"), "--out", dir.file("m.pmsc")});
    expectFailure(r, 2, {"cut.npy", "truncated data"});
    EXPECT_EQ(outputs(dir), std::vector<std::string>{"cut.npy"});
}

TEST_F(Cli, NanInFrames) {
    TempDir dir;
    std::string bytes = pmsc::test::readBytes(shot_->test);
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const std::size_t value = (7 * 144 + 33) * 3 + 2;  // frame 7, point 33, channel 2
    std::memcpy(bytes.data() + bytes.size() - 8 * (60 * 144 * 3 - value), &nan, 8);
    pmsc::test::writeBytes(dir.file("nan.npy"), bytes);
    const RunResult r = runPmsc(dir, {"replay", "--model", model_, "--frames", dir.file("nan.npy"), "--out",
                                      dir.file("out.npy"), "--report", dir.file("r.json")});
    expectFailure(r, 2, {"nan.npy", "NaN at frame 7, point 33, channel 2"});
    EXPECT_EQ(outputs(dir), std::vector<std::string>{"nan.npy"});
}

TEST_F(Cli, WrongDtype) {
    TempDir dir;
    std::string bytes = pmsc::test::readBytes(shot_->train);
    const auto at = bytes.find("<f8");
    ASSERT_NE(at, std::string::npos);
    bytes.replace(at, 3, "<i8");
    pmsc::test::writeBytes(dir.file("int.npy"), bytes);
    const RunResult r = runPmsc(dir, {"train", "--frames", dir.file("int.npy"), "--out", dir.file("m.pmsc")});
    expectFailure(r, 2, {"int.npy", "unsupported dtype '<i8'"});
    EXPECT_EQ(outputs(dir), std::vector<std::string>{"int.npy"});
}

TEST_F(Cli, CorruptedModel) {
    TempDir dir;
    std::string bytes = pmsc::test::readBytes(model_);
    bytes[bytes.size() / 2] ^= 0x10;
    pmsc::test::writeBytes(dir.file("bad.pmsc"), bytes);
    RunResult r = runPmsc(dir, {"replay", "--model", dir.file("bad.pmsc"), "--frames", shot_->test, "--out",
                                dir.file("out.npy"), "--report", dir.file("r.json")});
    expectFailure(r, 2, {"bad.pmsc", "checksum mismatch"});
    r = runPmsc(dir, {"inspect", dir.file("bad.pmsc")});
    expectFailure(r, 2, {"bad.pmsc", "checksum mismatch"});
    pmsc::test::writeBytes(dir.file("bad.pmsc"), bytes.substr(0, 1000));
    r = runPmsc(dir, {"inspect", dir.file("bad.pmsc")});
    expectFailure(r, 2, {"bad.pmsc", "truncated"});
    EXPECT_EQ(outputs(dir), std::vector<std::string>{"bad.pmsc"});
}

TEST_F(Cli, PointCountMismatch) {
    TempDir dir;
    pmsc::synthetic::SurfaceOptions o;
    o.grid = 11;
    o.frames = 5;
    pmsc::writeFrames(dir.file("other.npy"), pmsc::evaluateFrames(pmsc::synthetic::SyntheticSurface(o), 0, 5),
                      pmsc::NpyDtype::Float64);
    const RunResult r = runPmsc(dir, {"replay", "--model", model_, "--frames", dir.file("other.npy"), "--out",
                                      dir.file("out.npy"), "--report", dir.file("r.json")});
    expectFailure(r, 2, {"other.npy", "121 points", "144 points"});
    EXPECT_EQ(outputs(dir), std::vector<std::string>{"other.npy"});
}

TEST_F(Cli, UsageMistakes) {
    TempDir dir;
    const auto out = dir.file("m.pmsc");
    expectFailure(runPmsc(dir, {"train", "--frames", shot_->train, "--out", out, "--bogus", "1"}), 2,
                  {"unknown option '--bogus'", "pmsc train --help"});
    expectFailure(runPmsc(dir, {"train", "--frames", shot_->train, "--out"}), 2, {"missing value for --out"});
    expectFailure(runPmsc(dir, {"train", "--frames", shot_->train}), 2, {"missing --out"});
    expectFailure(runPmsc(dir, {"train", "--frames", shot_->train, "--out", out, "--basis", "ten"}), 2,
                  {"--basis", "'ten' is not an integer"});
    expectFailure(
        runPmsc(dir, {"train", "--frames", shot_->train, "--out", out, "--basis", "4", "--energy", "0.9"}), 2,
        {"at most one of --basis, --energy"});
    expectFailure(runPmsc(dir, {"train", "--frames", shot_->train, "--out", out, "--selector", "best"}), 2,
                  {"'best' is not teleconnection or qdeim"});
    expectFailure(runPmsc(dir, {"train", "--frames", shot_->train, "--out", out, "--energy", "1.5"}), 2,
                  {"--energy", "out of range"});
    expectFailure(runPmsc(dir, {"train", "--frames", shot_->train, "--out", out, "--regions", "2",
                                "--region-keys", "-1"}),
                  2, {"--region-keys", "out of range"});
    expectFailure(runPmsc(dir, {"train", "--frames", shot_->train, "--out", out, "--regions", "2",
                                "--region-keys", "2.5"}),
                  2, {"--region-keys", "'2.5' is not an integer"});
    expectFailure(runPmsc(dir, {"train", "--frames", shot_->train, "--out", out, "--key-error", "median"}), 2,
                  {"--key-error", "'median' is not predicted, rms, largest or loo"});
    expectFailure(runPmsc(dir, {"train", "--frames", shot_->train, "--out", out, "--key-error", "loo",
                                "--shared-channels"}),
                  2, {"--key-error loo needs channels of their own"});
    expectFailure(runPmsc(dir, {"train", "--frames", shot_->train, "--out", out, "--key-error", "predicted"}),
                  2, {"--key-error predicted needs --tolerance"});
    expectFailure(runPmsc(dir, {"frobnicate"}), 2, {"unknown command 'frobnicate'"});
    expectFailure(runPmsc(dir, {"view", "--model", out, "--allow-origin", "notebook:8888"}), 2,
                  {"--allow-origin", "'notebook:8888' is not an origin"});
    {
        // A config file's mistakes are the command line's: one line, exit 2, nothing written.
        const TempDir configDir;
        const std::string config = configDir.file("job.toml");
        std::ofstream(config) << "[train]\ntolerence = 0.1\n";
        expectFailure(runPmsc(dir, {"train", "--config", config, "--frames", shot_->train, "--out", out}), 2,
                      {"--config " + config + ": 'tolerence' is not an option of pmsc train"});
        EXPECT_FALSE(std::filesystem::exists(out));
    }
    expectFailure(runPmsc(dir, {"inspect"}), 2, {"missing MODEL.pmsc"});
    EXPECT_TRUE(outputs(dir).empty());
}

// --key-error loo: the model keeps the measure, calibrated in it, and says so.
TEST_F(Cli, TrainWithTheLeaveOneOutKeyError) {
    TempDir dir;
    const auto model = dir.file("m.pmsc");
    const RunResult r = runPmsc(
        dir, {"train", "--frames", shot_->train, "--out", model, "--basis", "8", "--max-keys", "16",
              "--tolerance", "0.05", "--calibration", "threshold", "--key-error", "loo", "--regions", "0"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("largest leave-one-out key error, calibrated for tolerance 0.05"), std::string::npos)
        << r.out;
    const pmsc::Model m = pmsc::readModel(model);
    EXPECT_EQ(m.keyErrorNorm, pmsc::KeyErrorNorm::LeaveOneOut);
    EXPECT_GT(m.epsMin, 0);
    const RunResult inspect = runPmsc(dir, {"inspect", model});
    EXPECT_NE(inspect.out.find("largest leave-one-out key error (data units)"), std::string::npos)
        << inspect.out;
}

// The demo commands parse numbers with Args' converters, as every other command does: face's
// "--threads 2.5" and "--regions 1e1" and cornell's " 2" (with its blank) are each a usage error
// (exit 2, one line) before any data is read, so no ICT data or scene is needed here.
TEST_F(Cli, DemoNumbersGoThroughArgs) {
    TempDir dir;
    const std::vector<std::string> face{"demo", "face", "--data", dir.file("ict"), "--out", dir.file("face")};
    const auto with = [](std::vector<std::string> args, std::initializer_list<std::string> more) {
        args.insert(args.end(), more);
        return args;
    };
    expectFailure(runPmsc(dir, with(face, {"--threads", "2.5"})), 2,
                  {"--threads", "'2.5' is not an integer"});
    expectFailure(runPmsc(dir, with(face, {"--basis", "4.7"})), 2, {"--basis", "'4.7' is not an integer"});
    expectFailure(runPmsc(dir, with(face, {"--regions", "1e1"})), 2,
                  {"--regions", "'1e1' is not an integer"});
    expectFailure(runPmsc(dir, with(face, {"--seed", "-3"})), 2, {"--seed", "out of range"});
    expectFailure(runPmsc(dir, with(face, {"--seed", "7x"})), 2, {"--seed", "'7x' is not an integer"});
    expectFailure(runPmsc(dir, with(face, {"--tolerance", "0"})), 2, {"--tolerance", "out of range"});
    expectFailure(runPmsc(dir, with(face, {"--tolerance", "1%"})), 2,
                  {"--tolerance", "'1%' is not a number"});
    expectFailure(runPmsc(dir, with(face, {"--key-error", "median"})), 2,
                  {"--key-error", "'median' is not predicted, rms, largest or loo"});
    expectFailure(runPmsc(dir, with(face, {"--calibration", "best"})), 2,
                  {"--calibration", "'best' is not threshold, max or conformal"});
    const std::vector<std::string> cornell{"demo", "cornell", "--quick", "--out", dir.file("cornell")};
    expectFailure(runPmsc(dir, with(cornell, {"--threads", " 2"})), 2, {"--threads", "is not an integer"});
    expectFailure(runPmsc(dir, with(cornell, {"--points", "10"})), 2, {"--points", "out of range"});
    EXPECT_TRUE(outputs(dir).empty());
}

TEST_F(Cli, BadEps) {
    TempDir dir;
    for (const char* eps : {"0.2,0.1", "abc", "0.1", "-1,2", "0.1,inf", "0.1,0.2,0.3"}) {
        const RunResult r = runPmsc(dir, {"replay", "--model", model_, "--frames", shot_->test, "--eps", eps,
                                          "--out", dir.file("out.npy"), "--report", dir.file("r.json")});
        expectFailure(r, 2, {"--eps"});
    }
    EXPECT_TRUE(outputs(dir).empty());
}

TEST_F(Cli, UnwritableOutputIsExitFour) {
    TempDir dir;
    RunResult r = runPmsc(dir, {"train", "--frames", shot_->train, "--out", dir.file("missing/m.pmsc")});
    expectFailure(r, 4, {"cannot write output", "missing/m.pmsc"});
    r = runPmsc(
        dir, {"replay", "--model", model_, "--frames", shot_->test, "--report", dir.file("missing/r.json")});
    expectFailure(r, 4, {"missing/r.json"});
    EXPECT_TRUE(outputs(dir).empty());
}

TEST_F(Cli, TrainingUnusableDataIsBadInput) {
    TempDir dir;
    pmsc::FrameSet same(4, 10, 3);  // four identical frames: nothing to learn
    pmsc::writeFrames(dir.file("same.npy"), same, pmsc::NpyDtype::Float64);
    const RunResult r =
        runPmsc(dir, {"train", "--frames", dir.file("same.npy"), "--out", dir.file("m.pmsc")});
    expectFailure(r, 2, {});
    EXPECT_EQ(outputs(dir), std::vector<std::string>{"same.npy"});
}

TEST_F(Cli, InterruptLeavesNoOutputAndExits130) {
    TempDir dir;
    // SIGINT after 2 s: long after the program installed its handler (starting the binary, which
    // loads OpenVDB, Embree, Assimp and MPI, took 0.3 s on a loaded 2-core machine, and a 0.3 s
    // delay then killed it before main()), and long before this training ends (15 s of CPU).
    pmsc::synthetic::SurfaceOptions o;
    o.grid = 64;
    o.frames = 1500;
    pmsc::writeFrames(dir.file("big.npy"),
                      pmsc::evaluateFrames(pmsc::synthetic::SyntheticSurface(o), 0, o.frames),
                      pmsc::NpyDtype::Float32);
    const RunResult r = runPmsc(
        dir, {"train", "--frames", dir.file("big.npy"), "--out", dir.file("m.pmsc"), "--tolerance", "0.01"},
        "timeout --preserve-status -s INT 2");
    expectFailure(r, 130, {"interrupted"});
    EXPECT_EQ(outputs(dir), std::vector<std::string>{"big.npy"});
}

}  // namespace
