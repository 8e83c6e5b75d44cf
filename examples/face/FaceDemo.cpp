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
    const std::vector<double>& kept(Index frame) const { return kept_.at(frame); }

private:
    std::map<Index, FrameRecord*> records_;
    std::vector<Index> keep_;
    std::map<Index, std::vector<double>> kept_;
};

const char* stateName(CacheState s) {
    return s == CacheState::Hit ? "hit" : s == CacheState::Blend ? "blend" : "miss";
}

}  // namespace

nlohmann::json runFaceDemo(const FaceDemoOptions& options) {
    namespace fs = std::filesystem;
    const Clock::time_point start = Clock::now();
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
    const std::string out = options.outDir + "/";
    auto step = [&](std::string_view stage, double done, double total) {
        if (options.progress && !options.progress(stage, done, total)) throw Cancelled("demo face");
    };
    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency());
    nlohmann::json report;
    nlohmann::json timings;

    // --- the face, the rig, the animation --------------------------------------------------
    Clock::time_point t = Clock::now();
    step("load", 0, 1);
    const IctFace face = loadIctFace(options.dataDir);
    auto rig = std::make_shared<const FaceRig>(face);
    auto mesh = std::make_shared<const ObjMesh>(face.neutral);
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
    auto animation = std::make_shared<const FaceAnimation>(FaceAnimation::generate(animationOptions));
    const FaceEvaluator evaluator(rig, animation, mesh);
    const Index n = rig->pointCount();
    const double diagonal = face.boundingBoxDiagonal();
    // The output folder only once the input is known to be good: a bad --data leaves nothing.
    std::error_code ec;
    fs::create_directories(options.outDir, ec);
    if (ec || !fs::is_directory(options.outDir)) {
        throw IoError(options.outDir +
                      ": cannot create the output folder: " + (ec ? ec.message() : "not a folder"));
    }
    const double percent = diagonal / 100.0;  // model units per % of the head diagonal
    timings["load_and_rig"] = seconds(t);

    std::vector<Index> trainingSeqs, validationSeqs, novelSeqs;
    animation->splitOrdinary(options.trainingFraction, options.seed + 4, trainingSeqs, validationSeqs);
    for (Index s = 0; s < static_cast<Index>(animation->sequences().size()); ++s) {
        if (animation->sequences()[s].novel) novelSeqs.push_back(s);
    }
    const std::vector<Index> trainingFrames = animation->framesOf(trainingSeqs);

    // --- training: pose the training sequences, then pmsc::train --------------------------------
    t = Clock::now();
    Model model;
    TrainingReport trainingReport;
    {
        FrameSet training(static_cast<Index>(trainingFrames.size()), n, 3);
        std::atomic<Index> posed{0};
        arena.execute([&] {
            tbb::parallel_for(size_t{0}, trainingFrames.size(), [&](size_t i) {
                evaluator.evaluateAll(trainingFrames[i], training.frame(static_cast<Index>(i)));
                ++posed;
            });
        });
        step("pose training", static_cast<double>(posed), static_cast<double>(trainingFrames.size()));
        timings["pose_training"] = seconds(t);
        t = Clock::now();
        TrainingOptions to;
        to.basis = options.basis;
        to.maxKeys = options.maxKeys;
        to.fiducials.assign(IctFace::multiPie68().begin(), IctFace::multiPie68().end());
        to.tolerance = options.tolerancePercent * percent;
        to.regions.count = options.regions;
        to.regions.featherFraction = options.featherPercent / 100.0;
        to.regions.maxLocalFraction = options.maxLocalFraction;
        to.progress = [&](std::string_view stage, double done, double total) {
            return !options.progress ||
                   options.progress(std::string("train: ") + std::string(stage), done, total);
        };
        arena.execute([&] { model = train(training, to, &trainingReport); });
        timings["train"] = seconds(t);
    }
    const PointMultiplier pm(model);
    const SoftCachePolicy policy(model.epsMin, model.epsMax);

    // --- ground truth: every test frame posed fully; PM and the soft cache evaluated on it ---------
    t = Clock::now();
    std::vector<FrameRecord> records;
    for (const auto* set : {&validationSeqs, &novelSeqs}) {
        for (Index s : *set) {
            const FaceSequence& seq = animation->sequences()[s];
            for (Index f = 0; f < seq.frameCount; ++f) {
                FrameRecord r;
                r.frame = seq.firstFrame + f;
                r.sequence = s;
                r.novel = seq.novel;
                records.push_back(r);
            }
        }
    }
    {
        std::atomic<Index> done{0};
        const Index keyCount = model.keyCount();
        arena.execute([&] {
            tbb::parallel_for(size_t{0}, records.size(), [&](size_t i) {
                FrameRecord& r = records[i];
                std::vector<double> full(static_cast<size_t>(3 * n)), rec(static_cast<size_t>(3 * n));
                std::vector<double> keys(static_cast<size_t>(3 * keyCount)),
                    coords(static_cast<size_t>(model.basisSize()));
                evaluator.evaluateAll(r.frame, full.data());
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
                if (k % 32 == 0)
                    step("ground truth", static_cast<double>(k), static_cast<double>(records.size()));
            });
        });
    }
    timings["ground_truth"] = seconds(t);

    // The frames shown: the validation frame with the largest PM error (the paper's figure 4),
    // the median validation frame, and the median novel frame.
    std::vector<const FrameRecord*> validation, novel;
    for (const FrameRecord& r : records) (r.novel ? novel : validation).push_back(&r);
    auto byError = [](const FrameRecord* a, const FrameRecord* b) {
        return a->pmMax < b->pmMax || (a->pmMax == b->pmMax && a->frame < b->frame);
    };
    std::vector<const FrameRecord*> sortedVal = validation, sortedNovel = novel;
    std::sort(sortedVal.begin(), sortedVal.end(), byError);
    std::sort(sortedNovel.begin(), sortedNovel.end(), byError);
    const std::vector<std::pair<std::string, const FrameRecord*>> shown = {
        {"worst", sortedVal.back()},
        {"typical", sortedVal[sortedVal.size() / 2]},
        {"novel", sortedNovel[sortedNovel.size() / 2]}};

    // --- the engine: the test sequences through the soft cache, the rig as evaluator ------------------
    t = Clock::now();
    std::map<Index, FrameRecord*> byFrame;
    for (FrameRecord& r : records) byFrame[r.frame] = &r;
    std::vector<Index> keep;
    for (const auto& s : shown) keep.push_back(s.second->frame);
    DemoSink sink(byFrame, keep);
    engine::EngineOptions eo;
    eo.threads = options.threads;
    // The rig shares work between points (relax rings, contact inputs): a miss is posed whole.
    eo.wholeFrameFailThrough = true;
    // The decisions checked below are the whole frame's: today's soft cache (local fail-through
    // is measured on its own afterwards).
    eo.localFailThrough = false;
    engine::Engine engine(model, evaluator, eo);
    nlohmann::json engineRuns = nlohmann::json::array();
    Index engineHits[2] = {0, 0}, engineBlends[2] = {0, 0}, engineMisses[2] = {0, 0},
          engineFrames[2] = {0, 0};
    double engineWall[2] = {0, 0};
    Index sequencesDone = 0;
    for (const auto* set : {&validationSeqs, &novelSeqs}) {
        const int which = set == &validationSeqs ? 0 : 1;
        for (Index s : *set) {
            const FaceSequence& seq = animation->sequences()[s];
            const engine::RunStats stats = engine.run({seq.firstFrame, seq.frameCount, 1}, sink);
            engineHits[which] += stats.hits;
            engineBlends[which] += stats.blends;
            engineMisses[which] += stats.misses;
            engineFrames[which] += stats.framesDelivered;
            engineWall[which] += stats.wallSeconds;
            if (engineRuns.size() < 2 || s == set->back()) {  // a sample of per-run stats, not all of them
                nlohmann::json j = nlohmann::json::parse(stats.toJson());
                j["sequence"] = seq.name;
                engineRuns.push_back(j);
            }
            step("engine", static_cast<double>(++sequencesDone),
                 static_cast<double>(validationSeqs.size() + novelSeqs.size()));
        }
    }
    timings["engine"] = seconds(t);
    Index disagreements = 0, unseen = 0;
    for (const FrameRecord& r : records) {
        if (!r.engineSeen)
            ++unseen;
        else if (!r.engineAgrees)
            ++disagreements;
    }

    // --- local fail-through (issue 9): validation sample, novel and mixed sets, both ways ------------
    if (model.regions) {
        t = Clock::now();
        report["local_fail_through"] = localFailThroughSets(model, evaluator, *animation, validationSeqs, novelSeqs,
                                                            percent, options.threads, step,
                                                            options.quick ? 24 : 0);
        timings["local_fail_through"] = seconds(t);
    }

    // --- timing: full pose vs PMSC, one frame at a time, one thread, interleaved ----------------------
    t = Clock::now();
    double cpuFull = 0, cpuKeys = 0, cpuProject = 0, cpuReconstruct = 0;
    double wallFull = 0, wallKeys = 0, wallProject = 0, wallReconstruct = 0;
    const Index timed = std::min<Index>(options.timingFrames, static_cast<Index>(validation.size()));
    {
        std::vector<double> full(static_cast<size_t>(3 * n)), rec(static_cast<size_t>(3 * n));
        std::vector<double> keys(static_cast<size_t>(3 * model.keyCount())),
            coords(static_cast<size_t>(model.basisSize()));
        evaluator.evaluate(validation.front()->frame, model.keyPoints,
                           keys.data());  // warm the key plan cache
        for (Index i = 0; i < timed; ++i) {
            const Index frame =
                validation[static_cast<size_t>(i * static_cast<Index>(validation.size()) / timed)]->frame;
            double c0 = threadCpuSeconds();
            Clock::time_point w0 = Clock::now();
            evaluator.evaluateAll(frame, full.data());
            cpuFull += threadCpuSeconds() - c0;
            wallFull += seconds(w0);
            c0 = threadCpuSeconds();
            w0 = Clock::now();
            evaluator.evaluate(frame, model.keyPoints, keys.data());
            cpuKeys += threadCpuSeconds() - c0;
            wallKeys += seconds(w0);
            c0 = threadCpuSeconds();
            w0 = Clock::now();
            pm.project(keys.data(), coords.data());
            volatile double e = pm.keyRmsError(keys.data(), coords.data());
            (void)e;
            cpuProject += threadCpuSeconds() - c0;
            wallProject += seconds(w0);
            c0 = threadCpuSeconds();
            w0 = Clock::now();
            pm.reconstruct(coords.data(), rec.data());
            cpuReconstruct += threadCpuSeconds() - c0;
            wallReconstruct += seconds(w0);
            step("timing", static_cast<double>(i + 1), static_cast<double>(timed));
        }
    }
    timings["timing"] = seconds(t);
    const double fullSeconds = cpuFull / static_cast<double>(timed);
    const double pmscSeconds = (cpuKeys + cpuProject + cpuReconstruct) / static_cast<double>(timed);

    // --- files: renders, meshes, per-frame table --------------------------------------------------------
    t = Clock::now();
    step("write", 0, 1);
    const FaceRenderer renderer(rig->topology(), FaceRenderer::ictHiddenVertices(n));
    const OrthoView faceView{400, 480, Eigen::Vector3d(0, 0, 0), 19.0, 0.0};
    const OrthoView mouthView{400, 260, Eigen::Vector3d(0, -3.6, 10), 55.0, 0.0};
    const std::vector<float> grey(static_cast<size_t>(3 * n), 0.8f);
    nlohmann::json files = nlohmann::json::array();
    nlohmann::json shownJson = nlohmann::json::array();
    for (const auto& [label, record] : shown) {
        std::vector<double> full(static_cast<size_t>(3 * n)), pmPose(static_cast<size_t>(3 * n));
        std::vector<double> keys(static_cast<size_t>(3 * model.keyCount())),
            coords(static_cast<size_t>(model.basisSize()));
        evaluator.evaluateAll(record->frame, full.data());
        for (Index k = 0; k < model.keyCount(); ++k) {
            for (int c = 0; c < 3; ++c) keys[3 * k + c] = full[3 * model.keyPoints[k] + c];
        }
        pm.project(keys.data(), coords.data());
        pm.reconstruct(coords.data(), pmPose.data());
        const std::vector<double>& soft = sink.kept(record->frame);
        const std::string frameName =
            animation->sequences()[record->sequence].name + " frame " +
            std::to_string(record->frame - animation->sequences()[record->sequence].firstFrame);
        writeObj(out + label + "_full.obj", *mesh, full, "pmsc demo face: " + frameName + ", full pose");
        writeObj(out + label + "_pm.obj", *mesh, pmPose,
                 "pmsc demo face: " + frameName + ", point multiplication");
        writeObj(
            out + label + "_soft.obj", *mesh, soft,
            std::string("pmsc demo face: ") + frameName + ", soft cache (" + stateName(record->state) + ")");
        std::vector<float> pmColour(static_cast<size_t>(3 * n)), softColour(static_cast<size_t>(3 * n));
        for (Index p = 0; p < n; ++p) {
            const Eigen::Vector3d f(&full[3 * p]);
            const auto a = errorColour((Eigen::Vector3d(&pmPose[3 * p]) - f).norm(), percent);
            const auto b = errorColour((Eigen::Vector3d(&soft[3 * p]) - f).norm(), percent);
            for (int c = 0; c < 3; ++c) {
                pmColour[3 * p + c] = a[c];
                softColour[3 * p + c] = b[c];
            }
        }
        RgbImage sheet(3 * faceView.width, faceView.height + mouthView.height + 16, {20, 20, 24});
        const std::vector<double>* poses[3] = {&full, &pmPose, &soft};
        const std::vector<float>* colours[3] = {&grey, &pmColour, &softColour};
        for (int col = 0; col < 3; ++col) {
            sheet.paste(renderer.render(*poses[col], *colours[col], faceView), col * faceView.width, 0);
            sheet.paste(renderer.render(*poses[col], *colours[col], mouthView), col * mouthView.width,
                        faceView.height);
        }
        // Colour bar under the PM and soft-cache columns: 0 .. 1% of the head diagonal.
        for (int x = 0; x < 2 * faceView.width; ++x) {
            const auto c = errorColour(static_cast<double>(x) / (2 * faceView.width - 1), 1.0);
            for (int y = 0; y < 12; ++y) {
                std::uint8_t* px = sheet.at(faceView.width + x, faceView.height + mouthView.height + 2 + y);
                for (int ch = 0; ch < 3; ++ch) px[ch] = static_cast<std::uint8_t>(255 * c[ch]);
            }
        }
        writePng(out + label + ".png", sheet);
        for (const char* suffix : {"_full.obj", "_pm.obj", "_soft.obj", ".png"})
            files.push_back(label + suffix);
        shownJson.push_back(
            {{"label", label},
             {"sequence", animation->sequences()[record->sequence].name},
             {"frame", record->frame},
             {"state", stateName(record->state)},
             {"weight", record->weight},
             {"key_rms", record->keyRms},
             {"pm_max_error_pct_bbox", record->pmMax / percent},
             {"soft_max_error_pct_bbox", record->softMax / percent},
             {"engine_soft_max_error_pct_bbox", maxPointError(soft.data(), full.data(), n) / percent}});
    }
    {
        std::vector<float> colour(static_cast<size_t>(3 * n), 0.8f);
        RgbImage image = renderer.render(rig->restPositions(), colour, faceView);
        renderer.drawPoints(image, rig->restPositions(), model.keyPoints, faceView, {230, 30, 30}, 2);
        const std::vector<Index> fiducials(IctFace::multiPie68().begin(), IctFace::multiPie68().end());
        renderer.drawPoints(image, rig->restPositions(), fiducials, faceView, {40, 110, 255}, 2);
        writePng(out + "keys.png", image);
        files.push_back("keys.png");
    }
    writeModel(out + "face.pmsc", model);
    files.push_back("face.pmsc");
    {
        std::ostringstream csv;
        csv << "frame,sequence,set,key_rms,state,weight,pm_max_error_pct_bbox,soft_max_error_pct_bbox,engine_"
               "agrees\n";
        char line[256];
        for (const FrameRecord& r : records) {
            std::snprintf(line, sizeof line, "%ld,%s,%s,%.9g,%s,%.6f,%.6f,%.6f,%d\n",
                          static_cast<long>(r.frame), animation->sequences()[r.sequence].name.c_str(),
                          r.novel ? "novel" : "validation", r.keyRms, stateName(r.state), r.weight,
                          r.pmMax / percent, r.softMax / percent, r.engineAgrees ? 1 : 0);
            csv << line;
        }
        writeFileAtomically(out + "frames.csv", csv.str());
        files.push_back("frames.csv");
    }
    timings["write"] = seconds(t);

    // --- the report ------------------------------------------------------------------------------------
    std::vector<double> pmVal, softVal, pmNovel, softAll, keyVal, keyNovel;
    Index hitsDirect = 0, blendsDirect = 0, nonHitNovel = 0;
    for (const FrameRecord& r : records) {
        softAll.push_back(r.softMax / percent);
        if (r.novel) {
            pmNovel.push_back(r.pmMax / percent);
            keyNovel.push_back(r.keyRms);
            nonHitNovel += r.state != CacheState::Hit;
        } else {
            pmVal.push_back(r.pmMax / percent);
            softVal.push_back(r.softMax / percent);
            keyVal.push_back(r.keyRms);
            hitsDirect += r.state == CacheState::Hit;
            blendsDirect += r.state == CacheState::Blend;
        }
    }
    const double valFrames = static_cast<double>(engineFrames[0]);
    const FaceRig::ClosureSize closure = rig->closureSize(model.keyPoints);
    Index lipKeys = 0;
    for (Index k : model.keyPoints) lipKeys += rig->lipContact().inZone(k) ? 1 : 0;

    report["experiment"] =
        "paper section 7: facial articulation, point multiplication and soft caching of a face rig";
    report["quick"] = options.quick;
    report["data"] = options.dataDir;
    report["points"] = n;
    report["key_points"] = model.keyCount();
    report["fiducials"] = static_cast<Index>(IctFace::multiPie68().size());
    report["basis"] = model.basisSize();
    report["train_frames"] = static_cast<Index>(trainingFrames.size());
    report["test_frames"] = static_cast<Index>(validation.size());
    report["novel_frames"] = static_cast<Index>(novel.size());
    report["sequences"] = {{"training", trainingSeqs.size()},
                           {"validation", validationSeqs.size()},
                           {"novel", novelSeqs.size()}};
    report["full_seconds_per_frame"] = fullSeconds;
    report["pmsc_seconds_per_frame"] = pmscSeconds;
    report["speedup"] = fullSeconds / pmscSeconds;
    report["timing"] = {{"clock",
                         "thread CPU time, one thread, one frame at a time, full pose and PMSC interleaved "
                         "on the same frames"},
                        {"frames", timed},
                        {"full_pose", fullSeconds},
                        {"key_posing", cpuKeys / static_cast<double>(timed)},
                        {"projection", cpuProject / static_cast<double>(timed)},
                        {"reconstruction", cpuReconstruct / static_cast<double>(timed)},
                        {"key_cost_fraction", cpuKeys / cpuFull},
                        {"wall",
                         {{"full_pose", wallFull / static_cast<double>(timed)},
                          {"pmsc", (wallKeys + wallProject + wallReconstruct) / static_cast<double>(timed)},
                          {"speedup", wallFull / (wallKeys + wallProject + wallReconstruct)}}}};
    {
        // Where the selector put the key points (upstream region table, face split by the mouth box).
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
            if (name == "face" && rig->lipContact().inMouthBox(k)) name = "face (mouth)";
            where[name] = where.value(name, 0) + 1;
        }
        report["key_points_by_region"] = where;
        report["key_point_indices"] = model.keyPoints;
    }
    report["dependency_closure_of_keys"] = {{"blendshape_stage", closure.blendshapes},
                                            {"relaxed", closure.relax},
                                            {"contact_evaluations", closure.contact},
                                            {"lip_keys", lipKeys}};
    report["hit_rate"] = static_cast<double>(engineHits[0]) / valFrames;
    report["blend_rate"] = static_cast<double>(engineBlends[0]) / valFrames;
    report["miss_rate"] = static_cast<double>(engineMisses[0]) / valFrames;
    report["max_error_pct_bbox_p995"] = percentile(pmVal, 0.995);
    report["soft_max_error_pct_bbox_max"] =
        softAll.empty() ? 0.0 : *std::max_element(softAll.begin(), softAll.end());
    report["novel_nonhit_rate"] =
        static_cast<double>(engineBlends[1] + engineMisses[1]) / static_cast<double>(engineFrames[1]);
    report["bbox_diagonal"] = diagonal;
    report["tolerance_pct_bbox"] = options.tolerancePercent;
    report["eps_min"] = model.epsMin;
    report["eps_max"] = model.epsMax;
    report["eps_min_pct_bbox"] = model.epsMin / percent;
    report["calibration_ratio"] = trainingReport.calibration.ratio;
    report["train_max_point_residual_pct_bbox"] = model.trainMaxPointResidual / percent;
    report["training_warnings"] = trainingReport.warnings;
    report["validation"] = {{"frames", validation.size()},
                            {"hits", engineHits[0]},
                            {"blends", engineBlends[0]},
                            {"misses", engineMisses[0]},
                            {"pm_max_error_pct_bbox", summary(pmVal)},
                            {"soft_max_error_pct_bbox", summary(softVal)},
                            {"key_rms", summary(keyVal)},
                            {"engine_wall_seconds", engineWall[0]}};
    report["novel"] = {{"frames", novel.size()},
                       {"hits", engineHits[1]},
                       {"blends", engineBlends[1]},
                       {"misses", engineMisses[1]},
                       {"pm_max_error_pct_bbox", summary(pmNovel)},
                       {"key_rms", summary(keyNovel)},
                       {"controls",
                        [&] {
                            nlohmann::json c = nlohmann::json::array();
                            for (const int control : animationOptions.novelControls)
                                c.push_back(controlName(control));
                            return c;
                        }()},
                       {"engine_wall_seconds", engineWall[1]}};
    report["engine"] = {{"decisions_equal_direct", disagreements == 0 && unseen == 0},
                        {"disagreements", disagreements},
                        {"frames_not_delivered", unseen},
                        {"threads", options.threads},
                        {"runs_sample", engineRuns}};
    (void)hitsDirect;
    (void)blendsDirect;
    (void)nonHitNovel;
    report["shown_frames"] = shownJson;
    report["files"] = files;
    timings["total"] = seconds(start);
    report["seconds"] = timings;
    writeFileAtomically(out + "report.json", report.dump(2) + "\n");
    return report;
}

}  // namespace pmsc::face
