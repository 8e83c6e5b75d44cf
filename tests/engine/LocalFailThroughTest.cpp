// Local fail-through: regions learned in training, per-region decisions in the engine,
// only the points of failing regions (and their feather bands) evaluated fully.
#include "engine/Engine.h"
#include "pmsc/ModelIO.h"
#include "pmsc/RegionLearning.h"
#include "pmsc/RegionMultiplier.h"
#include "pmsc/Training.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <mutex>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

using pmsc::CacheState;
using pmsc::Index;
using pmsc::Model;

/// A 40 x 40 sheet of points in the unit square (3 channels: positions). Training frames move it
/// with three global modes and four local bumps (one per quadrant, with a small nonlinear part);
/// novel frames add a fifth bump at (0.8, 0.5) that training never saw: a local change.
class LocalSurface : public pmsc::PointEvaluator {
public:
    static constexpr Index kSide = 40;
    LocalSurface(Index frames, bool novel, double phase) : frames_(frames), novel_(novel), phase_(phase) {}
    std::string name() const override { return "local-surface"; }
    Index pointCount() const override { return kSide * kSide; }
    Index channelCount() const override { return 3; }
    Index frameCount() const override { return frames_; }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override {
        if (frame < 0 || frame >= frames_) throw std::out_of_range("frame");
        evaluations_.fetch_add(Index(points.size()), std::memory_order_relaxed);
        const double t = double(frame) + phase_;
        for (size_t i = 0; i < points.size(); ++i) {
            const double x = double(points[i] % kSide) / double(kSide - 1);
            const double y = double(points[i] / kSide) / double(kSide - 1);
            double d[3] = {0, 0, 0};
            const double a0 = std::sin(0.05 * t), a1 = std::sin(0.083 * t + 1), a2 = std::sin(0.031 * t + 2);
            d[2] += a0 * std::sin(std::numbers::pi * x) * 0.2 + a1 * std::cos(std::numbers::pi * y) * 0.2;
            d[0] += a2 * 0.05 * x * y;
            const double cx[4] = {0.25, 0.75, 0.25, 0.75}, cy[4] = {0.25, 0.25, 0.75, 0.75};
            for (int b = 0; b < 4; ++b) {
                const double amp = 0.15 * std::sin(0.07 * (b + 1) * t + 2 * b);
                const double bump =
                    std::exp(-((x - cx[b]) * (x - cx[b]) + (y - cy[b]) * (y - cy[b])) / 0.015);
                d[2] += amp * bump;
                d[0] += 0.3 * amp * amp * bump;
            }
            if (novel_) {
                const double amp = 0.12 + 0.08 * std::sin(0.2 * t);
                d[2] += amp * std::exp(-((x - 0.8) * (x - 0.8) + (y - 0.5) * (y - 0.5)) / 0.008);
            }
            out[3 * i + 0] = x + d[0];
            out[3 * i + 1] = y + d[1];
            out[3 * i + 2] = d[2];
        }
    }
    Index evaluations() const { return evaluations_.load(); }

private:
    Index frames_;
    bool novel_;
    double phase_;
    mutable std::atomic<Index> evaluations_{0};
};

constexpr double kTolerance = 0.004;

const Model& trainedModel() {
    static const Model model = [] {
        const LocalSurface training(150, false, 0.0);
        const pmsc::FrameSet frames = pmsc::evaluateFrames(training, 0, training.frameCount());
        pmsc::TrainingOptions o;
        o.energy = 0.999999;
        o.maxKeys = 90;
        o.tolerance = kTolerance;
        o.sentinels = 0;  // the regions' own decisions, not the sentinels' (HitCheckTest)
        o.regions.count = 9;
        // A sparse grid among the keys (the paper's remedy for rendering, section 4), so that no
        // part of the sheet is unwatched: the novel bump lands where training saw no motion.
        for (Index gy = 2; gy < 40; gy += 6)
            for (Index gx = 2; gx < 40; gx += 6) o.gridPoints.push_back(gy * 40 + gx);
        o.regions.featherFraction = 0.08;
        o.regions.energy = 0.999999;
        // Sheet-sized key rules: the defaults are set for the ICT face (RegionLearning.h),
        // where a region holds a few hundred of 26,719 points; on this 1,600-point sheet 12 keys
        // and a 1.5 margin make each of the 9 regions watch most of its neighbours' keys.
        o.regions.minKeys = 6;
        o.regions.keyRadius = 0;
        o.regions.basisShare = 2.0 / 3.0;
        o.regions.ratioMargin = 1.0;
        // Region keys (RegionOptions::ownKeys): more than most regions of the sheet hold of the
        // model's keys, so the routing below also evaluates region keys.
        o.regions.ownKeys = 16;
        return pmsc::train(frames, o);
    }();
    return model;
}

