// `pmsc train`: frames (.npy) -> model (.pmsc). Sections 3-5 of the paper, plus calibration.
#include "app/ExitCodes.h"
#include "app/Train.h"
#include "cli/Args.h"
#include "cli/Commands.h"
#include "cli/CrossTrain.h"
#include "cli/Format.h"
#include "cli/Interrupt.h"
#include "cli/Progress.h"
#include "cli/TrainSummary.h"
#include "cli/mpi/MpiLaunch.h"
#include "pmsc/Training.h"

#include <cmath>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <memory>
#include <optional>

namespace pmsc::cli {

namespace {

constexpr app::Spelling kSpelling = app::Spelling::CommandLine;

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

/// What `pmsc train` was asked: app::TrainOptions, and the names and display the command line adds.
struct TrainArgs {
    app::TrainOptions request;
    std::string selector = "teleconnection", rule, keyError;  // named as typed; app:: checks the names
    bool quiet = false;
    bool noClamp = false;  // --no-clamp: TrainingOptions::clampAtZero off
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
        [&a](const std::string& v) { a.request.frames.push_back(v); }, true);
    parser.repeatable("--frames");
    parser.option("--out", "MODEL.pmsc", "model file to write (atomically)", a.request.out, true);
    return parser;
}

/// The options of the basis size M (section 3) and of the key points (section 4).
void declareBasisAndKeyOptions(ArgParser& parser, TrainArgs& a) {
    TrainingOptions& options = a.request.training;
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
    TrainingOptions& options = a.request.training;
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
                  [&](const std::string& v) { a.request.coverage = parseDouble("--coverage", v, 0.0, 1.0); });
    parser.option(
        "--positions", "POINTS.npy",
        "point positions (N x 3, or more columns whose first three are x, y, z) for values that are "
        "not positions themselves (light): the regions, key neighbours and sentinels read them",
        a.request.positions);
    parser.option(
        "--sentinels", "S",
        "points spread over what the training saw move, computed beside every hit of a model with "
        "a tolerance: a hit stands where PM is within 0.8 of the tolerance at each; spread over "
        "--positions, the training mean when it is a shape or a training frame when the data deform "
        "as a surface does, else drawn in point order, " +
            std::to_string(kPointOrderFactor) + "x as many (default " + std::to_string(options.sentinels) +
            ", at most 1 point in " + std::to_string(kSentinelSpacing) + "; 0 = none)",
        [&](const std::string& v) { options.sentinels = parseIndex("--sentinels", v, 0); });
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
    TrainingOptions& options = a.request.training;
    parser.option("--memory-limit", "BYTES",
                  "largest memory training may use (e.g. 2G): streams from disk when the data do not fit, "
                  "fails before any work when even that cannot fit",
                  [&](const std::string& v) { a.request.memoryLimit = parseBytes("--memory-limit", v); });
    parser.flag("--out-of-core", "stream the frames from disk even when they would fit in memory",
                a.request.outOfCore);
    parser.option("--block-points", "P",
                  "points per block read when streaming (default: ~64 MiB blocks, "
                  "fewer under --memory-limit)",
                  [&](const std::string& v) { a.request.blockPoints = parseIndex("--block-points", v, 1); });
    parser.option("--regions", "R|auto|0",
                  "regions for local fail-through (a version-2 model): only the regions that blend or\n"
                  "miss go to the full calculation. auto (default): R from the data where they pay\n"
                  "(--tolerance, 3-channel positions, motions that move parts, not the whole), else none;\n"
                  "R: learn R regions; 0: none",
                  [&](const std::string& v) { app::setRegions(options.regions, v, kSpelling); });
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
        a.request.targets);
    parser.flag(
        "--shared-channels",
        "the channels share one basis over the points (for light: RGB share their spatial\n"
        "modes, a light's colour is reproduced exactly and reconstruction reads a third of the basis)",
        options.sharedChannels);
    parser.flag("--no-clamp",
                "keep PM's output linear: by default, when every training value is >= 0 (light, density),\n"
                "the model clamps what it reconstructs at 0, which never moves a non-negative quantity\n"
                "further from its true value",
                a.noClamp);
    parser.flag("--quiet", "no progress display", a.quiet);
}

