#include "examples/face/FaceDemo.h"
#include "examples/face/FaceLocalReport.h"

#include "engine/Engine.h"
#include "examples/face/FaceEvaluator.h"
#include "examples/face/FaceRenderer.h"
#include "examples/face/ObjWriter.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/Metrics.h"
#include "pmsc/ModelIO.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/SoftCache.h"
#include "pmsc/Training.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <numeric>
#include <sstream>

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
    return o;
}

namespace {

using Clock = std::chrono::steady_clock;

double seconds(Clock::time_point since) {
    return std::chrono::duration<double>(Clock::now() - since).count();
}

// CPU time of the calling thread. Timings are taken on one thread, one frame at a time, so this
// is the work a frame costs, unaffected by other processes time-slicing a shared machine.
double threadCpuSeconds() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

nlohmann::json summary(const std::vector<double>& v) {
    return {{"p50", percentile(v, 0.5)},
            {"p99", percentile(v, 0.99)},
            {"p995", percentile(v, 0.995)},
            {"max", v.empty() ? 0.0 : *std::max_element(v.begin(), v.end())}};
}

// What the demo knows about one test frame.
struct FrameRecord {
    Index frame = 0;
    Index sequence = 0;
    bool novel = false;
    double keyRms = 0;
    CacheState state = CacheState::Hit;
    double weight = 0;
    double pmMax = 0;    // largest point error of PM vs the full pose (model units)
    double softMax = 0;  // same for the soft-cached result
    // From the engine run:
    bool engineSeen = false;
    bool engineAgrees = false;
};

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
                            std::memcmp(&r.keyRmsError, &rec->keyRms, sizeof(double)) == 0 &&
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

const char* stateName(CacheState s) {
    return s == CacheState::Hit ? "hit" : s == CacheState::Blend ? "blend" : "miss";
}

// --- the steps of runFaceDemo, in the order it runs them ---------------------------------------

// What every step needs: the options, the progress hook, the worker arena, the timings.
struct DemoRun {
    const FaceDemoOptions& options;
    tbb::task_arena& arena;
    nlohmann::json& timings;  // report.json's "seconds"
    std::string out;          // the output folder with a trailing '/'

    // Reports progress; throws Cancelled when the hook asks to stop.
    void step(std::string_view stage, double done, double total) const {
        if (options.progress && !options.progress(stage, done, total)) throw Cancelled("demo face");
    }
};

void checkOptions(const FaceDemoOptions& options) {
    if (options.outDir.empty()) throw InputError("demo face: --out is required");
    if (options.dataDir.empty()) throw InputError("demo face: --data is required");
    if (options.sequences < 2 || options.novelSequences < 1 || options.minFrames < 8 ||
        options.maxFrames < options.minFrames ||
        !(options.trainingFraction > 0 && options.trainingFraction < 1) || options.basis < 1 ||
        options.maxKeys < 1 || options.maxKeys > 170 || !(options.tolerancePercent > 0) ||
        options.timingFrames < 1 || options.threads < 0 || !(options.featherPercent >= 0 && options.featherPercent < 50) ||
        !(options.maxLocalFraction > 0 && options.maxLocalFraction <= 1) || options.mixedSequences < 0) {
        throw InputError(
            "demo face: options out of range (sequences >= 2, novel >= 1, 8 <= minFrames <= maxFrames, "
            "0 < training fraction < 1, basis >= 1, 1 <= keys <= 170, tolerance > 0, threads >= 0, "
            "0 <= feather < 50, 0 < largest local fraction <= 1, mixed >= 0)");
    }
}

// The face, the rig, the animation and the rig as an evaluator.
struct FaceScene {
    std::shared_ptr<const FaceRig> rig;
    std::shared_ptr<const ObjMesh> mesh;
    FaceAnimationOptions animationOptions;
    std::shared_ptr<const FaceAnimation> animation;
    FaceEvaluator evaluator;
    Index n = 0;          // points
    double diagonal = 0;  // of the head's bounding box
    double percent = 0;   // model units per % of the head diagonal
};

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
    run.step("load", 0, 1);
    const IctFace face = loadIctFace(run.options.dataDir);
    auto rig = std::make_shared<const FaceRig>(face);
    auto mesh = std::make_shared<const ObjMesh>(face.neutral);
    const FaceAnimationOptions animationOptions = animationOptionsFor(run.options);
    auto animation = std::make_shared<const FaceAnimation>(FaceAnimation::generate(animationOptions));
    const double diagonal = face.boundingBoxDiagonal();
    return FaceScene{rig,      mesh, animationOptions, animation, FaceEvaluator(rig, animation, mesh),
                     rig->pointCount(), diagonal, diagonal / 100.0};
}