/// Keeps every frame's output and its local-fail-through fields.
struct Collected {
    CacheState state;
    bool local;
    Index pointsEvaluated;
    std::vector<CacheState> regions;
    std::vector<double> values, weights;
    std::vector<Index> fullPoints;
    std::vector<double> fullValues;
};
class CollectingSink : public pmsc::engine::FrameSink {
public:
    std::vector<Collected> frames;
    void write(const pmsc::engine::FrameResult& r) override {
        frames.push_back({r.state,
                          r.local,
                          r.pointsEvaluated,
                          {r.regionStates.begin(), r.regionStates.end()},
                          {r.values.begin(), r.values.end()},
                          {r.pointWeights.begin(), r.pointWeights.end()},
                          {r.fullPoints.begin(), r.fullPoints.end()},
                          {r.fullValues.begin(), r.fullValues.end()}});
    }
};

std::vector<Collected> runNovel(const Model& model, bool local, int threads, Index* evaluated = nullptr) {
    const LocalSurface novel(40, true, 1000.0);
    pmsc::engine::EngineOptions o;
    o.threads = threads;
    o.localFailThrough = local;
    pmsc::engine::Engine engine(model, novel, o);
    CollectingSink sink;
    engine.run({0, novel.frameCount(), 1}, sink);
    EXPECT_EQ(engine.localFailThrough(), local && model.regions.has_value());
    if (evaluated) *evaluated = novel.evaluations();
    return sink.frames;
}

double maxPointError(const std::vector<double>& a, const std::vector<double>& b) {
    double worst = 0;
    for (size_t i = 0; i < a.size(); i += 3)
        worst = std::max(worst, std::hypot(a[i] - b[i], a[i + 1] - b[i + 1], a[i + 2] - b[i + 2]));
    return worst;
}

TEST(LocalFailThrough, TrainingLearnsCompactRegionsThatRoundTrip) {
    const Model& model = trainedModel();
    ASSERT_TRUE(model.regions.has_value());
    const auto& regions = *model.regions;
    EXPECT_GE(regions.regionCount(), 4);
    EXPECT_LE(regions.regionCount(), 9);
    // Compact: no region spans more than half of the sheet in both directions.
    for (const auto& g : regions.regions) {
        Index minX = 99, maxX = -1, minY = 99, maxY = -1;
        for (const Index p : g.points) {
            minX = std::min(minX, p % 40), maxX = std::max(maxX, p % 40);
            minY = std::min(minY, p / 40), maxY = std::max(maxY, p / 40);
        }
        EXPECT_TRUE(maxX - minX < 30 || maxY - minY < 30) << maxX - minX << " x " << maxY - minY;
        EXPECT_GT(g.epsMin, 0);
        EXPECT_GE(Index(g.keys.size()) * 3, g.basisSize());
    }
    // Region keys: every region holds at least ownKeys (16) keys of its own, the model's or
    // region keys, and region keys lie in regions that held fewer of the model's.
    ASSERT_FALSE(regions.extraKeyPoints.empty());
    const std::vector<Index> of = regions.regionOfPoints(model.points);
    std::vector<Index> own(size_t(regions.regionCount()), 0), modelOwn(size_t(regions.regionCount()), 0);
    for (const Index p : model.keyPoints) ++own[size_t(of[size_t(p)])], ++modelOwn[size_t(of[size_t(p)])];
    for (const Index p : regions.extraKeyPoints) {
        EXPECT_LT(modelOwn[size_t(of[size_t(p)])], 16) << p;
        ++own[size_t(of[size_t(p)])];
    }
    for (Index r = 0; r < regions.regionCount(); ++r)
        EXPECT_GE(own[size_t(r)], std::min<Index>(16, Index(regions.regions[size_t(r)].points.size()))) << r;
    const std::string bytes = pmsc::encodeModel(model);
    const Model back = pmsc::decodeModel(bytes, "m.pmsc");
    EXPECT_EQ(pmsc::encodeModel(back), bytes);
    EXPECT_EQ(back.regions->extraKeyPoints, regions.extraKeyPoints);
}

