// `pmsc run`: a render-farm task. One frame range of an evaluator through the soft-caching engine,
// one atomic file per frame, resumable, with a JSON stats file and documented exit codes.
#include "app/CrossRun.h"
#include "app/Run.h"

#include "app/ExitCodes.h"
#include "app/MemoryLimit.h"
#include "cli/Args.h"
#include "cli/Commands.h"
#include "cli/Interrupt.h"
#include "cli/Progress.h"
#include "evaluators/EvaluatorRegistry.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"

#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>

#include <unistd.h>

namespace fs = std::filesystem;

namespace pmsc::cli {

namespace {

std::string quoteForShell(const std::string& s) {
    if (!s.empty() && s.find_first_of(" \t\n'\"\\$`*?[]{}();&|<>!#~") == std::string::npos) return s;
    std::string q = "'";
    for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}

}  // namespace

int runRun(const std::vector<std::string>& args) {
    app::RunOptions o;
    std::string framesText, dtype = "float64";
    double logSeconds = 10;
    bool quiet = false;
    ArgParser parser(
        "run", "--model MODEL.pmsc --evaluator NAME[:ARGS] --frames A-B[:STEP] --out DIR [options]",
        "A render-farm task: evaluates frames A, A+STEP, ..., B through the soft cache (sections 5, 6)\n"
        "and writes one file per frame, DIR/frame.NNNNNN.npy (shape (1, N, C)) or another format the\n"
        "evaluator offers (--format obj for a mesh, vdb for an illumination grid). Each file is written\n"
        "under a temporary name and renamed, so a killed task never leaves half a frame; run the same\n"
        "command again and it skips frames whose output is there and valid (--force redoes them).\n"
        "Stats (frames evaluated/skipped, hit/blend/miss per frame, timings, host, command) go to\n"
        "DIR/pmsc-run.A-B.json. Exit codes: 0 ok, 2 bad input, 3 evaluator failure, 4 cannot write\n"
        "output, 130 interrupted (SIGINT/SIGTERM: finished frames are kept).");
    parser.option("--model", "MODEL.pmsc", "model from pmsc train", o.modelPath, true);
    parser.option(
        "--evaluator", "NAME[:ARGS]",
        "replay:FILE.npy, skin:ASSET, face:DIR, cornell, volume:FILE.vdb, exec:COMMAND (pmsc evaluators)",
        o.evaluatorSpec, true);
    parser.option("--frames", "A-B[:STEP]", "the frames of this task", framesText, true);
    parser.option("--out", "DIR", "output folder (created if missing)", o.outDir, true);
    parser.option(
        "--threads", "T", "worker threads (default: every core; outputs do not depend on it)",
        [&](const std::string& v) { o.threads = static_cast<int>(parseIndex("--threads", v, 1, 4096)); });
    parser.option("--format", "npy|obj|vdb",
                  "frame file format (default npy; others if the evaluator offers them)", o.format);
    parser.option("--dtype", "float64|float32", ".npy element type (default float64)", dtype);
    parser.option(
        "--basis-precision", "single|double",
        "the basis a hit reads (default: single when frames are stored in float, vdb or npy float32;\n"
        "double otherwise): single halves the bytes a hit reads, within a float's rounding",
        [&](const std::string& v) {
            if (v == "single")
                o.basisPrecision = BasisPrecision::Single;
            else if (v == "double")
                o.basisPrecision = BasisPrecision::Double;
            else
                throw UsageError("--basis-precision: '" + v + "' is not single or double");
        });
    parser.option("--stats", "FILE.json", "stats file (default DIR/pmsc-run.A-B.json)", o.statsPath);
    parser.option("--log-every", "SECONDS",
                  "progress line interval when stderr is not a terminal (default 10; 0 = every update)",
                  [&](const std::string& v) { logSeconds = parseDouble("--log-every", v, 0.0, 1e6); });
    parser.option(
        "--keep-misses", "FILE.npy",
        "append the frames that blended or missed (full values, --dtype) to FILE.npy, frame numbers to "
        "FILE.npy.frames: training for `pmsc learn`",
        o.keepMisses);
    parser.flag("--force", "redo frames whose output already exists", o.force);
    parser.flag("--quiet", "no progress display", quiet);
    parser.flag(
        "--whole-frame-fail-through",
        "models with regions: a frame that does not hit fails through whole (as version-1 models do)\n"
        "instead of only its regions that blend or miss",
        o.wholeFrameFailThrough);
    if (!parser.parse(args)) return kExitOk;
    try {
        o.frames = parseFrameSpan("--frames", framesText);
    } catch (const UsageError& e) {
        parser.fail(e.what());
    }
    try {
        o.dtype = parseDtype("--dtype", dtype);
    } catch (const UsageError& e) {
        parser.fail(e.what());
    }
    o.commandLine = "pmsc run";
    for (const auto& a : args) {
        o.commandLine += ' ';
        o.commandLine += quoteForShell(a);
    }
    o.cancel = &interruptFlag();

    const Model model = readModel(o.modelPath);
    const std::unique_ptr<PointEvaluator> evaluator = evaluators::makeEvaluator(o.evaluatorSpec);
    // The farm's limit (memory cgroup, ulimit -v), read with the model and the evaluator loaded.
    o.memoryLimit = app::frameBufferBudget(app::environmentMemoryLimit(), o.threads);
    if (model.cross) {
        // Cross point multiplication: the evaluator is the control's; targets are written.
        const app::RunReport r = app::runCrossFrames(model, *evaluator, o);
        std::cout << "pmsc run (cross model, no fail-through): frames " << o.frames.text() << " -> "
                  << o.outDir << ": " << r.evaluated << " target frames written, " << r.skipped
                  << " skipped as done\n  stats " << r.statsPath << "\n";
        return kExitOk;
    }
    Progress progress("run", !quiet, logSeconds);
    o.progress = [&progress](std::string_view stage, double done, double total) {
        return progress.update(stage, done, total);
    };
    const app::RunReport r = app::runFrames(model, *evaluator, o);
    progress.finish();

    std::cout << "pmsc run: frames " << o.frames.text() << " -> " << o.outDir << ": " << r.evaluated
              << " evaluated (" << r.hits << " hits, " << r.blends << " blends, " << r.misses << " misses), "
              << r.skipped << " skipped as done";
    if (r.replaced) std::cout << ", " << r.replaced << " invalid redone";
    char seconds[32];
    std::snprintf(seconds, sizeof seconds, "%.2f", r.seconds);
    std::cout << ", " << seconds << " s\n  stats " << r.statsPath << "\n";
    if (!o.keepMisses.empty())
        std::cout << "  kept  " << r.kept << " blended or missed frames -> " << o.keepMisses << "\n";
    return kExitOk;
}

}  // namespace pmsc::cli
