// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// exec:COMMAND through the real program: `pmsc run` on a Python child replaying recorded frames
// writes the same bytes as `replay:` on the same file; a child that crashes, hangs, answers short
// or NaN, or exits at start ends the run with exit code 3 and one stderr line, and leaves only
// the complete frames before the failure.
#include "tests/common/CliRunner.h"
#include "tests/common/MissingData.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>

namespace {

using pmsc::test::runPmsc;
using pmsc::test::RunResult;
using pmsc::test::TempDir;

const std::string kPython = PMSC_PYTHON;
const std::string kSource = PMSC_SOURCE_DIR;
const std::string kFault = kPython + " " + kSource + "/tests/evaluators/exec/fault_child.py";

std::string bytes(const std::filesystem::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}

void expectOneLine(const RunResult& r, int code, const std::string& fragment) {
    EXPECT_EQ(r.exitCode, code) << r.err;
    ASSERT_EQ(r.errLines().size(), 1u) << r.err;
    EXPECT_NE(r.err.find(fragment), std::string::npos) << r.err;
}

/// The fault child's frames 0-19 exported through exec:, and a model trained on 0-11.
struct Trained {
    TempDir dir;
    std::string frames = dir.file("frames.npy"), train = dir.file("train.npy"),
                model = dir.file("model.pmsc");
    Trained() {
        RunResult r = runPmsc(dir, {"export-frames", "exec:" + kFault, "--out", frames, "--quiet"});
        EXPECT_EQ(r.exitCode, 0) << r.err;
        r = runPmsc(dir, {"export-frames", "exec:" + kFault, "--out", train, "--frames", "0-11", "--quiet"});
        EXPECT_EQ(r.exitCode, 0) << r.err;
        r = runPmsc(dir, {"train", "--frames", train, "--out", model, "--max-keys", "8", "--basis", "4"});
        EXPECT_EQ(r.exitCode, 0) << r.err;
    }
};

TEST(ExecCli, RunThroughAPythonReplayChildWritesWhatReplayWrites) {
    Trained t;
    TempDir a, b;
    const std::vector<std::string> common = {"--model", t.model,     "--frames", "0-19",
                                             "--quiet", "--threads", "2"};
    std::vector<std::string> args = {"run"};
    args.insert(args.end(), common.begin(), common.end());
    args.insert(args.end(), {"--evaluator", "replay:" + t.frames, "--out", a.file("out")});
    RunResult r = runPmsc(a, args);
    ASSERT_EQ(r.exitCode, 0) << r.err;
    args = {"run"};
    args.insert(args.end(), common.begin(), common.end());
    args.insert(args.end(), {"--evaluator",
                             "exec:" + kPython + " " + kSource + "/examples/exec/replay_child.py " + t.frames,
                             "--out", b.file("out")});
    r = runPmsc(b, args);
    ASSERT_EQ(r.exitCode, 0) << r.err;
    int compared = 0;
    for (const auto& e : std::filesystem::directory_iterator(a.file("out"))) {
        if (e.path().extension() != ".npy") continue;
        EXPECT_EQ(bytes(e.path()), bytes(b.path() / "out" / e.path().filename())) << e.path().filename();
        ++compared;
    }
    EXPECT_EQ(compared, 20);
}

TEST(ExecCli, EveryChildFaultIsExitCode3AndOneLine) {
    Trained t;
    struct Case {
        std::string mode, expected;
    };
    const Case cases[] = {{"crash=5", "killed by signal 11"},
                          {"hang=5", "did not answer within 2 s"},
                          {"short=5", "too few bytes"},
                          {"nan=5", "non-finite value"},
                          {"exit", "exited with code 3 before its hello"}};
    for (const Case& c : cases) {
        TempDir dir;
        const RunResult r =
            runPmsc(dir, {"run", "--model", t.model, "--evaluator", "exec:timeout=2:" + kFault + " " + c.mode,
                          "--frames", "0-9", "--out", dir.file("out"), "--quiet", "--threads", "2"});
        EXPECT_EQ(r.exitCode, 3) << c.mode << ": " << r.err;
        const auto lines = r.errLines();
        ASSERT_EQ(lines.size(), 1u) << c.mode << ": " << r.err;
        EXPECT_NE(lines[0].find("fault_child.py " + c.mode + "'"), std::string::npos) << lines[0];
        EXPECT_NE(lines[0].find(c.expected), std::string::npos) << lines[0];
        if (c.mode == "exit") continue;  // nothing ran
        EXPECT_NE(lines[0].find("frame 5"), std::string::npos) << lines[0];
        // The frames before 5 are complete; nothing of 5 or later, no temporary file.
        std::vector<std::string> frames;
        for (const auto& e : std::filesystem::directory_iterator(dir.file("out")))
            if (e.path().extension() != ".json") frames.push_back(e.path().filename().string());
        std::sort(frames.begin(), frames.end());
        EXPECT_EQ(frames.size(), 5u) << c.mode;
        for (const auto& f : frames) EXPECT_EQ(f.find(".tmp"), std::string::npos) << f;
    }
}

TEST(ExecCli, ExportFramesPositionsThroughAChildAreTheEvaluatorsOwnAndAVersion1ChildWritesNothing) {
    TempDir dir;
    const std::string spec = "cornell:points=3000,samples=8";
    RunResult r = runPmsc(dir, {"export-frames", spec, "--out", dir.file("a.npy"), "--frames", "0-1",
                                "--positions", dir.file("a-positions.npy"), "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    r = runPmsc(
        dir, {"export-frames", "exec:" + std::string(PMSC_BINARY) + " serve " + spec, "--out",
              dir.file("b.npy"), "--frames", "0-1", "--positions", dir.file("b-positions.npy"), "--quiet"});
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_EQ(bytes(dir.file("a-positions.npy")), bytes(dir.file("b-positions.npy")));
    EXPECT_EQ(bytes(dir.file("a.npy")), bytes(dir.file("b.npy")));
    // A child of protocol version 1 has no positions request: exit 2, one line, no frames written.
    r = runPmsc(dir,
                {"export-frames",
                 "exec:" + kPython + " " + kSource + "/examples/exec/replay_child.py " + dir.file("a.npy"),
                 "--out", dir.file("c.npy"), "--positions", dir.file("c-positions.npy"), "--quiet"});
    expectOneLine(r, 2, "protocol version 1, which has no positions request");
    EXPECT_FALSE(std::filesystem::exists(dir.file("c.npy")));
    EXPECT_FALSE(std::filesystem::exists(dir.file("c-positions.npy")));
}

}  // namespace

namespace {

const std::string kModels = "/usr/share/assimp/models";

TEST(SkinIsolation, ADamagedAssetIsOneLineAndExitCode2AndTheImportIsolatedPosesTheSame) {
    if (!std::filesystem::exists(kModels + "/X/test.x"))
        PMSC_MISSING_DATA("assimp-testmodels not found in " << kModels);
    TempDir dir;
    // test.x with a vertex count that makes Assimp's X importer reserve 23 GB.
    std::ifstream in(kModels + "/X/test.x");
    std::string text{std::istreambuf_iterator<char>(in), {}};
    const auto at = text.find("        24;");
    ASSERT_NE(at, std::string::npos);
    text = text.substr(0, at) + "        1900000000;" + text.substr(at + 11);
    std::ofstream(dir.file("damaged.x")) << text;
    const RunResult r =
        runPmsc(dir, {"export-frames", "skin:" + dir.file("damaged.x"), "--out", dir.file("f.npy")});
    EXPECT_EQ(r.exitCode, 2) << r.err;
    ASSERT_EQ(r.errLines().size(), 1u) << r.err;
    EXPECT_NE(r.err.find("damaged.x"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir.file("f.npy")));

    const std::string clip = "skin:" + kModels + "/BVH/01_01.bvh:fps=60";
    for (const std::string isolate : {"yes", "no"}) {
        const RunResult e = runPmsc(dir, {"export-frames", clip + ":isolate=" + isolate, "--frames", "0-99",
                                          "--out", dir.file(isolate + ".npy"), "--quiet"});
        ASSERT_EQ(e.exitCode, 0) << e.err;
    }
    EXPECT_EQ(bytes(dir.file("yes.npy")), bytes(dir.file("no.npy")));
    expectOneLine(runPmsc(dir, {"export-frames", clip + ":isolate=maybe", "--out", dir.file("m.npy")}), 2,
                  "isolate must be yes or no");
}

}  // namespace
