// `pmsc train --targets` and `pmsc replay` of a cross model (cross point multiplication),
// through the real binary: an exact affine control -> target map comes back to rounding, the report
// says fail-through is impossible and gives each frame's key error and bound, and bad inputs fail
// with one line, a non-zero exit code and no output file.
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"
#include "tests/common/CliRunner.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <Eigen/Core>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

namespace {

using pmsc::test::runPmsc;
using pmsc::test::RunResult;
using pmsc::test::TempDir;
namespace fs = std::filesystem;

Eigen::MatrixXd gaussian(Eigen::Index rows, Eigen::Index cols, unsigned seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> normal(0.0, 1.0);
    Eigen::MatrixXd m(rows, cols);
    for (Eigen::Index j = 0; j < cols; ++j)
        for (Eigen::Index i = 0; i < rows; ++i) m(i, j) = normal(rng);
    return m;
}

void save(const std::string& path, const Eigen::MatrixXd& m, pmsc::Index channels) {
    pmsc::FrameSet s(m.cols(), m.rows() / channels, channels);
    s.matrix() = m;
    pmsc::writeFrames(path, s, pmsc::NpyDtype::Float64);
}

class CrossCli : public ::testing::Test {
protected:
    // Control: 50 points driven by 5 modes; target: 30 points, an affine map of the control.
    static void SetUpTestSuite() {
        dir_ = new TempDir;
        const Eigen::MatrixXd modes = gaussian(150, 5, 1), map = gaussian(90, 150, 2) / 8.0;
        const Eigen::VectorXd c0 = gaussian(150, 1, 3), t0 = gaussian(90, 1, 4);
        auto make = [&](Eigen::Index frames, unsigned seed, const std::string& name) {
            const Eigen::MatrixXd c = (modes * gaussian(5, frames, seed)).colwise() + c0;
            save(dir_->file(name + "-control.npy"), c, 3);
            save(dir_->file(name + "-target.npy"), (map * c).colwise() + t0, 3);
        };
        make(60, 10, "train");
        make(25, 11, "test");
        const RunResult r = runPmsc(*dir_, {"train", "--frames", dir_->file("train-control.npy"), "--targets",
                                            dir_->file("train-target.npy"), "--out", dir_->file("cross.pmsc"),
                                            "--max-keys", "10", "--quiet"});
        ASSERT_EQ(r.exitCode, 0) << r.err;
        ASSERT_NE(r.out.find("fail-through impossible"), std::string::npos) << r.out;
    }
    static void TearDownTestSuite() { delete dir_; }

