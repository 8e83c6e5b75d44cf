// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
//
// `pmsc run` and `pmsc export-frames` as a farm uses them: the real program, run as a child
// process on a real motion-capture clip from assimp-testmodels, killed with SIGKILL mid-run and
// resumed; every bad input checked for its exit code, its one stderr line and the absence of any
// partial file. Figures are printed (and recorded as test properties).
#include "app/Run.h"
#include "evaluators/EvaluatorRegistry.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"
#include "tests/common/MissingData.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace fs = std::filesystem;
using pmsc::Index;

namespace {

#ifndef PMSC_ASSIMP_TESTMODELS
#define PMSC_ASSIMP_TESTMODELS ""
#endif

const std::string kModels = PMSC_ASSIMP_TESTMODELS;
// 22.9 s of motion capture (CMU 01_01, 31 joints, 492 points) posed at 60 frames a second.
const std::string kClip = kModels + "/BVH/01_01.bvh";
const std::string kSpec = "skin:" + kClip + ":fps=60";
// Another character, with a different point count (11196).
const std::string kOther = "skin:" + kModels + "/X/Testwuson.X";

struct Child {
    pid_t pid = -1;
    std::string out, err;  // file paths
};

Child spawn(const std::vector<std::string>& args, const fs::path& logDir, const std::string& tag) {
    Child c;
    c.out = (logDir / (tag + ".stdout")).string();
    c.err = (logDir / (tag + ".stderr")).string();
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, c.out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&actions, 2, c.err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    std::vector<std::string> all{PMSC_BINARY};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    const int rc = posix_spawn(&c.pid, PMSC_BINARY, &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (rc != 0) throw std::runtime_error("cannot start " + std::string(PMSC_BINARY));
    return c;
}

std::string slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}

struct Result {
    int code = -1;
    std::string out, err;
};

// Waits with a deadline, so a hang fails the test instead of blocking ctest.
Result wait(Child& c, double seconds = 120) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    int status = 0;
    for (;;) {
        const pid_t r = waitpid(c.pid, &status, WNOHANG);
        if (r == c.pid) break;
        if (std::chrono::steady_clock::now() > deadline) {
            kill(c.pid, SIGKILL);
            waitpid(c.pid, &status, 0);
            ADD_FAILURE() << "pmsc did not finish within " << seconds << " s";
            break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    Result res;
    res.code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    res.out = slurp(c.out);
    res.err = slurp(c.err);
    return res;
}

Result pmscRun(const std::vector<std::string>& args, const fs::path& logDir, const std::string& tag) {
    Child c = spawn(args, logDir, tag);
    return wait(c);
}

std::vector<std::string> listDir(const fs::path& dir) {
    std::vector<std::string> names;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir, ec)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
}

Index countFrames(const fs::path& dir) {
    Index n = 0;
    for (const auto& name : listDir(dir))
        n += name.rfind("frame.", 0) == 0 && name.find(".tmp-") == std::string::npos;
    return n;
}

bool hasTemporaries(const fs::path& dir) {
    for (const auto& name : listDir(dir))
        if (name.find(".tmp-") != std::string::npos) return true;
    return false;
}

nlohmann::json readJson(const fs::path& path) { return nlohmann::json::parse(slurp(path.string())); }

/// One shared world: training frames of the clip and a model (made once, by the program itself).
class FarmRun : public ::testing::Test {
protected:
    static inline fs::path root;
    static inline std::string model;

    static void SetUpTestSuite() {
        if (!fs::exists(kClip)) return;
        root = fs::temp_directory_path() / ("pmsc-farm-test-" + std::to_string(::getpid()));
        fs::remove_all(root);
        fs::create_directories(root / "logs");
        model = (root / "clip.pmsc").string();
        const std::string train = (root / "train.npy").string();
        Result e = pmscRun({"export-frames", kSpec, "--out", train, "--frames", "0-1375:4", "--quiet"},
                           root / "logs", "export");
        ASSERT_EQ(e.code, 0) << e.err;
        Result t =
            pmscRun({"train", "--frames", train, "--out", model, "--max-keys", "40"}, root / "logs", "train");
        ASSERT_EQ(t.code, 0) << t.err;
    }
    static void TearDownTestSuite() {
        // Kept when something failed, for the logs/ of every child process.
        const auto* suite = ::testing::UnitTest::GetInstance()->current_test_suite();
        if (!root.empty() && suite && suite->Passed()) fs::remove_all(root);
    }
    void SetUp() override {
        if (!fs::exists(kClip))
            PMSC_MISSING_DATA("assimp-testmodels not installed ("
                              << kClip << " not found); install the Debian package");
        ASSERT_TRUE(fs::exists(model)) << "the suite's model was not made";
    }

