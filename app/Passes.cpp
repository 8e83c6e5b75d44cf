#include "app/Passes.h"

#include "engine/Engine.h"
#include "pmsc/Errors.h"
#include "pmsc/HitCheck.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/RegionMultiplier.h"
#include "pmsc/Training.h"  // pmsc::Cancelled

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

namespace pmsc::app {

Index PassResult::framesDone() const {
    return static_cast<Index>(
        std::count_if(frames.begin(), frames.end(), [](const PassFrame& f) { return f.done; }));
}

Index PassResult::pointsNeeded() const {
    Index n = 0;
    for (const PassFrame& f : frames) n += static_cast<Index>(f.needs.size());
    return n;
}

namespace {

/// Where the value of each point of one frame comes from: the key values, or the answer of the
/// pass that asked for it.
struct Sources {
    static constexpr std::int8_t kUnknown = -1;
    static constexpr std::int8_t kKey = 0;
    std::vector<std::int8_t> passOf;        ///< per point: kUnknown, kKey, or the pass (1, 2, ...)
    std::vector<std::vector<Index>> asked;  ///< asked[j]: the points pass j + 1 asked for, ascending
};

/// The values a frame has so far: its keys, and the answers at the points their passes asked for.
class KnownValues {
public:
    KnownValues(const Model& model, const FrameSet& keys, std::span<const MappedFrames* const> answers)
        : model_(model), keys_(keys), answers_(answers), keyNumberOf_(static_cast<size_t>(model.points), -1) {
        for (Index k = 0; k < model.keyCount(); ++k) keyNumberOf_[size_t(model.keyPoints[size_t(k)])] = k;
    }

    const std::vector<Index>& keyNumberOf() const { return keyNumberOf_; }
    std::span<const MappedFrames* const> answers() const { return answers_; }

    /// A frame's sources before any pass: the keys only.
    Sources keysOnly() const {
        Sources s;
        s.passOf.assign(size_t(model_.points), Sources::kUnknown);
        for (const Index p : model_.keyPoints) s.passOf[size_t(p)] = Sources::kKey;
        return s;
    }

    /// The values of `points` of `frame` (all known) into out (channel-minor).
    void read(const Sources& s, Index frame, std::span<const Index> points, double* out) const {
        const Index c = model_.channels;
        for (size_t i = 0; i < points.size(); ++i) {
            const Index p = points[i];
            double* dst = out + Index(i) * c;
            const std::int8_t pass = s.passOf[size_t(p)];
            if (pass == Sources::kKey) {
                std::copy_n(keys_.frame(frame) + keyNumberOf_[size_t(p)] * c, c, dst);
            } else {
                answers_[size_t(pass - 1)]->read(frame, std::span<const Index>(&points[i], 1), dst);
            }
        }
    }

    /// Records that pass `pass` (1, 2, ...) answered `points` of `frame`, after checking that the
    /// answer holds a finite value at each of them.
    void answer(Sources& s, Index frame, Index pass, std::vector<Index> points) const {
        const MappedFrames& file = *answers_[size_t(pass - 1)];
        const Index c = model_.channels;
        std::vector<double> values(points.size() * size_t(c));
        file.read(frame, points, values.data());
        for (size_t i = 0; i < values.size(); ++i) {
            if (std::isfinite(values[i])) continue;
            throw InputError(file.path() + ": pass " + std::to_string(pass) + " asked for point " +
                             std::to_string(points[i / size_t(c)]) + " of frame " + std::to_string(frame) +
                             ", but channel " + std::to_string(Index(i) % c) + " holds " +
                             std::to_string(values[i]) + " (an asked-for value must be finite)");
        }
        for (const Index p : points) s.passOf[size_t(p)] = static_cast<std::int8_t>(pass);
        s.asked.push_back(std::move(points));
    }

private:
    const Model& model_;
    const FrameSet& keys_;
    std::span<const MappedFrames* const> answers_;
    std::vector<Index> keyNumberOf_;
};

/// Decides, for one frame, what the soft cache needs next: the same decisions, from the same
/// values, as the engine's error monitor (nodes/ErrorMonitor.cpp) makes.
class FramePlanner {
public:
    FramePlanner(const Model& model, const SoftCachePolicy& policy, const RegionMultiplier* regions,
                 const KnownValues& known)
        : model_(model),
          multiplier_(model),
          check_(model, multiplier_),
          policy_(policy),
          regions_(regions),
          known_(known) {}