/// Region key neighbourhoods, basis share and ratio margin: learned
/// again from the same training with the rules switched, each must change what it claims to.
TEST(LocalFailThrough, RegionKeysBasisShareAndRatioMarginDoWhatTheySay) {
    const LocalSurface training(150, false, 0.0);
    const pmsc::FrameSet frames = pmsc::evaluateFrames(training, 0, training.frameCount());
    const Model& model = trainedModel();
    Eigen::MatrixXd q(model.points * 3, frames.frames);
    for (Index f = 0; f < frames.frames; ++f)
        q.col(f) = Eigen::Map<const Eigen::VectorXd>(frames.frame(f), model.points * 3) - model.mean;
    pmsc::RegionOptions o;
    o.count = 9;
    o.featherFraction = 0.08;
    o.energy = 0.999999;
    o.ratioMargin = 1.5;  // not the default (1): the margin's effect is tested below
    auto learn = [&](const pmsc::RegionOptions& ro) {
        return pmsc::learnRegions(q, model, ro, kTolerance, 5, {});
    };
    const pmsc::LocalRegions base = learn(o);
    const Eigen::MatrixXd pos =
        Eigen::Map<const Eigen::MatrixXd>(model.mean.data(), 3, model.points).transpose();
    const double diagonal = (pos.colwise().maxCoeff() - pos.colwise().minCoeff()).norm();
    for (const auto& g : base.regions) {
        // Every key within keyRadius of the region is one of its keys; at least minKeys (or all K).
        EXPECT_GE(Index(g.keys.size()), std::min<Index>(o.minKeys, model.keyCount()));
        for (Index k = 0; k < model.keyCount(); ++k) {
            double d = 1e300;
            for (const Index p : g.points)
                d = std::min(d, (pos.row(model.keyPoints[size_t(k)]) - pos.row(p)).norm());
            if (d <= o.keyRadius * diagonal) {
                EXPECT_TRUE(std::binary_search(g.keys.begin(), g.keys.end(), k)) << k;
            }
        }
        EXPECT_LE(g.basisSize(), std::max<Index>(1, Index(o.basisShare * double(g.keys.size() * 3))));
    }
    // The margin divides eps_min of every calibrated region and nothing else changes.
    pmsc::RegionOptions noMargin = o;
    noMargin.ratioMargin = 1.0;
    const pmsc::LocalRegions plain = learn(noMargin);
    ASSERT_EQ(plain.regionCount(), base.regionCount());
    for (Index r = 0; r < base.regionCount(); ++r) {
        const auto& a = base.regions[size_t(r)];
        const auto& b = plain.regions[size_t(r)];
        EXPECT_EQ(a.keys, b.keys);
        if (b.ratio > 0) {
            EXPECT_NEAR(a.epsMin * o.ratioMargin, b.epsMin, 1e-12 * b.epsMin) << r;
        }
        EXPECT_DOUBLE_EQ(a.epsMax, 1.5 * a.epsMin);
    }
    // A larger radius only adds keys.
    pmsc::RegionOptions wide = o;
    wide.keyRadius = 0.5;
    const pmsc::LocalRegions w = learn(wide);
    for (Index r = 0; r < base.regionCount(); ++r)
        EXPECT_TRUE(std::includes(w.regions[size_t(r)].keys.begin(), w.regions[size_t(r)].keys.end(),
                                  base.regions[size_t(r)].keys.begin(), base.regions[size_t(r)].keys.end()));
    pmsc::RegionOptions bad = o;
    bad.ratioMargin = 0.5;
    EXPECT_THROW(learn(bad), std::invalid_argument);
    bad = o;
    bad.basisShare = 0;
    EXPECT_THROW(learn(bad), std::invalid_argument);
}

