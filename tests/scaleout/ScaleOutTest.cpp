// Training past one machine: out-of-core streaming, several shots as one training set,
// MPI ranks, and training under an address-space limit smaller than the training matrix. Every
// path must give the model of in-memory, single-process training: the same M and keys, bases
// within 1e-9 principal angle, the same largest training residual.
#include "pmsc/Communicator.h"
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"
#include "pmsc/RowBlocks.h"
#include "pmsc/Training.h"
#include "tests/common/CliRunner.h"
#include "tests/common/MissingData.h"

#include <gtest/gtest.h>
#include <Eigen/SVD>

#include <sys/stat.h>
#include <unistd.h>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace pmsc::test {
namespace {

/// Writes a synthetic shot (pmsc_scaleout_frames) and returns its path.
std::string makeFrames(const TempDir& dir, const std::string& name, int grid, int frames, unsigned seed = 1,
                       const std::string& dtype = "float64", const std::string& extra = "") {
    const std::string path = dir.file(name);
    const std::string command = shellQuote(PMSC_FRAMES_TOOL) + " " + shellQuote(path) + " " +
                                std::to_string(grid) + " " + std::to_string(frames) + " " +
                                std::to_string(seed) + " " + dtype + " " + extra;
    if (std::system(command.c_str()) != 0) throw std::runtime_error("cannot make frames: " + command);
    return path;
}

/// sin of the largest principal angle between the column spaces of two orthonormal bases:
/// ||B - A (A^T B)||_2.
double basisAngle(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
    const Eigen::MatrixXd r = b - a * (a.transpose() * b);
    return Eigen::JacobiSVD<Eigen::MatrixXd>(r).singularValues()(0);
}

/// The agreement every scale-out path must reach. Returns a description of the first difference, or "".
void expectSameModel(const Model& a, const Model& b, const std::string& what) {
    SCOPED_TRACE(what);
    ASSERT_EQ(a.basisSize(), b.basisSize()) << "M differs";
    ASSERT_EQ(a.keyPoints, b.keyPoints) << "keys differ";
    EXPECT_LT(basisAngle(a.basis, b.basis), 1e-9) << "bases differ";
    EXPECT_NEAR(a.trainMaxPointResidual, b.trainMaxPointResidual, 1e-9 * a.trainMaxPointResidual + 1e-15);
    EXPECT_LT((a.mean - b.mean).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_NEAR(a.epsMin, b.epsMin, 1e-7 * a.epsMin + 1e-15);
    EXPECT_NEAR(a.totalEnergy, b.totalEnergy, 1e-10 * a.totalEnergy);
    EXPECT_EQ(a.nonNegative, b.nonNegative);
}

TrainingOptions smallOptions() {
    TrainingOptions o;
    o.maxKeys = 30;
    o.maxBasis = 40;
    return o;
}

// --- in process: the shared algorithm on a streamed RowBlocks equals the in-memory one ----------

struct Case {
    const char* name;
    void (*set)(TrainingOptions&);
};

TEST(OutOfCore, StreamedBlocksTrainTheInMemoryModel) {
    TempDir dir;
    const std::string path = makeFrames(dir, "train.npy", 24, 150);
    const FrameSet frames = readFrames(path).frames;
    const Case cases[] = {
        {"energy rule, uncalibrated", [](TrainingOptions&) {}},
        {"calibrated", [](TrainingOptions& o) { o.tolerance = 0.02; }},
        {"max-error basis rule", [](TrainingOptions& o) { o.basisMaxError = 0.01; }},
        {"Q-DEIM", [](TrainingOptions& o) { o.selector = Selector::QDeim; }},
        {"fiducials, max error",
         [](TrainingOptions& o) {
             o.fiducials = {3, 200};
             o.maxError = 0.004;
         }},
    };
    for (const Case& c : cases) {
        TrainingOptions o = smallOptions();
        c.set(o);
        TrainingReport inMemoryReport, streamedReport;
        const Model inMemory = train(frames, o, &inMemoryReport);
        // Blocks of 37 points: blocks end mid-row of the 24-point grid and the last one is short.
        NpyBlocks blocks(openShots({path}), {0, frames.points}, 37);
        SingleProcess one;
        const Model streamed = train(blocks, one, o, &streamedReport);
        EXPECT_GT(blocks.blockCount(), 10);
        expectSameModel(inMemory, streamed, c.name);
        EXPECT_EQ(inMemoryReport.iterations, streamedReport.iterations) << c.name;
    }
}

TEST(OutOfCore, TheMemoryLimitCapsTheBasisOnceTheDataTellM) {
    TempDir dir;
    const std::string path = makeFrames(dir, "cap.npy", 20, 90, 5);
    TrainingOptions o = smallOptions();
    o.maxBasis = 256;  // the default: the memory must follow M, not this
    o.energy = 0.999999;
    o.block = 4;  // so the data's M (9 here) is above the Varimax block, whose vectors are always formed
    const Model free = train(readFrames(path).frames, o);
    const Index m = free.basisSize();
    ASSERT_GT(m, o.block + 2) << "the data need too few basis vectors for this test";
    const Index bp = 64;
    auto bound = [&](Index r) { return trainingMemoryBound(400, 3, 90, r, o.block, o.maxKeys, bp, 1, true); };
    {
        // Exactly what the data's M needs: the same model, no warning.
        TrainingOptions limited = o;
        limited.memoryLimit = bound(m);
        NpyBlocks blocks(openShots({path}), {0, 400}, bp);
        SingleProcess one;
        TrainingReport report;
        expectSameModel(free, train(blocks, one, limited, &report), "limit at M");
        for (const auto& w : report.warnings) EXPECT_EQ(w.find("memory limit"), std::string::npos) << w;
        EXPECT_GT(bound(o.maxBasis), limited.memoryLimit) << "the limit would have held --max-basis";
    }
    {
        // Two vectors fewer fit: M is capped there, with a warning naming the limit.
        TrainingOptions limited = o;
        limited.memoryLimit = bound(m - 2);
        NpyBlocks blocks(openShots({path}), {0, 400}, bp);
        SingleProcess one;
        TrainingReport report;
        const Model capped = train(blocks, one, limited, &report);
        EXPECT_EQ(capped.basisSize(), m - 2);
        bool warned = false;
        for (const auto& w : report.warnings)
            warned = warned || w.find("the memory limit holds") != std::string::npos;
        EXPECT_TRUE(warned);
    }
    {
        // Not even the Varimax block fits: one line, before the basis is formed.
        TrainingOptions limited = o;
        limited.memoryLimit = bound(o.block) - 1;
        NpyBlocks blocks(openShots({path}), {0, 400}, bp);
        SingleProcess one;
        try {
            train(blocks, one, limited);
            FAIL() << "a limit below the Varimax block trained";
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find("cannot hold even 4 basis vectors"), std::string::npos)
                << e.what();
        }
    }
}

TEST(OutOfCore, Float32ShotsStreamLikeInMemory) {
    TempDir dir;
    const std::string path = makeFrames(dir, "train32.npy", 20, 90, 3, "float32");
    const Model inMemory = train(readFrames(path).frames, smallOptions());
    NpyBlocks blocks(openShots({path}), {0, 400}, 64);
    SingleProcess one;
    expectSameModel(inMemory, train(blocks, one, smallOptions()), "float32");
}

TEST(OutOfCore, BoundGrowsWithTheBlockNotWithTheFrameMatrix) {
    // Ten times the points at the same F and block: only the per-row terms (basis, Varimax block)
    // grow, never an N*C*F term.
    const auto small = trainingMemoryBound(10000, 3, 1000, 16, 16, 40, 100, 1, false);
    const auto large = trainingMemoryBound(100000, 3, 1000, 16, 16, 40, 100, 1, false);
    EXPECT_LT(static_cast<double>(large - small), 0.1 * 90000.0 * 3 * 1000 * 8);
    // In memory the frames are held once (centred where they were read), and counted.
    const auto inMemory = trainingMemoryBound(10000, 3, 1000, 16, 16, 40, 0, 1, true);
    EXPECT_GT(inMemory, 1u * 10000 * 3 * 1000 * 8);
    EXPECT_LT(inMemory, 2u * 10000 * 3 * 1000 * 8);
}

// --- the program: several shots, bad inputs ----------------------------------------------------

TEST(TrainCli, TwoShotsAreOneTrainingSet) {
    TempDir dir;
    const std::string a = makeFrames(dir, "a.npy", 20, 70, 1);
    const std::string b = makeFrames(dir, "b.npy", 20, 50, 2, "float32");
    FrameSet both(120, 400, 3);
    const FrameSet fa = readFrames(a).frames, fb = readFrames(b).frames;
    std::copy(fa.values.begin(), fa.values.end(), both.frame(0));
    std::copy(fb.values.begin(), fb.values.end(), both.frame(70));
    const Model reference = train(both, smallOptions());
    for (const bool stream : {true, false}) {
        const std::string out = dir.file(stream ? "streamed.pmsc" : "in-memory.pmsc");
        std::vector<std::string> args = {"train", "--frames",   a,    "--frames",    b,    "--out",
                                         out,     "--max-keys", "30", "--max-basis", "40", "--block-points",
                                         "33",    "--quiet"};
        if (stream) args.push_back("--out-of-core");
        const RunResult r = runPmsc(dir, args);
        ASSERT_EQ(r.exitCode, 0) << r.err;
        EXPECT_NE(r.out.find("120 frames x 400 points"), std::string::npos) << r.out;
        EXPECT_NE(r.out.find("2 --frames files"), std::string::npos) << r.out;
        EXPECT_NE(r.out.find(stream ? "streamed from disk in blocks of 33 points" : "in memory"),
                  std::string::npos)
            << r.out;
        expectSameModel(reference, readModel(out), stream ? "streamed" : "in memory");
    }
}

TEST(TrainCli, BadInputsAreOneLineAndExitCode2) {
    TempDir dir;
    const std::string a = makeFrames(dir, "a.npy", 20, 40, 1);
    const std::string other = makeFrames(dir, "other.npy", 21, 40, 1);
    const std::string nan = makeFrames(dir, "nan.npy", 20, 40, 1, "float64", "nan=17:123");
    const std::string out = dir.file("m.pmsc");
    struct Bad {
        std::vector<std::string> args;
        std::string says;
    };
    const Bad bads[] = {
        {{"--frames", a, "--frames", other}, "same N and C"},
        {{"--frames", a, "--memory-limit", "1M"}, "cannot be met"},
        {{"--frames", a, "--memory-limit", "lots"}, "is not a size"},
        // In memory needs ~3.4 MB here, streaming ~3.1 MB plus 2.9 kB a point of block.
        {{"--frames", a, "--memory-limit", "3.2M", "--block-points", "1000"}, "does not fit"},
        {{"--frames", a, "--frames", nan, "--out-of-core"}, "frame 17, point 123, channel 1 is nan"},
        {{"--frames", a, "--frames", dir.file("missing.npy")}, "no such file"},
    };
    for (const Bad& bad : bads) {
        std::vector<std::string> args = {"train", "--out", out, "--quiet"};
        args.insert(args.end(), bad.args.begin(), bad.args.end());
        const RunResult r = runPmsc(dir, args);
        EXPECT_EQ(r.exitCode, 2) << bad.says << ": " << r.err;
        ASSERT_EQ(r.errLines().size(), 1u) << r.err;
        EXPECT_EQ(r.err.rfind("pmsc: ", 0), 0u) << r.err;
        EXPECT_NE(r.err.find(bad.says), std::string::npos) << r.err;
        EXPECT_FALSE(std::filesystem::exists(out)) << bad.says;
    }
}

// --- MPI: mpirun -n 2 on this machine ----------------------------------------------------------

#ifdef PMSC_MPIEXEC
std::string mpirun(int ranks) {
    // Root is allowed (CI and containers run as root); --oversubscribe because a CI machine may
    // have fewer cores than ranks.
    return std::string("env OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 ") + PMSC_MPIEXEC +
           " --oversubscribe -n " + std::to_string(ranks);
}

TEST(Mpi, TwoRanksTrainTheSingleProcessModel) {
    TempDir dir;
    const std::string a = makeFrames(dir, "a.npy", 30, 120, 5);
    const std::string b = makeFrames(dir, "b.npy", 30, 60, 6, "float32");
    const std::vector<std::vector<std::string>> variants = {
        {"--max-keys", "40"},
        {"--max-keys", "40", "--tolerance", "0.02", "--block-points", "57"},
        {"--selector", "qdeim", "--max-keys", "24", "--basis", "12"},
    };
    for (const auto& variant : variants) {
        std::vector<std::string> common = {"train", "--frames", a, "--frames", b, "--quiet"};
        common.insert(common.end(), variant.begin(), variant.end());
        auto single = common, two = common;
        single.insert(single.end(), {"--out", dir.file("single.pmsc")});
        two.insert(two.end(), {"--out", dir.file("two.pmsc")});
        const RunResult one = runPmsc(dir, single);
        ASSERT_EQ(one.exitCode, 0) << one.err;
        EXPECT_NE(one.out.find("1 (one process)"), std::string::npos) << one.out;
        const RunResult r = runPmsc(dir, two, mpirun(2));
        ASSERT_EQ(r.exitCode, 0) << r.err;
        EXPECT_NE(r.out.find("2 MPI processes"), std::string::npos) << r.out;
        // Only rank 0 writes and reports.
        EXPECT_EQ(r.out.find("trained"), r.out.rfind("trained")) << r.out;
        expectSameModel(readModel(dir.file("single.pmsc")), readModel(dir.file("two.pmsc")), variant[1]);
    }
}

TEST(Mpi, ABadValueInOneRanksRowsStopsEveryRank) {
    TempDir dir;
    // Point 390 of 400 is in rank 1's half: rank 0 never reads it.
    const std::string nan = makeFrames(dir, "nan.npy", 20, 40, 1, "float64", "nan=30:390");
    const RunResult r = runPmsc(dir, {"train", "--frames", nan, "--out", dir.file("m.pmsc"), "--quiet"},
                                "timeout 60 " + mpirun(2));
    EXPECT_NE(r.exitCode, 0);
    EXPECT_NE(r.exitCode, 124) << "hung";
    EXPECT_NE(r.err.find("frame 30, point 390, channel 1 is nan (MPI rank 1)"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir.file("m.pmsc")));
}

TEST(Mpi, BadOptionsFailOnceBeforeAnyWork) {
    TempDir dir;
    const std::string a = makeFrames(dir, "a.npy", 20, 40, 1);
    const RunResult r = runPmsc(
        dir, {"train", "--frames", a, "--out", dir.file("m.pmsc"), "--memory-limit", "1M"}, mpirun(2));
    EXPECT_EQ(r.exitCode, 2) << r.err;
    EXPECT_NE(r.err.find("pmsc: train: --memory-limit 1.0 MiB cannot be met"), std::string::npos) << r.err;
}
#endif

// --- a training set larger than the address space the process may use -------------------------

/// The address space the program needs before any work (its libraries, TBB's and glibc's
/// reservations): the smallest RLIMIT_AS under which `pmsc train --help` still runs, to 4 MiB.
std::uint64_t baselineAddressSpace(const TempDir& dir) {
    std::uint64_t lo = 16u << 20, hi = 2048u << 20;
    while (hi - lo > (4u << 20)) {
        const std::uint64_t mid = (lo + hi) / 2;
        const RunResult r = runPmsc(dir, {"train", "--help"}, "prlimit --as=" + std::to_string(mid));
        if (r.exitCode == 0)
            hi = mid;
        else
            lo = mid;
    }
    return hi;
}

TEST(AddressLimit, ATrainingSetTwiceTheLimitTrainsToTheInMemoryModel) {
    if (std::system("command -v prlimit >/dev/null 2>&1") != 0) {
        if (underCi()) FAIL() << "prlimit (util-linux) is missing";
        GTEST_SKIP() << "prlimit not installed";
    }
    TempDir dir;
    const std::uint64_t baseline = baselineAddressSpace(dir);
    const int grid = 230, frames = 600;  // 52,900 points x 3 channels x 600 frames: 762 MB of doubles
    const std::string path = makeFrames(dir, "big.npy", grid, frames, 7);
    const double matrixBytes = double(grid) * grid * 3 * frames * 8;
    const std::vector<std::string> options = {"--max-basis", "16", "--block", "8",
                                              "--max-keys",  "24", "--quiet"};
    const std::uint64_t bound = trainingMemoryBound(Index(grid) * grid, 3, frames, 16, 8, 24, 1, 1, true);
    // The limit: the program's own address space, the streaming bound, and 32 MiB for blocks and
    // the allocator; the matrix must be at least twice that.
    const std::uint64_t limit = baseline + bound + (32u << 20);
    std::printf(
        "baseline address space %.1f MiB, streaming bound %.1f MiB, limit %.1f MiB, matrix %.1f MiB "
        "(%.2fx)\n",
        baseline / 1048576.0, bound / 1048576.0, limit / 1048576.0, matrixBytes / 1048576.0,
        matrixBytes / double(limit));
    ASSERT_GE(matrixBytes, 2.0 * double(limit)) << "the test data would not be twice the limit";

    auto limited = options, free = options;
    limited.insert(limited.begin(), {"train", "--frames", path, "--out", dir.file("limited.pmsc")});
    // In memory whatever the machine's size (without a limit pmsc would stream above half of it).
    free.insert(free.begin(),
                {"train", "--frames", path, "--out", dir.file("free.pmsc"), "--memory-limit", "64G"});
    const RunResult r = runPmsc(dir, limited, "prlimit --as=" + std::to_string(limit));
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("streamed from disk"), std::string::npos) << r.out;
    std::printf("%s", r.out.c_str());
    const RunResult f = runPmsc(dir, free);
    ASSERT_EQ(f.exitCode, 0) << f.err;
    EXPECT_NE(f.out.find("in memory"), std::string::npos) << f.out;
    const Model a = readModel(dir.file("free.pmsc")), b = readModel(dir.file("limited.pmsc"));
    expectSameModel(a, b, "address limit");
    std::printf(
        "in memory: M = %lld, K = %lld, residual %.9g; limited: M = %lld, K = %lld, residual %.9g, "
        "basis angle %.3g\n",
        static_cast<long long>(a.basisSize()), static_cast<long long>(a.keyCount()), a.trainMaxPointResidual,
        static_cast<long long>(b.basisSize()), static_cast<long long>(b.keyCount()), b.trainMaxPointResidual,
        basisAngle(a.basis, b.basis));
    // And in memory it would not have fitted: the same limit with the whole set read fails.
    const RunResult whole =
        runPmsc(dir, {"export-frames", "replay:" + path, "--out", dir.file("copy.npy"), "--quiet"},
                "prlimit --as=" + std::to_string(limit));
    EXPECT_NE(whole.exitCode, 0) << "reading the whole set fitted in the limit";
}

