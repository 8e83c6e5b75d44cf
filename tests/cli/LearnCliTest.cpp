// `pmsc learn`, `--keep-misses` (replay and run) and the calibration options of `pmsc train`, through
// the real binary: success paths, appending across runs, and bad inputs.
#include "evaluators/synthetic/SyntheticSurface.h"
#include "pmsc/KeptFrames.h"
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"
#include "pmsc/Sentinels.h"
#include "tests/common/CliRunner.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>

namespace {

using pmsc::test::runPmsc;
using pmsc::test::RunResult;
using pmsc::test::TempDir;
namespace fs = std::filesystem;

class LearnCli : public ::testing::Test {
protected:
    static void SetUpTestSuite() {
        dir_ = new TempDir;
        pmsc::synthetic::SurfaceOptions o;
        o.grid = 12;
        o.frames = 200;
        o.seed = 1;
        pmsc::writeFrames(dir_->file("train.npy"),
                          pmsc::evaluateFrames(pmsc::synthetic::SyntheticSurface(o), 0, o.frames),
                          pmsc::NpyDtype::Float64);
        o.frames = 60;
        o.seed = 2;
        o.novelFrames = 30;  // the last 30 frames carry motion training never saw: misses
        pmsc::writeFrames(dir_->file("test.npy"),
                          pmsc::evaluateFrames(pmsc::synthetic::SyntheticSurface(o), 0, o.frames),
                          pmsc::NpyDtype::Float64);
        const RunResult r =
            runPmsc(*dir_, {"train", "--frames", dir_->file("train.npy"), "--out", dir_->file("m.pmsc"),
                            "--max-keys", "24", "--tolerance", "0.02", "--calibration", "conformal",
                            "--coverage", "0.9", "--learn-rank", "30"});
        ASSERT_EQ(r.exitCode, 0) << r.err;
        ASSERT_NE(r.out.find("conformal"), std::string::npos) << r.out;
    }
    static void TearDownTestSuite() { delete dir_; }

    static void expectFailure(const RunResult& r, int code, std::initializer_list<std::string> fragments) {
        EXPECT_EQ(r.exitCode, code) << r.err;
        const auto lines = r.errLines();
        ASSERT_EQ(lines.size(), 1u) << r.err;
        EXPECT_EQ(lines[0].rfind("pmsc: ", 0), 0u) << lines[0];
        for (const auto& f : fragments) EXPECT_NE(lines[0].find(f), std::string::npos) << lines[0];
    }
    static nlohmann::json readJson(const std::string& path) {
        std::ifstream in(path);
        return nlohmann::json::parse(in);
    }
    static std::vector<pmsc::Index> nonHits(const nlohmann::json& report) {
        std::vector<pmsc::Index> frames;
        for (const auto& f : report.at("frames"))
            if (f.at("state") != "hit") frames.push_back(f.at("frame").get<pmsc::Index>());
        return frames;
    }

