// `pmsc reconstruct` end to end: the soft cache driven pass by pass through files, with a
// "renderer" that answers each pass from recorded frames (NaN everywhere it was not asked), must
// give `pmsc replay`'s output and states byte for byte; and every bad input is one line.
#include "SyntheticShot.h"
#include "evaluators/synthetic/SyntheticSurface.h"
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"
#include "tests/common/CliRunner.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <limits>

namespace {

using pmsc::Index;
using pmsc::test::readBytes;
using pmsc::test::runPmsc;
using pmsc::test::RunResult;
using pmsc::test::TempDir;
using json = nlohmann::json;

/// The shared generated shot, and the two models the tests drive.
struct ReconstructShot : pmsc::test::SyntheticShot {
    TempDir& dir = inputs;
    std::string plain = inputs.file("plain.pmsc"), regions = inputs.file("regions.pmsc");
};

json readJson(const std::string& path) {
    std::ifstream in(path);
    return json::parse(in);
}

/// The frames' values at the model's keys: what a renderer's first pass computes.
pmsc::FrameSet keyValues(const pmsc::FrameSet& frames, const pmsc::Model& model) {
    pmsc::FrameSet keys(frames.frames, model.keyCount(), frames.channels);
    for (Index f = 0; f < frames.frames; ++f)
        for (Index k = 0; k < model.keyCount(); ++k)
            for (Index c = 0; c < frames.channels; ++c)
                keys.frame(f)[k * frames.channels + c] =
                    frames.frame(f)[model.keyPoints[size_t(k)] * frames.channels + c];
    return keys;
}

/// A renderer's answer to a pass: the recorded values at the points each frame needs, NaN elsewhere.
pmsc::FrameSet answer(const pmsc::FrameSet& frames, const json& report) {
    pmsc::FrameSet out(frames.frames, frames.points, frames.channels);
    std::fill(out.values.begin(), out.values.end(), std::numeric_limits<double>::quiet_NaN());
    for (const auto& row : report["frames"]) {
        const Index f = row["frame"].get<Index>();
        for (const auto& p : row["needs"])
            for (Index c = 0; c < frames.channels; ++c)
                out.frame(f)[p.get<Index>() * frames.channels + c] =
                    frames.frame(f)[p.get<Index>() * frames.channels + c];
    }
    return out;
}

class Reconstruct : public ::testing::Test {
protected:
    static void SetUpTestSuite() {
        shot_ = new ReconstructShot;
        for (const auto& [model, extra] :
             {std::pair{shot_->plain, std::vector<std::string>{}},
              std::pair{shot_->regions, std::vector<std::string>{"--regions", "4"}}}) {
            // The paper's key RMS and the largest-ratio rule: on this shot they send novel frames to
            // the full calculation whole, so the region model has frames that go local. No sentinels:
            // a hit takes its keys' pass alone.
            std::vector<std::string> args = {"train", "--frames",      shot_->train, "--out",
                                             model,   "--max-keys",    "24",         "--tolerance",
                                             "0.1",   "--calibration", "max",        "--key-error",
                                             "rms",   "--sentinels",   "0"};
            args.insert(args.end(), extra.begin(), extra.end());
            const RunResult r = runPmsc(shot_->dir, args);
            ASSERT_EQ(r.exitCode, 0) << r.err;
        }
    }
    static void TearDownTestSuite() { delete shot_; }