/// A fresh memory cgroup limited to `bytes` (v1's memory controller, or v2 with memory enabled for
/// children), or "" when this machine offers none to root.
std::string makeMemoryCgroup(std::uint64_t bytes) {
    std::ifstream mounts("/proc/self/mounts");
    for (std::string line; std::getline(mounts, line);) {
        std::istringstream fields(line);
        std::string device, point, type, options;
        fields >> device >> point >> type >> options;
        const bool v1 = type == "cgroup" && ("," + options + ",").find(",memory,") != std::string::npos;
        bool v2 = false;
        if (type == "cgroup2") {
            std::ifstream controllers(point + "/cgroup.subtree_control");
            std::string text;
            std::getline(controllers, text);
            v2 = (" " + text + " ").find(" memory ") != std::string::npos;
        }
        if (!v1 && !v2) continue;
        const std::string dir = point + "/pmsc-test-" + std::to_string(::getpid());
        if (::mkdir(dir.c_str(), 0755) != 0) continue;
        std::ofstream(dir + (v1 ? "/memory.limit_in_bytes" : "/memory.max")) << bytes << "\n";
        if (v1)
            std::ofstream(dir + "/memory.memsw.limit_in_bytes")
                << bytes << "\n";  // no swap either, where accounted
        if (v2) std::ofstream(dir + "/memory.swap.max") << 0 << "\n";
        return dir;
    }
    return "";
}

