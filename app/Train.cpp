#include "app/Train.h"

#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"

#include "app/MemoryLimit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>

#include <unistd.h>

namespace pmsc::app {

std::string optionName(std::string_view name, Spelling spelling) {
    std::string out(name);
    if (spelling == Spelling::CommandLine) return "--" + out;
    std::replace(out.begin(), out.end(), '-', '_');
    return out;
}

Selector selectorNamed(const std::string& name, Spelling spelling) {
    if (name == "teleconnection") return Selector::Teleconnection;
    if (name == "qdeim") return Selector::QDeim;
    throw OptionError(optionName("selector", spelling) + ": '" + name + "' is not teleconnection or qdeim");
}

void setRegions(RegionOptions& regions, const std::string& value, Spelling spelling) {
    regions.automatic = value == "auto";
    if (regions.automatic) return;
    if (value.empty() || value.size() > 9 || value.find_first_not_of("0123456789") != std::string::npos)
        throw OptionError(optionName("regions", spelling) + ": '" + value +
                          "' is not auto or a region count (0 = none)");
    regions.count = std::stol(value);
}

std::optional<CalibrationRule> calibrationNamed(const std::string& name, Spelling spelling) {
    if (name.empty()) return std::nullopt;
    if (const auto rule = calibrationRuleNamed(name)) return rule;
    throw OptionError(optionName("calibration", spelling) + ": '" + name + "' is not " +
                      kCalibrationRuleChoices);
}

std::optional<KeyErrorNorm> keyErrorNamed(const std::string& name, Spelling spelling) {
    if (name.empty()) return std::nullopt;
    if (const auto norm = keyErrorNormNamed(name)) return norm;
    throw OptionError(optionName("key-error", spelling) + ": '" + name + "' is not " + kKeyErrorNormChoices);
}

namespace {

std::string num(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", v);
    return buf;
}

/// The options a request changed from their defaults, among `names` (the command line's names).
std::vector<std::string> changedOptions(const TrainOptions& o, std::initializer_list<const char*> names) {
    const TrainingOptions defaults = defaultTrainingOptions();
    const TrainingOptions& t = o.training;
    std::vector<std::string> changed;
    for (const std::string name : names) {
        const bool isChanged =
            (name == "targets" && !o.targets.empty()) ||
            (name == "regions" && !t.regions.automatic && t.regions.count > 0) ||
            (name == "feather" && !t.regions.automaticFeather) ||
            (name == "region-keys" && t.regions.ownKeys != defaults.regions.ownKeys) ||
            (name == "region-stride" && t.regions.frameStride != defaults.regions.frameStride) ||
            (name == "learn-rank" && t.learnRank > 0) || (name == "positions" && !o.positions.empty()) ||
            (name == "calibration" && t.calibrationRule.has_value()) ||
            (name == "key-error" && t.keyErrorNorm.has_value()) ||
            (name == "memory-limit" && o.memoryLimit > 0) || (name == "out-of-core" && o.outOfCore) ||
            (name == "block-points" && o.blockPoints > 0);
        if (isChanged) changed.push_back(name);
    }
    return changed;
}

/// Shared-channel models are trained in memory on one process, without regions, learning or targets.
void validateSharedChannels(TrainOptions& o, Spelling spelling) {
    const auto changed = changedOptions(o, {"targets", "regions", "feather", "region-keys", "region-stride",
                                            "learn-rank", "memory-limit", "out-of-core", "block-points"});
    if (!changed.empty())
        throw OptionError(optionName(changed.front(), spelling) + " does not combine with " +
                          optionName("shared-channels", spelling) +
                          " in this version (shared-channel models are trained in memory on one process, "
                          "without regions, learning or cross targets)");
    o.training.regions.automatic = false;
}

/// A cross model has no fail-through: nothing of the soft cache's calibration or regions applies.
void validateCross(TrainOptions& o, Spelling spelling) {
    if (o.frames.size() != 1)
        throw OptionError(optionName("targets", spelling) + " takes exactly one " +
                          optionName("frames", spelling) + " file (the control)");
    const auto changed =
        changedOptions(o, {"positions", "regions", "feather", "region-keys", "region-stride", "learn-rank",
                           "calibration", "key-error", "memory-limit", "out-of-core", "block-points"});
    if (!changed.empty())
        throw OptionError(optionName(changed.front(), spelling) + " does not apply to a cross model (" +
                          optionName("targets", spelling) +
                          "): it has no fail-through, and is trained in memory on one process");
    o.training.regions.automatic = false;
}

/// The rules of the basis size and of the calibration for a soft-cache model.
void validateCalibration(const TrainOptions& o, Spelling spelling) {
    const TrainingOptions& t = o.training;
    const auto name = [spelling](std::string_view n) { return optionName(n, spelling); };
    if ((t.basis > 0) + (t.energy > 0) + (t.basisMaxError > 0) > 1)
        throw OptionError("give at most one of " + name("basis") + ", " + name("energy") + ", " +
                          name("basis-error"));
    if (t.keyErrorNorm && *t.keyErrorNorm != KeyErrorNorm::Rms && t.sharedChannels)
        throw OptionError(name("key-error") + " " + toString(*t.keyErrorNorm) +
                          " needs channels of their own (not " + name("shared-channels") + ")");
    if (t.keyErrorNorm == KeyErrorNorm::Predicted && !(t.tolerance > 0))
        throw OptionError(name("key-error") + " predicted needs " + name("tolerance") +
                          " (each of its parts is calibrated for it)");
    if ((t.calibrationRule || o.coverage) && !(t.tolerance > 0))
        throw OptionError(name("calibration") + " and " + name("coverage") + " need " + name("tolerance"));
    if (o.coverage && resolvedCalibrationRule(t) == CalibrationRule::MaxRatio)
        throw OptionError(name("coverage") + " needs " + name("calibration") + " threshold or conformal");
}

}  // namespace

void validate(TrainOptions& o, Spelling spelling) {
    if (o.coverage) {
        if (!(*o.coverage > 0 && *o.coverage < 1))
            throw OptionError(optionName("coverage", spelling) + ": must be in (0, 1), got " +
                              num(*o.coverage));
        o.training.calibrationCoverage = *o.coverage;
    }
    const auto& regions = o.training.regions;
    if (regions.count < 0)
        throw OptionError(optionName("regions", spelling) + ": must be >= 0 (0 = none), got " +
                          std::to_string(regions.count));
    if (!(regions.featherFraction >= 0 && regions.featherFraction <= 0.5))
        throw OptionError(optionName("feather", spelling) + ": must be in [0, 0.5], got " +
                          num(regions.featherFraction));
    if (regions.ownKeys < 0)
        throw OptionError(optionName("region-keys", spelling) + ": must be >= 0 (0 = none), got " +
                          std::to_string(regions.ownKeys));
    if (o.training.sentinels < 0)
        throw OptionError(optionName("sentinels", spelling) + ": must be >= 0 (0 = none), got " +
                          std::to_string(o.training.sentinels));
    if (regions.frameStride < 1)
        throw OptionError(optionName("region-stride", spelling) + ": must be >= 1, got " +
                          std::to_string(regions.frameStride));
    if (o.training.sharedChannels) validateSharedChannels(o, spelling);
    if (!o.targets.empty()) {
        validateCross(o, spelling);
        return;
    }
    validateCalibration(o, spelling);
}

std::string bytesText(double bytes) {
    char buf[64];
    if (bytes >= 1024.0 * 1024 * 1024)
        std::snprintf(buf, sizeof buf, "%.2f GiB", bytes / (1024.0 * 1024 * 1024));
    else
        std::snprintf(buf, sizeof buf, "%.1f MiB", bytes / (1024.0 * 1024));
    return buf;
}

FrameSet readShots(const std::vector<Shot>& shots) {
    if (shots.size() == 1) return readFrames(shots.front().path).frames;
    Index total = 0;
    for (const Shot& s : shots) total += s.info.frames;
    FrameSet all(total, shots.front().info.points, shots.front().info.channels, FrameSet::Uninitialised{});
    Index at = 0;
    for (const Shot& s : shots) {
        const FrameFile f = readFrames(s.path);
        std::copy(f.frames.values.begin(), f.frames.values.end(), all.frame(at));
        at += f.frames.frames;
    }
    return all;
}

namespace {

/// The memory limit training plans with: --memory-limit, else the environment's; under MPI the
/// tightest of all ranks, so every rank takes the same decisions and meets in the same collectives.
/// The exchange is as doubles: whole bytes up to 2^53 (8 PiB) are exact.
void planLimit(const TrainOptions& o, Communicator& comm, MemoryPlan& plan) {
    plan.limit = o.memoryLimit;
    plan.limitSource = "--memory-limit";
    if (plan.limit == 0) {
        const MemoryLimit environment = environmentMemoryLimit();
        plan.limit = environment.bytes;
        plan.limitSource = environment.source;
    }
    if (comm.size() > 1) {
        double tightest =
            plan.limit == 0 ? -std::numeric_limits<double>::infinity() : -static_cast<double>(plan.limit);
        maxOverRanks(comm, &tightest, 1);
        if (std::isfinite(tightest) && static_cast<std::uint64_t>(-tightest) != plan.limit) {
            plan.limit = static_cast<std::uint64_t>(-tightest);
            plan.limitSource = "the tightest memory limit of the MPI ranks";
        }
    }
}

/// Decides in memory or streamed, and how large a block; fails at once when the limit cannot be met.
MemoryPlan planMemory(const TrainOptions& o, const TrainSizes& sizes, Communicator& comm) {
    const int ranks = comm.size();
    const TrainingOptions& options = o.training;
    const Index n = sizes.n, c = sizes.c, f = sizes.f;
    MemoryPlan plan;
    planLimit(o, comm, plan);
    const std::uint64_t limit = plan.limit;
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
    plan.stream = ranks > 1 || o.outOfCore || (limit > 0 && plan.inMemoryBytes > limit) ||
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
    Index bp = o.blockPoints > 0 ? o.blockPoints : defaultPoints;
    if (limit > 0) {
        const double perPoint =
            static_cast<double>(bound(planBasis, 2)) - static_cast<double>(bound(planBasis, 1));
        const double fixed = static_cast<double>(bound(planBasis, 1)) - perPoint;
        if (fixed + perPoint > static_cast<double>(limit)) {
            throw InputError("train: " + plan.limitSource + " " + bytesText(static_cast<double>(limit)) +
                             " cannot be met: streaming training of " + std::to_string(f) + " frames x " +
                             std::to_string(n) + " points x " + std::to_string(c) +
                             " channels needs at least " + bytesText(fixed + perPoint) +
                             " (lower --max-keys or --block, or use more MPI ranks)");
        }
        const Index fits = static_cast<Index>((static_cast<double>(limit) - fixed) / perPoint);
        if (o.blockPoints > 0 && o.blockPoints > fits) {
            throw InputError("train: --block-points " + std::to_string(o.blockPoints) + " does not fit in " +
                             plan.limitSource + " " + bytesText(static_cast<double>(limit)) + " (at most " +
                             std::to_string(fits) + ")");
        }
        const Index quarter =
            std::max<Index>(1, static_cast<Index>(static_cast<double>(limit) / 4 / perPoint));
        bp = std::min(bp, reserved || o.blockPoints > 0 ? fits : std::min(fits, quarter));
    }
    plan.blockPoints = std::min(bp, std::max<Index>(1, n));
    plan.streamBytes = bound(planBasis, plan.blockPoints);
    return plan;
}

}  // namespace

Eigen::MatrixXd positionsFromTable(const FrameSet& t, Index points, const std::string& what,
                                   std::string_view command) {
    if (t.frames != 1 || t.points != points || t.channels < 3)
        throw InputError(std::string(command) + ": " + what + " has " + std::to_string(t.points) +
                         " rows of " + std::to_string(t.channels) + " values, expected " +
                         std::to_string(points) + " rows (one per point) of at least 3 (x, y, z)");
    Eigen::MatrixXd out(points, 3);
    for (Index p = 0; p < points; ++p)
        for (Index k = 0; k < 3; ++k) out(p, k) = t.frame(0)[p * t.channels + k];
    if (!out.allFinite())
        throw InputError(std::string(command) + ": " + what + " has a position that is not finite");
    return out;
}

namespace {

/// The first three columns of a point table (TrainOptions::positions) of `points` rows.
Eigen::MatrixXd readPositions(const std::string& path, Index points) {
    return positionsFromTable(readPointTable(path).frames, points, "--positions " + path);
}

}  // namespace

TrainPlan planTraining(const TrainOptions& options, Communicator& comm) {
    // Fail on an unwritable destination now, not after a long training.
    if (comm.rank() == 0 && !options.out.empty()) AtomicFile(options.out).abandon();
    TrainPlan plan;
    plan.shots = openShots(options.frames);
    plan.sizes.n = plan.shots.front().info.points;
    plan.sizes.c = plan.shots.front().info.channels;
    for (const Shot& s : plan.shots) plan.sizes.f += s.info.frames;
    plan.memory = planMemory(options, plan.sizes, comm);
    if (!options.positions.empty()) plan.positions = readPositions(options.positions, plan.sizes.n);
    return plan;
}

TrainOutcome trainPlanned(const TrainOptions& options, TrainPlan& plan, Communicator& comm,
                          ProgressFn progress) {
    const auto start = std::chrono::steady_clock::now();
    TrainingOptions training = options.training;
    if (plan.positions.size() > 0) training.regions.positions = plan.positions;
    if (!training.sharedChannels) training.memoryLimit = plan.memory.limit;  // training caps M to it
    training.progress = std::move(progress);
    TrainOutcome outcome;
    if (plan.memory.stream) {
        NpyBlocks blocks(plan.shots, pointShare(plan.sizes.n, comm.rank(), comm.size()),
                         plan.memory.blockPoints);
        outcome.model = train(blocks, comm, training, &outcome.report);
        plan.memory.streamBytes = outcome.report.memoryBound;  // at the basis training settled on
    } else {
        // Consumed: training centres the frames where they were read, no copy of them.
        outcome.model = train(readShots(plan.shots), training, &outcome.report);
    }
    if (comm.rank() == 0 && !options.out.empty()) writeModel(options.out, outcome.model);
    outcome.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return outcome;
}

CrossOutcome trainCrossFiles(const TrainOptions& options, ProgressFn progress) {
    const std::string &controlPath = options.frames.front(), &targetsPath = options.targets;
    if (!options.out.empty()) AtomicFile(options.out).abandon();
    const auto start = std::chrono::steady_clock::now();
    const NpyInfo ci = readNpyInfo(controlPath), ti = readNpyInfo(targetsPath);
    if (ci.frames != ti.frames)
        throw InputError("train: " + controlPath + " has " + std::to_string(ci.frames) +
                         " control frames but " + targetsPath + " has " + std::to_string(ti.frames) +
                         " target frames: cross training needs one target frame per control frame");
    if (ci.channels != ti.channels)
        throw InputError("train: " + controlPath + " has " + std::to_string(ci.channels) + " channels but " +
                         targetsPath + " has " + std::to_string(ti.channels) +
                         ": cross training needs the same channels");
    const FrameSet control = readFrames(controlPath).frames;
    const FrameSet target = readFrames(targetsPath).frames;
    CrossOptions cross;
    cross.training = options.training;
    cross.coverage = options.training.calibrationCoverage;
    cross.slices = options.training.calibrationSlices;
    cross.training.progress = std::move(progress);
    CrossOutcome outcome;
    outcome.model = trainCross(control, target, cross, &outcome.report);
    if (!options.out.empty()) writeModel(options.out, outcome.model);
    outcome.controlPoints = ci.points;
    outcome.targetPoints = ti.points;
    outcome.channels = ci.channels;
    outcome.pairs = control.frames;
    outcome.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return outcome;
}

}  // namespace pmsc::app
