#include "app/Replay.h"

#include "engine/Engine.h"
#include "pmsc/Training.h"  // pmsc::Cancelled

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>

namespace pmsc::app {

ReplayScratch::ReplayScratch(const Model& model)
    : keys(static_cast<std::size_t>(model.keyCount() * model.channels)),
      coords(static_cast<std::size_t>(model.coordCount())),
      pm(static_cast<std::size_t>(model.points * model.channels)),
      full(pm.size()) {}

ReplayFrame replayFrame(const PointMultiplier& multiplier, const SoftCachePolicy& policy,
                        const PointEvaluator& recorded, Index frame, ReplayScratch& s, double* out) {
    const Model& model = multiplier.model();
    const Index n = model.points, c = model.channels;
    ReplayFrame row;
    row.frame = frame;
    recorded.evaluate(frame, model.keyPoints, s.keys.data());
    multiplier.project(s.keys.data(), s.coords.data());
    row.keyRms = multiplier.keyError(s.keys.data(), s.coords.data());
    row.decision = policy.decide(row.keyRms);
    // Replay exists to measure: the PM result and the recorded frame are needed for the errors
    // whatever the decision, so both are computed even where a production run would skip one.
    multiplier.reconstruct(s.coords.data(), s.pm.data());
    recorded.evaluateAll(frame, s.full.data());
    const std::size_t values = static_cast<std::size_t>(n * c);
    const double w = row.decision.weight;
    switch (row.decision.state) {
        case CacheState::Hit:
            std::copy_n(s.pm.data(), values, out);
            break;
        case CacheState::Miss:
            std::copy_n(s.full.data(), values, out);
            break;
        case CacheState::Blend:
            blendPoints(w, model.tolerance, c, s.pm.data(), s.full.data(), out, n);
            break;
    }
    row.pmMaxPointError = maxPointError(s.pm.data(), s.full.data(), n, c);
    row.softMaxPointError = maxPointError(out, s.full.data(), n, c);
    return row;
}

namespace {

/// The serial, in-order end of a replay on the engine: measures each finished frame against
/// the recording (the errors of the report) and writes it to the output file.
class ReplaySink : public engine::FrameSink {
public:
    ReplaySink(const Model& model, const PointMultiplier& multiplier, const PointEvaluator& recorded,
               ReplayResult& result, NpyFrameWriter* out, KeptFrames* keep,
               std::function<void(Index, const double*)> frameOut)
        : model_(model),
          recorded_(recorded),
          result_(result),
          out_(out),
          keep_(keep),
          frameOut_(std::move(frameOut)),
          full_(static_cast<std::size_t>(model.points * model.channels)),
          multiplier_(multiplier),
          pm_(full_.size()),
          coords_(static_cast<std::size_t>(model.coordCount())) {}

