#include "examples/face/FaceDemo.h"
#include "examples/face/FaceDemoSteps.h"
#include "examples/face/FaceLocalReport.h"

#include "engine/Engine.h"
#include "evaluators/face/FaceEvaluator.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/HitCheck.h"
#include "pmsc/Metrics.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/SoftCache.h"
#include "pmsc/Training.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>

namespace pmsc::face {

FaceDemoOptions FaceDemoOptions::quickOptions() {
    FaceDemoOptions o;
    o.quick = true;
    o.sequences = 9;
    o.novelSequences = 2;
    o.minFrames = 26;
    o.maxFrames = 36;
    o.timingFrames = 8;
    o.regions = 8;
    o.featherPercent = 3;
    o.mixedSequences = 1;
    o.localFailThroughReport = true;
    return o;
}

namespace {

/// The basis a hit reconstructs from. A posed face leaves for the renderer as float32 points (USD's
/// point3f, Alembic's P, Blender's vertex coordinates), so a hit reads the float copy, as the
/// Cornell and volume demos do for their float grids: half the bytes of the reconstruction, the
/// largest part of a hit after the rig. Its rounding is about 1e-7 of a coordinate, five orders
/// under T (1% of the head's 47.5-unit diagonal); projection, key errors and the check stay in
/// double.
constexpr BasisPrecision kFaceBasisPrecision = BasisPrecision::Single;

using namespace demo;

// The engine's consumer: records each frame's decision and keeps the output of a few frames.
class DemoSink : public engine::FrameSink {
public:
    DemoSink(std::map<Index, FrameRecord*> records, std::vector<Index> keep)
        : records_(std::move(records)), keep_(std::move(keep)) {}
    void write(const engine::FrameResult& r) override {
        if (r.failed)
            throw EvaluatorError("face demo: frame " + std::to_string(r.frame) + " failed: " + r.error);
        FrameRecord* rec = records_.at(r.frame);
        rec->engineSeen = true;
        rec->engineAgrees = r.state == rec->state &&
                            std::memcmp(&r.keyError, &rec->keyRms, sizeof(double)) == 0 &&
                            r.weight == rec->weight;
        if (std::find(keep_.begin(), keep_.end(), r.frame) != keep_.end()) {
            kept_[r.frame].assign(r.values.begin(), r.values.end());
        }
    }
    /// The outputs of the frames to keep, moved out of the sink.
    std::map<Index, std::vector<double>> takeKept() { return std::move(kept_); }

private:
    std::map<Index, FrameRecord*> records_;
    std::vector<Index> keep_;
    std::map<Index, std::vector<double>> kept_;
};

// --- the steps of runFaceDemo, in the order it runs them ---------------------------------------

void checkOptions(const FaceDemoOptions& options) {
    if (options.outDir.empty()) throw InputError("demo face: --out is required");
    if (options.dataDir.empty()) throw InputError("demo face: --data is required");
    if (options.sequences < 2 || options.novelSequences < 1 || options.minFrames < 8 ||
        options.maxFrames < options.minFrames ||
        !(options.trainingFraction > 0 && options.trainingFraction < 1) || options.basis < 1 ||
        options.maxKeys < 1 || options.maxKeys > 170 || !(options.tolerancePercent > 0) ||
        options.timingFrames < 1 || options.threads < 0 ||
        !(options.featherPercent >= 0 && options.featherPercent < 50) ||
        !(options.maxLocalFraction > 0 && options.maxLocalFraction <= 1) || options.mixedSequences < 0 ||
        options.regionStride < 1) {
        throw InputError(
            "demo face: options out of range (sequences >= 2, novel >= 1, 8 <= minFrames <= maxFrames, "
            "0 < training fraction < 1, basis >= 1, 1 <= keys <= 170, tolerance > 0, threads >= 0, "
            "0 <= feather < 50, 0 < largest local fraction <= 1, mixed >= 0, region stride >= 1)");
    }
}

FaceAnimationOptions animationOptionsFor(const FaceDemoOptions& options) {
    FaceAnimationOptions animationOptions;
    animationOptions.seed = options.seed;
    animationOptions.sequences = options.sequences;
    animationOptions.novelSequences = options.novelSequences;
    animationOptions.minFrames = options.minFrames;
    animationOptions.maxFrames = options.maxFrames;
    animationOptions.mixedSequences = options.mixedSequences;
    if (options.quick) {
        animationOptions.mixedMinFrames = 96;
        animationOptions.mixedMaxFrames = 96;
    }
    return animationOptions;
}

FaceScene loadFaceScene(const DemoRun& run) {
    run.setup.progress("load", 0, 1);
    const IctFace face = loadIctFace(run.options.dataDir);
    auto rig = std::make_shared<const FaceRig>(face);
    auto mesh = std::make_shared<const ObjMesh>(face.neutral);
    const FaceAnimationOptions animationOptions = animationOptionsFor(run.options);
    auto animation = std::make_shared<const FaceAnimation>(FaceAnimation::generate(animationOptions));
    const double diagonal = face.boundingBoxDiagonal();
    return FaceScene{rig,
                     mesh,
                     animationOptions,
                     animation,
                     FaceEvaluator(rig, animation, mesh),
                     rig->pointCount(),
                     diagonal,
                     diagonal / 100.0};
}

SequenceSplit splitSequences(const FaceDemoOptions& options, const FaceAnimation& animation) {
    SequenceSplit split;
    animation.splitOrdinary(options.trainingFraction, options.seed + 4, split.trainingSeqs,
                            split.validationSeqs);
    for (Index s = 0; s < static_cast<Index>(animation.sequences().size()); ++s) {
        if (animation.sequences()[s].novel) split.novelSeqs.push_back(s);
    }
    split.trainingFrames = animation.framesOf(split.trainingSeqs);
    return split;
}

FrameSet poseTrainingFrames(const DemoRun& run, const FaceScene& scene,
                            const std::vector<Index>& trainingFrames) {
    const DemoClock::time_point t = DemoClock::now();
    FrameSet training(static_cast<Index>(trainingFrames.size()), scene.n, 3);
    std::atomic<Index> posed{0};
    run.setup.arena.execute([&] {
        tbb::parallel_for(size_t{0}, trainingFrames.size(), [&](size_t i) {
            scene.evaluator.evaluateAll(trainingFrames[i], training.frame(static_cast<Index>(i)));
            ++posed;
        });
    });
    run.setup.progress("pose training", static_cast<double>(posed),
                       static_cast<double>(trainingFrames.size()));
    run.setup.lap("pose_training", t);
    return training;
}

// pmsc::train with the Multi-PIE 68 fiducials among the keys and a tolerance of the options' % of
// the head diagonal.
TrainedModel trainModel(const DemoRun& run, const FrameSet& training, double percent) {
    const FaceDemoOptions& options = run.options;
    const DemoClock::time_point t = DemoClock::now();
    TrainedModel trained;
    TrainingOptions to;
    to.basis = options.basis;
    to.maxKeys = options.maxKeys;
    to.fiducials.assign(IctFace::multiPie68().begin(), IctFace::multiPie68().end());
    to.tolerance = options.tolerancePercent * percent;
    if (options.keyErrorNorm) to.keyErrorNorm = *options.keyErrorNorm;
    if (options.calibrationRule) to.calibrationRule = *options.calibrationRule;
    to.regions.count = options.regions;
    to.regions.featherFraction = options.featherPercent / 100.0;
    to.regions.frameStride = options.regionStride;
    to.regions.maxLocalFraction = options.maxLocalFraction;
    to.progress = [&](std::string_view stage, double done, double total) {
        return !options.progress ||
               options.progress(std::string("train: ") + std::string(stage), done, total);
    };
    run.setup.arena.execute([&] { trained.model = train(training, to, &trained.report); });
    run.setup.lap("train", t);
    return trained;
}

// One record per frame of the validation sequences, then of the novel ones.
std::vector<FrameRecord> testFrameRecords(const FaceAnimation& animation, const SequenceSplit& split) {
    std::vector<FrameRecord> records;
    for (const auto* set : {&split.validationSeqs, &split.novelSeqs}) {
        for (Index s : *set) {
            const FaceSequence& seq = animation.sequences()[s];
            for (Index f = 0; f < seq.frameCount; ++f) {
                FrameRecord r;
                r.frame = seq.firstFrame + f;
                r.sequence = s;
                r.novel = seq.novel;
                records.push_back(r);
            }
        }
    }
    return records;
}

// Ground truth: every test frame posed fully; PM and the soft cache evaluated on it.
void measureAgainstFullPoses(const DemoRun& run, const FaceScene& scene, const Model& model,
                             const PointMultiplier& pm, const SoftCachePolicy& policy,
                             std::vector<FrameRecord>& records) {
    const Index n = scene.n;
    std::atomic<Index> done{0};
    const Index keyCount = model.keyCount();
    run.setup.arena.execute([&] {
        tbb::parallel_for(size_t{0}, records.size(), [&](size_t i) {
            FrameRecord& r = records[i];
            std::vector<double> full(static_cast<size_t>(3 * n)), rec(static_cast<size_t>(3 * n));
            std::vector<double> keys(static_cast<size_t>(3 * keyCount)),
                coords(static_cast<size_t>(model.coordCount()));
            scene.evaluator.evaluateAll(r.frame, full.data());
            for (Index k = 0; k < keyCount; ++k) {
                for (int c = 0; c < 3; ++c) keys[3 * k + c] = full[3 * model.keyPoints[k] + c];
            }
            pm.project(keys.data(), coords.data());
            r.keyRms = pm.keyError(keys.data(), coords.data());
            pm.reconstruct(coords.data(), rec.data());
            const CacheDecision d = policy.decide(r.keyRms);
            r.state = d.state;
            r.weight = d.weight;
            r.pmMax = maxPointError(rec.data(), full.data(), n);
            // soft = (1 - w) pm + w full point by point, w raised where PM is over the tolerance.
            r.softMax = blendedError(d.weight, r.pmMax, model.tolerance);
            const Index k = ++done;
            if (k % 32 == 0)
                run.setup.progress("ground truth", static_cast<double>(k),
                                   static_cast<double>(records.size()));
        });
    });
}

TestFrames pickShownFrames(const std::vector<FrameRecord>& records) {
    TestFrames sets;
    for (const FrameRecord& r : records) (r.novel ? sets.novel : sets.validation).push_back(&r);
    auto byError = [](const FrameRecord* a, const FrameRecord* b) {
        return a->pmMax < b->pmMax || (a->pmMax == b->pmMax && a->frame < b->frame);
    };
    std::vector<const FrameRecord*> sortedVal = sets.validation, sortedNovel = sets.novel;
    std::sort(sortedVal.begin(), sortedVal.end(), byError);
    std::sort(sortedNovel.begin(), sortedNovel.end(), byError);
    sets.shown = {{"worst", sortedVal.back()},
                  {"typical", sortedVal[sortedVal.size() / 2]},
                  {"novel", sortedNovel[sortedNovel.size() / 2]}};
    return sets;
}

// The engine: the test sequences through the soft cache, the rig as evaluator; each frame's
// decision checked against the direct one in `records`.
EngineTotals runTestSequencesThroughEngine(const DemoRun& run, const FaceScene& scene, const Model& model,
                                           const SequenceSplit& split, std::vector<FrameRecord>& records,
                                           const TestFrames& sets) {
    const DemoClock::time_point t = DemoClock::now();
    std::map<Index, FrameRecord*> byFrame;
    for (FrameRecord& r : records) byFrame[r.frame] = &r;
    std::vector<Index> keep;
    for (const auto& s : sets.shown) keep.push_back(s.second->frame);
    DemoSink sink(byFrame, keep);
    engine::EngineOptions eo;
    eo.threads = run.options.threads;
    // The rig shares work between points (relax rings, contact inputs): a miss is posed whole.
    eo.wholeFrameFailThrough = true;
    // The decisions checked below are the whole frame's: the whole-frame soft cache (local fail-through
    // is measured on its own afterwards).
    eo.localFailThrough = false;
    eo.basisPrecision = kFaceBasisPrecision;
    engine::Engine engine(model, scene.evaluator, eo);
    EngineTotals totals;
    Index sequencesDone = 0;
    for (const auto* set : {&split.validationSeqs, &split.novelSeqs}) {
        const int which = set == &split.validationSeqs ? 0 : 1;
        for (Index s : *set) {
            const FaceSequence& seq = scene.animation->sequences()[s];
            const engine::RunStats stats = engine.run({seq.firstFrame, seq.frameCount, 1}, sink);
            totals.hits[which] += stats.hits;
            totals.blends[which] += stats.blends;
            totals.misses[which] += stats.misses;
            totals.frames[which] += stats.framesDelivered;
            totals.wall[which] += stats.wallSeconds;
            if (totals.runs.size() < 2 || s == set->back()) {  // a sample of per-run stats, not all of them
                nlohmann::json j = nlohmann::json::parse(stats.toJson());
                j["sequence"] = seq.name;
                totals.runs.push_back(j);
            }
            run.setup.progress("engine", static_cast<double>(++sequencesDone),
                               static_cast<double>(split.validationSeqs.size() + split.novelSeqs.size()));
        }
    }
    run.setup.lap("engine", t);
    for (const FrameRecord& r : records) {
        if (!r.engineSeen)
            ++totals.unseen;
        else if (!r.engineAgrees)
            ++totals.disagreements;
    }
    totals.kept = sink.takeKept();
    return totals;
}

// Local fail-through: validation sample, novel and mixed sets, both ways.
nlohmann::json measureLocalFailThrough(const DemoRun& run, const FaceScene& scene, const Model& model,
                                       const SequenceSplit& split) {
    const DemoClock::time_point t = DemoClock::now();
    nlohmann::json local = localFailThroughSets(
        model, scene.evaluator, *scene.animation, split.validationSeqs, split.novelSeqs, scene.percent,
        run.options.threads,
        [&run](std::string_view stage, double done, double total) { run.setup.progress(stage, done, total); },
        run.options.quick ? 24 : 0);
    run.setup.lap("local_fail_through", t);
    return local;
}

// A check's values at `points`: the sentinels' from `sentinelValues` (posed with the keys), the
// others posed in one call, as nodes::ErrorMonitor does.
void checkValuesOf(const FaceEvaluator& evaluator, Index frame, const HitCheck& check,
                   const double* sentinelValues, std::span<const Index> points, double* out) {
    const std::vector<size_t> othersAt = check.copySentinelValues(points, sentinelValues, out);
    if (othersAt.empty()) return;
    std::vector<Index> others;
    for (const size_t i : othersAt) others.push_back(points[i]);
    std::vector<double> posed(3 * others.size());
    evaluator.evaluate(frame, others, posed.data());
    for (size_t j = 0; j < others.size(); ++j) std::copy_n(posed.data() + 3 * j, 3, out + 3 * othersAt[j]);
}

// Timing: full pose vs PMSC, one frame at a time, one thread, interleaved, on validation frames
// spread over the set. A hit is timed as the engine runs it for this rig (a whole-frame evaluator:
// engine/Engine.cpp, sentinelsWithTheKeys): its keys and sentinels posed in one call, projection,
// the check (posing any key neighbours it adds, and the comparison), reconstruction. The keys
// alone are posed last, for the speed of a hit without the check.
PoseTimings timeFullPoseAgainstPmsc(const DemoRun& run, const FaceScene& scene, const Model& model,
                                    const PointMultiplier& pm,
                                    const std::vector<const FrameRecord*>& validation) {
    const DemoClock::time_point t = DemoClock::now();
    PoseTimings pt;
    const Index timed = std::min<Index>(run.options.timingFrames, static_cast<Index>(validation.size()));
    pt.timed = timed;
    const FaceEvaluator& evaluator = scene.evaluator;
    const HitCheck check(model, pm);
    std::vector<Index> posed = model.keyPoints;  // the keys, then the sentinels
    posed.insert(posed.end(), check.sentinels().begin(), check.sentinels().end());
    const size_t k3 = static_cast<size_t>(3 * model.keyCount());
    std::vector<double> full(static_cast<size_t>(3 * scene.n)), rec(static_cast<size_t>(3 * scene.n));
    std::vector<double> values(3 * posed.size()), keys(k3), coords(static_cast<size_t>(model.coordCount()));
    evaluator.evaluate(validation.front()->frame, posed, values.data());  // warm the plan caches
    evaluator.evaluate(validation.front()->frame, model.keyPoints, keys.data());
    std::vector<double> checkValues;
    for (Index i = 0; i < timed; ++i) {
        const Index frame =
            validation[static_cast<size_t>(i * static_cast<Index>(validation.size()) / timed)]->frame;
        double c0 = threadCpuSeconds();
        DemoClock::time_point w0 = DemoClock::now();
        evaluator.evaluateAll(frame, full.data());
        pt.cpuFull += threadCpuSeconds() - c0;
        pt.wallFull += secondsSince(w0);
        c0 = threadCpuSeconds();
        w0 = DemoClock::now();
        evaluator.evaluate(frame, posed, values.data());
        pt.cpuPosing += threadCpuSeconds() - c0;
        pt.wallPosing += secondsSince(w0);
        c0 = threadCpuSeconds();
        w0 = DemoClock::now();
        pm.project(values.data(), coords.data());
        PredictedParts parts;
        volatile double e = pm.keyError(values.data(), coords.data(), &parts);
        (void)e;
        pt.cpuProject += threadCpuSeconds() - c0;
        pt.wallProject += secondsSince(w0);
        c0 = threadCpuSeconds();
        w0 = DemoClock::now();
        if (check.needed({CacheState::Hit, 0.0}, parts)) {
            const std::vector<Index> points = check.points(values.data(), coords.data(), parts);
            checkValues.resize(points.size() * 3);
            checkValuesOf(evaluator, frame, check, values.data() + k3, points, checkValues.data());
            volatile bool passes = check.passes(coords.data(), points, checkValues.data());
            (void)passes;
            pt.checkPoints += static_cast<double>(points.size());
        }
        pt.cpuCheck += threadCpuSeconds() - c0;
        pt.wallCheck += secondsSince(w0);
        c0 = threadCpuSeconds();
        w0 = DemoClock::now();
        pm.reconstruct(coords.data(), rec.data());
        pt.cpuReconstruct += threadCpuSeconds() - c0;
        pt.wallReconstruct += secondsSince(w0);
        c0 = threadCpuSeconds();
        evaluator.evaluate(frame, model.keyPoints, keys.data());
        pt.cpuKeys += threadCpuSeconds() - c0;
        run.setup.progress("timing", static_cast<double>(i + 1), static_cast<double>(timed));
    }
    run.setup.lap("timing", t);
    return pt;
}

}  // namespace

nlohmann::json runFaceDemo(const FaceDemoOptions& options) {
    const DemoClock::time_point start = DemoClock::now();
    checkOptions(options);
    DemoSetup setup(options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency(),
                    options.progress, "demo face", start);
    nlohmann::json report;
    const DemoRun run{options, setup, options.outDir + "/"};

    DemoClock::time_point t = DemoClock::now();
    const FaceScene scene = loadFaceScene(run);
    // The output folder only once the input is known to be good: a bad --data leaves nothing.
    examples::createOutputFolder(options.outDir, examples::FolderErrorWording::OutputFolder);
    setup.lap("load_and_rig", t);
    const SequenceSplit split = splitSequences(options, *scene.animation);

    const TrainedModel trained =
        trainModel(run, poseTrainingFrames(run, scene, split.trainingFrames), scene.percent);
    const Model& model = trained.model;
    const PointMultiplier pm(model, kFaceBasisPrecision);
    const SoftCachePolicy policy(model.epsMin, model.epsMax);

    t = DemoClock::now();
    std::vector<FrameRecord> records = testFrameRecords(*scene.animation, split);
    measureAgainstFullPoses(run, scene, model, pm, policy, records);
    setup.lap("ground_truth", t);
    const TestFrames sets = pickShownFrames(records);

    const EngineTotals engine = runTestSequencesThroughEngine(run, scene, model, split, records, sets);
    if (model.regions && options.localFailThroughReport)
        report["local_fail_through"] = measureLocalFailThrough(run, scene, model, split);
    const PoseTimings poseTimings = timeFullPoseAgainstPmsc(run, scene, model, pm, sets.validation);
    const WrittenFiles written = writeFiles(run, scene, model, pm, records, sets, engine);

    reportSetUp(report, options, scene, model, split, sets);
    reportTiming(report, poseTimings);
    reportKeyPoints(report, *scene.rig, model);
    reportAccuracy(report, options, scene, trained, records, sets, engine);
    report["shown_frames"] = written.shown;
    report["files"] = written.files;
    report["seconds"] = setup.finish();
    writeFileAtomically(run.out + "report.json", report.dump(2) + "\n");
    return report;
}

}  // namespace pmsc::face