// The output folder only once the input is known to be good: a bad --data leaves nothing.
void createOutputFolder(const std::string& outDir) {
    namespace fs = std::filesystem;
    std::error_code ec;
    fs::create_directories(outDir, ec);
    if (ec || !fs::is_directory(outDir)) {
        throw IoError(outDir + ": cannot create the output folder: " + (ec ? ec.message() : "not a folder"));
    }
}

// Sequences (indices into the animation's) by use; the training sequences' frames.
struct SequenceSplit {
    std::vector<Index> trainingSeqs, validationSeqs, novelSeqs;
    std::vector<Index> trainingFrames;
};

SequenceSplit splitSequences(const FaceDemoOptions& options, const FaceAnimation& animation) {
    SequenceSplit split;
    animation.splitOrdinary(options.trainingFraction, options.seed + 4, split.trainingSeqs, split.validationSeqs);
    for (Index s = 0; s < static_cast<Index>(animation.sequences().size()); ++s) {
        if (animation.sequences()[s].novel) split.novelSeqs.push_back(s);
    }
    split.trainingFrames = animation.framesOf(split.trainingSeqs);
    return split;
}

FrameSet poseTrainingFrames(const DemoRun& run, const FaceScene& scene, const std::vector<Index>& trainingFrames) {
    const Clock::time_point t = Clock::now();
    FrameSet training(static_cast<Index>(trainingFrames.size()), scene.n, 3);
    std::atomic<Index> posed{0};
    run.arena.execute([&] {
        tbb::parallel_for(size_t{0}, trainingFrames.size(), [&](size_t i) {
            scene.evaluator.evaluateAll(trainingFrames[i], training.frame(static_cast<Index>(i)));
            ++posed;
        });
    });
    run.step("pose training", static_cast<double>(posed), static_cast<double>(trainingFrames.size()));
    run.timings["pose_training"] = seconds(t);
    return training;
}

struct TrainedModel {
    Model model;
    TrainingReport report;
};

// pmsc::train with the Multi-PIE 68 fiducials among the keys and a tolerance of the options' % of
// the head diagonal.
TrainedModel trainModel(const DemoRun& run, const FrameSet& training, double percent) {
    const FaceDemoOptions& options = run.options;
    const Clock::time_point t = Clock::now();
    TrainedModel trained;
    TrainingOptions to;
    to.basis = options.basis;
    to.maxKeys = options.maxKeys;
    to.fiducials.assign(IctFace::multiPie68().begin(), IctFace::multiPie68().end());
    to.tolerance = options.tolerancePercent * percent;
    to.regions.count = options.regions;
    to.regions.featherFraction = options.featherPercent / 100.0;
    to.regions.maxLocalFraction = options.maxLocalFraction;
    to.progress = [&](std::string_view stage, double done, double total) {
        return !options.progress || options.progress(std::string("train: ") + std::string(stage), done, total);
    };
    run.arena.execute([&] { trained.model = train(training, to, &trained.report); });
    run.timings["train"] = seconds(t);
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
    run.arena.execute([&] {
        tbb::parallel_for(size_t{0}, records.size(), [&](size_t i) {
            FrameRecord& r = records[i];
            std::vector<double> full(static_cast<size_t>(3 * n)), rec(static_cast<size_t>(3 * n));
            std::vector<double> keys(static_cast<size_t>(3 * keyCount)),
                coords(static_cast<size_t>(model.basisSize()));
            scene.evaluator.evaluateAll(r.frame, full.data());
            for (Index k = 0; k < keyCount; ++k) {
                for (int c = 0; c < 3; ++c) keys[3 * k + c] = full[3 * model.keyPoints[k] + c];
            }
            pm.project(keys.data(), coords.data());
            r.keyRms = pm.keyRmsError(keys.data(), coords.data());
            pm.reconstruct(coords.data(), rec.data());
            const CacheDecision d = policy.decide(r.keyRms);
            r.state = d.state;
            r.weight = d.weight;
            r.pmMax = maxPointError(rec.data(), full.data(), n);
            // soft = (1 - w) pm + w full, so its error is (1 - w) times PM's, point by point.
            r.softMax = (1.0 - d.weight) * r.pmMax;
            const Index k = ++done;
            if (k % 32 == 0) run.step("ground truth", static_cast<double>(k), static_cast<double>(records.size()));
        });
    });
}

