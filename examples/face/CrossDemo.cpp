#include "examples/face/CrossDemo.h"

#include "evaluators/face/FaceEvaluator.h"
#include "examples/common/DemoSetup.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Cross.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <sstream>

namespace pmsc::face {

CrossDemoOptions CrossDemoOptions::quickOptions() {
    CrossDemoOptions o;
    o.quick = true;
    o.sequences = 6;
    o.novelSequences = 1;
    o.minFrames = 16;
    o.maxFrames = 22;
    o.basis = 12;  // ~35 training pairs: a larger joint basis is not determined by the control keys
    o.maxKeys = 120;
    o.timingFrames = 8;
    return o;
}

namespace {

using examples::createOutputFolder;
using examples::DemoClock;
using examples::DemoSetup;
using examples::FolderErrorWording;
using examples::secondsSince;
using examples::threadCpuSeconds;

// NumPy's default percentile (linear between closest ranks), as the replay report.
double percentile(std::vector<double> v, double q) {
    if (v.empty()) return 0;
    std::sort(v.begin(), v.end());
    const double h = q * static_cast<double>(v.size() - 1);
    const size_t lo = static_cast<size_t>(std::floor(h));
    const size_t hi = std::min(lo + 1, v.size() - 1);
    return v[lo] + (h - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

double maxPointDistance(const double* a, const double* b, Index points) {
    double worst = 0;
    for (Index p = 0; p < points; ++p) {
        const double dx = a[3 * p] - b[3 * p], dy = a[3 * p + 1] - b[3 * p + 1],
                     dz = a[3 * p + 2] - b[3 * p + 2];
        worst = std::max(worst, dx * dx + dy * dy + dz * dz);
    }
    return std::sqrt(worst);
}

struct FrameScore {
    Index frame = 0;
    double keyRms = 0;      // the control's key RMS
    double bound = 0;       // the learned bound on the target's largest point error
    double error = 0;       // the target's largest point error against the full rig
    double controlGap = 0;  // the control face's own largest distance to the full rig
};

nlohmann::json summarize(const std::vector<FrameScore>& s, double percent) {
    std::vector<double> e, b, k, gap;
    Index inside = 0;
    for (const FrameScore& f : s) {
        e.push_back(f.error / percent);
        b.push_back(f.bound / percent);
        k.push_back(f.keyRms);
        gap.push_back(f.controlGap / percent);
        inside += f.error <= f.bound;
    }
    auto pct = [](const std::vector<double>& v) {
        return nlohmann::json{{"p50", percentile(v, 0.5)},
                              {"p95", percentile(v, 0.95)},
                              {"p99", percentile(v, 0.99)},
                              {"max", percentile(v, 1.0)}};
    };
    return {
        {"frames", s.size()},
        {"error_pct_bbox", pct(e)},
        {"bound_pct_bbox", pct(b)},
        {"inside_bound", inside},
        {"inside_bound_rate", s.empty() ? 0.0 : static_cast<double>(inside) / static_cast<double>(s.size())},
        {"key_rms", pct(k)},
        {"control_vs_full_pct_bbox", pct(gap)}};
}

// --- the steps of runCrossDemo, in the order it runs them ------------------------------------

/// Throws InputError unless the options are usable.
void checkOptions(const CrossDemoOptions& options) {
    if (options.outDir.empty()) throw InputError("demo cross: --out is required");
    if (options.dataDir.empty()) throw InputError("demo cross: --data is required");
    if (options.sequences < 2 || options.novelSequences < 1 || options.minFrames < 8 ||
        options.maxFrames < options.minFrames ||
        !(options.trainingFraction > 0 && options.trainingFraction < 1) || options.basis < 1 ||
        options.maxKeys < 68 || options.maxKeys > 170 || !(options.coverage > 0 && options.coverage < 1) ||
        options.timingFrames < 1 || options.threads < 0) {
        throw InputError(
            "demo cross: options out of range (sequences >= 2, novel >= 1, 8 <= minFrames <= maxFrames, "
            "0 < training fraction < 1, basis >= 1, 68 <= keys <= 170, 0 < coverage < 1, timing frames >= 1, "
            "threads >= 0)");
    }
}

/// The face's rig, the animation (the face demo's), the frames by use, and every point's index.
struct CrossScene {
    double diagonal = 0;  // of the head's bounding box
    double percent = 0;   // model units per % of the head diagonal
    std::shared_ptr<const FaceRig> rig;
    FaceAnimation animation;
    Index n = 0;  // points
    std::vector<Index> trainingFrames{}, validationFrames{}, novelFrames{};
    std::vector<Index> all{};  // 0 .. n-1: the control face at every point
};

/// The face's rig and the animation, without the frames.
CrossScene loadScene(const DemoSetup& run, const CrossDemoOptions& options) {
    run.progress("load", 0, 1);
    const IctFace face = loadIctFace(options.dataDir);
    auto rig = std::make_shared<const FaceRig>(face);
    FaceAnimationOptions ao;
    ao.seed = options.seed;
    ao.sequences = options.sequences;
    ao.novelSequences = options.novelSequences;
    ao.minFrames = options.minFrames;
    ao.maxFrames = options.maxFrames;
    return CrossScene{.diagonal = face.boundingBoxDiagonal(),
                      .percent = face.boundingBoxDiagonal() / 100.0,
                      .rig = rig,
                      .animation = FaceAnimation::generate(ao),
                      .n = rig->pointCount()};
}

/// The frames by use (the face demo's split) and every point's index.
void splitFrames(const CrossDemoOptions& options, CrossScene& scene) {
    const FaceAnimation& animation = scene.animation;
    std::vector<Index> trainingSeqs, validationSeqs, novelSeqs;
    animation.splitOrdinary(options.trainingFraction, options.seed + 4, trainingSeqs, validationSeqs);
    for (Index s = 0; s < static_cast<Index>(animation.sequences().size()); ++s)
        if (animation.sequences()[static_cast<size_t>(s)].novel) novelSeqs.push_back(s);
    scene.trainingFrames = animation.framesOf(trainingSeqs);
    scene.validationFrames = animation.framesOf(validationSeqs);
    scene.novelFrames = animation.framesOf(novelSeqs);
    scene.all.resize(static_cast<size_t>(scene.n));
    for (Index v = 0; v < scene.n; ++v) scene.all[static_cast<size_t>(v)] = v;
}

/// The cross model and its training report.
struct CrossTrained {
    CrossReport report;
    Model model;
};

/// Training pairs (the control face and the full rig on the training frames) and the cross
/// model trained on them, written as cross.pmsc.
CrossTrained trainCrossModel(DemoSetup& run, const CrossDemoOptions& options, const CrossScene& scene,
                             const std::string& out) {
    DemoClock::time_point t = DemoClock::now();
    const Index f = static_cast<Index>(scene.trainingFrames.size()), n = scene.n;
    FrameSet control(f, n, 3), target(f, n, 3);
    std::atomic<Index> posed{0};
    run.arena.execute([&] {
        tbb::parallel_for(Index{0}, f, [&](Index i) {
            const ControlVector& c = scene.animation.frame(scene.trainingFrames[static_cast<size_t>(i)]);
            scene.rig->evaluateControl(c, scene.all, control.frame(i));
            scene.rig->evaluateAll(c, target.frame(i));
            const Index k = ++posed;
            if (k % 64 == 0)
                run.progress("pose training pairs", static_cast<double>(k), static_cast<double>(f));
        });
    });
    run.lap("pose_training", t);
    CrossOptions co;
    co.coverage = options.coverage;
    co.training.basis = options.basis;
    co.training.maxKeys = options.maxKeys;
    co.training.fiducials.assign(IctFace::multiPie68().begin(), IctFace::multiPie68().end());
    co.training.tolerance =
        scene.percent;  // 1% of the head diagonal: frames whose bound exceeds it are flagged
    co.training.progress = [&run](std::string_view stage, double done, double total) {
        run.progress(stage, done, total);
        return true;
    };
    t = DemoClock::now();
    CrossTrained trained;
    run.arena.execute([&] { trained.model = trainCross(control, target, co, &trained.report); });
    run.lap("train", t);
    decltype(control.values)().swap(control.values);
    decltype(target.values)().swap(target.values);
    writeModel(out + "cross.pmsc", trained.model);
    return trained;
}

/// Validation or novel frames: cross PM against the full rig; the seconds taken go to
/// timings[stage].
std::vector<FrameScore> scoreFrames(DemoSetup& run, const CrossScene& scene, const Model& model,
                                    const CrossMultiplier& cross, const std::vector<Index>& frames,
                                    const char* stage) {
    const DemoClock::time_point t = DemoClock::now();
    const Index n = scene.n;
    std::vector<FrameScore> r(frames.size());
    std::atomic<Index> done{0};
    run.arena.execute([&] {
        tbb::parallel_for(size_t{0}, frames.size(), [&](size_t i) {
            const ControlVector& c = scene.animation.frame(frames[i]);
            std::vector<double> keys(static_cast<size_t>(3 * model.keyCount())),
                rec(static_cast<size_t>(3 * n)), full(static_cast<size_t>(3 * n)),
                ctl(static_cast<size_t>(3 * n));
            scene.rig->evaluateControl(c, cross.keyPoints(), keys.data());
            const CrossMultiplier::Result res = cross.apply(keys.data(), rec.data());
            scene.rig->evaluateAll(c, full.data());
            scene.rig->evaluateControl(c, scene.all, ctl.data());
            r[i] = {frames[i], res.keyRms, res.bound, maxPointDistance(rec.data(), full.data(), n),
                    maxPointDistance(ctl.data(), full.data(), n)};
            const Index k = ++done;
            if (k % 64 == 0) run.progress(stage, static_cast<double>(k), static_cast<double>(frames.size()));
        });
    });
    run.lap(stage, t);
    return r;
}

/// Thread CPU and wall seconds, summed over the timed frames.
struct SpeedTotals {
    Index timed = 0;
    double cpuFull = 0, cpuKeys = 0, cpuProject = 0, cpuReconstruct = 0, wallFull = 0, wallCross = 0;
};

/// Speed: one thread, one frame at a time, full rig and cross PM interleaved.
SpeedTotals timeFullRigAgainstCross(DemoSetup& run, const CrossDemoOptions& options, const CrossScene& scene,
                                    const Model& model, const CrossMultiplier& cross) {
    const DemoClock::time_point t = DemoClock::now();
    const std::vector<Index>& validationFrames = scene.validationFrames;
    SpeedTotals s;
    s.timed = std::min<Index>(options.timingFrames, static_cast<Index>(validationFrames.size()));
    std::vector<double> full(static_cast<size_t>(3 * scene.n)), rec(static_cast<size_t>(3 * scene.n)),
        keys(static_cast<size_t>(3 * model.keyCount()));
    Eigen::VectorXd coords(model.coordCount());
    const PointMultiplier pm(model);
    for (Index i = 0; i < s.timed; ++i) {
        const ControlVector& c = scene.animation.frame(
            validationFrames[static_cast<size_t>(i * static_cast<Index>(validationFrames.size()) / s.timed)]);
        double c0 = threadCpuSeconds();
        DemoClock::time_point w0 = DemoClock::now();
        scene.rig->evaluateAll(c, full.data());
        s.cpuFull += threadCpuSeconds() - c0;
        s.wallFull += secondsSince(w0);
        w0 = DemoClock::now();
        c0 = threadCpuSeconds();
        scene.rig->evaluateControl(c, cross.keyPoints(), keys.data());
        double c1 = threadCpuSeconds();
        s.cpuKeys += c1 - c0;
        pm.project(keys.data(), coords.data());
        volatile double e = pm.keyError(keys.data(), coords.data());
        (void)e;
        double c2 = threadCpuSeconds();
        s.cpuProject += c2 - c1;
        pm.reconstructRange(coords.data(), cross.controlPoints(), cross.targetPoints(), rec.data());
        s.cpuReconstruct += threadCpuSeconds() - c2;
        s.wallCross += secondsSince(w0);
        run.progress("timing", static_cast<double>(i + 1), static_cast<double>(s.timed));
    }
    run.lap("timing", t);
    return s;
}

/// Writes `text` to `path` atomically.
void writeAtomically(const std::string& path, const std::string& text) {
    AtomicFile file(path);
    file.write(text.data(), text.size());
    file.commit();
}

/// frames.csv: one row per validation and novel frame.
void writeFramesCsv(const std::string& path, const std::vector<FrameScore>& validation,
                    const std::vector<FrameScore>& novel, double percent) {
    std::ostringstream csv;
    csv << "set,frame,key_rms,bound_pct_bbox,error_pct_bbox,control_vs_full_pct_bbox\n";
    for (const auto* set : {&validation, &novel})
        for (const FrameScore& s : *set)
            csv << (set == &validation ? "validation" : "novel") << ',' << s.frame << ',' << s.keyRms << ','
                << s.bound / percent << ',' << s.error / percent << ',' << s.controlGap / percent << '\n';
    writeAtomically(path, csv.str());
}

/// The report's speed figures: per frame, in milliseconds.
nlohmann::json speedJson(const SpeedTotals& s) {
    const double per = 1.0 / static_cast<double>(s.timed);
    const double crossCpu = (s.cpuKeys + s.cpuProject + s.cpuReconstruct) * per;
    return {{"timed_frames", s.timed},
            {"full_rig_cpu_ms", 1e3 * s.cpuFull * per},
            {"cross_cpu_ms", 1e3 * crossCpu},
            {"control_keys_cpu_ms", 1e3 * s.cpuKeys * per},
            {"projection_cpu_ms", 1e3 * s.cpuProject * per},
            {"reconstruction_cpu_ms", 1e3 * s.cpuReconstruct * per},
            {"speedup_cpu", crossCpu > 0 ? s.cpuFull * per / crossCpu : 0.0},
            {"full_rig_wall_ms", 1e3 * s.wallFull * per},
            {"cross_wall_ms", 1e3 * s.wallCross * per},
            {"speedup_wall", s.wallCross > 0 ? s.wallFull / s.wallCross : 0.0}};
}

/// The report: the model, its bound, the errors and the speed (the timings are added by the caller).
nlohmann::json makeReport(const CrossDemoOptions& options, const CrossScene& scene,
                          const CrossTrained& trained, const std::vector<FrameScore>& validation,
                          const std::vector<FrameScore>& novel, const SpeedTotals& speed) {
    const Model& model = trained.model;
    const CrossState& st = *model.cross;
    const double percent = scene.percent;
    nlohmann::json report;
    report["head_diagonal"] = scene.diagonal;
    report["control"] = "FaceRig::evaluateControl: blendshapes (with correctives), jaw, eyelids, eyes";
    report["target"] = "FaceRig::evaluateAll: the full rig (plus relax, flesh muscles, lip and lid contact)";
    report["fail_through"] = "impossible (cross point multiplication)";
    report["model"] = {{"points_joint", model.points},
                       {"control_points", st.controlPoints},
                       {"target_points", model.points - st.controlPoints},
                       {"basis", model.basisSize()},
                       {"key_points", model.keyCount()},
                       {"train_frames", model.trainFrames},
                       {"energy_captured", model.energyCaptured()},
                       {"train_max_point_residual_pct_bbox", model.trainMaxPointResidual / percent},
                       {"warnings", trained.report.training.warnings}};
    report["bound"] = {{"rule", "quantile * (key_rms + scale), split-conformal on held-out training pairs"},
                       {"coverage", st.coverage},
                       {"quantile", st.quantile},
                       {"scale", st.scale},
                       {"held_out_pairs", st.keyRms.size()},
                       {"held_out_inside_rate", trained.report.heldOutCoverage}};
    report["validation"] = summarize(validation, percent);
    report["novel"] = summarize(novel, percent);
    report["speed"] = speedJson(speed);
    report["frames"] = {{"training", scene.trainingFrames.size()},
                        {"validation", scene.validationFrames.size()},
                        {"novel", scene.novelFrames.size()}};
    report["quick"] = options.quick;
    return report;
}

}  // namespace

nlohmann::json runCrossDemo(const CrossDemoOptions& options) {
    const DemoClock::time_point start = DemoClock::now();
    checkOptions(options);
    DemoSetup run(options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency(),
                  options.progress, "demo cross", start);

    // --- the face, the rig, the animation (the face demo's) -------------------------------------------
    const DemoClock::time_point t = DemoClock::now();
    CrossScene scene = loadScene(run, options);
    createOutputFolder(options.outDir, FolderErrorWording::OutputFolder);
    const std::string out = options.outDir + "/";
    splitFrames(options, scene);
    run.lap("load", t);

    const CrossTrained trained = trainCrossModel(run, options, scene, out);
    const CrossMultiplier cross(trained.model);
    const std::vector<FrameScore> validation =
        scoreFrames(run, scene, trained.model, cross, scene.validationFrames, "validation");
    const std::vector<FrameScore> novel =
        scoreFrames(run, scene, trained.model, cross, scene.novelFrames, "novel");
    const SpeedTotals speed = timeFullRigAgainstCross(run, options, scene, trained.model, cross);

    writeFramesCsv(out + "frames.csv", validation, novel, scene.percent);
    nlohmann::json report = makeReport(options, scene, trained, validation, novel, speed);
    report["seconds"] = run.finish();
    writeAtomically(out + "report.json", report.dump(2) + "\n");
    return report;
}

}  // namespace pmsc::face
