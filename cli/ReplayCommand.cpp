// `pmsc replay`: recorded frames through a model's soft cache, with a report of what it did.
#include "cli/Args.h"
#include "cli/Commands.h"
#include "cli/CrossReplay.h"
#include "cli/ExitCodes.h"
#include "cli/Interrupt.h"
#include "cli/Progress.h"
#include "cli/Replay.h"
#include "cli/ReplaySummary.h"
#include "evaluators/ReplayEvaluator.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"

#include <iostream>
#include <memory>
#include <optional>

namespace pmsc::cli {

int runReplay(const std::vector<std::string>& args) {
    std::string modelPath, framesPath, outPath, reportPath;
    ReplayOptions options;
    bool quiet = false;
    ArgParser parser("replay", "--model MODEL.pmsc --frames TEST.npy --report REPORT.json [options]",
                     "Replays recorded frames through the soft cache (sections 5, 6): each frame's key\n"
                     "points are read from the recording, projected, and their RMS error decides hit,\n"
                     "blend or miss; a fail-through reads the recorded frame. The report gives, per frame\n"
                     "and in percentiles, the largest point error of point multiplication alone and of\n"
                     "the soft-cached result: how PMSC would hold on this shot.");
    parser.option("--model", "MODEL.pmsc", "model from pmsc train", modelPath, true);
    parser.option("--frames", "TEST.npy", "recorded frames (frames, points, channels), float32/64",
                  framesPath, true);
    parser.option("--report", "REPORT.json", "report to write", reportPath, true);
    parser.option("--out", "OUT.npy", "soft-cached frames to write (same shape and dtype as --frames)",
                  outPath);
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
    bool wholeFrame = false;
    parser.flag(
        "--whole-frame-fail-through",
        "models with regions: a frame that does not hit fails through whole (as version-1 models do)\n"
        "instead of only its regions that blend or miss",
        wholeFrame);
    std::string keepPath;
    parser.option(
        "--keep-misses", "FILE.npy",
        "append the frames that blended or missed (their recorded values) to FILE.npy, frame numbers "
        "to FILE.npy.frames: training for `pmsc learn`",
        keepPath);
    std::string targetsPath;
    parser.option(
        "--targets", "TRUE.npy",
        "cross models (train --targets): the true target frames, to measure each frame's error and the "
        "bound's coverage",
        targetsPath);
    parser.flag("--quiet", "no progress display", quiet);
    if (!parser.parse(args)) return kExitOk;
    options.localFailThrough = !wholeFrame;

    const Model model = readModel(modelPath);
    if (model.cross) {
        // Cross point multiplication (issue 10): control frames in, target frames out, no fail-through.
        if (options.eps)
            parser.fail("--eps: " + modelPath + " is a cross model, which has no fail-through to threshold");
        if (!keepPath.empty())
            parser.fail("--keep-misses: " + modelPath + " is a cross model, which has no misses");
        if (wholeFrame)
            parser.fail("--whole-frame-fail-through: " + modelPath +
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
                throw InputError(targetsPath + ": targets have " + std::to_string(truth->frameCount()) +
                                 " frames x " + std::to_string(truth->pointCount()) + " points x " +
                                 std::to_string(truth->channelCount()) + " channels, expected " +
                                 std::to_string(control.frameCount()) + " x " + std::to_string(nt) + " x " +
                                 std::to_string(model.channels) +
                                 " (the control frames' count, the model's target)");
        }
        AtomicFile report(reportPath);
        std::optional<NpyFrameWriter> out;
        if (!outPath.empty()) out.emplace(outPath, control.frameCount(), nt, model.channels, control.dtype());
        Progress progress("replay", !quiet);
        CrossReplayOptions co;
        co.threads = options.threads;
        co.cancel = &interruptFlag();
        co.progress = [&](Index done, Index total) {
            progress.update("frames", static_cast<double>(done), static_cast<double>(total));
        };
        const CrossReplayResult result =
            crossReplay(model, control, truth ? &*truth : nullptr, co, out ? &*out : nullptr);
        progress.finish();
        const std::string text = crossReplayReport(model, result).dump(2) + "\n";
        report.write(text.data(), text.size());
        if (out) out->commit();
        report.commit();
        printCrossReplaySummary(std::cout, model, result);
        std::cout << "  report      " << reportPath << (outPath.empty() ? "" : "\n  output      " + outPath)
                  << "\n";
        return kExitOk;
    }
    if (!targetsPath.empty())
        parser.fail("--targets: " + modelPath + " is not a cross model (pmsc train --targets)");
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
    Progress progress("replay", !quiet);
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

}  // namespace pmsc::cli
