// `pmsc replay`: recorded frames through a model's soft cache, with a report of what it did.
#include "app/ExitCodes.h"
#include "app/Replay.h"
#include "app/ReplayFiles.h"
#include "cli/Args.h"
#include "cli/Commands.h"
#include "cli/Interrupt.h"
#include "cli/Progress.h"
#include "cli/ReplaySummary.h"
#include "pmsc/ModelIO.h"

#include <iostream>
#include <memory>
#include <optional>

namespace pmsc::cli {

namespace {

/// What `pmsc replay` was asked.
struct ReplayArgs {
    app::ReplayFileOptions request;
    bool wholeFrame = false;
    bool quiet = false;
};

/// Declares the options and parses them; std::nullopt when --help was asked for.
std::optional<ReplayArgs> parseReplayArgs(const std::vector<std::string>& args) {
    ReplayArgs a;
    ReplayOptions& options = a.request.replay;
    ArgParser parser("replay", "--model MODEL.pmsc --frames TEST.npy --report REPORT.json [options]",
                     "Replays recorded frames through the soft cache (sections 5, 6): each frame's key\n"
                     "points are read from the recording, projected, and their RMS error decides hit,\n"
                     "blend or miss; a fail-through reads the recorded frame. The report gives, per frame\n"
                     "and in percentiles, the largest point error of point multiplication alone and of\n"
                     "the soft-cached result: how PMSC would hold on this shot.");
    parser.option("--model", "MODEL.pmsc", "model from pmsc train", a.request.model, true);
    parser.option("--frames", "TEST.npy", "recorded frames (frames, points, channels), float32/64",
                  a.request.frames, true);
    parser.option("--report", "REPORT.json", "report to write", a.request.report, true);
    parser.option("--out", "OUT.npy", "soft-cached frames to write (same shape and dtype as --frames)",
                  a.request.out);
    parser.option("--eps", "MIN,MAX",
                  "override the model's thresholds (in its key error, which pmsc inspect names; data units)",
                  [&](const std::string& v) {
                      const auto eps = parseDoublePair("--eps", v);
                      try {
                          app::checkEps(eps, app::Spelling::CommandLine);
                      } catch (const app::OptionError& e) {
                          throw UsageError(e.what());
                      }
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
        a.request.keep);
    parser.option(
        "--targets", "TRUE.npy",
        "cross models (train --targets): the true target frames, to measure each frame's error and the "
        "bound's coverage",
        a.request.targets);
    parser.flag("--quiet", "no progress display", a.quiet);
    if (!parser.parse(args)) return std::nullopt;
    options.localFailThrough = !a.wholeFrame;
    return a;
}

}  // namespace

int runReplay(const std::vector<std::string>& args) {
    const std::optional<ReplayArgs> a = parseReplayArgs(args);
    if (!a) return kExitOk;
    app::ReplayFileOptions request = a->request;
    const Model model = readModel(request.model);
    try {
        app::validate(request, model, app::Spelling::CommandLine);
    } catch (const app::OptionError& e) {
        ArgParser("replay", "", "").fail(e.what());  // worded as the parser words its own mistakes
    }
    Progress progress("replay", !a->quiet);
    request.replay.cancel = &interruptFlag();
    request.replay.progress = [&](Index done, Index total) {
        progress.update("frames", static_cast<double>(done), static_cast<double>(total));
    };
    const app::ReplayFileOutcome outcome = app::replayFiles(request, model);
    progress.finish();
    if (outcome.cross) {
        printCrossReplaySummary(std::cout, model, *outcome.cross);
    } else {
        printReplaySummary(std::cout, model, *outcome.replay, request.replay.eps.has_value());
        if (!request.keep.empty())
            std::cout << "  kept        " << outcome.kept << " blended or missed frames -> " << request.keep
                      << " (now " << outcome.keptBefore + outcome.kept << " frames)\n";
    }
    std::cout << "  report      " << request.report
              << (request.out.empty() ? "" : "\n  output      " + request.out) << "\n";
    return kExitOk;
}

}  // namespace pmsc::cli
