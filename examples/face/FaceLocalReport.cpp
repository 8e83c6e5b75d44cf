#include "examples/face/FaceLocalReport.h"

#include "engine/Engine.h"

#include <time.h>

#include <algorithm>
#include <cmath>

namespace pmsc::face {

namespace {


// CPU time of the whole process: the one-thread runs below are timed by the work they cost, not
// by the wall clock, which other processes on a loaded machine stretch (a one-thread engine's
// idle workers add nothing).
double processCpuSeconds() {
    timespec t{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

/// Records each frame's state, locality, evaluated points and largest error against a full pose.
class ErrorSink : public engine::FrameSink {
public:
    ErrorSink(const PointEvaluator& evaluator, const std::vector<Index>& frames, Index n)
        : evaluator_(evaluator), frames_(frames), full_(size_t(3 * n)), n_(n) {}
    void write(const engine::FrameResult& r) override {
        evaluator_.evaluateAll(r.frame, full_.data());
        double worst = 0;
        for (Index p = 0; p < n_; ++p)
            worst = std::max(worst, std::hypot(r.values[3 * p] - full_[3 * p], r.values[3 * p + 1] - full_[3 * p + 1],
                                               r.values[3 * p + 2] - full_[3 * p + 2]));
        maxError.push_back(worst);
        states.push_back(r.state);
        local.push_back(r.local);
        fraction.push_back(double(r.pointsEvaluated) / double(n_));
    }
    std::vector<double> maxError, fraction;
    std::vector<CacheState> states;
    std::vector<bool> local;

private:
    const PointEvaluator& evaluator_;
    const std::vector<Index>& frames_;
    std::vector<double> full_;
    Index n_;
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

}  // namespace

nlohmann::json localFailThroughReport(const Model& model, const PointEvaluator& evaluator,
                                      const std::vector<Index>& frames, double percent, int threads,
                                      const std::function<void(double)>& progress) {
    nlohmann::json j;
    const Index n = model.points;
    const double count = std::max<double>(1, double(frames.size()));
    // Errors, every core, both ways: local fail-through (the default for a model with regions)
    // and whole-frame fail-through; each output against a full pose of the frame.
    for (const bool localWay : {true, false}) {
        engine::EngineOptions o;
        o.threads = threads;
        o.localFailThrough = localWay;
        engine::Engine engine(model, evaluator, o);
        ErrorSink sink(evaluator, frames, n);
        runFrames(engine, frames, sink);
        double worst = 0, fractionAll = 0, fractionNonHit = 0;
        Index nonHit = 0, local = 0, hits = 0, over = 0;
        for (size_t i = 0; i < sink.maxError.size(); ++i) {
            worst = std::max(worst, sink.maxError[i]);
            over += sink.maxError[i] > percent;
            fractionAll += sink.fraction[i];
            if (sink.states[i] != CacheState::Hit) {
                ++nonHit;
                fractionNonHit += sink.fraction[i];
            } else {
                ++hits;
            }
            local += sink.local[i];
        }
        nlohmann::json w;
        w["soft_max_error_pct_bbox_max"] = worst / percent;
        w["frames_over_1pct"] = over;
        w["points_evaluated_fraction_mean"] = fractionAll / count;
        w["points_evaluated_fraction_non_hit_mean"] = nonHit > 0 ? fractionNonHit / double(nonHit) : 0.0;
        if (localWay) {
            j["frames"] = frames.size();
            j["hit_rate"] = double(hits) / count;
            j["non_hit_frames"] = nonHit;
            j["local_fail_through"] = engine.localFailThrough();
            w["local_frames"] = local;
            const engine::RunStats& s = engine.lastStats();
            nlohmann::json regions = nlohmann::json::array();
            for (const auto& r : s.regions) regions.push_back({r.hits, r.blends, r.misses});
            w["region_states_last_run"] = regions;
        }
        j[localWay ? "local" : "whole_frame"] = w;
        if (progress) progress(localWay ? 0.2 : 0.4);
    }
    if (progress) progress(0.4);
    // Speed, one thread, the three ways in one run.
    {
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
        std::vector<double> full(size_t(3 * n));
        const double t = processCpuSeconds();
        for (const Index f : frames) evaluator.evaluateAll(f, full.data());
        const double fullSeconds = processCpuSeconds() - t;
        j["clock"] = "process CPU time, one engine thread";
        j["one_thread_seconds_per_frame"] = {{"full_pose", fullSeconds / count},
                                             {"local_fail_through", localSeconds / count},
                                             {"whole_frame_fail_through", wholeSeconds / count}};
        j["speedup_local"] = localSeconds > 0 ? fullSeconds / localSeconds : 0.0;
        j["speedup_whole_frame"] = wholeSeconds > 0 ? fullSeconds / wholeSeconds : 0.0;
    }
    if (progress) progress(1.0);
    return j;
}

nlohmann::json localFailThroughSets(const Model& model, const PointEvaluator& evaluator, const FaceAnimation& animation,
                                    const std::vector<Index>& validationSeqs, const std::vector<Index>& novelSeqs,
                                    double percent, int threads,
                                    const std::function<void(std::string_view, double, double)>& step,
                                    Index maxFramesPerSet) {
    std::vector<Index> validationSample, mixedSeqs;
    for (size_t i = 0; i < validationSeqs.size() && i < 4; ++i) validationSample.push_back(validationSeqs[i]);
    for (Index s = 0; s < Index(animation.sequences().size()); ++s)
        if (animation.sequences()[size_t(s)].mixed) mixedSeqs.push_back(s);
    nlohmann::json local;
    local["regions"] = model.regions->regionCount();
    local["region_keys"] = model.regions->extraKeyPoints.size();
    local["feather_width_pct_bbox"] = model.regions->featherWidth / percent;
    local["max_local_fraction"] = model.regions->maxLocalFraction;
    const std::pair<const char*, const std::vector<Index>*> sets[] = {
        {"validation", &validationSample}, {"novel", &novelSeqs}, {"mixed", &mixedSeqs}};
    for (const auto& [name, seqs] : sets) {
        if (seqs->empty()) continue;
        const std::string stage = std::string("local ") + name;
        std::vector<Index> frames = animation.framesOf(*seqs);
        if (maxFramesPerSet > 0 && Index(frames.size()) > maxFramesPerSet) frames.resize(size_t(maxFramesPerSet));
        local[name] = localFailThroughReport(model, evaluator, frames, percent, threads,
                                             [&](double d) { step(stage, d, 1); });
    }
    return local;
}

}  // namespace pmsc::face