// The test records by set, and the frames shown: the validation frame with the largest PM error
// (the paper's figure 4), the median validation frame, and the median novel frame.
struct TestFrames {
    std::vector<const FrameRecord*> validation, novel;
    std::vector<std::pair<std::string, const FrameRecord*>> shown;
};

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

// What the engine did with the test sequences; [0] validation, [1] novel.
struct EngineTotals {
    nlohmann::json runs = nlohmann::json::array();  // a sample of per-run stats
    Index hits[2] = {0, 0}, blends[2] = {0, 0}, misses[2] = {0, 0}, frames[2] = {0, 0};
    double wall[2] = {0, 0};
    Index disagreements = 0, unseen = 0;  // frames whose decision differs from the direct one; not delivered
    std::map<Index, std::vector<double>> kept;  // the output of the shown frames
};

// The engine: the test sequences through the soft cache, the rig as evaluator; each frame's
// decision checked against the direct one in `records`.
EngineTotals runTestSequencesThroughEngine(const DemoRun& run, const FaceScene& scene, const Model& model,
                                           const SequenceSplit& split, std::vector<FrameRecord>& records,
                                           const TestFrames& sets) {
    const Clock::time_point t = Clock::now();
    std::map<Index, FrameRecord*> byFrame;
    for (FrameRecord& r : records) byFrame[r.frame] = &r;
    std::vector<Index> keep;
    for (const auto& s : sets.shown) keep.push_back(s.second->frame);
    DemoSink sink(byFrame, keep);
    engine::EngineOptions eo;
    eo.threads = run.options.threads;
    // The rig shares work between points (relax rings, contact inputs): a miss is posed whole.
    eo.wholeFrameFailThrough = true;
    // The decisions checked below are the whole frame's: today's soft cache (local fail-through
    // is measured on its own afterwards).
    eo.localFailThrough = false;
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
            run.step("engine", static_cast<double>(++sequencesDone),
                     static_cast<double>(split.validationSeqs.size() + split.novelSeqs.size()));
        }
    }
    run.timings["engine"] = seconds(t);
    for (const FrameRecord& r : records) {
        if (!r.engineSeen)
            ++totals.unseen;
        else if (!r.engineAgrees)
            ++totals.disagreements;
    }
    totals.kept = sink.takeKept();
    return totals;
}

// Local fail-through (issue 9): validation sample, novel and mixed sets, both ways.
nlohmann::json measureLocalFailThrough(const DemoRun& run, const FaceScene& scene, const Model& model,
                                       const SequenceSplit& split) {
    const Clock::time_point t = Clock::now();
    nlohmann::json local = localFailThroughSets(
        model, scene.evaluator, *scene.animation, split.validationSeqs, split.novelSeqs, scene.percent,
        run.options.threads, [&run](std::string_view stage, double done, double total) { run.step(stage, done, total); },
        run.options.quick ? 24 : 0);
    run.timings["local_fail_through"] = seconds(t);
    return local;
}

// Seconds summed over the timed frames: thread CPU time and wall time.
struct PoseTimings {
    double cpuFull = 0, cpuKeys = 0, cpuProject = 0, cpuReconstruct = 0;
    double wallFull = 0, wallKeys = 0, wallProject = 0, wallReconstruct = 0;
    Index timed = 0;  // frames

