#include "examples/face/CrossDemo.h"

#include "examples/face/FaceEvaluator.h"
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

void FaceControlEvaluator::evaluate(Index frame, std::span<const Index> points, double* out) const {
    if (frame < 0 || frame >= frameCount())
        throw std::out_of_range("face-control: frame " + std::to_string(frame) + " outside [0, " +
                                std::to_string(frameCount()) + ")");
    rig_->evaluateControl(animation_->frame(frame), points, out);
}

std::unique_ptr<FaceControlEvaluator> makeFaceControlEvaluator(const std::string& folder) {
    const IctFace face = loadIctFace(folder);
    return std::make_unique<FaceControlEvaluator>(
        std::make_shared<const FaceRig>(face),
        std::make_shared<const FaceAnimation>(FaceAnimation::generate({})));
}

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

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

double threadCpuSeconds() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

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

}  // namespace

nlohmann::json runCrossDemo(const CrossDemoOptions& options) {
    namespace fs = std::filesystem;
    const Clock::time_point start = Clock::now();
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
    auto step = [&](std::string_view stage, double done, double total) {
        if (options.progress && !options.progress(stage, done, total)) throw Cancelled("demo cross");
    };
    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency());
    nlohmann::json report, seconds;

    // --- the face, the rig, the animation (the face demo's) -------------------------------------------
    Clock::time_point t = Clock::now();
    step("load", 0, 1);
    const IctFace face = loadIctFace(options.dataDir);
    auto rig = std::make_shared<const FaceRig>(face);
    FaceAnimationOptions ao;
    ao.seed = options.seed;
    ao.sequences = options.sequences;
    ao.novelSequences = options.novelSequences;
    ao.minFrames = options.minFrames;
    ao.maxFrames = options.maxFrames;
    const FaceAnimation animation = FaceAnimation::generate(ao);
    const Index n = rig->pointCount();
    const double percent = face.boundingBoxDiagonal() / 100.0;
    std::error_code ec;
    fs::create_directories(options.outDir, ec);
    if (ec || !fs::is_directory(options.outDir))
        throw IoError(options.outDir +
                      ": cannot create the output folder: " + (ec ? ec.message() : "not a folder"));
    const std::string out = options.outDir + "/";
    std::vector<Index> trainingSeqs, validationSeqs, novelSeqs;
    animation.splitOrdinary(options.trainingFraction, options.seed + 4, trainingSeqs, validationSeqs);
    for (Index s = 0; s < static_cast<Index>(animation.sequences().size()); ++s)
        if (animation.sequences()[static_cast<size_t>(s)].novel) novelSeqs.push_back(s);
    const std::vector<Index> trainingFrames = animation.framesOf(trainingSeqs);
    const std::vector<Index> validationFrames = animation.framesOf(validationSeqs);
    const std::vector<Index> novelFrames = animation.framesOf(novelSeqs);
    std::vector<Index> all(static_cast<size_t>(n));
    for (Index v = 0; v < n; ++v) all[static_cast<size_t>(v)] = v;
    seconds["load"] = since(t);

    // --- training pairs: the control face and the full rig on the training frames -----------------
    t = Clock::now();
    const Index f = static_cast<Index>(trainingFrames.size());
    FrameSet control(f, n, 3), target(f, n, 3);
    {
        std::atomic<Index> posed{0};
        arena.execute([&] {
            tbb::parallel_for(Index{0}, f, [&](Index i) {
                const ControlVector& c = animation.frame(trainingFrames[static_cast<size_t>(i)]);
                rig->evaluateControl(c, all, control.frame(i));
                rig->evaluateAll(c, target.frame(i));
                const Index k = ++posed;
                if (k % 64 == 0) step("pose training pairs", static_cast<double>(k), static_cast<double>(f));
            });
        });
    }
    seconds["pose_training"] = since(t);
    CrossOptions co;
    co.coverage = options.coverage;
    co.training.basis = options.basis;
    co.training.maxKeys = options.maxKeys;
    co.training.fiducials.assign(IctFace::multiPie68().begin(), IctFace::multiPie68().end());
    co.training.tolerance = percent;  // 1% of the head diagonal: frames whose bound exceeds it are flagged
    co.training.progress = [&](std::string_view stage, double done, double total) {
        step(stage, done, total);
        return true;
    };
    t = Clock::now();
    CrossReport trainReport;
    Model model;
    arena.execute([&] { model = trainCross(control, target, co, &trainReport); });
    seconds["train"] = since(t);
    std::vector<double>().swap(control.values);
    std::vector<double>().swap(target.values);
    writeModel(out + "cross.pmsc", model);
    const CrossMultiplier cross(model);

    // --- validation and novel: cross PM against the full rig -----------------------------------------
    auto score = [&](const std::vector<Index>& frames, const char* stage) {
        std::vector<FrameScore> r(frames.size());
        std::atomic<Index> done{0};
        arena.execute([&] {
            tbb::parallel_for(size_t{0}, frames.size(), [&](size_t i) {
                const ControlVector& c = animation.frame(frames[i]);
                std::vector<double> keys(static_cast<size_t>(3 * model.keyCount())),
                    rec(static_cast<size_t>(3 * n)), full(static_cast<size_t>(3 * n)),
                    ctl(static_cast<size_t>(3 * n));
                rig->evaluateControl(c, cross.keyPoints(), keys.data());
                const CrossMultiplier::Result res = cross.apply(keys.data(), rec.data());
                rig->evaluateAll(c, full.data());
                rig->evaluateControl(c, all, ctl.data());
                r[i] = {frames[i], res.keyRms, res.bound, maxPointDistance(rec.data(), full.data(), n),
                        maxPointDistance(ctl.data(), full.data(), n)};
                const Index k = ++done;
                if (k % 64 == 0) step(stage, static_cast<double>(k), static_cast<double>(frames.size()));
            });
        });
        return r;
    };
    t = Clock::now();
    const std::vector<FrameScore> validation = score(validationFrames, "validation");
    seconds["validation"] = since(t);
    t = Clock::now();
    const std::vector<FrameScore> novel = score(novelFrames, "novel");
    seconds["novel"] = since(t);

    // --- speed: one thread, one frame at a time, full rig and cross PM interleaved ------------------
    t = Clock::now();
    double cpuFull = 0, cpuKeys = 0, cpuProject = 0, cpuReconstruct = 0, wallFull = 0, wallCross = 0;
    const Index timed = std::min<Index>(options.timingFrames, static_cast<Index>(validationFrames.size()));
    {
        std::vector<double> full(static_cast<size_t>(3 * n)), rec(static_cast<size_t>(3 * n)),
            keys(static_cast<size_t>(3 * model.keyCount()));
        Eigen::VectorXd coords(model.coordCount());
        const PointMultiplier pm(model);
        for (Index i = 0; i < timed; ++i) {
            const ControlVector& c = animation.frame(validationFrames[static_cast<size_t>(
                i * static_cast<Index>(validationFrames.size()) / timed)]);
            double c0 = threadCpuSeconds();
            Clock::time_point w0 = Clock::now();
            rig->evaluateAll(c, full.data());
            cpuFull += threadCpuSeconds() - c0;
            wallFull += since(w0);
            w0 = Clock::now();
            c0 = threadCpuSeconds();
            rig->evaluateControl(c, cross.keyPoints(), keys.data());
            double c1 = threadCpuSeconds();
            cpuKeys += c1 - c0;
            pm.project(keys.data(), coords.data());
            volatile double e = pm.keyRmsError(keys.data(), coords.data());
            (void)e;
            double c2 = threadCpuSeconds();
            cpuProject += c2 - c1;
            pm.reconstructRange(coords.data(), cross.controlPoints(), cross.targetPoints(), rec.data());
            cpuReconstruct += threadCpuSeconds() - c2;
            wallCross += since(w0);
            step("timing", static_cast<double>(i + 1), static_cast<double>(timed));
        }
    }
    seconds["timing"] = since(t);
    const double per = 1.0 / static_cast<double>(timed);
    const double crossCpu = (cpuKeys + cpuProject + cpuReconstruct) * per;

    // --- files ----------------------------------------------------------------------------------------
    {
        std::ostringstream csv;
        csv << "set,frame,key_rms,bound_pct_bbox,error_pct_bbox,control_vs_full_pct_bbox\n";
        for (const auto* set : {&validation, &novel})
            for (const FrameScore& s : *set)
                csv << (set == &validation ? "validation" : "novel") << ',' << s.frame << ',' << s.keyRms
                    << ',' << s.bound / percent << ',' << s.error / percent << ',' << s.controlGap / percent
                    << '\n';
        AtomicFile file(out + "frames.csv");
        const std::string text = csv.str();
        file.write(text.data(), text.size());
        file.commit();
    }
    const CrossState& st = *model.cross;
    report["head_diagonal"] = face.boundingBoxDiagonal();
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
                       {"warnings", trainReport.training.warnings}};
    report["bound"] = {{"rule", "quantile * (key_rms + scale), split-conformal on held-out training pairs"},
                       {"coverage", st.coverage},
                       {"quantile", st.quantile},
                       {"scale", st.scale},
                       {"held_out_pairs", st.keyRms.size()},
                       {"held_out_inside_rate", trainReport.heldOutCoverage}};
    report["validation"] = summarize(validation, percent);
    report["novel"] = summarize(novel, percent);
    report["speed"] = {{"timed_frames", timed},
                       {"full_rig_cpu_ms", 1e3 * cpuFull * per},
                       {"cross_cpu_ms", 1e3 * crossCpu},
                       {"control_keys_cpu_ms", 1e3 * cpuKeys * per},
                       {"projection_cpu_ms", 1e3 * cpuProject * per},
                       {"reconstruction_cpu_ms", 1e3 * cpuReconstruct * per},
                       {"speedup_cpu", crossCpu > 0 ? cpuFull * per / crossCpu : 0.0},
                       {"full_rig_wall_ms", 1e3 * wallFull * per},
                       {"cross_wall_ms", 1e3 * wallCross * per},
                       {"speedup_wall", wallCross > 0 ? wallFull / wallCross : 0.0}};
    report["frames"] = {{"training", trainingFrames.size()},
                        {"validation", validationFrames.size()},
                        {"novel", novelFrames.size()}};
    seconds["total"] = since(start);
    report["seconds"] = seconds;
    report["quick"] = options.quick;
    {
        AtomicFile file(out + "report.json");
        const std::string text = report.dump(2) + "\n";
        file.write(text.data(), text.size());
        file.commit();
    }
    return report;
}

}  // namespace pmsc::face