    /// Decides frame f from its keys and the answers given, and returns its row; `sources` gets
    /// where each value the frame used comes from.
    PassFrame plan(Index frame, const double* keyValues, Sources& sources) const {
        PassFrame row;
        row.frame = frame;
        std::vector<double> coords(size_t(model_.coordCount()));
        multiplier_.project(keyValues, coords.data());
        PredictedParts parts;
        row.keyRms = multiplier_.keyError(keyValues, coords.data(), &parts);
        row.decision = policy_.decide(row.keyRms);
        // As the error monitor: a hit one part alone certifies is checked (HitCheck), and computed
        // whole when the check fails.
        const bool check = check_.needed(row.decision, parts);
        if (row.decision.state == CacheState::Hit && !check) {
            row.done = true;
            return row;
        }
        const std::vector<Index> checkPoints =
            check ? check_.points(keyValues, coords.data(), parts) : std::vector<Index>{};
        const Index given = static_cast<Index>(known_.answers().size());
        for (Index pass = 1;; ++pass) {
            std::vector<Index> needs;
            if (check && row.decision.state == CacheState::Hit) {
                needs = unknown(sources, checkPoints);
                if (needs.empty()) {
                    std::vector<double> values(checkPoints.size() * size_t(model_.channels));
                    known_.read(sources, frame, checkPoints, values.data());
                    if (check_.passes(coords.data(), checkPoints, values.data())) {
                        row.done = true;
                        break;
                    }
                    row.decision = CacheDecision{CacheState::Blend, 0.0};
                    needs = allUnknown(sources);  // the whole frame, as the error monitor
                }
            } else if (check) {
                needs = allUnknown(sources);
            } else {
                needs = nextNeeds(frame, keyValues, coords.data(), sources);
            }
            if (needs.empty()) {
                row.done = true;
                break;
            }
            if (pass > given) {
                row.needs = std::move(needs);
                break;
            }
            row.pointsAnswered += static_cast<Index>(needs.size());
            row.passes = pass;
            known_.answer(sources, frame, pass, std::move(needs));
        }
        return row;
    }

private:
    /// The points not yet known among `points` (ascending when `points` is).
    static std::vector<Index> unknown(const Sources& s, std::span<const Index> points) {
        std::vector<Index> out;
        for (const Index p : points)
            if (s.passOf[size_t(p)] == Sources::kUnknown) out.push_back(p);
        return out;
    }

    std::vector<Index> allUnknown(const Sources& s) const {
        std::vector<Index> all(size_t(model_.points));
        std::iota(all.begin(), all.end(), Index{0});
        return unknown(s, all);
    }

    /// The region keys not yet known, ascending.
    std::vector<Index> unknownRegionKeys(const Sources& s) const {
        std::vector<Index> regionKeys = regions_->regionKeyPoints();
        std::sort(regionKeys.begin(), regionKeys.end());
        return unknown(s, regionKeys);
    }

    /// Each region's weight of the full result, from the keys and the (known) region keys.
    std::vector<double> regionWeights(Index frame, const double* keyValues, const Sources& s) const {
        const auto& extra = regions_->regionKeyPoints();
        const Index c = model_.channels, r = regions_->regionCount();
        std::vector<double> extraValues(extra.size() * size_t(c));
        known_.read(s, frame, extra, extraValues.data());
        std::vector<double> coords(static_cast<size_t>(regions_->coordsSize()));
        std::vector<double> weights(static_cast<size_t>(r));
        for (Index i = 0; i < r; ++i) {
            const double e =
                regions_->project(i, keyValues, extraValues.empty() ? nullptr : extraValues.data(),
                                  coords.data() + regions_->coordsOffset(i));
            weights[size_t(i)] = regions_->decide(i, e).weight;
        }
        return weights;
    }

    /// A frame that did not hit: its region keys first, then (as the error monitor) the sentinels
    /// it would hand back as PM alone, then the points its failing regions evaluate (with the
    /// regions of the sentinels PM misses), or every point when it fails through whole.
    std::vector<Index> nextNeeds(Index frame, const double* keyValues, const double* coords,
                                 const Sources& s) const {
        if (regions_ == nullptr) return allUnknown(s);
        std::vector<Index> missing = unknownRegionKeys(s);
        if (!missing.empty()) return missing;
        std::vector<double> weights = regionWeights(frame, keyValues, s);
        std::vector<double> pointWeights(size_t(model_.points));
        regions_->pointWeights(weights, pointWeights.data());
        std::vector<Index> local(size_t(model_.points));
        Index full = regions_->fullPoints(pointWeights, local.data());
        const double most = regions_->regions().maxLocalFraction * double(model_.points);
        if (!(double(full) <= most)) return allUnknown(s);
        const std::vector<Index> sentinels = check_.unblendedSentinels(pointWeights);
        if (!sentinels.empty()) {
            std::vector<Index> missingSentinels = unknown(s, sentinels);
            if (!missingSentinels.empty()) return missingSentinels;
            std::vector<double> values(sentinels.size() * size_t(model_.channels));
            known_.read(s, frame, sentinels, values.data());
            const std::vector<Index> off = check_.offPoints(coords, sentinels, values.data());
            if (!regions_->failRegionsOf(off, weights)) return allUnknown(s);
            if (!off.empty()) {
                regions_->pointWeights(weights, pointWeights.data());
                full = regions_->fullPoints(pointWeights, local.data());
                if (!(double(full) <= most)) return allUnknown(s);
            }
        }
        local.resize(size_t(full));
        return unknown(s, local);
    }

