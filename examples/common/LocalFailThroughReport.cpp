#include "examples/common/LocalFailThroughReport.h"

#include "engine/Engine.h"
#include "pmsc/SoftCache.h"

#include <tbb/task_arena.h>

#include <time.h>

#include <algorithm>
#include <cmath>
#include <utility>

namespace pmsc::examples {

namespace {

// CPU time of the whole process: the one-thread runs below are timed by the work they cost, not
// by the wall clock, which other processes on a loaded machine stretch (a one-thread engine's
// idle workers add nothing).
double processCpuSeconds() {
    timespec t{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

/// Records each frame's state, locality, evaluated points and errors against the full values.
class ErrorSink : public engine::FrameSink {
public:
    ErrorSink(const PointEvaluator& evaluator, const FullValues& fullValues, Index n, Index c)
        : evaluator_(evaluator), fullValues_(fullValues), full_(size_t(n * c)), n_(n), c_(c) {}
    void write(const engine::FrameResult& r) override {
        if (fullValues_)
            fullValues_(r.frame, full_.data());
        else
            evaluator_.evaluateAll(r.frame, full_.data());
        double worst = 0;
        for (Index p = 0; p < n_; ++p) {
            double e2 = 0;
            for (Index c = 0; c < c_; ++c) {
                const double d = r.values[size_t(c_ * p + c)] - full_[size_t(c_ * p + c)];
                e2 += d * d;
                ref2 += full_[size_t(c_ * p + c)] * full_[size_t(c_ * p + c)];
            }
            err2 += e2;
            worst = std::max(worst, std::sqrt(e2));
        }
        maxError.push_back(worst);
        states.push_back(r.state);
        weights.push_back(r.weight);
        local.push_back(r.local);
        fraction.push_back(double(r.pointsEvaluated) / double(n_));
    }
    std::vector<double> maxError, fraction, weights;
    std::vector<CacheState> states;
    std::vector<bool> local;
    double err2 = 0, ref2 = 0;  // over every point and channel of every frame

private:
    const PointEvaluator& evaluator_;
    const FullValues& fullValues_;
    std::vector<double> full_;
    Index n_, c_;
};

class NullSink : public engine::FrameSink {
public:
    void write(const engine::FrameResult&) override {}
};

/// Runs `frames` (contiguous runs become one engine run each) through `engine`.
/// Returns the process CPU seconds it took.
template <class Sink>
double runFrames(engine::Engine& engine, const std::vector<Index>& frames, Sink& sink) {
    const double t = processCpuSeconds();
    for (size_t i = 0; i < frames.size();) {
        size_t j = i + 1;
        while (j < frames.size() && frames[j] == frames[j - 1] + 1) ++j;
        engine.run({frames[i], Index(j - i), 1}, sink);
        i = j;
    }
    return processCpuSeconds() - t;
}

/// One way of running the engine: local fail-through, whole-frame, or the regions on every frame.
struct Way {
    const char* name;
    bool local, everyFrame;
};

/// What an ErrorSink recorded, summed over its frames.
struct FrameTotals {
    double worst = 0, fractionAll = 0, fractionNonHit = 0;
    Index nonHit = 0, local = 0, hits = 0, over = 0;
    /// Hits the check of a hit one measure alone certifies refused (pmsc/HitCheck.h): blends of weight 0,
    /// computed whole.
    Index refused = 0;
};

/// Sums the sink's per-frame records: largest error, frames over `limit`, states, fractions evaluated.
FrameTotals sumFrames(const ErrorSink& sink, double limit) {
    FrameTotals t;
    for (size_t i = 0; i < sink.maxError.size(); ++i) {
        t.worst = std::max(t.worst, sink.maxError[i]);
        t.over += sink.maxError[i] > limit;
        t.fractionAll += sink.fraction[i];
        if (sink.states[i] != CacheState::Hit) {
            ++t.nonHit;
            t.fractionNonHit += sink.fraction[i];
        } else {
            ++t.hits;
        }
        t.local += sink.local[i];
        t.refused += sink.states[i] == CacheState::Blend && sink.weights[i] == 0 && !sink.local[i];
    }
    return t;
}

/// The frames through the engine one way at `threads` cores: its errors (and, for the local way,
/// the set's frames, hit rate and non-hit frames into `j`).
nlohmann::json errorsOneWay(const Model& model, const PointEvaluator& evaluator,
                            const std::vector<Index>& frames, const LocalReportScale& scale, int threads,
                            const FullValues& fullValues, const Way& way, nlohmann::json& j) {
    const Index n = model.points, c = model.channels;
    const double count = std::max<double>(1, double(frames.size()));
    const bool localWay = way.local && !way.everyFrame;
    engine::EngineOptions o;
    o.threads = threads;
    o.localFailThrough = way.local;
    // Thresholds (0, 0): no frame passes the whole-frame test, so every frame is decided region
    // by region; one whose regions all hit is a local frame with no point gathered.
    if (way.everyFrame) o.policy = SoftCachePolicy(0, 0);
    engine::Engine engine(model, evaluator, o);
    ErrorSink sink(evaluator, fullValues, n, c);
    runFrames(engine, frames, sink);
    const FrameTotals t = sumFrames(sink, scale.limit * scale.unit);
    nlohmann::json w;
    w[scale.maxErrorKey] = t.worst / scale.unit;
    w[scale.rmsErrorKey] = std::sqrt(sink.err2 / (count * double(n))) / scale.unit;
    w["soft_rms_rel_error"] = sink.ref2 > 0 ? std::sqrt(sink.err2 / sink.ref2) : 0.0;
    w[scale.overKey] = t.over;
    w["points_evaluated_fraction_mean"] = t.fractionAll / count;
    w["points_evaluated_fraction_non_hit_mean"] = t.nonHit > 0 ? t.fractionNonHit / double(t.nonHit) : 0.0;
    if (localWay) {
        j["frames"] = frames.size();
        j["hit_rate"] = double(t.hits) / count;
        j["non_hit_frames"] = t.nonHit;
        j["local_fail_through"] = engine.localFailThrough();
        w["local_frames"] = t.local;
        w["refused_hits"] = t.refused;
        const engine::RunStats& s = engine.lastStats();
        nlohmann::json regions = nlohmann::json::array();
        for (const auto& r : s.regions) regions.push_back({r.hits, r.blends, r.misses});
        w["region_states_last_run"] = regions;
    }
    if (way.everyFrame) {
        Index none = 0;
        for (const double f : sink.fraction) none += f == 0;
        w["frames_without_gathers"] = none;
        w["local_frames"] = t.local;
    }
    return w;
}

/// Speed, one thread, the ways (with the regions on every frame if `everyFrame`) and full
/// evaluations in one run: `j`'s clock, one_thread_seconds_per_frame and speedups.
void measureSpeed(const Model& model, const PointEvaluator& evaluator, const std::vector<Index>& frames,
                  bool everyFrame, const std::function<void(double)>& progress, nlohmann::json& j) {
    const Index n = model.points, c = model.channels;
    const double count = std::max<double>(1, double(frames.size()));
    engine::EngineOptions o;
    o.threads = 1;
    NullSink sink;
    engine::Engine local(model, evaluator, o);
    const double localSeconds = runFrames(local, frames, sink);
    if (progress) progress(0.6);
    o.localFailThrough = false;
    engine::Engine whole(model, evaluator, o);
    const double wholeSeconds = runFrames(whole, frames, sink);
    if (progress) progress(0.8);
    // In a one-thread arena, as the engine's: an evaluateAll() that runs a parallel_for (the
    // Cornell gather) would otherwise spread over every core and bill their spinning too.
    std::vector<double> full(size_t(n * c));
    tbb::task_arena one(1);
    const double t = processCpuSeconds();
    one.execute([&] {
        for (const Index f : frames) evaluator.evaluateAll(f, full.data());
    });
    const double fullSeconds = processCpuSeconds() - t;
    j["clock"] = "process CPU time, one engine thread";
    j["one_thread_seconds_per_frame"] = {{"full_pose", fullSeconds / count},
                                         {"local_fail_through", localSeconds / count},
                                         {"whole_frame_fail_through", wholeSeconds / count}};
    j["speedup_local"] = localSeconds > 0 ? fullSeconds / localSeconds : 0.0;
    j["speedup_whole_frame"] = wholeSeconds > 0 ? fullSeconds / wholeSeconds : 0.0;
    if (everyFrame) {
        o.localFailThrough = true;
        o.policy = SoftCachePolicy(0, 0);
        engine::Engine every(model, evaluator, o);
        const double everySeconds = runFrames(every, frames, sink);
        j["one_thread_seconds_per_frame"]["regions_every_frame"] = everySeconds / count;
        j["speedup_regions_every_frame"] = everySeconds > 0 ? fullSeconds / everySeconds : 0.0;
    }
}

}  // namespace

nlohmann::json localFailThroughReport(const Model& model, const PointEvaluator& evaluator,
                                      const std::vector<Index>& frames, const LocalReportScale& scale,
                                      int threads, const std::function<void(double)>& progress,
                                      const FullValues& fullValues, bool regionsEveryFrame) {
    nlohmann::json j;
    // Errors, `threads` cores, both ways: local fail-through (the default for a model with regions)
    // and whole-frame fail-through; each output against the frame's full values.
    std::vector<Way> ways = {{"local", true, false}, {"whole_frame", false, false}};
    if (regionsEveryFrame && model.regions) ways.push_back({"regions_every_frame", true, true});
    for (const Way& way : ways) {
        nlohmann::json w = errorsOneWay(model, evaluator, frames, scale, threads, fullValues, way, j);
        j[way.name] = std::move(w);
        if (progress) progress(way.local && !way.everyFrame ? 0.2 : 0.4);
    }
    measureSpeed(model, evaluator, frames, ways.size() > 2, progress, j);
    if (progress) progress(1.0);
    return j;
}

}  // namespace pmsc::examples