    double fullSeconds() const { return cpuFull / static_cast<double>(timed); }
    double pmscSeconds() const { return (cpuKeys + cpuProject + cpuReconstruct) / static_cast<double>(timed); }
};

// Timing: full pose vs PMSC, one frame at a time, one thread, interleaved, on validation frames
// spread over the set.
PoseTimings timeFullPoseAgainstPmsc(const DemoRun& run, const FaceScene& scene, const Model& model,
                                    const PointMultiplier& pm, const std::vector<const FrameRecord*>& validation) {
    const Clock::time_point t = Clock::now();
    PoseTimings pt;
    const Index timed = std::min<Index>(run.options.timingFrames, static_cast<Index>(validation.size()));
    pt.timed = timed;
    const FaceEvaluator& evaluator = scene.evaluator;
    std::vector<double> full(static_cast<size_t>(3 * scene.n)), rec(static_cast<size_t>(3 * scene.n));
    std::vector<double> keys(static_cast<size_t>(3 * model.keyCount())), coords(static_cast<size_t>(model.basisSize()));
    evaluator.evaluate(validation.front()->frame, model.keyPoints, keys.data());  // warm the key plan cache
    for (Index i = 0; i < timed; ++i) {
        const Index frame = validation[static_cast<size_t>(i * static_cast<Index>(validation.size()) / timed)]->frame;
        double c0 = threadCpuSeconds();
        Clock::time_point w0 = Clock::now();
        evaluator.evaluateAll(frame, full.data());
        pt.cpuFull += threadCpuSeconds() - c0;
        pt.wallFull += seconds(w0);
        c0 = threadCpuSeconds();
        w0 = Clock::now();
        evaluator.evaluate(frame, model.keyPoints, keys.data());
        pt.cpuKeys += threadCpuSeconds() - c0;
        pt.wallKeys += seconds(w0);
        c0 = threadCpuSeconds();
        w0 = Clock::now();
        pm.project(keys.data(), coords.data());
        volatile double e = pm.keyRmsError(keys.data(), coords.data());
        (void)e;
        pt.cpuProject += threadCpuSeconds() - c0;
        pt.wallProject += seconds(w0);
        c0 = threadCpuSeconds();
        w0 = Clock::now();
        pm.reconstruct(coords.data(), rec.data());
        pt.cpuReconstruct += threadCpuSeconds() - c0;
        pt.wallReconstruct += seconds(w0);
        run.step("timing", static_cast<double>(i + 1), static_cast<double>(timed));
    }
    run.timings["timing"] = seconds(t);
    return pt;
}

// The renderer and the two views of the pictures written.
struct FacePictures {
    FaceRenderer renderer;
    OrthoView faceView{400, 480, Eigen::Vector3d(0, 0, 0), 19.0, 0.0};
    OrthoView mouthView{400, 260, Eigen::Vector3d(0, -3.6, 10), 55.0, 0.0};
};

// Per point: the error colour of `pose` against `full`.
std::vector<float> errorColours(const std::vector<double>& pose, const std::vector<double>& full, Index n,
                                double percent) {
    std::vector<float> colours(static_cast<size_t>(3 * n));
    for (Index p = 0; p < n; ++p) {
        const auto a = errorColour((Eigen::Vector3d(&pose[3 * p]) - Eigen::Vector3d(&full[3 * p])).norm(), percent);
        for (int c = 0; c < 3; ++c) colours[3 * p + c] = a[c];
    }
    return colours;
}