/// Declares the options, parses and checks them; std::nullopt when --help was asked for.
std::optional<TrainArgs> parseTrainArgs(const std::vector<std::string>& args) {
    TrainArgs a;
    ArgParser parser = trainParser(a);
    declareBasisAndKeyOptions(parser, a);
    declareCalibrationOptions(parser, a);
    declareScaleOptions(parser, a);
    try {
        if (!parser.parse(args)) return std::nullopt;
        a.request.training.selector = app::selectorNamed(a.selector, kSpelling);
        a.request.training.calibrationRule = app::calibrationNamed(a.rule, kSpelling);
        a.request.training.keyErrorNorm = app::keyErrorNamed(a.keyError, kSpelling);
        a.request.training.clampAtZero = !a.noClamp;
        app::validate(a.request, kSpelling);
    } catch (const app::OptionError& e) {
        parser.fail(e.what());
    }
    return a;
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
                    const app::MemoryPlan& plan) {
    std::cout << "  cpu         ";
    for (std::size_t r = 0; r < cpuPerRank.size(); ++r)
        std::cout << (r ? ", " : "") << fmt("%.2f", cpuPerRank[r]);
    std::cout << " s of CPU" << (cpuPerRank.size() > 1 ? " per rank" : "") << "\n";
    if (shots > 1) std::cout << "  shots       " << shots << " --frames files, " << f << " frames in all\n";
    if (plan.stream) {
        std::cout << "  memory      streamed from disk in blocks of " << plan.blockPoints << " points; bound "
                  << app::bytesText(static_cast<double>(plan.streamBytes)) << " (rank 0)"
                  << (plan.limit > 0 ? ", limit " + app::bytesText(static_cast<double>(plan.limit)) + " (" +
                                           plan.limitSource + ")"
                                     : std::string())
                  << "\n";
    } else {
        std::cout << "  memory      in memory; bound "
                  << app::bytesText(static_cast<double>(plan.inMemoryBytes)) << "\n";
    }
}

/// Trains on one process or on the MPI ranks, in memory or streamed (app::trainPlanned); rank 0
/// writes the model and prints the summary.
int trainModel(TrainArgs& a) {
    // MPI only when a launcher started us (cli/mpi/MpiLaunch.h); otherwise one process.
    std::unique_ptr<MpiWorld> mpi = joinMpiIfLaunched();
    SingleProcess one;
    Communicator& comm = mpi ? static_cast<Communicator&>(*mpi) : one;
    const bool root = comm.rank() == 0;
    bool collective = false;  // true once the ranks may be waiting for each other
    try {
        app::TrainPlan plan = app::planTraining(a.request, comm);
        collective = plan.memory.stream && comm.size() > 1;
        Progress progress("train", !a.quiet && root);
        const app::TrainOutcome outcome =
            app::trainPlanned(a.request, plan, comm, [&](std::string_view stage, double done, double total) {
                return progress.update(stage, done, total);
            });
        const std::vector<double> cpuPerRank = cpuSecondsPerRank(comm);
        if (!root) return kExitOk;
        progress.finish();
        FrameSet shape;
        shape.frames = plan.sizes.f;
        shape.points = plan.sizes.n;
        shape.channels = plan.sizes.c;
        printTrainSummary(std::cout, a.request.out, shape, outcome.model, outcome.report, outcome.seconds);
        printResources(cpuPerRank, plan.shots.size(), plan.sizes.f, plan.memory);
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
    if (!a->request.targets.empty()) return runTrainCross(a->request, a->quiet);
    return trainModel(*a);
}

}  // namespace pmsc::cli
