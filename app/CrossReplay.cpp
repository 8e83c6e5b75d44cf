#include "app/CrossReplay.h"

#include "app/Replay.h"  // percentiles
#include "pmsc/Cross.h"
#include "pmsc/Errors.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>

namespace pmsc::app {

CrossReplayResult crossReplay(const Model& model, const PointEvaluator& control, const PointEvaluator* truth,
                              const CrossReplayOptions& options, NpyFrameWriter* out) {
    const CrossMultiplier cross(model);
    const Index frames = control.frameCount();
    const Index c = model.channels, nt = cross.targetPoints();
    CrossReplayResult result;
    result.frames.resize(static_cast<size_t>(frames));
    result.measured = truth != nullptr;
    const int threads = options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency();
    result.threads = threads;
    tbb::task_arena arena(threads);
    std::atomic<Index> done{0};
    std::mutex progressMutex;
    const auto start = std::chrono::steady_clock::now();
    arena.execute([&] {
        tbb::parallel_for(Index{0}, frames, [&](Index f) {
            if (options.cancel && options.cancel->load()) return;
            thread_local std::vector<double> keys, target, full;
            keys.resize(static_cast<size_t>(model.keyCount() * c));
            target.resize(static_cast<size_t>(nt * c));
            control.evaluate(f, cross.keyPoints(), keys.data());
            const CrossMultiplier::Result r = cross.apply(keys.data(), target.data());
            CrossFrame& row = result.frames[static_cast<size_t>(f)];
            row.frame = f;
            row.keyRms = r.keyRms;
            row.bound = r.bound;
            if (truth) {
                full.resize(static_cast<size_t>(nt * c));
                truth->evaluateAll(f, full.data());
                double worst = 0;
                for (Index p = 0; p < nt; ++p) {
                    double s = 0;
                    for (Index j = 0; j < c; ++j) {
                        const double d =
                            target[static_cast<size_t>(p * c + j)] - full[static_cast<size_t>(p * c + j)];
                        s += d * d;
                    }
                    worst = std::max(worst, s);
                }
                row.targetMaxError = std::sqrt(worst);
            }
            if (out) out->writeFrame(f, target.data());
            const Index k = ++done;
            if (options.progress && (k % 32 == 0 || k == frames)) {
                std::lock_guard<std::mutex> lock(progressMutex);
                options.progress(k, frames);
            }
        });
    });
    if (options.cancel && options.cancel->load()) throw Cancelled("replay interrupted");
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
}

namespace {

nlohmann::ordered_json pct(const Percentiles& p) {
    return {{"p50", p.p50}, {"p99", p.p99}, {"p995", p.p995}, {"max", p.max}};
}

}  // namespace

CrossTally tally(const Model& model, const CrossReplayResult& result) {
    CrossTally t;
    for (const CrossFrame& f : result.frames) {
        t.key.push_back(f.keyRms);
        t.bound.push_back(f.bound);
        if (result.measured) {
            t.error.push_back(f.targetMaxError);
            t.inside += f.targetMaxError <= f.bound;
        }
        t.overTolerance += model.tolerance > 0 && f.bound > model.tolerance;
    }
    return t;
}

nlohmann::ordered_json crossReplayReport(const Model& model, const CrossReplayResult& result) {
    const CrossState& st = *model.cross;
    const CrossTally t = tally(model, result);
    const std::vector<double>&key = t.key, &bound = t.bound, &error = t.error;
    const Index inside = t.inside, overTolerance = t.overTolerance;
    nlohmann::ordered_json summary = {
        {"cross", true},
        {"fail_through",
         "impossible: cross point multiplication has no full calculation of the target to fall back on"},
        {"frames", result.frames.size()},
        {"control_points", st.controlPoints},
        {"target_points", model.points - st.controlPoints},
        {"channels", model.channels},
        {"key_points", model.keyCount()},
        {"basis", model.basisSize()},
        {"bound",
         {{"rule",
           "bound = quantile * (key_rms + scale): split-conformal quantile of held-out target error / (key "
           "RMS + scale)"},
          {"coverage", st.coverage},
          {"quantile", st.quantile},
          {"scale", st.scale},
          {"held_out_pairs", st.keyRms.size()},
          {"slices", st.slices}}},
        {"key_rms", pct(percentiles(key))},
        {"bound_max_point_error", pct(percentiles(bound))},
    };
    if (model.tolerance > 0) {
        summary["tolerance"] = model.tolerance;
        summary["frames_bound_over_tolerance"] = overTolerance;
    }
    if (result.measured) {
        summary["target_max_point_error"] = pct(percentiles(error));
        summary["frames_inside_bound"] = inside;
        summary["inside_bound_rate"] =
            result.frames.empty() ? 0.0
                                  : static_cast<double>(inside) / static_cast<double>(result.frames.size());
    }
    summary["seconds"] = result.seconds;
    nlohmann::ordered_json rows = nlohmann::ordered_json::array();
    for (const CrossFrame& f : result.frames) {
        nlohmann::ordered_json r = {{"frame", f.frame}, {"key_rms", f.keyRms}, {"bound", f.bound}};
        if (result.measured) r["target_max_point_error"] = f.targetMaxError;
        if (model.tolerance > 0) r["bound_over_tolerance"] = f.bound > model.tolerance;
        rows.push_back(std::move(r));
    }
    return {{"summary", summary}, {"frames", rows}};
}

}  // namespace pmsc::app