// Full | PM | soft-cached side by side, the face above the mouth, with a colour bar of 0 .. 1%
// of the head diagonal under the PM and soft-cache columns.
RgbImage comparisonSheet(const FacePictures& pics, const std::vector<double>* poses[3],
                         const std::vector<float>* colours[3]) {
    const OrthoView& faceView = pics.faceView;
    const OrthoView& mouthView = pics.mouthView;
    RgbImage sheet(3 * faceView.width, faceView.height + mouthView.height + 16, {20, 20, 24});
    for (int col = 0; col < 3; ++col) {
        sheet.paste(pics.renderer.render(*poses[col], *colours[col], faceView), col * faceView.width, 0);
        sheet.paste(pics.renderer.render(*poses[col], *colours[col], mouthView), col * mouthView.width,
                    faceView.height);
    }
    for (int x = 0; x < 2 * faceView.width; ++x) {
        const auto c = errorColour(static_cast<double>(x) / (2 * faceView.width - 1), 1.0);
        for (int y = 0; y < 12; ++y) {
            std::uint8_t* px = sheet.at(faceView.width + x, faceView.height + mouthView.height + 2 + y);
            for (int ch = 0; ch < 3; ++ch) px[ch] = static_cast<std::uint8_t>(255 * c[ch]);
        }
    }
    return sheet;
}

// LABEL_{full,pm,soft}.obj and LABEL.png of one shown frame; returns its entry of "shown_frames".
nlohmann::json writeShownFrame(const DemoRun& run, const FaceScene& scene, const Model& model,
                               const PointMultiplier& pm, const FacePictures& pics, const std::string& label,
                               const FrameRecord& record, const std::vector<double>& soft, nlohmann::json& files) {
    const Index n = scene.n;
    const std::string& out = run.out;
    std::vector<double> full(static_cast<size_t>(3 * n)), pmPose(static_cast<size_t>(3 * n));
    std::vector<double> keys(static_cast<size_t>(3 * model.keyCount())), coords(static_cast<size_t>(model.basisSize()));
    scene.evaluator.evaluateAll(record.frame, full.data());
    for (Index k = 0; k < model.keyCount(); ++k) {
        for (int c = 0; c < 3; ++c) keys[3 * k + c] = full[3 * model.keyPoints[k] + c];
    }
    pm.project(keys.data(), coords.data());
    pm.reconstruct(coords.data(), pmPose.data());
    const FaceSequence& seq = scene.animation->sequences()[record.sequence];
    const std::string frameName = seq.name + " frame " + std::to_string(record.frame - seq.firstFrame);
    writeObj(out + label + "_full.obj", *scene.mesh, full, "pmsc demo face: " + frameName + ", full pose");
    writeObj(out + label + "_pm.obj", *scene.mesh, pmPose, "pmsc demo face: " + frameName + ", point multiplication");
    writeObj(out + label + "_soft.obj", *scene.mesh, soft,
             std::string("pmsc demo face: ") + frameName + ", soft cache (" + stateName(record.state) + ")");
    const std::vector<float> grey(static_cast<size_t>(3 * n), 0.8f);
    const std::vector<float> pmColour = errorColours(pmPose, full, n, scene.percent);
    const std::vector<float> softColour = errorColours(soft, full, n, scene.percent);
    const std::vector<double>* poses[3] = {&full, &pmPose, &soft};
    const std::vector<float>* colours[3] = {&grey, &pmColour, &softColour};
    writePng(out + label + ".png", comparisonSheet(pics, poses, colours));
    for (const char* suffix : {"_full.obj", "_pm.obj", "_soft.obj", ".png"}) files.push_back(label + suffix);
    return {{"label", label},
            {"sequence", seq.name},
            {"frame", record.frame},
            {"state", stateName(record.state)},
            {"weight", record.weight},
            {"key_rms", record.keyRms},
            {"pm_max_error_pct_bbox", record.pmMax / scene.percent},
            {"soft_max_error_pct_bbox", record.softMax / scene.percent},
            {"engine_soft_max_error_pct_bbox", maxPointError(soft.data(), full.data(), n) / scene.percent}};
}

// keys.png: the neutral face with the key points (red) and the fiducials (blue).
void writeKeyPointsImage(const DemoRun& run, const FaceScene& scene, const Model& model, const FacePictures& pics) {
    const std::vector<double>& rest = scene.rig->restPositions();
    std::vector<float> colour(static_cast<size_t>(3 * scene.n), 0.8f);
    RgbImage image = pics.renderer.render(rest, colour, pics.faceView);
    pics.renderer.drawPoints(image, rest, model.keyPoints, pics.faceView, {230, 30, 30}, 2);
    const std::vector<Index> fiducials(IctFace::multiPie68().begin(), IctFace::multiPie68().end());
    pics.renderer.drawPoints(image, rest, fiducials, pics.faceView, {40, 110, 255}, 2);
    writePng(run.out + "keys.png", image);
}