    void write(const engine::FrameResult& r) override {
        ReplayFrame& row = result_.frames[static_cast<std::size_t>(r.sequence)];
        row.frame = r.frame;
        row.keyRms = r.keyError;
        row.decision = CacheDecision{r.state, r.weight};
        // The recorded frame is the reference for both errors, whatever the decision. A miss
        // already holds it: the fail-through read exactly the recorded values.
        const double* full = full_.data();
        if (r.state == CacheState::Miss && !r.failed && !r.local) {
            full = r.values.data();
        } else {
            recorded_.evaluateAll(r.frame, full_.data());
        }
        const Index n = model_.points, c = model_.channels;
        // Recorded frames are finite (the reader rejects NaN/Inf), so the keys are too and the
        // engine always hands over the PM result (keepPointMultiplication).
        // A local frame (local fail-through) carries no whole-frame PM result: it is computed here, the same
        // projection of the same key values, so the report's PM column means the same thing.
        const double* pm = r.pmValues.data();
        if (r.pmValues.empty() && r.local) {
            multiplier_.project(r.keyValues.data(), coords_.data());
            multiplier_.reconstruct(coords_.data(), pm_.data());
            pm = pm_.data();
        }
        row.pmMaxPointError =
            pm == nullptr ? std::numeric_limits<double>::quiet_NaN() : maxPointError(pm, full, n, c);
        row.local = r.local;
        row.pointsEvaluatedFraction = double(r.pointsEvaluated) / double(n);
        row.regionStates.assign(r.regionStates.begin(), r.regionStates.end());
        row.softMaxPointError = maxPointError(r.values.data(), full, n, c);
        if (out_) out_->writeFrame(r.sequence, r.values.data());
        if (frameOut_) frameOut_(r.sequence, r.values.data());
        if (keep_ && !r.failed && r.state != CacheState::Hit) keep_->add(r.frame, r.state, r.keyError, full);
    }

private:
    const Model& model_;
    const PointEvaluator& recorded_;
    ReplayResult& result_;
    NpyFrameWriter* out_;
    KeptFrames* keep_;
    std::function<void(Index, const double*)> frameOut_;
    std::vector<double> full_;
    const PointMultiplier& multiplier_;  // the engine's: one copy of the basis, not two
    std::vector<double> pm_, coords_;
};

}  // namespace

ReplayResult replay(const Model& model, const PointEvaluator& recorded, const ReplayOptions& options,
                    NpyFrameWriter* out) {
    ReplayResult result;
    result.epsMin = options.eps ? options.eps->first : model.epsMin;
    result.epsMax = options.eps ? options.eps->second : model.epsMax;
    const Index frames = recorded.frameCount();
    result.frames.resize(static_cast<std::size_t>(frames));

    // The frames stream through the evaluation engine: key values, projection, the
    // soft-cache decision, PM reconstruction or the (chunked, parallel) fail-through, in frame
    // order to the sink. Its output is the same, bit for bit, as replayFrame() computes, and
    // does not depend on the thread count.
    engine::EngineOptions engineOptions;
    engineOptions.threads = options.threads;
    engineOptions.policy = SoftCachePolicy(result.epsMin, result.epsMax);
    engineOptions.keepPointMultiplication = true;  // the report needs PM's error on every frame
    engineOptions.cancel = options.cancel;
    engineOptions.localFailThrough = options.localFailThrough;
    engineOptions.memoryLimit = options.memoryLimit;
    if (options.progress) {
        engineOptions.progress = [&](const engine::Progress& p) {
            options.progress(p.framesDone, p.framesTotal);
        };
    }
    engine::Engine engine(model, recorded, std::move(engineOptions));
    ReplaySink sink(model, engine.pointMultiplier(), recorded, result, out, options.keep, options.frameOut);
    // pmsc::Cancelled (interrupt) and pmsc::EvaluatorError propagate unchanged.
    const engine::RunStats stats = engine.run({0, frames, 1}, sink);
    result.threads = stats.threads;
    result.localFailThrough = engine.localFailThrough();
    result.framesInFlight = stats.maxFramesInFlight;
    result.seconds = stats.wallSeconds;
    return result;
}

nlohmann::ordered_json replayReport(const Model& model, const ReplayResult& result) {
    using json = nlohmann::ordered_json;
    const auto pct = [](const Percentiles& p) {
        return json{{"p50", p.p50}, {"p99", p.p99}, {"p995", p.p995}, {"max", p.max}};
    };
    std::vector<double> pm, soft;
    Index hits = 0, blends = 0, misses = 0;
    json frames = json::array();
    for (const auto& r : result.frames) {
        pm.push_back(r.pmMaxPointError);
        soft.push_back(r.softMaxPointError);
        hits += r.decision.state == CacheState::Hit;
        blends += r.decision.state == CacheState::Blend;
        misses += r.decision.state == CacheState::Miss;
        frames.push_back({{"frame", r.frame},
                          {"key_rms", r.keyRms},
                          {"state", std::string(toString(r.decision.state))},
                          {"weight", r.decision.weight},
                          {"pm_max_point_error", r.pmMaxPointError},
                          {"soft_max_point_error", r.softMaxPointError}});
    }
    const double count = std::max<double>(1.0, static_cast<double>(result.frames.size()));
    // The share of points computed, for models whose frames compute more than the keys or
    // everything: regions (local fail-through) or a hit check (its sentinels, region keys and key
    // neighbours are computed on every checked hit). A version-1 model's report is unchanged,
    // byte for byte.
    const Index regionCount = model.regions ? model.regions->regionCount() : 0;
    const bool partial = regionCount > 0 || model.sentinels.has_value() || model.keyNeighbours.has_value();
    for (std::size_t i = 0; partial && i < result.frames.size(); ++i) {
        const auto& r = result.frames[i];
        frames[i]["points_evaluated_fraction"] = r.pointsEvaluatedFraction;
        if (regionCount == 0) continue;
        std::string states;
        for (const CacheState st : r.regionStates)
            states += st == CacheState::Hit ? 'h' : st == CacheState::Blend ? 'b' : 'm';
        frames[i]["local"] = r.local;
        frames[i]["regions"] = states;
    }
    json summary = {{"frames", result.frames.size()},
                    {"points", model.points},
                    {"channels", model.channels},
                    {"key_points", model.keyCount()},
                    {"basis", model.basisSize()},
                    {"eps_min", result.epsMin},
                    {"eps_max", result.epsMax},
                    {"hit_rate", static_cast<double>(hits) / count},
                    {"blend_rate", static_cast<double>(blends) / count},
                    {"miss_rate", static_cast<double>(misses) / count},
                    {"pm_max_point_error", pct(percentiles(pm))},
                    {"soft_max_point_error", pct(percentiles(soft))},
                    {"seconds", result.seconds}};
    if (partial) {
        double evaluated = 0;
        for (const auto& r : result.frames) evaluated += r.pointsEvaluatedFraction;
        summary["points_evaluated_fraction"] = evaluated / count;
    }
    if (regionCount > 0) {
        Index local = 0;
        std::vector<std::array<Index, 3>> perRegion(static_cast<std::size_t>(regionCount), {0, 0, 0});
        for (const auto& r : result.frames) {
            local += r.local;
            for (std::size_t g = 0; g < r.regionStates.size() && g < perRegion.size(); ++g)
                ++perRegion[g][static_cast<std::size_t>(r.regionStates[g])];
        }
        json regions = json::array();
        for (const auto& g : perRegion)
            regions.push_back({{"hits", g[0]}, {"blends", g[1]}, {"misses", g[2]}});
        summary["regions"] = regionCount;
        summary["local_fail_through"] = result.localFailThrough;
        summary["local_frames"] = local;
        summary["region_states"] = std::move(regions);
    }
    return json{{"summary", std::move(summary)}, {"frames", std::move(frames)}};
}

void checkEps(const std::pair<double, double>& eps, Spelling spelling) {
    if (!(eps.first >= 0 && eps.first <= eps.second && std::isfinite(eps.second))) {
        char got[96];
        std::snprintf(got, sizeof got, "%g, %g", eps.first, eps.second);
        throw OptionError(optionName("eps", spelling) + ": need 0 <= MIN <= MAX, got " + got);
    }
}

}  // namespace pmsc::app
