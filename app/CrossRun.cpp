// `pmsc run` with a cross model: an evaluator of the CONTROL (e.g. face-control:DIR)
// is evaluated at the control key points only; the target frames come from the joint subspace and
// are written one file per frame (FrameOutput: atomic, resumable). No fail-through exists.
#include "app/CrossRun.h"

#include "app/OptionError.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Cross.h"
#include "pmsc/Errors.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <nlohmann/json.hpp>

#include <atomic>
#include <chrono>

namespace pmsc::app {

RunReport runCrossFrames(const Model& model, const PointEvaluator& control, const RunOptions& options) {
    const auto start = std::chrono::steady_clock::now();
    const CrossMultiplier cross(model);
    const FrameSpan& span = options.frames;
    if (control.pointCount() != cross.controlPoints() || control.channelCount() != model.channels)
        throw InputError("evaluator '" + options.evaluatorSpec + "' has " +
                         std::to_string(control.pointCount()) + " points x " +
                         std::to_string(control.channelCount()) + " channels, but the cross model " +
                         options.modelPath + " takes a control of " + std::to_string(cross.controlPoints()) +
                         " points x " + std::to_string(model.channels) + " channels");
    if (!options.keepMisses.empty())
        throw OptionError("--keep-misses: " + options.modelPath + " is a cross model, which has no misses");
    if (options.wholeFrameFailThrough)
        throw OptionError("--whole-frame-fail-through: " + options.modelPath +
                          " is a cross model, which cannot fail through");
    if (options.format != "npy")
        throw OptionError("--format: a cross model writes its target frames as npy only");
    checkFramesInside(span, control, options.evaluatorSpec);
    const FrameOutput output(options.outDir, "npy", {}, cross.targetPoints(), model.channels, options.dtype);
    ensureWritableFolder(options.outDir);
    RunReport report;
    report.frames = span.count();
    report.statsPath = options.statsPath.empty() ? defaultStatsPath(options.outDir, span) : options.statsPath;
    std::vector<Index> frames(static_cast<size_t>(span.count()));
    for (Index i = 0; i < span.count(); ++i) frames[static_cast<size_t>(i)] = span.frame(i);
    output.removeStaleTemporaries(frames);
    std::vector<char> skip(frames.size(), 0);
    for (size_t i = 0; i < frames.size(); ++i)
        if (!options.force && output.isValid(frames[i])) skip[i] = 1;
    std::vector<double> keyRms(frames.size(), -1), bound(frames.size(), -1);
    std::atomic<Index> done{0};
    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency());
    arena.execute([&] {
        tbb::parallel_for(size_t{0}, frames.size(), [&](size_t i) {
            if (skip[i] || (options.cancel && options.cancel->load())) return;
            std::vector<double> keys(static_cast<size_t>(model.keyCount() * model.channels)),
                target(static_cast<size_t>(cross.targetPoints() * model.channels));
            control.evaluate(frames[i], cross.keyPoints(), keys.data());
            const CrossMultiplier::Result r = cross.apply(keys.data(), target.data());
            output.write(frames[i], target.data());
            keyRms[i] = r.keyRms;
            bound[i] = r.bound;
            ++done;
        });
    });
    const bool cancelled = options.cancel && options.cancel->load();
    report.evaluated = done;
    for (char s : skip) report.skipped += s;
    report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    nlohmann::ordered_json rows = nlohmann::ordered_json::array();
    Index overTolerance = 0;
    for (size_t i = 0; i < frames.size(); ++i) {
        if (keyRms[i] < 0) continue;
        nlohmann::ordered_json row = {{"frame", frames[i]}, {"key_rms", keyRms[i]}, {"bound", bound[i]}};
        if (model.tolerance > 0) {
            row["bound_over_tolerance"] = bound[i] > model.tolerance;
            overTolerance += bound[i] > model.tolerance;
        }
        rows.push_back(std::move(row));
    }
    nlohmann::ordered_json j = {
        {"status", cancelled ? "interrupted" : "ok"},
        {"command", options.commandLine},
        {"model", options.modelPath},
        {"evaluator", options.evaluatorSpec},
        {"cross", true},
        {"fail_through",
         "impossible: cross point multiplication has no full calculation of the target to fall back on"},
        {"frames", span.text()},
        {"evaluated", report.evaluated},
        {"skipped", report.skipped},
        {"bound",
         {{"coverage", cross.state().coverage},
          {"quantile", cross.state().quantile},
          {"scale", cross.state().scale}}},
        {"seconds", report.seconds},
        {"per_frame", rows}};
    if (model.tolerance > 0) {
        j["tolerance"] = model.tolerance;
        j["frames_bound_over_tolerance"] = overTolerance;
    }
    writeFileAtomically(report.statsPath, j.dump(2) + "\n");
    if (cancelled) throw Cancelled("run interrupted");
    return report;
}

}  // namespace pmsc::app