    /// Passes until no frame needs anything; returns how many answers it took.
    static int drivePasses(const TempDir& dir, const std::string& model,
                           std::vector<std::string> extra = {}) {
        const pmsc::Model m = pmsc::readModel(model);
        pmsc::writeFrames(dir.file("keys.npy"), keyValues(shot_->recorded, m), pmsc::NpyDtype::Float64);
        std::vector<std::string> fulls;
        for (int pass = 0; pass < 5; ++pass) {
            std::vector<std::string> args = {"reconstruct",
                                             "--model",
                                             model,
                                             "--keys",
                                             dir.file("keys.npy"),
                                             "--out",
                                             dir.file("out.npy"),
                                             "--report",
                                             dir.file("passes.json")};
            for (const auto& f : fulls) args.insert(args.end(), {"--full", f});
            args.insert(args.end(), extra.begin(), extra.end());
            const RunResult r = runPmsc(dir, args);
            EXPECT_EQ(r.exitCode, 0) << r.err;
            const json report = readJson(dir.file("passes.json"));
            if (report["summary"]["complete"].get<bool>()) return pass;
            fulls.push_back(dir.file("full" + std::to_string(pass) + ".npy"));
            pmsc::writeFrames(fulls.back(), answer(shot_->recorded, report), pmsc::NpyDtype::Float64);
        }
        ADD_FAILURE() << "no end after 5 passes";
        return -1;
    }

    /// pmsc replay on the same frames, and the comparison: output bytes and states.
    static void expectSameAsReplay(const TempDir& dir, const std::string& model,
                                   std::vector<std::string> extra = {}) {
        std::vector<std::string> args = {"replay",
                                         "--model",
                                         model,
                                         "--frames",
                                         shot_->test,
                                         "--out",
                                         dir.file("replay.npy"),
                                         "--report",
                                         dir.file("replay.json")};
        args.insert(args.end(), extra.begin(), extra.end());
        const RunResult r = runPmsc(dir, args);
        ASSERT_EQ(r.exitCode, 0) << r.err;
        EXPECT_EQ(readBytes(dir.file("out.npy")), readBytes(dir.file("replay.npy")));
        const json replay = readJson(dir.file("replay.json")), passes = readJson(dir.file("passes.json"));
        ASSERT_EQ(replay["frames"].size(), passes["frames"].size());
        for (size_t i = 0; i < replay["frames"].size(); ++i) {
            EXPECT_EQ(replay["frames"][i]["state"], passes["frames"][i]["state"]) << "frame " << i;
            EXPECT_EQ(replay["frames"][i]["key_rms"], passes["frames"][i]["key_rms"]) << "frame " << i;
            if (replay["frames"][i].contains("regions")) {
                EXPECT_EQ(replay["frames"][i]["regions"], passes["frames"][i]["regions"]) << "frame " << i;
            }
        }
    }