// frames.csv: one line per test frame.
void writeFramesCsv(const DemoRun& run, const FaceScene& scene, const std::vector<FrameRecord>& records) {
    std::ostringstream csv;
    csv << "frame,sequence,set,key_rms,state,weight,pm_max_error_pct_bbox,soft_max_error_pct_bbox,engine_"
           "agrees\n";
    char line[256];
    for (const FrameRecord& r : records) {
        std::snprintf(line, sizeof line, "%ld,%s,%s,%.9g,%s,%.6f,%.6f,%.6f,%d\n", static_cast<long>(r.frame),
                      scene.animation->sequences()[r.sequence].name.c_str(), r.novel ? "novel" : "validation",
                      r.keyRms, stateName(r.state), r.weight, r.pmMax / scene.percent, r.softMax / scene.percent,
                      r.engineAgrees ? 1 : 0);
        csv << line;
    }
    writeFileAtomically(run.out + "frames.csv", csv.str());
}

struct WrittenFiles {
    nlohmann::json files = nlohmann::json::array();  // names, in the order written
    nlohmann::json shown = nlohmann::json::array();  // report.json's "shown_frames"
};

// Files: renders, meshes, the model, the per-frame table.
WrittenFiles writeFiles(const DemoRun& run, const FaceScene& scene, const Model& model, const PointMultiplier& pm,
                        const std::vector<FrameRecord>& records, const TestFrames& sets, const EngineTotals& engine) {
    const Clock::time_point t = Clock::now();
    run.step("write", 0, 1);
    const FacePictures pics{FaceRenderer(scene.rig->topology(), FaceRenderer::ictHiddenVertices(scene.n))};
    WrittenFiles written;
    for (const auto& [label, record] : sets.shown) {
        written.shown.push_back(writeShownFrame(run, scene, model, pm, pics, label, *record,
                                                engine.kept.at(record->frame), written.files));
    }
    writeKeyPointsImage(run, scene, model, pics);
    written.files.push_back("keys.png");
    writeModel(run.out + "face.pmsc", model);
    written.files.push_back("face.pmsc");
    writeFramesCsv(run, scene, records);
    written.files.push_back("frames.csv");
    run.timings["write"] = seconds(t);
    return written;
}

// Per-frame values of the report's summaries (errors in % of the head diagonal).
struct ErrorSamples {
    std::vector<double> pmVal, softVal, pmNovel, softAll, keyVal, keyNovel;
};

ErrorSamples collectErrors(const std::vector<FrameRecord>& records, double percent) {
    ErrorSamples e;
    for (const FrameRecord& r : records) {
        e.softAll.push_back(r.softMax / percent);
        if (r.novel) {
            e.pmNovel.push_back(r.pmMax / percent);
            e.keyNovel.push_back(r.keyRms);
        } else {
            e.pmVal.push_back(r.pmMax / percent);
            e.softVal.push_back(r.softMax / percent);
            e.keyVal.push_back(r.keyRms);
        }
    }
    return e;
}

// What was run on what: sizes of the face, the model and the sets.
void reportSetUp(nlohmann::json& report, const FaceDemoOptions& options, const FaceScene& scene, const Model& model,
                 const SequenceSplit& split, const TestFrames& sets) {
    report["experiment"] =
        "paper section 7: facial articulation, point multiplication and soft caching of a face rig";
    report["quick"] = options.quick;
    report["data"] = options.dataDir;
    report["points"] = scene.n;
    report["key_points"] = model.keyCount();
    report["fiducials"] = static_cast<Index>(IctFace::multiPie68().size());
    report["basis"] = model.basisSize();
    report["train_frames"] = static_cast<Index>(split.trainingFrames.size());
    report["test_frames"] = static_cast<Index>(sets.validation.size());
    report["novel_frames"] = static_cast<Index>(sets.novel.size());
    report["sequences"] = {{"training", split.trainingSeqs.size()},
                           {"validation", split.validationSeqs.size()},
                           {"novel", split.novelSeqs.size()}};
}

