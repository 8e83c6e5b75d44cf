// `pmsc replay`: recorded frames through a model's soft cache, with a report of what it did.
#include "app/CrossReplay.h"
#include "app/ExitCodes.h"
#include "app/MemoryLimit.h"
#include "app/Replay.h"
#include "cli/Args.h"
#include "cli/Commands.h"
#include "cli/Interrupt.h"
#include "cli/Progress.h"
#include "cli/ReplaySummary.h"
#include "evaluators/ReplayEvaluator.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"

#include <iostream>
#include <memory>
#include <optional>

namespace pmsc::cli {

namespace {

/// What `pmsc replay` was asked.
struct ReplayArgs {
    std::string modelPath, framesPath, outPath, reportPath, keepPath, targetsPath;
    ReplayOptions options;
    bool wholeFrame = false;
    bool quiet = false;
};

/// Declares the options and parses them; std::nullopt when --help was asked for.
std::optional<ReplayArgs> parseReplayArgs(const std::vector<std::string>& args) {
    ReplayArgs a;
    ReplayOptions& options = a.options;
    ArgParser parser("replay", "--model MODEL.pmsc --frames TEST.npy --report REPORT.json [options]",
                     "Replays recorded frames through the soft cache (sections 5, 6): each frame's key\n"
                     "points are read from the recording, projected, and their RMS error decides hit,\n"
                     "blend or miss; a fail-through reads the recorded frame. The report gives, per frame\n"
                     "and in percentiles, the largest point error of point multiplication alone and of\n"
                     "the soft-cached result: how PMSC would hold on this shot.");
    parser.option("--model", "MODEL.pmsc", "model from pmsc train", a.modelPath, true);
    parser.option("--frames", "TEST.npy", "recorded frames (frames, points, channels), float32/64",
                  a.framesPath, true);
    parser.option("--report", "REPORT.json", "report to write", a.reportPath, true);
    parser.option("--out", "OUT.npy", "soft-cached frames to write (same shape and dtype as --frames)",
                  a.outPath);
    parser.option("--eps", "MIN,MAX", "override the model's thresholds (key RMS, data units)",
                  [&](const std::string& v) {
                      const auto eps = parseDoublePair("--eps", v);
                      if (!(eps.first >= 0 && eps.first <= eps.second))
                          throw UsageError("--eps: need 0 <= MIN <= MAX, got " + v);
                      options.eps = eps;
                  });
    parser.option("--threads", "T", "worker threads (default: every core; results do not depend on it)",
                  [&](const std::string& v) {
                      options.threads = static_cast<int>(parseIndex("--threads", v, 1, 4096));
                  });
    parser.flag(
        "--whole-frame-fail-through",
        "models with regions: a frame that does not hit fails through whole (as version-1 models do)\n"
        "instead of only its regions that blend or miss",
        a.wholeFrame);
    parser.option(
        "--keep-misses", "FILE.npy",
        "append the frames that blended or missed (their recorded values) to FILE.npy, frame numbers "
        "to FILE.npy.frames: training for `pmsc learn`",
        a.keepPath);
    parser.option(
        "--targets", "TRUE.npy",
        "cross models (train --targets): the true target frames, to measure each frame's error and the "
        "bound's coverage",
        a.targetsPath);
    parser.flag("--quiet", "no progress display", a.quiet);
    if (!parser.parse(args)) return std::nullopt;
    options.localFailThrough = !a.wholeFrame;
    return a;
}

/// A mistake on the command line found once the model is read, worded as the parser words its own.
[[noreturn]] void failUsage(const std::string& what) { ArgParser("replay", "", "").fail(what); }

/// Cross point multiplication: control frames in, target frames out, no fail-through.
int replayCross(const ReplayArgs& a, const Model& model) {
    const std::string &modelPath = a.modelPath, &framesPath = a.framesPath, &outPath = a.outPath,
                      &reportPath = a.reportPath, &targetsPath = a.targetsPath;
    const ReplayOptions& options = a.options;
    if (options.eps)
        failUsage("--eps: " + modelPath + " is a cross model, which has no fail-through to threshold");
    if (!a.keepPath.empty())
        failUsage("--keep-misses: " + modelPath + " is a cross model, which has no misses");
    if (a.wholeFrame)
        failUsage("--whole-frame-fail-through: " + modelPath +
                  " is a cross model, which cannot fail through");
    const Index nc = model.cross->controlPoints, nt = model.points - nc;
    const evaluators::ReplayEvaluator control(framesPath);
    if (control.pointCount() != nc || control.channelCount() != model.channels)
        throw InputError(framesPath + ": control frames have " + std::to_string(control.pointCount()) +
                         " points x " + std::to_string(control.channelCount()) +
                         " channels, but the cross model " + modelPath + " takes " + std::to_string(nc) +
                         " control points x " + std::to_string(model.channels) + " channels");
    std::optional<evaluators::ReplayEvaluator> truth;
    if (!targetsPath.empty()) {
        truth.emplace(targetsPath);
        if (truth->pointCount() != nt || truth->channelCount() != model.channels ||
            truth->frameCount() != control.frameCount())
            throw InputError(
                targetsPath + ": targets have " + std::to_string(truth->frameCount()) + " frames x " +
                std::to_string(truth->pointCount()) + " points x " + std::to_string(truth->channelCount()) +
                " channels, expected " + std::to_string(control.frameCount()) + " x " + std::to_string(nt) +
                " x " + std::to_string(model.channels) + " (the control frames' count, the model's target)");
    }
    AtomicFile report(reportPath);
    std::optional<NpyFrameWriter> out;
    if (!outPath.empty()) out.emplace(outPath, control.frameCount(), nt, model.channels, control.dtype());
    Progress progress("replay", !a.quiet);
    app::CrossReplayOptions co;
    co.threads = options.threads;
    co.cancel = &interruptFlag();
    co.progress = [&](Index done, Index total) {
        progress.update("frames", static_cast<double>(done), static_cast<double>(total));
    };
    const app::CrossReplayResult result =
        app::crossReplay(model, control, truth ? &*truth : nullptr, co, out ? &*out : nullptr);
    progress.finish();
    const std::string text = app::crossReplayReport(model, result).dump(2) + "\n";
    report.write(text.data(), text.size());
    if (out) out->commit();
    report.commit();
    printCrossReplaySummary(std::cout, model, result);
    std::cout << "  report      " << reportPath << (outPath.empty() ? "" : "\n  output      " + outPath)
              << "\n";
    return kExitOk;
}

/// Recorded frames through the soft cache: the report, and optionally the output and the kept frames.
int replayRecorded(const ReplayArgs& a, const Model& model) {
    const std::string &modelPath = a.modelPath, &framesPath = a.framesPath, &outPath = a.outPath,
                      &reportPath = a.reportPath, &keepPath = a.keepPath;
    ReplayOptions options = a.options;
    if (!a.targetsPath.empty())
        failUsage("--targets: " + modelPath + " is not a cross model (pmsc train --targets)");
    const evaluators::ReplayEvaluator recorded(framesPath);
    if (recorded.pointCount() != model.points || recorded.channelCount() != model.channels)
        throw InputError(framesPath + ": frames have " + std::to_string(recorded.pointCount()) +
                         " points x " + std::to_string(recorded.channelCount()) +
                         " channels, but the model " + modelPath + " was trained on " +
                         std::to_string(model.points) + " points x " + std::to_string(model.channels) +
                         " channels");

    // Both outputs are temporary files until everything succeeded: a failure or an interrupt
    // leaves neither behind.
    AtomicFile report(reportPath);
    std::optional<NpyFrameWriter> out;
    if (!outPath.empty())
        out.emplace(outPath, recorded.frameCount(), recorded.pointCount(), recorded.channelCount(),
                    recorded.dtype());

    std::optional<KeptFrames> keep;
    if (!keepPath.empty()) {
        keep.emplace(keepPath, recorded.pointCount(), recorded.channelCount(), recorded.dtype(),
                     "model=" + modelPath + " frames=" + framesPath);
        options.keep = &*keep;
    }
    // The farm's limit (memory cgroup, ulimit -v), read with the model and the frames mapped.
    options.memoryLimit = app::frameBufferBudget(app::environmentMemoryLimit(), options.threads);
    Progress progress("replay", !a.quiet);
    options.cancel = &interruptFlag();
    options.progress = [&](Index done, Index total) {
        progress.update("frames", static_cast<double>(done), static_cast<double>(total));
    };
    const ReplayResult result = replay(model, recorded, options, out ? &*out : nullptr);
    progress.finish();

    const std::string text = replayReport(model, result).dump(2) + "\n";
    report.write(text.data(), text.size());
    if (out) out->commit();
    if (keep) keep->commit();
    report.commit();
    printReplaySummary(std::cout, model, result, options.eps.has_value());
    if (keep)
        std::cout << "  kept        " << keep->count() << " blended or missed frames -> " << keepPath
                  << " (now " << keep->countBefore() + keep->count() << " frames)\n";
    std::cout << "  report      " << reportPath << (outPath.empty() ? "" : "\n  output      " + outPath)
              << "\n";
    return kExitOk;
}

}  // namespace

int runReplay(const std::vector<std::string>& args) {
    const std::optional<ReplayArgs> a = parseReplayArgs(args);
    if (!a) return kExitOk;
    const Model model = readModel(a->modelPath);
    return model.cross ? replayCross(*a, model) : replayRecorded(*a, model);
}

}  // namespace pmsc::cli