TEST(LocalFailThrough, OnlyTheRegionsThatMissAreEvaluatedAndTheErrorStaysUnderTolerance) {
    const Model& model = trainedModel();
    const LocalSurface novel(40, true, 1000.0);
    Index localEvaluations = 0, wholeEvaluations = 0;
    const auto local = runNovel(model, true, 2, &localEvaluations);
    const auto whole = runNovel(model, false, 2, &wholeEvaluations);
    ASSERT_EQ(local.size(), 40u);
    const Index n = model.points;
    std::vector<double> truth(size_t(n * 3));
    Index localFrames = 0, regionHits = 0, regionMisses = 0;
    double fraction = 0;
    for (Index f = 0; f < 40; ++f) {
        novel.evaluateAll(f, truth.data());
        const Collected& l = local[size_t(f)];
        const Collected& w = whole[size_t(f)];
        EXPECT_EQ(l.state, w.state);  // the whole-frame decision is the same
        EXPECT_LE(maxPointError(l.values, truth), kTolerance) << "frame " << f;
        if (l.state == CacheState::Hit) {
            EXPECT_EQ(l.values, w.values);  // a global hit is reconstructed exactly as before
            continue;
        }
        EXPECT_EQ(w.pointsEvaluated, n);
        localFrames += l.local;
        fraction += double(l.pointsEvaluated) / double(n);
        for (const CacheState s : l.regions) (s == CacheState::Hit ? regionHits : regionMisses) += 1;
    }
    // The novel bump misses every frame as a whole, but only its own regions fail through.
    EXPECT_GE(localFrames, 30);
    EXPECT_GT(regionHits, regionMisses);
    // Some regions of this sheet have few keys and tight thresholds, so more than the bump's
    // regions fail; still well under the whole frame.
    EXPECT_LE(fraction / double(std::max<Index>(1, localFrames)), 0.7);
    EXPECT_LT(localEvaluations, wholeEvaluations);
}

// A local frame evaluates the union of its failing regions' fail sets, each point once (bands
// shared by two failing regions are not posed twice), and hands those full values to the sink.
TEST(LocalFailThrough, EachFailingPointIsEvaluatedOnceAndItsFullValueReachesTheSink) {
    const Model& model = trainedModel();
    const LocalSurface novel(40, true, 1000.0);
    Index evaluated = 0;
    const auto local = runNovel(model, true, 2, &evaluated);
    const Index n = model.points, k = model.keyCount();
    const Index e = Index(model.regions->extraKeyPoints.size());
    ASSERT_GT(e, 0);  // the model has region keys
    Index expected = 0, localFrames = 0, framesWithSharedBands = 0;
    const pmsc::LocalRegions& regions = *model.regions;
    for (Index f = 0; f < Index(local.size()); ++f) {
        const Collected& c = local[size_t(f)];
        expected += k;                             // every frame evaluates its keys
        if (c.state == CacheState::Hit) continue;  // region keys only for frames that do not hit
        expected += e;
        if (!c.local) {
            expected += n - k;  // whole-frame fail-through: the rest of the points
            continue;
        }
        ++localFrames;
        expected += c.pointsEvaluated;
        std::vector<Index> want;
        for (Index p = 0; p < n; ++p)
            if (c.weights[size_t(p)] > 0) want.push_back(p);
        EXPECT_EQ(c.fullPoints, want) << "frame " << f;
        EXPECT_EQ(Index(c.fullPoints.size()), c.pointsEvaluated);
        std::vector<double> truth(c.fullPoints.size() * 3);
        novel.evaluate(f, c.fullPoints, truth.data());
        EXPECT_EQ(c.fullValues, truth) << "frame " << f;
        // Frames where failing regions' fail sets overlap: separate per-region branches would pose
        // the shared points twice.
        Index sum = 0;
        for (Index r = 0; r < regions.regionCount(); ++r)
            if (c.regions[size_t(r)] != CacheState::Hit) sum += Index(regions.failSet(r).size());
        framesWithSharedBands += sum > c.pointsEvaluated;
    }
    EXPECT_GE(localFrames, 30);
    EXPECT_GT(framesWithSharedBands, 0);  // the test exercises the overlap
    EXPECT_EQ(evaluated, expected);
}