void reportTiming(nlohmann::json& report, const PoseTimings& pt) {
    const Index timed = pt.timed;
    const double fullSeconds = pt.fullSeconds();
    const double pmscSeconds = pt.pmscSeconds();
    report["full_seconds_per_frame"] = fullSeconds;
    report["pmsc_seconds_per_frame"] = pmscSeconds;
    report["speedup"] = fullSeconds / pmscSeconds;
    report["timing"] = {{"clock",
                         "thread CPU time, one thread, one frame at a time, full pose and PMSC interleaved "
                         "on the same frames"},
                        {"frames", timed},
                        {"full_pose", fullSeconds},
                        {"key_posing", pt.cpuKeys / static_cast<double>(timed)},
                        {"projection", pt.cpuProject / static_cast<double>(timed)},
                        {"reconstruction", pt.cpuReconstruct / static_cast<double>(timed)},
                        {"key_cost_fraction", pt.cpuKeys / pt.cpuFull},
                        {"wall",
                         {{"full_pose", pt.wallFull / static_cast<double>(timed)},
                          {"pmsc", (pt.wallKeys + pt.wallProject + pt.wallReconstruct) / static_cast<double>(timed)},
                          {"speedup", pt.wallFull / (pt.wallKeys + pt.wallProject + pt.wallReconstruct)}}}};
}

// Where the selector put the key points (upstream region table, face split by the mouth box), and
// what posing them costs.
void reportKeyPoints(nlohmann::json& report, const FaceRig& rig, const Model& model) {
    const FaceRig::ClosureSize closure = rig.closureSize(model.keyPoints);
    Index lipKeys = 0;
    for (Index k : model.keyPoints) lipKeys += rig.lipContact().inZone(k) ? 1 : 0;
    nlohmann::json where = nlohmann::json::object();
    for (Index k : model.keyPoints) {
        std::string name = "other";
        for (const char* r : {"face", "head_and_neck", "mouth_socket", "eye_socket_left", "eye_socket_right",
                              "gums_and_tongue", "teeth", "eyeball_left", "eyeball_right", "eyelashes_left",
                              "eyelashes_right", "lacrimal_left", "lacrimal_right", "eye_occlusion_left",
                              "eye_occlusion_right", "eye_blend_left", "eye_blend_right"}) {
            if (IctFace::region(r).contains(k)) {
                name = r;
                break;
            }
        }
        if (name == "face" && rig.lipContact().inMouthBox(k)) name = "face (mouth)";
        where[name] = where.value(name, 0) + 1;
    }
    report["key_points_by_region"] = where;
    report["key_point_indices"] = model.keyPoints;
    report["dependency_closure_of_keys"] = {{"blendshape_stage", closure.blendshapes},
                                            {"relaxed", closure.relax},
                                            {"contact_evaluations", closure.contact},
                                            {"lip_keys", lipKeys}};
}