    static TempDir* dir_;
};

TempDir* LearnCli::dir_ = nullptr;

TEST_F(LearnCli, ReplayKeepsMissesAppendsAndLearnUsesThem) {
    TempDir work;
    const std::string kept = work.file("kept.npy");
    RunResult r =
        runPmsc(work, {"replay", "--model", dir_->file("m.pmsc"), "--frames", dir_->file("test.npy"),
                       "--report", work.file("r.json"), "--keep-misses", kept, "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const std::vector<pmsc::Index> missed = nonHits(readJson(work.file("r.json")));
    ASSERT_GE(missed.size(), 20u);  // the unseen motion at least
    EXPECT_EQ(pmsc::readKeptFrameNumbers(kept), missed);
    const pmsc::FrameFile keptFrames = pmsc::readFrames(kept);
    const pmsc::FrameFile test = pmsc::readFrames(dir_->file("test.npy"));
    ASSERT_EQ(keptFrames.frames.frames, static_cast<pmsc::Index>(missed.size()));
    // Kept are the recorded (full) values, not the blended output.
    for (size_t i = 0; i < missed.size(); ++i)
        for (pmsc::Index v = 0; v < test.frames.rows(); ++v)
            ASSERT_EQ(keptFrames.frames.frame(static_cast<pmsc::Index>(i))[v],
                      test.frames.frame(missed[i])[v]);

    // A second run appends.
    r = runPmsc(work, {"replay", "--model", dir_->file("m.pmsc"), "--frames", dir_->file("test.npy"),
                       "--report", work.file("r2.json"), "--keep-misses", kept, "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(pmsc::readFrames(kept).frames.frames, static_cast<pmsc::Index>(2 * missed.size()));
    EXPECT_EQ(pmsc::readKeptFrameNumbers(kept).size(), 2 * missed.size());

    // learn, then the learned model replays the unseen motion with fewer misses.
    r = runPmsc(work, {"learn", "--model", dir_->file("m.pmsc"), "--frames", kept, "--out",
                       work.file("m2.pmsc"), "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("learned"), std::string::npos) << r.out;
    const pmsc::Model m2 = pmsc::readModel(work.file("m2.pmsc"));
    EXPECT_EQ(m2.trainFrames, 200 + static_cast<pmsc::Index>(2 * missed.size()));
    r = runPmsc(work, {"replay", "--model", work.file("m2.pmsc"), "--frames", dir_->file("test.npy"),
                       "--report", work.file("r3.json"), "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const auto after = readJson(work.file("r3.json")).at("summary");
    EXPECT_GT(after.at("hit_rate").get<double>(),
              readJson(work.file("r.json")).at("summary").at("hit_rate").get<double>());
}

TEST_F(LearnCli, RunKeepsMissesWithTheirFullValues) {
    TempDir work;
    const std::string kept = work.file("kept.npy");
    const RunResult r = runPmsc(
        work, {"run", "--model", dir_->file("m.pmsc"), "--evaluator", "replay:" + dir_->file("test.npy"),
               "--frames", "20-59", "--out", work.file("frames"), "--keep-misses", kept, "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const auto stats = readJson(work.file("frames/pmsc-run.20-59.json"));
    std::vector<pmsc::Index> missed;
    for (const auto& f : stats.at("per_frame"))
        if (f.at("state") == "blend" || f.at("state") == "miss")
            missed.push_back(f.at("frame").get<pmsc::Index>());
    ASSERT_FALSE(missed.empty());
    EXPECT_EQ(stats.at("kept_misses").at("frames").get<size_t>(), missed.size());
    EXPECT_EQ(pmsc::readKeptFrameNumbers(kept), missed);
    const pmsc::FrameFile keptFrames = pmsc::readFrames(kept),
                          test = pmsc::readFrames(dir_->file("test.npy"));
    for (size_t i = 0; i < missed.size(); ++i)
        for (pmsc::Index v = 0; v < test.frames.rows(); ++v)
            ASSERT_EQ(keptFrames.frames.frame(static_cast<pmsc::Index>(i))[v],
                      test.frames.frame(missed[i])[v]);
}

TEST_F(LearnCli, PositionsTheModelWasTrainedWithChooseItsSentinelsAgain) {
    TempDir work;
    // The training frames' first frame as the points' positions (a point table).
    const pmsc::FrameSet train = pmsc::readFrames(dir_->file("train.npy")).frames;
    pmsc::FrameSet positions(1, train.points, 3);
    std::copy(train.frame(0), train.frame(0) + positions.values.size(), positions.values.begin());
    pmsc::writeFrames(work.file("p.npy"), positions, pmsc::NpyDtype::Float64);
    RunResult r = runPmsc(work, {"train", "--frames", dir_->file("train.npy"), "--out",
                                 work.file("given.pmsc"), "--max-keys", "24", "--tolerance", "0.02",
                                 "--learn-rank", "30", "--positions", work.file("p.npy"), "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    ASSERT_EQ(pmsc::readModel(work.file("given.pmsc")).sentinels->source, pmsc::SentinelSource::Given);

    r = runPmsc(work, {"learn", "--model", work.file("given.pmsc"), "--frames", dir_->file("test.npy"),
                       "--out", work.file("kept.pmsc"), "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("learn with the same --positions to choose them again"), std::string::npos) << r.out;
    EXPECT_NO_THROW(pmsc::readModel(work.file("kept.pmsc")));
    r = runPmsc(work, {"learn", "--model", work.file("given.pmsc"), "--frames", dir_->file("test.npy"),
                       "--out", work.file("again.pmsc"), "--positions", work.file("p.npy"), "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(r.out.find("--positions"), std::string::npos) << r.out;
    const pmsc::Model again = pmsc::readModel(work.file("again.pmsc"));
    ASSERT_TRUE(again.sentinels.has_value());
    EXPECT_EQ(again.sentinels->source, pmsc::SentinelSource::Given);

    // Positions of another size, a file that is not there, a model that took nothing from positions.
    pmsc::writeFrames(work.file("short.npy"), pmsc::FrameSet(1, train.points - 1, 3),
                      pmsc::NpyDtype::Float64);
    r = runPmsc(work, {"learn", "--model", work.file("given.pmsc"), "--frames", dir_->file("test.npy"),
                       "--out", work.file("bad.pmsc"), "--positions", work.file("short.npy")});
    expectFailure(r, 2, {"learn: --positions", "short.npy", std::to_string(train.points) + " rows"});
    r = runPmsc(work, {"learn", "--model", work.file("given.pmsc"), "--frames", dir_->file("test.npy"),
                       "--out", work.file("bad.pmsc"), "--positions", work.file("none.npy")});
    expectFailure(r, 2, {"none.npy"});
    r = runPmsc(work, {"learn", "--model", dir_->file("m.pmsc"), "--frames", dir_->file("test.npy"), "--out",
                       work.file("bad.pmsc"), "--positions", work.file("p.npy")});
    expectFailure(r, 2, {"give no positions"});
    EXPECT_FALSE(fs::exists(work.file("bad.pmsc")));
}

// A model with regions keeps them through learn, unless --no-regions drops them.
TEST_F(LearnCli, AModelWithRegionsKeepsThemUnlessToldToDropThem) {
    TempDir work;
    RunResult r = runPmsc(
        work, {"train", "--frames", dir_->file("train.npy"), "--out", work.file("r.pmsc"), "--max-keys", "24",
               "--tolerance", "0.02", "--learn-rank", "30", "--regions", "3", "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const pmsc::Model trained = pmsc::readModel(work.file("r.pmsc"));
    ASSERT_TRUE(trained.regions.has_value());
    r = runPmsc(work, {"learn", "--model", work.file("r.pmsc"), "--frames", dir_->file("test.npy"), "--out",
                       work.file("kept.pmsc"), "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("regions     " + std::to_string(trained.regions->regionCount()) + " kept"),
              std::string::npos)
        << r.out;
    const pmsc::Model kept = pmsc::readModel(work.file("kept.pmsc"));
    ASSERT_TRUE(kept.regions.has_value());
    EXPECT_EQ(kept.regions->regionCount(), trained.regions->regionCount());
    r = runPmsc(work, {"learn", "--model", work.file("r.pmsc"), "--frames", dir_->file("test.npy"), "--out",
                       work.file("dropped.pmsc"), "--no-regions", "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(r.out.find("regions "), std::string::npos) << r.out;
    EXPECT_FALSE(pmsc::readModel(work.file("dropped.pmsc")).regions.has_value());
}

TEST_F(LearnCli, BadInputsFailWithOneLineAndLeaveFilesAlone) {
    TempDir work;
    // Kept frames of another shape: refused before any work, the old files untouched.
    pmsc::FrameSet other(2, 5, 3);
    pmsc::writeFrames(work.file("other.npy"), other, pmsc::NpyDtype::Float64);
    {
        std::ofstream side(pmsc::KeptFrames::sidecarPath(work.file("other.npy")));
        side << "# pmsc kept frames\n0\tmiss\t1\tx\n1\tmiss\t1\tx\n";
    }
    const auto before = fs::file_size(work.file("other.npy"));
    RunResult r =
        runPmsc(work, {"replay", "--model", dir_->file("m.pmsc"), "--frames", dir_->file("test.npy"),
                       "--report", work.file("r.json"), "--keep-misses", work.file("other.npy")});
    expectFailure(r, 2, {"other.npy", "5 points"});
    // A sidecar that disagrees with its frames is refused too.
    {
        std::ofstream side(pmsc::KeptFrames::sidecarPath(work.file("other.npy")));
        side << "# pmsc kept frames\n0\tmiss\t1\tx\n";
    }
    pmsc::FrameSet same(2, 144, 3);
    pmsc::writeFrames(work.file("other.npy"), same, pmsc::NpyDtype::Float64);
    r = runPmsc(work, {"replay", "--model", dir_->file("m.pmsc"), "--frames", dir_->file("test.npy"),
                       "--report", work.file("r.json"), "--keep-misses", work.file("other.npy")});
    expectFailure(r, 2, {"lists 1 frames", "holds 2"});
    pmsc::writeFrames(work.file("other.npy"), other, pmsc::NpyDtype::Float64);
    EXPECT_EQ(fs::file_size(work.file("other.npy")), before);
    EXPECT_FALSE(fs::exists(work.file("r.json")));
    r = runPmsc(work, {"learn", "--model", dir_->file("m.pmsc"), "--frames", work.file("other.npy"), "--out",
                       work.file("m2.pmsc")});
    expectFailure(r, 2, {"5 points"});
    EXPECT_FALSE(fs::exists(work.file("m2.pmsc")));
    r = runPmsc(work, {"learn", "--model", work.file("missing.pmsc"), "--frames", dir_->file("test.npy"),
                       "--out", work.file("m2.pmsc")});
    expectFailure(r, 2, {"missing.pmsc"});
    r = runPmsc(work, {"learn", "--model", dir_->file("m.pmsc"), "--frames", dir_->file("test.npy") + ",",
                       "--out", work.file("m2.pmsc")});
    expectFailure(r, 2, {"--frames"});
    r = runPmsc(work, {"learn", "--model", dir_->file("m.pmsc"), "--frames", dir_->file("test.npy"), "--out",
                       work.file("no/such/dir/m2.pmsc")});
    expectFailure(r, 4, {"m2.pmsc"});
    r = runPmsc(work, {"learn", "--model", dir_->file("m.pmsc"), "--frames", dir_->file("test.npy"), "--out",
                       work.file("m2.pmsc"), "--calibration", "median"});
    expectFailure(r, 2, {"--calibration", "median"});
    for (const char* energy : {"0", "1.5", "x"}) {
        r = runPmsc(work, {"learn", "--model", dir_->file("m.pmsc"), "--frames", dir_->file("test.npy"),
                           "--out", work.file("m2.pmsc"), "--energy", energy});
        expectFailure(r, 2, {"--energy"});
    }
    r = runPmsc(work, {"learn", "--model", dir_->file("m.pmsc"), "--frames", dir_->file("test.npy"), "--out",
                       work.file("m2.pmsc"), "--energy", "0.99", "--basis", "4"});
    expectFailure(r, 2, {"--basis", "--energy"});
    r = runPmsc(work, {"learn", "--model", dir_->file("m.pmsc"), "--frames", dir_->file("test.npy"), "--out",
                       work.file("m2.pmsc"), "--slices", "1"});
    expectFailure(r, 2, {"--slices"});
    EXPECT_FALSE(fs::exists(work.file("m2.pmsc")));
    r = runPmsc(work, {"train", "--frames", dir_->file("train.npy"), "--out", work.file("t.pmsc"),
                       "--tolerance", "0.02", "--calibration", "max", "--coverage", "0.9"});
    expectFailure(r, 2, {"--coverage", "conformal"});
    r = runPmsc(work, {"train", "--frames", dir_->file("train.npy"), "--out", work.file("t.pmsc"),
                       "--tolerance", "0.02", "--calibration", "conformal", "--coverage", "1"});
    expectFailure(r, 2, {"--coverage"});
    r = runPmsc(work, {"train", "--frames", dir_->file("train.npy"), "--out", work.file("t.pmsc"),
                       "--calibration", "conformal"});
    expectFailure(r, 2, {"--tolerance"});
    EXPECT_FALSE(fs::exists(work.file("t.pmsc")));
}

}  // namespace