/// The novel sheet, except that evaluating the region keys throws.
class RegionKeysFail : public pmsc::PointEvaluator {
public:
    RegionKeysFail(const LocalSurface& inner, std::vector<Index> regionKeys)
        : inner_(inner), keys_(std::move(regionKeys)) {}
    std::string name() const override { return "region-keys-fail"; }
    Index pointCount() const override { return inner_.pointCount(); }
    Index channelCount() const override { return 3; }
    Index frameCount() const override { return inner_.frameCount(); }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override {
        if (std::equal(points.begin(), points.end(), keys_.begin(), keys_.end()))
            throw std::runtime_error("no region keys today");
        inner_.evaluate(frame, points, out);
    }

private:
    const LocalSurface& inner_;
    std::vector<Index> keys_;
};

TEST(LocalFailThrough, ARegionKeyFailureFailsOnlyTheFramesThatNeedThem) {
    const Model& model = trainedModel();
    const LocalSurface novel(40, true, 1000.0);
    const RegionKeysFail evaluator(novel, model.regions->extraKeyPoints);
    pmsc::engine::EngineOptions o;
    o.threads = 2;
    o.failurePolicy = pmsc::engine::FailurePolicy::MarkFailedAndContinue;
    pmsc::engine::Engine engine(model, evaluator, o);
    struct Sink : pmsc::engine::FrameSink {
        Index failed = 0, hits = 0;
        void write(const pmsc::engine::FrameResult& r) override {
            if (r.failed) {
                ++failed;
                EXPECT_NE(r.error.find("region keys"), std::string::npos) << r.error;
                EXPECT_NE(r.error.find("no region keys today"), std::string::npos) << r.error;
            } else {
                EXPECT_EQ(r.state, CacheState::Hit);  // only a hit never asks for the region keys
                ++hits;
            }
        }
    } sink;
    engine.run({0, novel.frameCount(), 1}, sink);
    EXPECT_GE(sink.failed, 30);
    EXPECT_EQ(sink.failed + sink.hits, novel.frameCount());
}

TEST(LocalFailThrough, BitIdenticalAtAnyThreadCount) {
    const Model& model = trainedModel();
    const auto one = runNovel(model, true, 1);
    const auto four = runNovel(model, true, 4);
    ASSERT_EQ(one.size(), four.size());
    for (size_t f = 0; f < one.size(); ++f) {
        EXPECT_EQ(one[f].values, four[f].values) << f;
        EXPECT_EQ(one[f].weights, four[f].weights) << f;
    }
}

/// The novel sheet declaring that every call pays a set-up (FailThroughShape::callSetUp); counts
/// the calls of each frame.
class NovelWithSetUp : public LocalSurface {
public:
    NovelWithSetUp() : LocalSurface(40, true, 1000.0) {}
    FailThroughShape failThroughShape() const override {
        FailThroughShape shape;
        shape.callSetUp = true;
        return shape;
    }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            ++calls_[frame];
        }
        LocalSurface::evaluate(frame, points, out);
    }
    std::map<Index, Index> calls() const {
        std::lock_guard<std::mutex> lock(mutex_);
        return calls_;
    }

private:
    mutable std::mutex mutex_;
    mutable std::map<Index, Index> calls_;
};