// Decisions, errors and thresholds: the headline rates and the validation, novel and engine sections.
void reportAccuracy(nlohmann::json& report, const FaceDemoOptions& options, const FaceScene& scene,
                    const TrainedModel& trained, const std::vector<FrameRecord>& records, const TestFrames& sets,
                    const EngineTotals& engine) {
    const Model& model = trained.model;
    const double percent = scene.percent;
    const ErrorSamples e = collectErrors(records, percent);
    const double valFrames = static_cast<double>(engine.frames[0]);
    report["hit_rate"] = static_cast<double>(engine.hits[0]) / valFrames;
    report["blend_rate"] = static_cast<double>(engine.blends[0]) / valFrames;
    report["miss_rate"] = static_cast<double>(engine.misses[0]) / valFrames;
    report["max_error_pct_bbox_p995"] = percentile(e.pmVal, 0.995);
    report["soft_max_error_pct_bbox_max"] =
        e.softAll.empty() ? 0.0 : *std::max_element(e.softAll.begin(), e.softAll.end());
    report["novel_nonhit_rate"] =
        static_cast<double>(engine.blends[1] + engine.misses[1]) / static_cast<double>(engine.frames[1]);
    report["bbox_diagonal"] = scene.diagonal;
    report["tolerance_pct_bbox"] = options.tolerancePercent;
    report["eps_min"] = model.epsMin;
    report["eps_max"] = model.epsMax;
    report["eps_min_pct_bbox"] = model.epsMin / percent;
    report["calibration_ratio"] = trained.report.calibration.ratio;
    report["train_max_point_residual_pct_bbox"] = model.trainMaxPointResidual / percent;
    report["training_warnings"] = trained.report.warnings;
    report["validation"] = {{"frames", sets.validation.size()},
                            {"hits", engine.hits[0]},
                            {"blends", engine.blends[0]},
                            {"misses", engine.misses[0]},
                            {"pm_max_error_pct_bbox", summary(e.pmVal)},
                            {"soft_max_error_pct_bbox", summary(e.softVal)},
                            {"key_rms", summary(e.keyVal)},
                            {"engine_wall_seconds", engine.wall[0]}};
    nlohmann::json controls = nlohmann::json::array();
    for (const int control : scene.animationOptions.novelControls) controls.push_back(controlName(control));
    report["novel"] = {{"frames", sets.novel.size()},
                       {"hits", engine.hits[1]},
                       {"blends", engine.blends[1]},
                       {"misses", engine.misses[1]},
                       {"pm_max_error_pct_bbox", summary(e.pmNovel)},
                       {"key_rms", summary(e.keyNovel)},
                       {"controls", controls},
                       {"engine_wall_seconds", engine.wall[1]}};
    report["engine"] = {{"decisions_equal_direct", engine.disagreements == 0 && engine.unseen == 0},
                        {"disagreements", engine.disagreements},
                        {"frames_not_delivered", engine.unseen},
                        {"threads", options.threads},
                        {"runs_sample", engine.runs}};
}

}  // namespace

nlohmann::json runFaceDemo(const FaceDemoOptions& options) {
    const Clock::time_point start = Clock::now();
    checkOptions(options);
    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency());
    nlohmann::json report;
    nlohmann::json timings;
    const DemoRun run{options, arena, timings, options.outDir + "/"};

    Clock::time_point t = Clock::now();
    const FaceScene scene = loadFaceScene(run);
    createOutputFolder(options.outDir);
    timings["load_and_rig"] = seconds(t);
    const SequenceSplit split = splitSequences(options, *scene.animation);

    const TrainedModel trained = trainModel(run, poseTrainingFrames(run, scene, split.trainingFrames), scene.percent);
    const Model& model = trained.model;
    const PointMultiplier pm(model);
    const SoftCachePolicy policy(model.epsMin, model.epsMax);

    t = Clock::now();
    std::vector<FrameRecord> records = testFrameRecords(*scene.animation, split);
    measureAgainstFullPoses(run, scene, model, pm, policy, records);
    timings["ground_truth"] = seconds(t);
    const TestFrames sets = pickShownFrames(records);

    const EngineTotals engine = runTestSequencesThroughEngine(run, scene, model, split, records, sets);
    if (model.regions) report["local_fail_through"] = measureLocalFailThrough(run, scene, model, split);
    const PoseTimings poseTimings = timeFullPoseAgainstPmsc(run, scene, model, pm, sets.validation);
    const WrittenFiles written = writeFiles(run, scene, model, pm, records, sets, engine);

    reportSetUp(report, options, scene, model, split, sets);
    reportTiming(report, poseTimings);
    reportKeyPoints(report, *scene.rig, model);
    reportAccuracy(report, options, scene, trained, records, sets, engine);
    report["shown_frames"] = written.shown;
    report["files"] = written.files;
    timings["total"] = seconds(start);
    report["seconds"] = timings;
    writeFileAtomically(run.out + "report.json", report.dump(2) + "\n");
    return report;
}

}  // namespace pmsc::face