    static ReconstructShot* shot_;
};

ReconstructShot* Reconstruct::shot_ = nullptr;

TEST_F(Reconstruct, PlainModelTakesOnePassAndEqualsReplayByteForByte) {
    TempDir dir;
    EXPECT_EQ(drivePasses(dir, shot_->plain), 1);
    expectSameAsReplay(dir, shot_->plain);
    const json report = readJson(dir.file("passes.json"));
    Index hits = 0;
    for (const auto& row : report["frames"]) {
        if (row["state"] != "hit") continue;
        ++hits;
        EXPECT_EQ(row["passes"], 0);  // a hit costs the renderer its keys only
        EXPECT_EQ(row["points_answered"], 0);
    }
    EXPECT_GT(hits, 0);
    EXPECT_LT(hits, 60);  // the novel frames do not hit
}

TEST_F(Reconstruct, RegionModelAsksRegionKeysThenFailingRegionsAndEqualsReplay) {
    TempDir dir;
    const int passes = drivePasses(dir, shot_->regions);
    EXPECT_GE(passes, 1);
    EXPECT_LE(passes, 2);
    expectSameAsReplay(dir, shot_->regions);
    bool anyLocal = false;
    std::string routes;
    const json report = readJson(dir.file("passes.json"));
    for (const auto& row : report["frames"]) {
        anyLocal |= row.value("local", false);
        routes += row.dump() + "\n";
    }
    EXPECT_TRUE(anyLocal) << "no frame took the local route: the test does not cover it\n" << routes;
}

TEST_F(Reconstruct, WholeFrameFailThroughEqualsReplayWithTheSameOption) {
    TempDir dir;
    EXPECT_EQ(drivePasses(dir, shot_->regions, {"--whole-frame-fail-through"}), 1);
    expectSameAsReplay(dir, shot_->regions, {"--whole-frame-fail-through"});
}

TEST_F(Reconstruct, NeedsAsAPlyPointCloudWithFrameAndIndex) {
    TempDir dir;
    const pmsc::Model m = pmsc::readModel(shot_->plain);
    pmsc::writeFrames(dir.file("keys.npy"), keyValues(shot_->recorded, m), pmsc::NpyDtype::Float32);
    pmsc::FrameSet positions(1, m.points, 3);
    std::copy_n(shot_->recorded.frame(0), m.points * 3, positions.values.data());
    pmsc::writeFrames(dir.file("positions.npy"), positions, pmsc::NpyDtype::Float64);
    const RunResult r = runPmsc(
        dir, {"reconstruct", "--model", shot_->plain, "--keys", dir.file("keys.npy"), "--out",
              dir.file("out.npy"), "--report", dir.file("r.json"), "--points", dir.file("positions.npy")});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const json report = readJson(dir.file("r.json"));
    const Index needed = report["summary"]["points_needed"].get<Index>();
    EXPECT_GT(needed, 0);
    const std::string ply = readBytes(dir.file("r.ply"));
    const std::string header = "element vertex " + std::to_string(needed) + "\n";
    EXPECT_NE(ply.find(header), std::string::npos);
    const auto end = ply.find("end_header\n");
    ASSERT_NE(end, std::string::npos);
    EXPECT_EQ(ply.size() - (end + 11), size_t(needed) * 20);                           // 3 floats, 2 ints
    EXPECT_EQ(pmsc::readNpyInfo(dir.file("out.npy")).dtype, pmsc::NpyDtype::Float32);  // the keys' dtype
}

TEST_F(Reconstruct, BadInputsAreOneLineAndLeaveNoOutput) {
    TempDir dir;
    const pmsc::Model m = pmsc::readModel(shot_->plain);
    pmsc::writeFrames(dir.file("keys.npy"), keyValues(shot_->recorded, m), pmsc::NpyDtype::Float64);
    const auto run = [&](std::vector<std::string> extra) {
        std::vector<std::string> args = {"reconstruct",        "--model", shot_->plain,        "--keys",
                                         dir.file("keys.npy"), "--out",   dir.file("out.npy"), "--report",
                                         dir.file("r.json")};
        args.insert(args.end(), extra.begin(), extra.end());
        return runPmsc(dir, args);
    };
    const auto expectOneLine = [&](const RunResult& r, int code, const std::string& fragment) {
        EXPECT_EQ(r.exitCode, code) << r.err;
        ASSERT_EQ(r.errLines().size(), 1u) << r.err;
        EXPECT_NE(r.err.find(fragment), std::string::npos) << r.err;
        EXPECT_FALSE(std::filesystem::exists(dir.file("out.npy")));
        EXPECT_FALSE(std::filesystem::exists(dir.file("r.json")));
    };
    // Keys of the wrong shape: the test frames themselves.
    expectOneLine(runPmsc(dir, {"reconstruct", "--model", shot_->plain, "--keys", shot_->test, "--out",
                                dir.file("out.npy"), "--report", dir.file("r.json")}),
                  2, "key points");
    // An answer of the wrong shape.
    expectOneLine(run({"--full", dir.file("keys.npy")}), 2, "expected (60, 144, 3)");
    // An answer with NaN where the pass asked.
    pmsc::FrameSet nan(60, m.points, 3);
    std::fill(nan.values.begin(), nan.values.end(), std::numeric_limits<double>::quiet_NaN());
    pmsc::writeFrames(dir.file("nan.npy"), nan, pmsc::NpyDtype::Float64);
    expectOneLine(run({"--full", dir.file("nan.npy")}), 2, "pass 1 asked for point");
    expectOneLine(run({"--full", dir.file("missing.npy")}), 2, "missing.npy");
    expectOneLine(run({"--needs-ply", dir.file("n.ply")}), 2, "--needs-ply: needs --points");
    expectOneLine(run({"--points", shot_->test}), 2, "not a table of points");
    expectOneLine(run({"--eps", "2,1"}), 2, "--eps");
}

}  // namespace