    const Model& model_;
    PointMultiplier multiplier_;
    HitCheck check_;
    SoftCachePolicy policy_;
    const RegionMultiplier* regions_;
    const KnownValues& known_;
};

/// The frames that need nothing more, as an evaluator that serves exactly the values the passes
/// gave: its frame i is done frame i. Asked for any other value it throws, which fails the run: the
/// engine and the planner would disagree, an internal error.
class AnsweredEvaluator : public PointEvaluator {
public:
    AnsweredEvaluator(const Model& model, const KnownValues& known, std::vector<Index> frames,
                      std::vector<Sources> sources)
        : model_(model), known_(known), frames_(std::move(frames)), sources_(std::move(sources)) {}

    std::string name() const override { return "reconstruct"; }
    Index pointCount() const override { return model_.points; }
    Index channelCount() const override { return model_.channels; }
    Index frameCount() const override { return static_cast<Index>(frames_.size()); }
    Index fileFrame(Index i) const { return frames_[size_t(i)]; }

    void evaluate(Index frame, std::span<const Index> points, double* out) const override {
        const Sources& s = sources_[size_t(frame)];
        for (const Index p : points) {
            if (p < 0 || p >= model_.points || s.passOf[size_t(p)] == Sources::kUnknown)
                throw std::logic_error("pmsc reconstruct: the engine asked for point " + std::to_string(p) +
                                       " of frame " + std::to_string(frames_[size_t(frame)]) +
                                       ", which no pass asked for (an internal error)");
        }
        known_.read(s, frames_[size_t(frame)], points, out);
    }

private:
    const Model& model_;
    const KnownValues& known_;
    std::vector<Index> frames_;
    std::vector<Sources> sources_;
};

/// Writes the done frames' soft-cached values and fills in their rows from what the engine did.
class PassSink : public engine::FrameSink {
public:
    PassSink(const AnsweredEvaluator& evaluator, PassResult& result, NpyFrameWriter* out)
        : evaluator_(evaluator), result_(result), out_(out) {}