/// A shell that joins `cgroup`, then becomes pmsc ($0 "$@": the program and its arguments).
std::string insideCgroup(const std::string& cgroup) {
    return "sh -c 'echo $$ > " + cgroup + "/cgroup.procs && exec \"$0\" \"$@\"'";
}

/// The cgroup's peak usage (v1; 0 where the file is missing), then the cgroup removed.
double peakAndRemove(const std::string& cgroup) {
    std::ifstream file(cgroup + "/memory.max_usage_in_bytes");
    double peak = 0;
    file >> peak;
    ::rmdir(cgroup.c_str());
    return peak;
}

TEST(Cgroup, ATrainingSetTwiceTheLimitStreamsInsideAMemoryCgroup) {
    TempDir dir;
    const int grid = 230, frames = 600;  // 52,900 points x 3 channels x 600 frames: 762 MB of doubles
    const std::string path = makeFrames(dir, "big.npy", grid, frames, 7);
    const double matrixBytes = double(grid) * grid * 3 * frames * 8;
    const std::uint64_t bound = trainingMemoryBound(Index(grid) * grid, 3, frames, 16, 8, 24, 1, 1, true);
    // The cgroup: the streaming bound plus 128 MiB for the program itself, blocks and page cache.
    const std::uint64_t limit = bound + (128u << 20);
    ASSERT_GE(matrixBytes, 2.0 * double(limit)) << "the test data would not be twice the limit";
    const std::string cgroup = ::geteuid() == 0 ? makeMemoryCgroup(limit) : "";
    if (cgroup.empty()) {
        if (underCi()) FAIL() << "no memory cgroup could be made (needs root and a memory controller)";
        GTEST_SKIP() << "no memory cgroup could be made (needs root and a memory controller)";
    }
    std::printf("cgroup %s: limit %.1f MiB (streaming bound %.1f MiB), matrix %.1f MiB (%.2fx)\n",
                cgroup.c_str(), limit / 1048576.0, bound / 1048576.0, matrixBytes / 1048576.0,
                matrixBytes / double(limit));
    const std::string inside = insideCgroup(cgroup);
    const std::vector<std::string> options = {"--max-basis", "16", "--block", "8",
                                              "--max-keys",  "24", "--quiet"};
    auto limited = options, free = options, forced = options;
    limited.insert(limited.begin(), {"train", "--frames", path, "--out", dir.file("limited.pmsc")});
    free.insert(free.begin(),
                {"train", "--frames", path, "--out", dir.file("free.pmsc"), "--memory-limit", "64G"});
    forced.insert(forced.begin(),
                  {"train", "--frames", path, "--out", dir.file("forced.pmsc"), "--memory-limit", "64G"});
    const RunResult r = runPmsc(dir, limited, inside);
    // In memory inside the same cgroup: the kernel kills it (what a farm task met without the limit).
    const RunResult killed = runPmsc(dir, forced, inside);
    const double peak = peakAndRemove(cgroup);
    ASSERT_EQ(r.exitCode, 0) << r.err;
    EXPECT_NE(r.out.find("streamed from disk"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("cgroup memory limit"), std::string::npos) << r.out;
    std::printf("%s", r.out.c_str());
    if (peak > 0)
        std::printf("cgroup peak usage (resident and page cache) %.1f MiB of %.1f MiB\n", peak / 1048576.0,
                    limit / 1048576.0);
    EXPECT_EQ(killed.exitCode, 128 + 9) << "in-memory training fitted in the cgroup: " << killed.err;
    const RunResult f = runPmsc(dir, free);
    ASSERT_EQ(f.exitCode, 0) << f.err;
    expectSameModel(readModel(dir.file("free.pmsc")), readModel(dir.file("limited.pmsc")), "cgroup");

    // Default options (--max-basis 256) in a cgroup of half what in-memory training of these frames
    // needs at the basis they need: the plan reserves for that basis, not for 256, so it streams.
    const RunResult d = runPmsc(dir, {"train", "--frames", path, "--out", dir.file("defaults-free.pmsc"),
                                      "--memory-limit", "64G", "--quiet"});
    ASSERT_EQ(d.exitCode, 0) << d.err;
    const Model defaults = readModel(dir.file("defaults-free.pmsc"));
    const TrainingOptions o;
    const std::uint64_t inMemory =
        trainingMemoryBound(Index(grid) * grid, 3, frames, std::max(defaults.basisSize(), o.block), o.block,
                            o.maxKeys, 0, 1, true);
    const std::string half = makeMemoryCgroup(inMemory / 2);
    ASSERT_FALSE(half.empty());
    const RunResult h =
        runPmsc(dir, {"train", "--frames", path, "--out", dir.file("defaults-half.pmsc"), "--quiet"},
                insideCgroup(half));
    const double halfPeak = peakAndRemove(half);
    ASSERT_EQ(h.exitCode, 0) << h.err;
    EXPECT_NE(h.out.find("streamed from disk"), std::string::npos) << h.out;
    std::printf("defaults: M = %lld, in memory %.1f MiB, cgroup %.1f MiB, peak %.1f MiB\n%s",
                static_cast<long long>(defaults.basisSize()), inMemory / 1048576.0, inMemory / 2 / 1048576.0,
                halfPeak / 1048576.0, h.out.c_str());
    expectSameModel(defaults, readModel(dir.file("defaults-half.pmsc")), "defaults in half the memory");
}

TEST(Cgroup, ReplayCutsItsFramesInFlightToTheCgroup) {
    TempDir dir;
    const int grid = 230, frames = 40;  // 52,900 points x 3: a frame's buffers are about 4 MB
    const std::string path = makeFrames(dir, "shot.npy", grid, frames, 3);
    const RunResult t =
        runPmsc(dir, {"train", "--frames", path, "--out", dir.file("m.pmsc"), "--max-basis", "16", "--block",
                      "8", "--max-keys", "24", "--memory-limit", "64G", "--quiet"});
    ASSERT_EQ(t.exitCode, 0) << t.err;
    auto inFlight = [](const std::string& out) {
        const auto at = out.find(" frames in flight)");
        if (at == std::string::npos) return -1;
        const auto start = out.rfind(", ", at);
        return std::stoi(out.substr(start + 2, at - start - 2));
    };
    const std::vector<std::string> replay = {"replay",    "--model", dir.file("m.pmsc"), "--frames", path,
                                             "--threads", "8",       "--quiet"};
    auto free = replay, limited = replay;
    free.insert(free.end(), {"--report", dir.file("free.json")});
    limited.insert(limited.end(), {"--report", dir.file("limited.json")});
    const RunResult f = runPmsc(dir, free);
    ASSERT_EQ(f.exitCode, 0) << f.err;
    EXPECT_GT(inFlight(f.out), 8) << f.out;  // 2 x threads where memory allows
    const std::string cgroup = ::geteuid() == 0 ? makeMemoryCgroup(64u << 20) : "";
    if (cgroup.empty()) {
        if (underCi()) FAIL() << "no memory cgroup could be made (needs root and a memory controller)";
        GTEST_SKIP() << "no memory cgroup could be made (needs root and a memory controller)";
    }
    const RunResult r = runPmsc(dir, limited, insideCgroup(cgroup));
    peakAndRemove(cgroup);
    ASSERT_EQ(r.exitCode, 0) << r.err;
    std::printf("%s", r.out.c_str());
    EXPECT_GE(inFlight(r.out), 1) << r.out;
    EXPECT_LT(inFlight(r.out), inFlight(f.out)) << r.out;
    // The same decisions, frame by frame: the frames in flight change nothing but memory.
    std::ifstream a(dir.file("free.json")), b(dir.file("limited.json"));
    std::stringstream ta, tb;
    ta << a.rdbuf();
    tb << b.rdbuf();
    const auto framesOf = [](const std::string& text) { return text.substr(text.find("\"frames\": [")); };
    EXPECT_EQ(framesOf(ta.str()), framesOf(tb.str()));
}

}  // namespace
}  // namespace pmsc::test