    std::vector<std::string> runArgs(const fs::path& out, const std::string& frames) const {
        return {"run", "--model", model, "--evaluator", kSpec, "--frames", frames, "--out", out.string()};
    }
};

}  // namespace

TEST_F(FarmRun, KilledRunResumesToByteIdenticalOutputsEvaluatingOnlyMissingFrames) {
    const std::string frames = "0-399";
    const Index total = 400;
    const fs::path reference = root / "reference", killed = root / "killed";
    ASSERT_EQ(pmscRun(runArgs(reference, frames), root / "logs", "reference").code, 0);
    ASSERT_EQ(countFrames(reference), total);

    // SIGKILL once a tenth of the frames are written: no handler runs, nothing is cleaned up.
    Child c = spawn(runArgs(killed, frames), root / "logs", "killed");
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (countFrames(killed) < total / 10 && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    kill(c.pid, SIGKILL);
    const Result k = wait(c);
    ASSERT_EQ(k.code, 128 + SIGKILL);
    const Index present = countFrames(killed);
    ASSERT_GE(present, total / 10);
    ASSERT_LT(present, total) << "the run finished before the kill; the test needs a longer range";
    EXPECT_FALSE(fs::exists(killed / "pmsc-run.0-399.json")) << "a killed run writes no stats";

    // The same command again.
    const Result again = pmscRun(runArgs(killed, frames), root / "logs", "resumed");
    ASSERT_EQ(again.code, 0) << again.err;
    const auto stats = readJson(killed / "pmsc-run.0-399.json");
    EXPECT_EQ(stats["status"], "ok");
    EXPECT_EQ(stats["frames_evaluated"].get<Index>(), total - present);
    EXPECT_EQ(stats["frames_skipped"].get<Index>(), present);
    EXPECT_EQ(stats["frames_replaced_invalid"].get<Index>(), 0);

    ASSERT_EQ(countFrames(killed), total);
    EXPECT_FALSE(hasTemporaries(killed)) << "the resumed run removes the killed run's temporary file";
    Index identical = 0;
    for (const auto& name : listDir(reference))
        if (name.rfind("frame.", 0) == 0)
            identical += slurp((reference / name).string()) == slurp((killed / name).string());
    EXPECT_EQ(identical, total);

    std::printf(
        "[ figures  ] SIGKILL after %lld of %lld frames written (%lld temporary file(s) left); "
        "second run evaluated %lld, skipped %lld, removed %lld temporary; %lld/%lld frames byte-identical\n",
        static_cast<long long>(present), static_cast<long long>(total),
        static_cast<long long>(stats["stale_temporaries_removed"].get<Index>()),
        static_cast<long long>(stats["frames_evaluated"].get<Index>()),
        static_cast<long long>(stats["frames_skipped"].get<Index>()),
        static_cast<long long>(stats["stale_temporaries_removed"].get<Index>()),
        static_cast<long long>(identical), static_cast<long long>(total));
    RecordProperty("killed_after_frames", static_cast<int>(present));
    RecordProperty("second_run_evaluated", static_cast<int>(stats["frames_evaluated"].get<Index>()));
}

TEST_F(FarmRun, DamagedOutputIsRedoneAndForceRedoesEverything) {
    const fs::path out = root / "damaged";
    ASSERT_EQ(pmscRun(runArgs(out, "10-29"), root / "logs", "first").code, 0);
    const std::string good = slurp((out / "frame.000017.npy").string());
    {
        std::ofstream f(out / "frame.000017.npy", std::ios::binary | std::ios::trunc);
        f << good.substr(0, good.size() - 100);  // a copy that stopped short
    }
    // A temporary file as a run killed while writing frame 17 leaves it; frame 40 is not ours.
    std::ofstream(out / "frame.000017.npy.tmp-AbC123") << "half a frame";
    std::ofstream(out / "frame.000040.npy.tmp-XyZ789") << "another task's";
    Result r = pmscRun(runArgs(out, "10-29"), root / "logs", "repair");
    ASSERT_EQ(r.code, 0) << r.err;
    auto stats = readJson(out / "pmsc-run.10-29.json");
    EXPECT_EQ(stats["frames_evaluated"].get<Index>(), 1);
    EXPECT_EQ(stats["frames_replaced_invalid"].get<Index>(), 1);
    EXPECT_EQ(stats["stale_temporaries_removed"].get<Index>(), 1);
    EXPECT_FALSE(fs::exists(out / "frame.000017.npy.tmp-AbC123"));
    EXPECT_TRUE(fs::exists(out / "frame.000040.npy.tmp-XyZ789")) << "outside the range: left alone";
    fs::remove(out / "frame.000040.npy.tmp-XyZ789");
    EXPECT_EQ(stats["frames_skipped"].get<Index>(), 19);
    EXPECT_EQ(slurp((out / "frame.000017.npy").string()), good);

    auto args = runArgs(out, "10-29");
    args.push_back("--force");
    r = pmscRun(args, root / "logs", "force");
    ASSERT_EQ(r.code, 0) << r.err;
    stats = readJson(out / "pmsc-run.10-29.json");
    EXPECT_EQ(stats["frames_evaluated"].get<Index>(), 20);
    EXPECT_EQ(stats["frames_skipped"].get<Index>(), 0);
    EXPECT_EQ(stats["per_frame"].size(), 20u);
    EXPECT_EQ(stats["per_frame"][0]["frame"], 10);
    EXPECT_EQ(stats["frames"]["range"], "10-29");
    EXPECT_FALSE(stats["host"].get<std::string>().empty());
    EXPECT_NE(stats["command"].get<std::string>().find("--force"), std::string::npos);
}

TEST_F(FarmRun, OverlappingRunsBothFinishAndALiveRunsTemporaryIsLeftAlone) {
    const fs::path out = root / "overlap";
    fs::create_directories(out);
    const std::string tag = pmsc::temporaryTag();
    const std::string host = tag.substr(tag.find('@') + 1, tag.size() - tag.find('@') - 2);
    // A live writer of frame 12 on this host (a child that waits) and a dead one of frame 13.
    const pid_t live = ::fork();
    ASSERT_GE(live, 0);
    if (live == 0) {
        ::pause();
        ::_exit(0);
    }
    const pid_t dead = ::fork();
    ASSERT_GE(dead, 0);
    if (dead == 0) ::_exit(0);
    ::waitpid(dead, nullptr, 0);
    const std::string liveTemp = "frame.000012.npy.tmp-" + std::to_string(live) + "@" + host + "-Live01";
    const std::string deadTemp = "frame.000013.npy.tmp-" + std::to_string(dead) + "@" + host + "-Dead01";
    std::ofstream(out / liveTemp) << "being written";
    std::ofstream(out / deadTemp) << "left by a killed run";
    Result r = pmscRun(runArgs(out, "10-19"), root / "logs", "overlap-temporaries");
    ::kill(live, SIGKILL);
    ::waitpid(live, nullptr, 0);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(fs::exists(out / liveTemp)) << "a live process's temporary file was removed";
    EXPECT_FALSE(fs::exists(out / deadTemp));
    EXPECT_EQ(readJson(out / "pmsc-run.10-19.json")["stale_temporaries_removed"].get<Index>(), 1);
    fs::remove(out / liveTemp);

    // Two runs at once on overlapping frames (the same array task submitted twice): both succeed,
    // and every frame is the one a single run writes.
    const fs::path both = root / "overlap-both", single = root / "overlap-single";
    auto a = runArgs(both, "0-299"), b = runArgs(both, "100-399");
    a.push_back("--force");
    b.push_back("--force");
    Child ca = spawn(a, root / "logs", "overlap-a"), cb = spawn(b, root / "logs", "overlap-b");
    const Result ra = wait(ca), rb = wait(cb);
    EXPECT_EQ(ra.code, 0) << ra.err;
    EXPECT_EQ(rb.code, 0) << rb.err;
    ASSERT_EQ(pmscRun(runArgs(single, "0-399"), root / "logs", "overlap-single").code, 0);
    EXPECT_EQ(countFrames(both), 400);
    EXPECT_FALSE(hasTemporaries(both));
    Index identical = 0;
    for (const auto& name : listDir(single))
        if (name.rfind("frame.", 0) == 0)
            identical += slurp((single / name).string()) == slurp((both / name).string());
    EXPECT_EQ(identical, 400);
}

TEST_F(FarmRun, StepsThreadCountsAndFormatsGiveTheSameFrames) {
    const fs::path one = root / "threads1", two = root / "threads2", stepped = root / "stepped";
    auto a = runArgs(one, "0-59");
    a.insert(a.end(), {"--threads", "1"});
    auto b = runArgs(two, "0-59");
    b.insert(b.end(), {"--threads", "2"});
    ASSERT_EQ(pmscRun(a, root / "logs", "t1").code, 0);
    ASSERT_EQ(pmscRun(b, root / "logs", "t2").code, 0);
    ASSERT_EQ(pmscRun(runArgs(stepped, "0-59:3"), root / "logs", "step").code, 0);
    EXPECT_EQ(countFrames(stepped), 20);
    for (Index f = 0; f < 60; ++f) {
        char name[32];
        std::snprintf(name, sizeof name, "frame.%06lld.npy", static_cast<long long>(f));
        EXPECT_EQ(slurp((one / name).string()), slurp((two / name).string())) << name;
        if (f % 3 == 0) {
            EXPECT_EQ(slurp((one / name).string()), slurp((stepped / name).string())) << name;
        }
    }
    EXPECT_TRUE(fs::exists(stepped / "pmsc-run.0-57_by3.json"));
    EXPECT_EQ(readJson(one / "pmsc-run.0-59.json")["basis_precision"], "double") << "float64 frames";

    // Float32 frames read the float basis by default: the same frames as the double basis's
    // within a float's rounding, and the stats say which basis ran.
    const fs::path single = root / "float32", dbl = root / "float32-double";
    auto f = runArgs(single, "0-9");
    f.insert(f.end(), {"--dtype", "float32"});
    auto d = runArgs(dbl, "0-9");
    d.insert(d.end(), {"--dtype", "float32", "--basis-precision", "double"});
    ASSERT_EQ(pmscRun(f, root / "logs", "float32").code, 0);
    ASSERT_EQ(pmscRun(d, root / "logs", "float32-double").code, 0);
    EXPECT_EQ(readJson(single / "pmsc-run.0-9.json")["basis_precision"], "single");
    EXPECT_EQ(readJson(dbl / "pmsc-run.0-9.json")["basis_precision"], "double");
    for (Index fr = 0; fr < 10; ++fr) {
        char name[32];
        std::snprintf(name, sizeof name, "frame.%06lld.npy", static_cast<long long>(fr));
        const pmsc::FrameSet a32 = pmsc::readFrames((single / name).string()).frames;
        const pmsc::FrameSet b32 = pmsc::readFrames((dbl / name).string()).frames;
        ASSERT_EQ(a32.values.size(), b32.values.size()) << name;
        double largest = 0, scale = 0;
        for (size_t i = 0; i < a32.values.size(); ++i) {
            largest = std::max(largest, std::abs(a32.values[i] - b32.values[i]));
            scale = std::max(scale, std::abs(b32.values[i]));
        }
        EXPECT_LE(largest, 1e-6 * scale) << name;
    }

    // The skin evaluator offers .obj: a mesh per frame, also resumable.
    const fs::path obj = root / "obj";
    auto o = runArgs(obj, "0-4");
    o.insert(o.end(), {"--format", "obj"});
    ASSERT_EQ(pmscRun(o, root / "logs", "obj").code, 0);
    EXPECT_EQ(countFrames(obj), 5);
    EXPECT_TRUE(fs::exists(obj / "frame.000004.obj"));
    ASSERT_EQ(pmscRun(o, root / "logs", "obj2").code, 0);
    EXPECT_EQ(readJson(obj / "pmsc-run.0-4.json")["frames_skipped"].get<Index>(), 5);
}

TEST_F(FarmRun, SigtermStopsCleanlyWithExitCode130AndKeepsFinishedFrames) {
    const fs::path out = root / "terminated";
    Child c = spawn(runArgs(out, "0-599"), root / "logs", "sigterm");
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (countFrames(out) < 30 && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    kill(c.pid, SIGTERM);  // what scancel and pre-emption send
    const Result r = wait(c);
    EXPECT_EQ(r.code, 130) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_FALSE(hasTemporaries(out));
    const auto stats = readJson(out / "pmsc-run.0-599.json");
    EXPECT_EQ(stats["status"], "interrupted");
    EXPECT_EQ(stats["exit_code"], 130);
    const Index kept = countFrames(out);
    EXPECT_EQ(stats["frames_evaluated"].get<Index>(), kept);
    EXPECT_LT(kept, 600);
    for (Index f = 0; f < kept; ++f) {
        char name[32];
        std::snprintf(name, sizeof name, "frame.%06lld.npy", static_cast<long long>(f));
        EXPECT_TRUE(fs::exists(out / name)) << "finished frames are a prefix: " << name;
    }
}

TEST_F(FarmRun, PlainProgressLinesWhenNotATerminal) {
    auto args = runArgs(root / "progress", "0-199");
    // --log-every 0: a line at every update, so the test does not depend on how long 200 frames take
    // (on a fast machine they take under 0.2 s and no line would be due).
    args.insert(args.end(), {"--log-every", "0"});
    const Result r = pmscRun(args, root / "logs", "progress");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("pmsc run: "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("frames/s"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find('\r'), std::string::npos) << "no terminal redraws in a log";
    EXPECT_NE(r.out.find("200 evaluated"), std::string::npos) << r.out;
}

TEST_F(FarmRun, EveryBadInputHasItsExitCodeOneLineAndNoPartialFile) {
    const fs::path bad = root / "bad";
    fs::create_directories(bad);
    const std::string corrupt = (bad / "corrupt.pmsc").string(),
                      truncated = (bad / "truncated.pmsc").string();
    {
        std::string bytes = slurp(model);
        std::string flipped = bytes;
        flipped[flipped.size() / 2] ^= 0x5a;
        std::ofstream(corrupt, std::ios::binary) << flipped;
        std::ofstream(truncated, std::ios::binary) << bytes.substr(0, bytes.size() / 3);
    }
    const std::string garbage = (bad / "character.fbx").string();
    std::ofstream(garbage) << "Kaydara FBX Binary, or so it claims\n";
    const std::string aFile = (bad / "a-file").string();
    std::ofstream(aFile) << "x";

    struct Case {
        std::string what;
        std::vector<std::string> args;
        int code;
    };
    auto run = [&](const std::string& out, std::vector<std::string> extra, std::string modelPath = "",
                   std::string spec = "", std::string frames = "0-9") {
        std::vector<std::string> a{"run",
                                   "--model",
                                   modelPath.empty() ? model : modelPath,
                                   "--evaluator",
                                   spec.empty() ? kSpec : spec,
                                   "--frames",
                                   frames,
                                   "--out",
                                   out};
        a.insert(a.end(), extra.begin(), extra.end());
        return a;
    };
    int index = 0;
    auto outDir = [&] { return (bad / ("out" + std::to_string(index))).string(); };
    const std::vector<Case> cases = {
        {"missing model", run(outDir(), {}, (bad / "nope.pmsc").string()), 2},
        {"corrupt model (one byte flipped)", run(outDir(), {}, corrupt), 2},
        {"truncated model", run(outDir(), {}, truncated), 2},
        {"evaluator point count differs from the model's", run(outDir(), {}, "", kOther), 2},
        {"unwritable output folder", run(aFile + "/frames", {}), 4},
        {"frame range outside the data", run(outDir(), {}, "", "", "1370-1400"), 2},
        {"asset Assimp cannot read", run(outDir(), {}, "", "skin:" + garbage), 2},
        {"missing asset", run(outDir(), {}, "", "skin:" + (bad / "gone.glb").string()), 2},
        {"asset without animation", run(outDir(), {}, "", "skin:" + kModels + "/IQM/mrfixit.iqm"), 2},
        {"unknown evaluator", run(outDir(), {}, "", "teapot"), 2},
        {"malformed frame range", run(outDir(), {}, "", "", "9-3"), 2},
        {"format the evaluator does not offer", run(outDir(), {"--format", "vdb"}), 2},
        {"unknown basis precision", run(outDir(), {"--basis-precision", "half"}), 2},
    };
    std::string table = "[ figures  ] bad input -> exit code, message\n";
    for (const auto& c : cases) {
        const fs::path out = c.args[8];
        const Result r = pmscRun(c.args, root / "logs", "bad" + std::to_string(index++));
        EXPECT_EQ(r.code, c.code) << c.what << ": " << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << c.what << ": " << r.err;
        EXPECT_EQ(r.err.rfind("pmsc: ", 0), 0u) << c.what << ": " << r.err;
        EXPECT_TRUE(listDir(out).empty())
            << c.what << ": left " << (listDir(out).empty() ? "" : listDir(out)[0]);
        table += "             " + c.what + " -> " + std::to_string(r.code) + "  " + r.err;
    }
    std::printf("%s", table.c_str());
}

TEST_F(FarmRun, ExportFramesWritesWhatRunEvaluatesAndRejectsBadInput) {
    const fs::path dir = root / "export";
    fs::create_directories(dir);
    const std::string npy = (dir / "poses.npy").string();
    // A plain asset path means skin:ASSET (24 fps by default).
    Result r =
        pmscRun({"export-frames", kClip, "--out", npy, "--frames", "5-9"}, root / "logs", "export-asset");
    ASSERT_EQ(r.code, 0) << r.err;
    const pmsc::FrameFile f = pmsc::readFrames(npy);
    EXPECT_EQ(f.frames.frames, 5);
    EXPECT_EQ(f.frames.points, 492);
    EXPECT_EQ(f.frames.channels, 3);

    r = pmscRun({"export-frames", "skin:" + (dir / "none.gltf").string(), "--out", (dir / "x.npy").string()},
                root / "logs", "export-bad");
    EXPECT_EQ(r.code, 2);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    r = pmscRun({"export-frames", kClip, "--out", (dir / "y.npy").string(), "--frames", "0-99999"},
                root / "logs", "export-range");
    EXPECT_EQ(r.code, 2) << r.err;
    r = pmscRun(
        {"export-frames", kClip, "--out", (dir / "missing-folder" / "z.npy").string(), "--frames", "0-1"},
        root / "logs", "export-io");
    EXPECT_EQ(r.code, 4) << r.err;
    EXPECT_EQ(listDir(dir), std::vector<std::string>{"poses.npy"}) << "no partial file";
}

// --- an evaluator that fails mid-run: exit code 3's path, in process -------------------------------

namespace {

/// Wraps the clip's evaluator and fails on one frame, as a crashing rig would.
class FailingOn final : public pmsc::PointEvaluator {
public:
    FailingOn(const pmsc::PointEvaluator& inner, Index badFrame) : inner_(inner), bad_(badFrame) {}
    std::string name() const override { return "failing"; }
    Index pointCount() const override { return inner_.pointCount(); }
    Index channelCount() const override { return inner_.channelCount(); }
    Index frameCount() const override { return inner_.frameCount(); }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override {
        if (frame == bad_) throw std::runtime_error("rig exploded");
        inner_.evaluate(frame, points, out);
    }

private:
    const pmsc::PointEvaluator& inner_;
    Index bad_;
};

}  // namespace

TEST_F(FarmRun, EvaluatorFailureKeepsEarlierFramesAndReportsTheFrame) {
    const pmsc::Model m = pmsc::readModel(model);
    const fs::path out = root / "failing";
    pmsc::app::RunOptions o;
    o.modelPath = model;
    o.evaluatorSpec = "failing";
    o.frames = pmsc::app::FrameSpan{0, 19, 1};
    o.outDir = out.string();
    o.threads = 2;
    const auto inner = pmsc::evaluators::makeEvaluator(kSpec);  // as the command line makes it
    FailingOn failing(*inner, 12);
    try {
        pmsc::app::runFrames(m, failing, o);
        FAIL() << "expected an EvaluatorError";
    } catch (const pmsc::EvaluatorError& e) {
        EXPECT_NE(std::string(e.what()).find("frame 12"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("rig exploded"), std::string::npos) << e.what();
    }
    EXPECT_EQ(countFrames(out), 12) << "frames before the failing one are kept, none after";
    EXPECT_FALSE(hasTemporaries(out));
    const auto stats = readJson(out / "pmsc-run.0-19.json");
    EXPECT_EQ(stats["status"], "evaluator failure");
    EXPECT_EQ(stats["exit_code"], 3);
    EXPECT_EQ(stats["frames_evaluated"].get<Index>(), 12);
}

// --- the Cornell box's .vdb frames through the FrameWriter hook ------------------------------------

TEST(FarmRunCornell, VdbFramesAreWrittenSkippedWhenValidAndRedoneWhenDamaged) {
    const fs::path dir = fs::temp_directory_path() / ("pmsc-farm-vdb-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir / "logs");
    // A small box (3000 voxels, 8 samples) keeps this a few seconds on two cores.
    const std::string spec = "cornell:points=3000,samples=8";
    const std::string train = (dir / "train.npy").string(), model = (dir / "box.pmsc").string();
    Result r = pmscRun({"export-frames", spec, "--out", train, "--frames", "0-143:6", "--quiet"},
                       dir / "logs", "export");
    if (r.code == 2 && r.err.find("unknown evaluator") != std::string::npos)
        GTEST_SKIP() << "this build has no cornell evaluator";
    ASSERT_EQ(r.code, 0) << r.err;
    ASSERT_EQ(
        pmscRun({"train", "--frames", train, "--out", model, "--max-keys", "40"}, dir / "logs", "train").code,
        0);

    const std::vector<std::string> args{"run",      "--model", model,   "--evaluator",          spec,
                                        "--frames", "144-149", "--out", (dir / "vdb").string(), "--format",
                                        "vdb"};
    r = pmscRun(args, dir / "logs", "run1");
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(countFrames(dir / "vdb"), 6);
    const std::string good = slurp((dir / "vdb" / "frame.000146.vdb").string());
    ASSERT_GT(good.size(), 1000u);
    {
        std::ofstream f(dir / "vdb" / "frame.000146.vdb", std::ios::binary | std::ios::trunc);
        f << good.substr(0, good.size() / 2);
    }
    r = pmscRun(args, dir / "logs", "run2");
    ASSERT_EQ(r.code, 0) << r.err;
    const auto stats = readJson(dir / "vdb" / "pmsc-run.144-149.json");
    EXPECT_EQ(stats["format"], "vdb");
    EXPECT_EQ(stats["basis_precision"], "single") << "a float grid reads the float basis";
    EXPECT_EQ(stats["frames_skipped"].get<Index>(), 5);
    EXPECT_EQ(stats["frames_replaced_invalid"].get<Index>(), 1);
    EXPECT_EQ(stats["frames_evaluated"].get<Index>(), 1);
    // Not byte-compared: OpenVDB stamps every file with a fresh random UUID. Same size, and the
    // writer's own check accepts it.
    EXPECT_EQ(slurp((dir / "vdb" / "frame.000146.vdb").string()).size(), good.size());
    EXPECT_FALSE(hasTemporaries(dir / "vdb"));
    if (!HasFailure()) fs::remove_all(dir);
}
