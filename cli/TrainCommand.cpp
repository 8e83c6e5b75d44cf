// `pmsc train`: frames (.npy) -> model (.pmsc). Sections 3-5 of the paper, plus calibration.
#include "app/ExitCodes.h"
#include "app/MemoryLimit.h"
#include "app/TrainingDefaults.h"
#include "cli/Args.h"
#include "cli/Commands.h"
#include "cli/CrossTrain.h"
#include "cli/Format.h"
#include "cli/Interrupt.h"
#include "cli/Progress.h"
#include "cli/TrainSummary.h"
#include "cli/mpi/MpiLaunch.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"
#include "pmsc/RowBlocks.h"
#include "pmsc/Training.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>

#include <sys/resource.h>
#include <unistd.h>

namespace pmsc::cli {

namespace {

/// "512M", "8G", "1.5GiB", "100000" -> bytes (K/M/G/T are powers of 1024).
std::uint64_t parseBytes(const std::string& option, const std::string& text) {
    std::size_t used = 0;
    double value = 0;
    try {
        value = std::stod(text, &used);
    } catch (const std::exception&) {
        throw UsageError(option + ": '" + text + "' is not a size (e.g. 512M, 8G)");
    }
    std::string unit = text.substr(used);
    if (unit.size() > 1 && (unit.back() == 'B' || unit.back() == 'b')) unit.pop_back();
    if (unit.size() > 1 && unit.back() == 'i') unit.pop_back();
    double scale = 1;
    if (unit.empty())
        scale = 1;
    else if (unit == "K" || unit == "k")
        scale = 1024.0;
    else if (unit == "M" || unit == "m")
        scale = 1024.0 * 1024;
    else if (unit == "G" || unit == "g")
        scale = 1024.0 * 1024 * 1024;
    else if (unit == "T" || unit == "t")
        scale = 1024.0 * 1024 * 1024 * 1024;
    else
        throw UsageError(option + ": unknown unit in '" + text + "' (use K, M, G or T)");
    if (!(value > 0) || !std::isfinite(value * scale))
        throw UsageError(option + ": must be a positive size, got '" + text + "'");
    return static_cast<std::uint64_t>(value * scale);
}

std::string bytesText(double bytes) {
    char buf[64];
    if (bytes >= 1024.0 * 1024 * 1024)
        std::snprintf(buf, sizeof buf, "%.2f GiB", bytes / (1024.0 * 1024 * 1024));
    else
        std::snprintf(buf, sizeof buf, "%.1f MiB", bytes / (1024.0 * 1024));
    return buf;
}

/// Address space this process already uses (VmSize), 0 if unknown.
/// The whole training set in memory: the shots read one after the other into one FrameSet.
FrameSet readShots(const std::vector<Shot>& shots) {
    if (shots.size() == 1) return readFrames(shots.front().path).frames;
    Index total = 0;
    for (const Shot& s : shots) total += s.info.frames;
    FrameSet all(total, shots.front().info.points, shots.front().info.channels);
    Index at = 0;
    for (const Shot& s : shots) {
        const FrameFile f = readFrames(s.path);
        std::copy(f.frames.values.begin(), f.frames.values.end(), all.frame(at));
        at += f.frames.frames;
    }
    return all;
}

/// What `pmsc train` was asked; the training settings themselves are in `options`.
struct TrainArgs {
    std::vector<std::string> framePaths;
    std::string outPath, selector = "teleconnection", rule,
                         targetsPath;  // rule empty: TrainingOptions decides
    std::string keyError;              // empty: TrainingOptions decides (resolvedKeyErrorNorm)
    std::uint64_t memoryLimit = 0;
    Index blockPoints = 0;
    bool outOfCore = false, sharedChannels = false, quiet = false;
    TrainingOptions options = app::defaultTrainingOptions();
};

/// The parser with the command's description and its inputs and output (--frames, --out).
ArgParser trainParser(TrainArgs& a) {
    ArgParser parser(
        "train", "--frames TRAIN.npy [--frames SHOT2.npy ...] --out MODEL.pmsc [options]",
        "Trains a point-multiplication model: mean removal, a truncated SVD basis (section 3),\n"
        "key points by Varimax + teleconnection or Q-DEIM (section 4), the least-squares\n"
        "projector, and the soft-cache thresholds eps (section 5). With --tolerance, eps is\n"
        "calibrated by leave-one-slice-out so that a hit's largest point error stays under it.\n"
        "\n"
        "Larger than memory: several --frames files (shots, same points and channels) are one\n"
        "training set. When it does not fit (--memory-limit, the memory cgroup's limit, the address-space\n"
        "limit, or half the machine's memory) or with --out-of-core, the frames are streamed from disk in\n"
        "blocks of points, and memory is bounded by, in doubles (F frames, r = max(M, block), at most\n"
        "F, B = --block, K = --max-keys, R = N*C/P rows per rank, b = block rows):\n"
        "  5 F^2 + 3 r F + 2 R r + 4 R B + K C (F + r) + 3 b F, plus 3 N C (r + 1) on rank 0,\n"
        "never N*C*F. M is checked against the limit once the first pass has told it, and capped to\n"
        "fit with a warning. --memory-limit fails at once when even one point per block cannot fit.\n"
        "Under MPI (mpirun -n P pmsc train ..., or srun --mpi=pmix) each of the P ranks reads\n"
        "only its share of the points; rank 0 writes the model. Started plainly, one process.");
    parser.option(
        "--frames", "FILE.npy",
        "training frames, shape (frames, points, channels), float32/64; repeat for several shots",
        [&a](const std::string& v) { a.framePaths.push_back(v); }, true);
    parser.repeatable("--frames");
    parser.option("--out", "MODEL.pmsc", "model file to write (atomically)", a.outPath, true);
    return parser;
}

/// The options of the basis size M (section 3) and of the key points (section 4).
void declareBasisAndKeyOptions(ArgParser& parser, TrainArgs& a) {
    TrainingOptions& options = a.options;
    parser.option("--basis", "M", "basis size M",
                  [&](const std::string& v) { options.basis = parseIndex("--basis", v, 1); });
    parser.option("--energy", "E", "smallest M capturing this fraction of the energy, in (0, 1]",
                  [&](const std::string& v) {
                      options.energy = parseDouble("--energy", v, 0.0, 1.0);
                      if (options.energy <= 0) throw UsageError("--energy: must be in (0, 1]");
                  });
    parser.option(
        "--basis-error", "X", "smallest M whose largest point projection error <= X (data units)",
        [&](const std::string& v) { options.basisMaxError = parseDouble("--basis-error", v, 0.0); });
    parser.option("--max-basis", "M",
                  "cap on M whatever the rule (default " + std::to_string(options.maxBasis) + ")",
                  [&](const std::string& v) { options.maxBasis = parseIndex("--max-basis", v, 1); });
    parser.option("--max-error", "X", "stop adding keys once the largest training point residual <= X",
                  [&](const std::string& v) { options.maxError = parseDouble("--max-error", v, 0.0); });
    parser.option("--max-keys", "K", "key point budget (default " + std::to_string(options.maxKeys) + ")",
                  [&](const std::string& v) { options.maxKeys = parseIndex("--max-keys", v, 1); });
    parser.option(
        "--block", "B",
        "basis vectors per Varimax block (paper: 10-20; default " + std::to_string(options.block) + ")",
        [&](const std::string& v) { options.block = parseIndex("--block", v, 1); });
    parser.option("--fiducials", "i,j,...", "designer key points, seeded first",
                  [&](const std::string& v) { options.fiducials = parseIndexList("--fiducials", v); });
    parser.option("--grid-points", "i,j,...", "sparse grid of points seeded as keys (rendering)",
                  [&](const std::string& v) { options.gridPoints = parseIndexList("--grid-points", v); });
    parser.option("--selector", "NAME", "teleconnection (the paper's, default) or qdeim", a.selector);
}

/// The options of the thresholds' calibration (section 5), of learning and of the randomized SVD.
void declareCalibrationOptions(ArgParser& parser, TrainArgs& a) {
    TrainingOptions& options = a.options;
    parser.option("--tolerance", "T", "largest point error a hit may have (data units): calibrates eps",
                  [&](const std::string& v) { options.tolerance = parseDouble("--tolerance", v, 0.0); });
    parser.option("--slices", "S",
                  "leave-one-slice-out folds for --tolerance (default " +
                      std::to_string(options.calibrationSlices) + ")",
                  [&](const std::string& v) { options.calibrationSlices = parseIndex("--slices", v, 2); });
    parser.option(
        "--calibration", "RULE",
        "how --tolerance sets eps: threshold (the largest held-out key error with no held-out frame over "
        "the tolerance at or below it, at most conformal's; max's where no held-out frame crossed the "
        "tolerance; default for the predicted key error, whose RMS part is always max), max (tolerance / the "
        "largest held-out error ratio, default for the other key errors) or conformal (tolerance / the "
        "held-out error ratios' quantile at --coverage)",
        a.rule);
    parser.option("--key-error", "NORM",
                  "the key error eps apply to: predicted (the point error the key RMS and the leave-one-out "
                  "error predict, the smaller: a hit when either is under its calibrated threshold; default "
                  "with --tolerance), rms (the paper's RMS over the keys; default without --tolerance and "
                  "with --shared-channels), largest (the largest key's error) or loo (the largest key's "
                  "leave-one-out error: each key's residual over 1 - its leverage); predicted, largest and "
                  "loo not with --shared-channels, predicted only with --tolerance",
                  a.keyError);
    parser.option("--coverage", "C",
                  "coverage of --calibration threshold or conformal, in (0, 1) (default " +
                      std::to_string(options.calibrationCoverage).substr(0, 4) + ")",
                  [&](const std::string& v) {
                      options.calibrationCoverage = parseDouble("--coverage", v, 0.0, 1.0);
                      if (!(options.calibrationCoverage > 0 && options.calibrationCoverage < 1))
                          throw UsageError("--coverage: must be in (0, 1), got " + v);
                  });
    parser.option(
        "--learn-rank", "R",
        "store what `pmsc learn` needs: R singular vectors (>= M; 2M is a good start), the key "
        "selection settings and the calibration scores (the model file grows by (R - M)/M of its basis)",
        [&](const std::string& v) { options.learnRank = parseIndex("--learn-rank", v, 1); });
    parser.option("--seed", "S", "seed of the randomized SVD (training is deterministic for a seed)",
                  [&](const std::string& v) {
                      options.seed = static_cast<unsigned>(parseIndex("--seed", v, 0, 0xffffffffll));
                  });
    parser.option("--power-iterations", "Q",
                  "randomized SVD power iterations (default " + std::to_string(options.powerIterations) + ")",
                  [&](const std::string& v) {
                      options.powerIterations = static_cast<int>(parseIndex("--power-iterations", v, 0, 20));
                  });
}

/// The options of larger-than-memory training, regions, cross models, shared channels and --quiet.
void declareScaleOptions(ArgParser& parser, TrainArgs& a) {
    TrainingOptions& options = a.options;
    parser.option("--memory-limit", "BYTES",
                  "largest memory training may use (e.g. 2G): streams from disk when the data do not fit, "
                  "fails before any work when even that cannot fit",
                  [&](const std::string& v) { a.memoryLimit = parseBytes("--memory-limit", v); });
    parser.flag("--out-of-core", "stream the frames from disk even when they would fit in memory",
                a.outOfCore);
    parser.option("--block-points", "P",
                  "points per block read when streaming (default: ~64 MiB blocks, "
                  "fewer under --memory-limit)",
                  [&](const std::string& v) { a.blockPoints = parseIndex("--block-points", v, 1); });
    parser.option("--regions", "R|auto|0",
                  "regions for local fail-through (a version-2 model): only the regions that blend or\n"
                  "miss go to the full calculation. auto (default): R from the data where they pay\n"
                  "(--tolerance, 3-channel positions, motions that move parts, not the whole), else none;\n"
                  "R: learn R regions; 0: none",
                  [&](const std::string& v) {
                      options.regions.automatic = v == "auto";
                      if (v == "auto") return;
                      if (v.empty() || v.find_first_not_of("0123456789") != std::string::npos)
                          throw UsageError("--regions: '" + v + "' is not auto or a region count (0 = none)");
                      options.regions.count = parseIndex("--regions", v, 0);
                  });
    parser.option("--feather", "F",
                  "feather width of region borders, fraction of the bounding-box diagonal (default: "
                  "0.25 / sqrt(R) with --regions auto, else " +
                      fmt("%g", options.regions.featherFraction) + ")",
                  [&](const std::string& v) {
                      options.regions.featherFraction = parseDouble("--feather", v, 0.0, 0.5);
                      options.regions.automaticFeather = false;
                  });
    parser.option(
        "--region-keys", "N",
        "keys of its own every region gets: a region holding fewer of the model's keys gets region\n"
        "keys among its points, evaluated only for frames that miss as a whole (default " +
            std::to_string(options.regions.ownKeys) + "; 0 = none)",
        [&](const std::string& v) { options.regions.ownKeys = parseIndex("--region-keys", v, 0, 1000); });
    parser.option("--region-stride", "S",
                  "regions learn their bases and thresholds from every S-th training frame (default " +
                      std::to_string(options.regions.frameStride) + ")",
                  [&](const std::string& v) {
                      options.regions.frameStride = parseIndex("--region-stride", v, 1, 1000);
                  });
    parser.option(
        "--targets", "TARGET.npy",
        "cross point multiplication (paper section 7): frame f of --frames (the control) and frame f of\n"
        "TARGET.npy are a pair; learns their joint subspace with keys among the control's points, and an\n"
        "error bound on the target from held-out pairs (--coverage, default 0.9; --slices folds)",
        a.targetsPath);
    parser.flag(
        "--shared-channels",
        "the channels share one basis over the points (for light: RGB share their spatial\n"
        "modes, a light's colour is reproduced exactly and reconstruction reads a third of the basis)",
        a.sharedChannels);
    parser.flag("--quiet", "no progress display", a.quiet);
}

/// Checks the combinations of options and sets the selector and the calibration rule.
void checkTrainArgs(const ArgParser& parser, TrainArgs& a) {
    TrainingOptions& options = a.options;
    const std::string &selector = a.selector, &rule = a.rule;
    if (a.sharedChannels) {
        for (const char* o : {"--targets", "--regions", "--feather", "--region-keys", "--region-stride",
                              "--learn-rank", "--memory-limit", "--out-of-core", "--block-points"})
            if (parser.given(o) && !(o == std::string("--regions") && options.regions.count == 0))
                parser.fail(std::string(o) +
                            " does not combine with --shared-channels in this version (shared-channel "
                            "models are trained in memory on one process, without regions, learning or cross "
                            "targets)");
        options.sharedChannels = true;
        options.regions.automatic = false;
    }
    if (!a.targetsPath.empty()) {
        if (a.framePaths.size() != 1) parser.fail("--targets takes exactly one --frames file (the control)");
        options.regions.automatic = false;
        for (const char* o :
             {"--regions", "--feather", "--region-keys", "--region-stride", "--learn-rank", "--calibration",
              "--key-error", "--memory-limit", "--out-of-core", "--block-points"})
            if (parser.given(o) && !(o == std::string("--regions") && options.regions.count == 0))
                parser.fail(std::string(o) +
                            " does not apply to a cross model (--targets): it has no fail-through, "
                            "and is trained in memory on one process");
        if (selector == "qdeim")
            options.selector = Selector::QDeim;
        else if (selector != "teleconnection")
            parser.fail("--selector: '" + selector + "' is not teleconnection or qdeim");
        return;
    }

    const int sizeRules = parser.given("--basis") + parser.given("--energy") + parser.given("--basis-error");
    if (sizeRules > 1) parser.fail("give at most one of --basis, --energy, --basis-error");
    if (selector == "teleconnection") {
        options.selector = Selector::Teleconnection;
    } else if (selector == "qdeim") {
        options.selector = Selector::QDeim;
    } else {
        parser.fail("--selector: '" + selector + "' is not teleconnection or qdeim");
    }

    if (const auto r = calibrationRuleNamed(rule))
        options.calibrationRule = *r;
    else if (!rule.empty())
        parser.fail("--calibration: '" + rule + "' is not " + kCalibrationRuleChoices);
    if (const auto norm = keyErrorNormNamed(a.keyError))
        options.keyErrorNorm = *norm;
    else if (!a.keyError.empty())
        parser.fail("--key-error: '" + a.keyError + "' is not " + kKeyErrorNormChoices);
    if (options.keyErrorNorm && *options.keyErrorNorm != KeyErrorNorm::Rms && a.sharedChannels)
        parser.fail(std::string("--key-error ") + toString(*options.keyErrorNorm) +
                    " needs channels of their own (not --shared-channels)");
    if (options.keyErrorNorm == KeyErrorNorm::Predicted && !(options.tolerance > 0))
        parser.fail("--key-error predicted needs --tolerance (each of its parts is calibrated for it)");
    if ((parser.given("--calibration") || parser.given("--coverage")) && !(options.tolerance > 0))
        parser.fail("--calibration and --coverage need --tolerance");
    if (parser.given("--coverage") && resolvedCalibrationRule(options) == CalibrationRule::MaxRatio)
        parser.fail("--coverage needs --calibration threshold or conformal");
}

/// Declares the options, parses and checks them; std::nullopt when --help was asked for.
std::optional<TrainArgs> parseTrainArgs(const std::vector<std::string>& args) {
    TrainArgs a;
    ArgParser parser = trainParser(a);
    declareBasisAndKeyOptions(parser, a);
    declareCalibrationOptions(parser, a);
    declareScaleOptions(parser, a);
    if (!parser.parse(args)) return std::nullopt;
    checkTrainArgs(parser, a);
    return a;
}

/// The frames' sizes over all the shots: N points, C channels, F frames.
struct TrainSizes {
    Index n = 0, c = 0, f = 0;
};

/// In memory or streamed, and how large a block, with the memory bounds (Training.h's).
struct MemoryPlan {
    std::uint64_t limit = 0;          ///< bytes training may use; 0 = none known
    std::string limitSource;          ///< where `limit` comes from, for the messages
    std::uint64_t inMemoryBytes = 0;  ///< the bound of training in memory
    bool stream = false;              ///< the frames are streamed from disk in blocks of points
    Index blockPoints = 0;            ///< points per block when streaming
    std::uint64_t streamBytes = 0;    ///< the bound of streaming blocks of `blockPoints` (rank 0)
};

/// Decides in memory or streamed, and how large a block; fails at once when the limit cannot be met.
MemoryPlan planMemory(const TrainArgs& a, const TrainSizes& sizes, Communicator& comm) {
    const int ranks = comm.size();
    const TrainingOptions& options = a.options;
    const Index n = sizes.n, c = sizes.c, f = sizes.f;
    MemoryPlan plan;
    std::uint64_t& limit = plan.limit;
    std::string& limitSource = plan.limitSource;
    limit = a.memoryLimit;
    limitSource = "--memory-limit";
    if (limit == 0) {
        const app::MemoryLimit environment = app::environmentMemoryLimit();
        limit = environment.bytes;
        limitSource = environment.source;
    }
    // Every rank plans with the smallest limit of all (each reads its own cgroup and usage), so
    // they take the same decisions and meet in the same collectives. The exchange is as doubles:
    // whole bytes up to 2^53 (8 PiB) are exact.
    if (ranks > 1) {
        double tightest = limit == 0 ? -std::numeric_limits<double>::infinity() : -static_cast<double>(limit);
        maxOverRanks(comm, &tightest, 1);
        if (std::isfinite(tightest) && static_cast<std::uint64_t>(-tightest) != limit) {
            limit = static_cast<std::uint64_t>(-tightest);
            limitSource = "the tightest memory limit of the MPI ranks";
        }
    }
    auto bound = [&](Index r, Index bp) {
        if (options.sharedChannels && c > 1)  // the C=1 training of F*C channel frames, beside the frames
            return trainingMemoryBound(n, 1, f * c, r, options.block, options.maxKeys, bp, ranks,
                                       /*rootRank=*/true) +
                   static_cast<std::uint64_t>(8) * static_cast<std::uint64_t>(n * c * f);
        return trainingMemoryBound(n, c, f, r, options.block, options.maxKeys, bp, ranks, /*rootRank=*/true);
    };
    const double physical =
        static_cast<double>(sysconf(_SC_PHYS_PAGES)) * static_cast<double>(sysconf(_SC_PAGESIZE));
    plan.inMemoryBytes = bound(options.maxBasis, 0);
    plan.stream = ranks > 1 || a.outOfCore || (limit > 0 && plan.inMemoryBytes > limit) ||
                  (limit == 0 && static_cast<double>(plan.inMemoryBytes) > physical / 2);
    if (plan.stream && options.sharedChannels)
        throw InputError("train: --shared-channels trains in memory on one process, but " +
                         std::string(ranks > 1 ? "MPI started several ranks"
                                               : "the frames do not fit in memory (or the limit)"));
    if (!plan.stream) return plan;
    // Decision: reserve for --max-basis when the limit holds it, as before any data is read nothing
    // says M will be smaller. When it does not, reserve only for the Varimax block (or --basis)
    // and let blocks of points take at most a quarter of the limit: M is known after the first
    // pass, and training checks the bound at M then and caps M to the limit with a warning
    // (TrainingOptions::memoryLimit). So streaming never refuses data that need fewer basis
    // vectors than --max-basis, and never needs more memory than training them in memory.
    Index planBasis = std::max(options.maxBasis, options.learnRank);
    if (limit > 0 && bound(planBasis, 1) > limit)
        planBasis = std::max({options.basis, options.block, options.learnRank});
    const bool reserved = planBasis >= options.maxBasis;
    const Index defaultPoints = std::max<Index>(1, (Index{64} << 20) / (c * f * 8));
    Index bp = a.blockPoints > 0 ? a.blockPoints : defaultPoints;
    if (limit > 0) {
        const double perPoint =
            static_cast<double>(bound(planBasis, 2)) - static_cast<double>(bound(planBasis, 1));
        const double fixed = static_cast<double>(bound(planBasis, 1)) - perPoint;
        if (fixed + perPoint > static_cast<double>(limit)) {
            throw InputError("train: " + limitSource + " " + bytesText(static_cast<double>(limit)) +
                             " cannot be met: streaming training of " + std::to_string(f) + " frames x " +
                             std::to_string(n) + " points x " + std::to_string(c) +
                             " channels needs at least " + bytesText(fixed + perPoint) +
                             " (lower --max-keys or --block, or use more MPI ranks)");
        }
        const Index fits = static_cast<Index>((static_cast<double>(limit) - fixed) / perPoint);
        if (a.blockPoints > 0 && a.blockPoints > fits) {
            throw InputError("train: --block-points " + std::to_string(a.blockPoints) + " does not fit in " +
                             limitSource + " " + bytesText(static_cast<double>(limit)) + " (at most " +
                             std::to_string(fits) + ")");
        }
        const Index quarter =
            std::max<Index>(1, static_cast<Index>(static_cast<double>(limit) / 4 / perPoint));
        bp = std::min(bp, reserved || a.blockPoints > 0 ? fits : std::min(fits, quarter));
    }
    plan.blockPoints = std::min(bp, std::max<Index>(1, n));
    plan.streamBytes = bound(planBasis, plan.blockPoints);
    return plan;
}

/// Each rank's CPU seconds, to rank 0: the busiest rank is the critical path when every rank
/// has a core of its own (wall time says that only on an idle machine).
std::vector<double> cpuSecondsPerRank(Communicator& comm) {
    timespec cpu{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &cpu);
    const double mine = static_cast<double>(cpu.tv_sec) + 1e-9 * static_cast<double>(cpu.tv_nsec);
    std::vector<double> cpuPerRank;
    comm.gather(&mine, 1, cpuPerRank, 0);
    return cpuPerRank;
}

/// The summary's last lines: CPU per rank, the shots, and how the frames were held in memory.
void printResources(const std::vector<double>& cpuPerRank, std::size_t shots, Index f,
                    const MemoryPlan& plan) {
    std::cout << "  cpu         ";
    for (std::size_t r = 0; r < cpuPerRank.size(); ++r)
        std::cout << (r ? ", " : "") << fmt("%.2f", cpuPerRank[r]);
    std::cout << " s of CPU" << (cpuPerRank.size() > 1 ? " per rank" : "") << "\n";
    if (shots > 1) std::cout << "  shots       " << shots << " --frames files, " << f << " frames in all\n";
    if (plan.stream) {
        std::cout << "  memory      streamed from disk in blocks of " << plan.blockPoints << " points; bound "
                  << bytesText(static_cast<double>(plan.streamBytes)) << " (rank 0)"
                  << (plan.limit > 0 ? ", limit " + bytesText(static_cast<double>(plan.limit)) + " (" +
                                           plan.limitSource + ")"
                                     : std::string())
                  << "\n";
    } else {
        std::cout << "  memory      in memory; bound " << bytesText(static_cast<double>(plan.inMemoryBytes))
                  << "\n";
    }
}

/// Trains on one process or on the MPI ranks, in memory or streamed; rank 0 writes the model and
/// prints the summary.
int trainModel(TrainArgs& a) {
    TrainingOptions& options = a.options;
    const std::string& outPath = a.outPath;
    // MPI only when a launcher started us (cli/mpi/MpiLaunch.h); otherwise one process.
    std::unique_ptr<MpiWorld> mpi = joinMpiIfLaunched();
    SingleProcess one;
    Communicator& comm = mpi ? static_cast<Communicator&>(*mpi) : one;
    const bool root = comm.rank() == 0;
    bool collective = false;  // true once the ranks may be waiting for each other
    try {
        // Fail on an unwritable destination now, not after a long training.
        if (root) AtomicFile(outPath).abandon();

        const auto start = std::chrono::steady_clock::now();
        const std::vector<Shot> shots = openShots(a.framePaths);
        TrainSizes sizes;
        sizes.n = shots.front().info.points;
        sizes.c = shots.front().info.channels;
        for (const Shot& s : shots) sizes.f += s.info.frames;
        MemoryPlan plan = planMemory(a, sizes, comm);
        if (!options.sharedChannels) options.memoryLimit = plan.limit;  // training caps M to it

        Progress progress("train", !a.quiet && root);
        options.progress = [&](std::string_view stage, double done, double total) {
            return progress.update(stage, done, total);
        };
        TrainingReport report;
        Model model;
        if (plan.stream) {
            NpyBlocks blocks(shots, pointShare(sizes.n, comm.rank(), comm.size()), plan.blockPoints);
            collective = comm.size() > 1;
            model = train(blocks, comm, options, &report);
        } else {
            const FrameSet frames = readShots(shots);
            model = train(frames, options, &report);
        }
        const std::vector<double> cpuPerRank = cpuSecondsPerRank(comm);
        if (!root) return kExitOk;
        if (plan.stream) plan.streamBytes = report.memoryBound;  // at the basis training settled on
        writeModel(outPath, model);
        progress.finish();
        const double seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        FrameSet shape;
        shape.frames = sizes.f;
        shape.points = sizes.n;
        shape.channels = sizes.c;
        printTrainSummary(std::cout, outPath, shape, model, report, seconds);
        printResources(cpuPerRank, shots.size(), sizes.f, plan);
        return kExitOk;
    } catch (...) {
        if (!mpi) throw;
        const ExitReason reason = exitReason(std::current_exception());
        if (collective) {
            // Maybe this rank alone failed (its rows hold a NaN): the others wait in a collective.
            std::fprintf(stderr, "pmsc: %s (MPI rank %d)\n", reason.message.c_str(), comm.rank());
            mpi->abort(reason.code);
        }
        // Before the ranks depend on each other every rank fails the same way: rank 0 reports it.
        if (root) throw;
        return reason.code;
    }
}

}  // namespace

int runTrain(const std::vector<std::string>& args) {
    std::optional<TrainArgs> a = parseTrainArgs(args);
    if (!a) return kExitOk;
    if (!a->targetsPath.empty())
        return runTrainCross(a->framePaths.front(), a->targetsPath, a->outPath, a->options,
                             a->options.calibrationCoverage, a->options.calibrationSlices, a->quiet);
    return trainModel(*a);
}

}  // namespace pmsc::cli