    void write(const engine::FrameResult& r) override {
        const Index frame = evaluator_.fileFrame(r.frame);
        PassFrame& row = result_.frames[size_t(frame)];
        if (r.state != row.decision.state || r.keyError != row.keyRms)
            throw std::logic_error("pmsc reconstruct: frame " + std::to_string(frame) +
                                   ": the engine decided otherwise than the passes (an internal error)");
        row.local = r.local;
        row.pointsEvaluated = r.pointsEvaluated;
        row.regionStates.assign(r.regionStates.begin(), r.regionStates.end());
        if (out_) out_->writeFrame(frame, r.values.data());
    }

private:
    const AnsweredEvaluator& evaluator_;
    PassResult& result_;
    NpyFrameWriter* out_;
};

void checkShapes(const Model& model, const FrameSet& keys, std::span<const MappedFrames* const> answers) {
    if (model.cross)
        throw std::invalid_argument(
            "a cross model has no fail-through to drive pass by pass (use pmsc replay)");
    if (keys.points != model.keyCount() || keys.channels != model.channels)
        throw InputError("key values have " + std::to_string(keys.points) + " points x " +
                         std::to_string(keys.channels) + " channels, the model has " +
                         std::to_string(model.keyCount()) + " keys x " + std::to_string(model.channels) +
                         " channels");
    for (const MappedFrames* a : answers) {
        const NpyInfo& i = a->info();
        if (i.frames != keys.frames || i.points != model.points || i.channels != model.channels)
            throw InputError(a->path() + ": shape (" + std::to_string(i.frames) + ", " +
                             std::to_string(i.points) + ", " + std::to_string(i.channels) + "), expected (" +
                             std::to_string(keys.frames) + ", " + std::to_string(model.points) + ", " +
                             std::to_string(model.channels) +
                             "): (frames of the keys, the model's points, channels)");
    }
}

/// Frames still waiting get the point-multiplication estimate from their keys.
void writeEstimates(const Model& model, const FrameSet& keys, const PassResult& result, NpyFrameWriter& out) {
    const PointMultiplier multiplier(model);
    std::vector<double> coords(size_t(model.coordCount())), values(size_t(model.points * model.channels));
    for (const PassFrame& row : result.frames) {
        if (row.done) continue;
        multiplier.project(keys.frame(row.frame), coords.data());
        multiplier.reconstruct(coords.data(), values.data());
        out.writeFrame(row.frame, values.data());
    }
}

}  // namespace

PassResult reconstructPasses(const Model& model, const FrameSet& keys,
                             std::span<const MappedFrames* const> answers, const PassOptions& options,
                             NpyFrameWriter* out) {
    checkShapes(model, keys, answers);
    PassResult result;
    result.epsMin = options.eps ? options.eps->first : model.epsMin;
    result.epsMax = options.eps ? options.eps->second : model.epsMax;
    result.answersGiven = static_cast<Index>(answers.size());
    const SoftCachePolicy policy(result.epsMin, result.epsMax);
    std::optional<RegionMultiplier> regions;
    if (model.regions && options.localFailThrough) regions.emplace(model);
    result.localFailThrough = regions.has_value();

    const KnownValues known(model, keys, answers);
    const FramePlanner planner(model, policy, regions ? &*regions : nullptr, known);
    std::vector<Index> doneFrames;
    std::vector<Sources> doneSources;
    for (Index f = 0; f < keys.frames; ++f) {
        if (options.cancel && options.cancel->load()) throw Cancelled("reconstruct interrupted");
        Sources sources = known.keysOnly();
        result.frames.push_back(planner.plan(f, keys.frame(f), sources));
        if (!result.frames.back().done) continue;
        doneFrames.push_back(f);
        doneSources.push_back(std::move(sources));
    }

    if (!doneFrames.empty()) {
        const AnsweredEvaluator evaluator(model, known, std::move(doneFrames), std::move(doneSources));
        engine::EngineOptions engineOptions;
        engineOptions.threads = options.threads;
        engineOptions.policy = policy;
        engineOptions.keepPointMultiplication = true;  // as `pmsc replay` runs, so the outputs agree
        engineOptions.cancel = options.cancel;
        engineOptions.localFailThrough = options.localFailThrough;
        engine::Engine engine(model, evaluator, std::move(engineOptions));
        PassSink sink(evaluator, result, out);
        engine.run({0, evaluator.frameCount(), 1}, sink);
    }
    if (out) writeEstimates(model, keys, result, *out);
    return result;
}

nlohmann::ordered_json passReport(const Model& model, const PassResult& result) {
    using json = nlohmann::ordered_json;
    Index hits = 0, blends = 0, misses = 0, answered = 0;
    json frames = json::array();
    for (const PassFrame& r : result.frames) {
        hits += r.decision.state == CacheState::Hit;
        blends += r.decision.state == CacheState::Blend;
        misses += r.decision.state == CacheState::Miss;
        answered += r.pointsAnswered;
        json row = {{"frame", r.frame},
                    {"key_rms", r.keyRms},
                    {"state", std::string(toString(r.decision.state))},
                    {"weight", r.decision.weight},
                    {"done", r.done},
                    {"passes", r.passes},
                    {"points_answered", r.pointsAnswered},
                    {"needs", r.needs}};
        if (model.regions && r.done) {
            std::string states;
            for (const CacheState st : r.regionStates)
                states += st == CacheState::Hit ? 'h' : st == CacheState::Blend ? 'b' : 'm';
            row["local"] = r.local;
            row["regions"] = states;
        }
        frames.push_back(std::move(row));
    }
    const double count = std::max<double>(1.0, static_cast<double>(result.frames.size()));
    const double allPoints = count * static_cast<double>(model.points);
    json summary = {
        {"frames", result.frames.size()},
        {"points", model.points},
        {"channels", model.channels},
        {"key_points", model.keyCount()},
        {"eps_min", result.epsMin},
        {"eps_max", result.epsMax},
        {"local_fail_through", result.localFailThrough},
        {"answers_given", result.answersGiven},
        {"frames_done", result.framesDone()},
        {"complete", result.framesDone() == static_cast<Index>(result.frames.size())},
        {"points_needed", result.pointsNeeded()},
        {"hit_rate", static_cast<double>(hits) / count},
        {"blend_rate", static_cast<double>(blends) / count},
        {"miss_rate", static_cast<double>(misses) / count},
        {"key_fraction", static_cast<double>(model.keyCount()) / static_cast<double>(model.points)},
        {"answered_fraction", static_cast<double>(answered) / allPoints}};
    return json{{"summary", summary}, {"frames", frames}};
}

}  // namespace pmsc::app