TEST(LocalFailThrough, AnEvaluatorWhoseCallsPayASetUpIsAskedOncePerThreadForALocalFrame) {
    const Model& model = trainedModel();
    const auto plain = runNovel(model, true, 2);
    for (const int threads : {1, 2}) {
        const NovelWithSetUp novel;
        pmsc::engine::EngineOptions o;
        o.threads = threads;
        pmsc::engine::Engine engine(model, novel, o);
        CollectingSink sink;
        engine.run({0, novel.frameCount(), 1}, sink);
        ASSERT_EQ(sink.frames.size(), plain.size());
        const auto calls = novel.calls();
        Index localFrames = 0;
        for (size_t f = 0; f < plain.size(); ++f) {
            EXPECT_EQ(sink.frames[f].values, plain[f].values) << f;
            if (!sink.frames[f].local) continue;
            ++localFrames;
            // The keys, the region keys, then at most one piece per thread.
            EXPECT_LE(calls.at(Index(f)), 2 + threads) << "frame " << f;
        }
        EXPECT_GE(localFrames, 30);
    }
}

/// Largest change of the point error between grid neighbours, across region borders and inside regions.
struct Steps {
    double border = 0, inside = 0;
};
/// Border pairs count only where a region that blends or misses meets another region: between two
/// regions that hit, each has its own block projection and feathering does not apply.
Steps errorSteps(const Model& model, const std::vector<CacheState>& states, const std::vector<double>& out,
                 const std::vector<double>& truth) {
    const auto regionOf = model.regions->regionOfPoints(model.points);
    const auto error = [&](Index p) {
        return std::hypot(out[3 * p] - truth[3 * p], out[3 * p + 1] - truth[3 * p + 1],
                          out[3 * p + 2] - truth[3 * p + 2]);
    };
    Steps s;
    for (Index p = 0; p < model.points; ++p) {
        for (const Index q : {p + 1, p + 40}) {
            if (q >= model.points || (q == p + 1 && q % 40 == 0)) continue;
            const double step = std::abs(error(p) - error(q));
            const Index a = regionOf[size_t(p)], b = regionOf[size_t(q)];
            if (a == b) {
                s.inside = std::max(s.inside, step);
            } else if (states[size_t(a)] != CacheState::Hit || states[size_t(b)] != CacheState::Hit) {
                s.border = std::max(s.border, step);
            }
        }
    }
    return s;
}

TEST(LocalFailThrough, FeatheredBordersHaveNoJumpLargerThanInsideRegions) {
    const Model& model = trainedModel();
    const LocalSurface novel(40, true, 1000.0);
    const auto frames = runNovel(model, true, 2);
    // The same frames without feathering: a region that misses next to one that hits jumps from
    // the full result to PM at the border (this shows the check can fail).
    Model hard = model;
    hard.regions->featherStart.assign(size_t(model.points) + 1, 0);
    hard.regions->featherRegion.clear();
    hard.regions->featherFactor.clear();
    const auto unfeathered = runNovel(hard, true, 2);
    std::vector<double> truth(size_t(model.points * 3));
    Index checked = 0, hardJumps = 0;
    for (size_t f = 0; f < frames.size(); ++f) {
        if (!frames[f].local) continue;
        const auto& states = frames[f].regions;
        if (std::count(states.begin(), states.end(), CacheState::Hit) == 0) continue;
        novel.evaluateAll(Index(f), truth.data());
        const Steps s = errorSteps(model, states, frames[f].values, truth);
        // Known limit (docs/local-fail-through.md): next to a region that blends, the two sides' block
        // projections differ, so the step across the border can exceed the largest step inside a region by a
        // little (1.5x at most on this sheet); without feathering it is many times larger.
        EXPECT_LE(s.border, 2.0 * s.inside + 1e-12) << "frame " << f;
        ++checked;
        if (unfeathered[f].local) {
            const Steps h = errorSteps(model, unfeathered[f].regions, unfeathered[f].values, truth);
            hardJumps += h.border > s.border;  // feathering made this frame's border step smaller
        }
    }
    EXPECT_GT(checked, 10);
    EXPECT_GT(hardJumps, 0);
}

TEST(LocalFailThrough, AVersion1ModelIsRoutedAsBefore) {
    Model v1 = trainedModel();
    v1.regions.reset();
    const auto frames = runNovel(v1, true, 2);
    for (const auto& f : frames) {
        EXPECT_FALSE(f.local);
        EXPECT_TRUE(f.regions.empty());
        EXPECT_EQ(f.pointsEvaluated, f.state == CacheState::Hit ? 0 : v1.points);
    }
}

}  // namespace