    static void expectFailure(const RunResult& r, int code, std::initializer_list<std::string> fragments) {
        EXPECT_EQ(r.exitCode, code) << r.err;
        const auto lines = r.errLines();
        ASSERT_EQ(lines.size(), 1u) << r.err;
        EXPECT_EQ(lines[0].rfind("pmsc: ", 0), 0u) << lines[0];
        for (const auto& f : fragments) EXPECT_NE(lines[0].find(f), std::string::npos) << lines[0];
    }
    static TempDir* dir_;
};

TempDir* CrossCli::dir_ = nullptr;

TEST_F(CrossCli, ReplayWritesTargetsThatFollowAnExactMapToRounding) {
    TempDir work;
    const RunResult r =
        runPmsc(work, {"replay", "--model", dir_->file("cross.pmsc"), "--frames",
                       dir_->file("test-control.npy"), "--targets", dir_->file("test-target.npy"), "--out",
                       work.file("out.npy"), "--report", work.file("r.json"), "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("fail-through impossible"), std::string::npos) << r.out;
    const pmsc::FrameFile out = pmsc::readFrames(work.file("out.npy"));
    const pmsc::FrameFile truth = pmsc::readFrames(dir_->file("test-target.npy"));
    ASSERT_EQ(out.frames.frames, 25);
    ASSERT_EQ(out.frames.points, 30);
    const double scale = truth.frames.matrix().cwiseAbs().maxCoeff();
    EXPECT_LT((out.frames.matrix() - truth.frames.matrix()).cwiseAbs().maxCoeff(), 1e-9 * scale);

    std::ifstream in(work.file("r.json"));
    const nlohmann::json report = nlohmann::json::parse(in);
    const auto& s = report.at("summary");
    EXPECT_TRUE(s.at("cross").get<bool>());
    EXPECT_NE(s.at("fail_through").get<std::string>().find("impossible"), std::string::npos);
    EXPECT_EQ(s.at("control_points").get<long>(), 50);
    EXPECT_EQ(s.at("target_points").get<long>(), 30);
    EXPECT_DOUBLE_EQ(s.at("bound").at("coverage").get<double>(), 0.9);
    EXPECT_LT(s.at("target_max_point_error").at("max").get<double>(), 1e-9 * scale);
    ASSERT_EQ(report.at("frames").size(), 25u);
    for (const auto& f : report.at("frames")) {
        EXPECT_TRUE(f.contains("key_rms"));
        EXPECT_TRUE(f.contains("bound"));
        EXPECT_LE(f.at("target_max_point_error").get<double>(), f.at("bound").get<double>() + 1e-12);
    }
    // inspect names the cross section.
    const RunResult i = runPmsc(work, {"inspect", dir_->file("cross.pmsc")});
    ASSERT_EQ(i.exitCode, 0) << i.err;
    EXPECT_NE(i.out.find("cross"), std::string::npos) << i.out;
}

TEST_F(CrossCli, RunTakesAnEvaluatorOfTheControlAndWritesTargetFrames) {
    TempDir work;
    const RunResult r = runPmsc(work, {"run", "--model", dir_->file("cross.pmsc"), "--evaluator",
                                       "replay:" + dir_->file("test-control.npy"), "--frames", "0-24:3",
                                       "--out", work.file("frames"), "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    const pmsc::FrameFile truth = pmsc::readFrames(dir_->file("test-target.npy"));
    const double scale = truth.frames.matrix().cwiseAbs().maxCoeff();
    for (pmsc::Index f = 0; f <= 24; f += 3) {
        char name[64];
        std::snprintf(name, sizeof name, "frame.%06ld.npy", static_cast<long>(f));
        const pmsc::FrameFile out = pmsc::readFrames(work.file("frames/" + std::string(name)));
        ASSERT_EQ(out.frames.points, 30);
        EXPECT_LT((out.frames.matrix().col(0) - truth.frames.matrix().col(f)).cwiseAbs().maxCoeff(),
                  1e-9 * scale);
    }
    std::ifstream in(work.file("frames/pmsc-run.0-24_by3.json"));
    ASSERT_TRUE(in.good());
    const nlohmann::json stats = nlohmann::json::parse(in);
    EXPECT_NE(stats.at("fail_through").get<std::string>().find("impossible"), std::string::npos);
    EXPECT_EQ(stats.at("per_frame").size(), 9u);
    // The plain face of another size is not a control of this model.
    expectFailure(runPmsc(work, {"run", "--model", dir_->file("cross.pmsc"), "--evaluator",
                                 "replay:" + dir_->file("test-target.npy"), "--frames", "0-3", "--out",
                                 work.file("bad"), "--quiet"}),
                  2, {"control of 50 points"});
}

TEST_F(CrossCli, BadInputsFailWithOneLineAndNoFile) {
    TempDir work;
    const Eigen::MatrixXd short29 = gaussian(90, 29, 5);
    save(work.file("t29.npy"), short29, 3);
    save(work.file("t1ch.npy"), gaussian(30, 60, 6), 1);
    const std::string model = work.file("m.pmsc");
    expectFailure(runPmsc(work, {"train", "--frames", dir_->file("train-control.npy"), "--targets",
                                 work.file("t29.npy"), "--out", model, "--quiet"}),
                  2, {"60 control frames", "29 target frames"});
    EXPECT_FALSE(fs::exists(model));
    expectFailure(runPmsc(work, {"train", "--frames", dir_->file("train-control.npy"), "--targets",
                                 work.file("t1ch.npy"), "--out", model, "--quiet"}),
                  2, {"channels"});
    EXPECT_FALSE(fs::exists(model));
    expectFailure(
        runPmsc(work, {"train", "--frames", dir_->file("train-control.npy"), "--targets",
                       dir_->file("train-target.npy"), "--out", model, "--regions", "2", "--quiet"}),
        2, {"--regions"});
    EXPECT_FALSE(fs::exists(model));
    // Targets with a plain model; a cross model with frames of the wrong size; options without meaning.
    const RunResult plain = runPmsc(work, {"train", "--frames", dir_->file("train-control.npy"), "--out",
                                           work.file("plain.pmsc"), "--max-keys", "10", "--quiet"});
    ASSERT_EQ(plain.exitCode, 0) << plain.err;
    expectFailure(runPmsc(work, {"replay", "--model", work.file("plain.pmsc"), "--frames",
                                 dir_->file("test-control.npy"), "--targets", dir_->file("test-target.npy"),
                                 "--report", work.file("r.json"), "--quiet"}),
                  2, {"not a cross model"});
    expectFailure(runPmsc(work, {"replay", "--model", dir_->file("cross.pmsc"), "--frames",
                                 dir_->file("test-target.npy"), "--report", work.file("r.json"), "--quiet"}),
                  2, {"50 control points"});
    expectFailure(runPmsc(work, {"replay", "--model", dir_->file("cross.pmsc"), "--frames",
                                 dir_->file("test-control.npy"), "--eps", "0.1,0.2", "--report",
                                 work.file("r.json"), "--quiet"}),
                  2, {"--eps", "cross"});
    EXPECT_FALSE(fs::exists(work.file("r.json")));
    expectFailure(runPmsc(work, {"learn", "--model", dir_->file("cross.pmsc"), "--frames",
                                 dir_->file("test-control.npy"), "--out", work.file("l.pmsc"), "--quiet"}),
                  2, {"cross model"});
    EXPECT_FALSE(fs::exists(work.file("l.pmsc")));
}

}  // namespace
