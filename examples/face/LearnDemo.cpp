#include "examples/face/LearnDemo.h"

#include "examples/face/FaceEvaluator.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"
#include "pmsc/IncrementalSvd.h"
#include "pmsc/KeptFrames.h"
#include "pmsc/Learning.h"
#include "pmsc/Metrics.h"
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/SoftCache.h"
#include "pmsc/Training.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>

namespace pmsc::face {

LearnDemoOptions LearnDemoOptions::quickOptions() {
    LearnDemoOptions o;
    o.quick = true;
    o.sequences = 9;
    o.novelSequences = 4;
    o.minFrames = 26;
    o.maxFrames = 36;
    o.basis = 24;
    o.maxKeys = 120;
    o.learnRank = 48;
    return o;
}

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// What point multiplication of one model makes of one fully posed frame.
struct Score {
    double keyRms = 0;  // e: the soft cache's decision variable
    double pmMax = 0;   // E: largest point error of PM against the full pose
};

class Probe {
public:
    explicit Probe(const Model& model) : model_(model), pm_(model) {}
    Score score(const double* full) const {
        const Index n = model_.points, k = model_.keyCount();
        std::vector<double> keys(static_cast<size_t>(3 * k)),
            coords(static_cast<size_t>(model_.coordCount())), rec(static_cast<size_t>(3 * n));
        for (Index i = 0; i < k; ++i)
            for (int c = 0; c < 3; ++c)
                keys[static_cast<size_t>(3 * i + c)] = full[3 * model_.keyPoints[static_cast<size_t>(i)] + c];
        pm_.project(keys.data(), coords.data());
        Score s;
        s.keyRms = pm_.keyRmsError(keys.data(), coords.data());
        pm_.reconstruct(coords.data(), rec.data());
        s.pmMax = maxPointError(rec.data(), full, n);
        return s;
    }
    const Model& model() const { return model_; }

private:
    const Model& model_;
    PointMultiplier pm_;
};

// The soft cache with thresholds [a, 2a]... or any [a, b]: hit/blend/miss and the soft-cached error
// (1 - w) E (a blend mixes w of the full pose in; a miss is the full pose).
struct Outcome {
    Index hits = 0, blends = 0, misses = 0;
    Index overTolerance = 0;  // frames whose soft-cached error exceeds T
    double softMax = 0;
    double hitMax = 0;  // largest PM error among hits
};

Outcome outcome(const std::vector<Score>& scores, double epsMin, double epsMax, double tolerance = 0) {
    const SoftCachePolicy policy(epsMin, epsMax);
    Outcome o;
    for (const Score& s : scores) {
        const CacheDecision d = policy.decide(s.keyRms);
        o.hits += d.state == CacheState::Hit;
        o.blends += d.state == CacheState::Blend;
        o.misses += d.state == CacheState::Miss;
        o.softMax = std::max(o.softMax, (1 - d.weight) * s.pmMax);
        o.overTolerance += tolerance > 0 && (1 - d.weight) * s.pmMax > tolerance;
        if (d.state == CacheState::Hit) o.hitMax = std::max(o.hitMax, s.pmMax);
    }
    return o;
}

// The best single threshold that keeps every hit under T, seeing the errors (an oracle): the
// frames sorted by key error, hits up to the first one whose error exceeds T.
std::pair<double, Index> bestThreshold(const std::vector<Score>& scores, double tolerance) {
    std::vector<Score> s = scores;
    std::sort(s.begin(), s.end(), [](const Score& a, const Score& b) { return a.keyRms < b.keyRms; });
    Index hits = 0;
    double threshold = 0;
    for (size_t i = 0; i < s.size(); ++i) {
        if (s[i].pmMax > tolerance) {
            // Frames tied with the failing one cannot be separated from it.
            while (hits > 0 && s[static_cast<size_t>(hits) - 1].keyRms == s[i].keyRms) --hits;
            break;
        }
        ++hits;
        threshold = s[i].keyRms;
    }
    if (hits > 0) threshold = s[static_cast<size_t>(hits) - 1].keyRms;
    return {threshold, hits};
}

nlohmann::json summarize(const std::vector<Score>& scores, const Model& model, double percent) {
    const Outcome o = outcome(scores, model.epsMin, model.epsMax);
    std::vector<double> e, big;
    double meanKey = 0;
    for (const Score& s : scores) {
        e.push_back(s.keyRms);
        big.push_back(s.pmMax / percent);
        meanKey += s.keyRms / static_cast<double>(scores.size());
    }
    const double count = std::max<double>(1.0, static_cast<double>(scores.size()));
    return {{"frames", scores.size()},
            {"hits", o.hits},
            {"blends", o.blends},
            {"misses", o.misses},
            {"hit_rate", static_cast<double>(o.hits) / count},
            {"soft_max_error_pct_bbox", o.softMax / percent},
            {"key_rms_mean", meanKey},
            {"key_rms_max", e.empty() ? 0.0 : *std::max_element(e.begin(), e.end())},
            {"pm_max_error_pct_bbox",
             {{"p50", percentile(big, 0.5)}, {"p95", percentile(big, 0.95)}, {"max", percentile(big, 1.0)}}}};
}

}  // namespace

nlohmann::json runLearnDemo(const LearnDemoOptions& options) {
    namespace fs = std::filesystem;
    const Clock::time_point start = Clock::now();
    if (options.outDir.empty()) throw InputError("demo learn: --out is required");
    if (options.dataDir.empty()) throw InputError("demo learn: --data is required");
    if (options.sequences < 2 || options.novelSequences < 2 || options.minFrames < 8 ||
        options.maxFrames < options.minFrames ||
        !(options.trainingFraction > 0 && options.trainingFraction < 1) || options.basis < 1 ||
        options.maxKeys < 1 || options.maxKeys > 170 || !(options.tolerancePercent > 0) ||
        options.learnRank < options.basis || !(options.coverage > 0 && options.coverage < 1) ||
        options.threads < 0) {
        throw InputError(
            "demo learn: options out of range (sequences >= 2, novel >= 2, 8 <= minFrames <= maxFrames, "
            "0 < training fraction < 1, 1 <= keys <= 170, tolerance > 0, learn rank >= basis, "
            "0 < coverage < 1, threads >= 0)");
    }
    auto step = [&](std::string_view stage, double done, double total) {
        if (options.progress && !options.progress(stage, done, total)) throw Cancelled("demo learn");
    };
    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency());
    nlohmann::json report, seconds;

    // --- the face, the rig, the animation -------------------------------------------------------
    Clock::time_point t = Clock::now();
    step("load", 0, 1);
    const IctFace face = loadIctFace(options.dataDir);
    auto rig = std::make_shared<const FaceRig>(face);
    auto mesh = std::make_shared<const ObjMesh>(face.neutral);
    FaceAnimationOptions ao;
    ao.seed = options.seed;
    ao.sequences = options.sequences;
    ao.novelSequences = options.novelSequences;
    ao.minFrames = options.minFrames;
    ao.maxFrames = options.maxFrames;
    auto animation = std::make_shared<const FaceAnimation>(FaceAnimation::generate(ao));
    const FaceEvaluator evaluator(rig, animation, mesh);
    const Index n = rig->pointCount();
    const double percent = face.boundingBoxDiagonal() / 100.0;
    const double tolerance = options.tolerancePercent * percent;
    std::error_code ec;
    fs::create_directories(options.outDir, ec);
    if (ec || !fs::is_directory(options.outDir))
        throw IoError(options.outDir +
                      ": cannot create the output folder: " + (ec ? ec.message() : "not a folder"));
    const std::string out = options.outDir + "/";

    std::vector<Index> trainingSeqs, validationSeqs, day1Seqs, day2Seqs;
    animation->splitOrdinary(options.trainingFraction, options.seed + 4, trainingSeqs, validationSeqs);
    {
        std::vector<Index> novel;
        for (Index s = 0; s < static_cast<Index>(animation->sequences().size()); ++s)
            if (animation->sequences()[s].novel) novel.push_back(s);
        const size_t half = novel.size() / 2;
        day1Seqs.assign(novel.begin(), novel.begin() + static_cast<std::ptrdiff_t>(half));
        day2Seqs.assign(novel.begin() + static_cast<std::ptrdiff_t>(half), novel.end());
    }
    const std::vector<Index> trainingFrames = animation->framesOf(trainingSeqs);
    const std::vector<Index> day1Frames = animation->framesOf(day1Seqs);
    const std::vector<Index> day2Frames = animation->framesOf(day2Seqs);
    const std::vector<Index> validationFrames = animation->framesOf(validationSeqs);
    seconds["load"] = since(t);

    // --- training (the night before day 1) ------------------------------------------------------
    t = Clock::now();
    FrameSet training(static_cast<Index>(trainingFrames.size()), n, 3);
    {
        std::atomic<Index> posed{0};
        arena.execute([&] {
            tbb::parallel_for(size_t{0}, trainingFrames.size(), [&](size_t i) {
                evaluator.evaluateAll(trainingFrames[i], training.frame(static_cast<Index>(i)));
                ++posed;
            });
        });
        step("pose training", static_cast<double>(posed), static_cast<double>(trainingFrames.size()));
    }
    seconds["pose_training"] = since(t);
    TrainingOptions to;
    to.basis = options.basis;
    to.maxKeys = options.maxKeys;
    to.fiducials.assign(IctFace::multiPie68().begin(), IctFace::multiPie68().end());
    to.tolerance = tolerance;
    to.calibrationRule = options.conformal ? CalibrationRule::Conformal : CalibrationRule::MaxRatio;
    to.calibrationCoverage = options.coverage;
    to.learnRank = options.learnRank;
    t = Clock::now();
    TrainingReport day1Report;
    Model day1;
    arena.execute([&] { day1 = train(training, to, &day1Report); });
    seconds["train_day1"] = since(t);
    step("train", 1, 1);
    writeModel(out + "day1.pmsc", day1);
    // Both rules' eps from the same held-out frames and the same model (only eps differ).
    CalibrationStats oldRule = day1Report.calibration;
    setThresholds(oldRule, tolerance, CalibrationRule::MaxRatio, 0);
    std::vector<CalibrationStats> conformalRules;
    for (double coverage : {0.9, 0.95, 0.99}) {
        conformalRules.push_back(day1Report.calibration);
        setThresholds(conformalRules.back(), tolerance, CalibrationRule::Conformal, coverage);
    }

    // --- day 1: the shot through the soft cache, misses kept ------------------------------------
    t = Clock::now();
    const Probe day1Probe(day1);
    std::vector<Score> day1Scores(day1Frames.size());
    std::vector<std::vector<double>> keptValues(day1Frames.size());
    const SoftCachePolicy day1Policy(day1.epsMin, day1.epsMax);
    arena.execute([&] {
        tbb::parallel_for(size_t{0}, day1Frames.size(), [&](size_t i) {
            std::vector<double> full(static_cast<size_t>(3 * n));
            evaluator.evaluateAll(day1Frames[i], full.data());
            day1Scores[i] = day1Probe.score(full.data());
            if (day1Policy.decide(day1Scores[i].keyRms).state != CacheState::Hit)
                keptValues[i] = std::move(full);
        });
    });
    const std::string keptPath = out + "day1-misses.npy";
    fs::remove(keptPath, ec);
    fs::remove(KeptFrames::sidecarPath(keptPath), ec);
    Index keptCount = 0;
    {
        KeptFrames kept(keptPath, n, 3, NpyDtype::Float32, "demo learn day 1, model=day1.pmsc");
        for (size_t i = 0; i < day1Frames.size(); ++i) {
            if (keptValues[i].empty()) continue;
            const CacheDecision d = day1Policy.decide(day1Scores[i].keyRms);
            kept.add(day1Frames[i], d.state, day1Scores[i].keyRms, keptValues[i].data());
            std::vector<double>().swap(keptValues[i]);
        }
        keptCount = kept.count();
        kept.commit();
    }
    seconds["day1"] = since(t);
    step("day 1", 1, 1);
    if (keptCount == 0) throw InputError("demo learn: day 1 kept no frame; nothing to learn");

    // --- the night: learn from the kept frames; and, for comparison, train from scratch ----------
    const FrameSet misses = readFrames(keptPath).frames;  // what `pmsc learn --frames` would read
    t = Clock::now();
    LearnReport learnReport;
    Model day2;
    arena.execute([&] { day2 = learn(day1, misses, {}, &learnReport); });
    const double learnSeconds = since(t);
    writeModel(out + "day2.pmsc", day2);
    step("learn", 1, 1);
    FrameSet all(training.frames + misses.frames, n, 3);
    std::copy(training.values.begin(), training.values.end(), all.values.begin());
    std::copy(misses.values.begin(), misses.values.end(),
              all.values.begin() + static_cast<std::ptrdiff_t>(training.values.size()));
    std::vector<double>().swap(training.values);
    t = Clock::now();
    Model scratch;
    TrainingReport scratchReport;
    arena.execute([&] { scratch = train(all, to, &scratchReport); });
    const double scratchSeconds = since(t);
    std::vector<double>().swap(all.values);
    writeModel(out + "scratch.pmsc", scratch);
    step("train from scratch", 1, 1);

    // --- day 2 and validation through the three models ------------------------------------------
    const Probe day2Probe(day2), scratchProbe(scratch);
    struct Three {
        std::vector<Score> day1, day2, scratch;
    };
    auto scoreAll = [&](const std::vector<Index>& frames, const char* stage) {
        Three r;
        r.day1.resize(frames.size());
        r.day2.resize(frames.size());
        r.scratch.resize(frames.size());
        std::atomic<Index> done{0};
        arena.execute([&] {
            tbb::parallel_for(size_t{0}, frames.size(), [&](size_t i) {
                std::vector<double> full(static_cast<size_t>(3 * n));
                evaluator.evaluateAll(frames[i], full.data());
                r.day1[i] = day1Probe.score(full.data());
                r.day2[i] = day2Probe.score(full.data());
                r.scratch[i] = scratchProbe.score(full.data());
                const Index k = ++done;
                if (k % 64 == 0) step(stage, static_cast<double>(k), static_cast<double>(frames.size()));
            });
        });
        return r;
    };
    t = Clock::now();
    const Three day2Scores = scoreAll(day2Frames, "day 2");
    seconds["day2"] = since(t);
    t = Clock::now();
    const Three validation = scoreAll(validationFrames, "validation");
    seconds["validation"] = since(t);

    // --- the report -------------------------------------------------------------------------------
    report["points"] = n;
    report["tolerance"] = tolerance;
    report["tolerance_pct_bbox"] = options.tolerancePercent;
    report["frames"] = {{"training", trainingFrames.size()},
                        {"day1", day1Frames.size()},
                        {"day1_kept", keptCount},
                        {"day2", day2Frames.size()},
                        {"validation", validationFrames.size()}};
    nlohmann::json novel = nlohmann::json::array();
    for (const auto* set : {&day1Seqs, &day2Seqs})
        for (Index s : *set) {
            nlohmann::json controls = nlohmann::json::array();
            for (int c : animation->sequences()[s].novelControls)
                controls.push_back(std::string(controlName(c)));
            novel.push_back({{"sequence", animation->sequences()[s].name},
                             {"day", set == &day1Seqs ? 1 : 2},
                             {"frames", animation->sequences()[s].frameCount},
                             {"novel_controls", controls}});
        }
    report["novel_sequences"] = novel;
    auto modelJson = [&](const Model& m) {
        return nlohmann::json{{"basis", m.basisSize()},        {"key_points", m.keyCount()},
                              {"train_frames", m.trainFrames}, {"eps_min", m.epsMin},
                              {"eps_max", m.epsMax},           {"energy_captured", m.energyCaptured()}};
    };
    report["models"] = {
        {"day1", modelJson(day1)}, {"day2_learned", modelJson(day2)}, {"scratch", modelJson(scratch)}};
    report["day1"] = summarize(day1Scores, day1, percent);
    report["day2"] = {{"day1_model", summarize(day2Scores.day1, day1, percent)},
                      {"learned_model", summarize(day2Scores.day2, day2, percent)},
                      {"scratch_model", summarize(day2Scores.scratch, scratch, percent)}};
    report["validation"] = {{"day1_model", summarize(validation.day1, day1, percent)},
                            {"learned_model", summarize(validation.day2, day2, percent)},
                            {"scratch_model", summarize(validation.scratch, scratch, percent)}};
    const Index commonM = std::min(day2.basisSize(), scratch.basisSize());
    report["learn_vs_scratch"] = {
        {"largest_principal_angle_deg",
         largestPrincipalAngle(scratch.basis.leftCols(commonM), day2.basis.leftCols(commonM)) * 180.0 /
             3.141592653589793},
        {"keys_shared",
         [&] {
             Index shared = 0;
             for (Index k : day2.keyPoints)
                 shared += std::find(scratch.keyPoints.begin(), scratch.keyPoints.end(), k) !=
                           scratch.keyPoints.end();
             return shared;
         }()},
        {"learn_seconds", learnSeconds},
        {"scratch_train_seconds", scratchSeconds},
        {"learn_stage_seconds",
         {{"subspace", learnReport.secondsSubspace},
          {"keys", learnReport.secondsKeys},
          {"calibration", learnReport.secondsCalibration}}},
        {"state_rank", learnReport.rankAfter},
        {"state_tail_norm", learnReport.tailNorm},
        {"calibration_ratio_new_frames", learnReport.calibrationRatioNew},
        {"calibration_ratio_stored", learnReport.calibrationRatioOld},
        {"warnings", learnReport.warnings}};
    // Calibration: the old rule and the new on the same model and held-out frames, against the
    // oracle threshold, on the validation set and on day 2's shot.
    auto compare = [&](const std::vector<Score>& scores) {
        const auto [threshold, bestHits] = bestThreshold(scores, tolerance);
        const double count = static_cast<double>(scores.size());
        auto rule = [&](const CalibrationStats& c) {
            const Outcome o = outcome(scores, c.epsMin, c.epsMax, tolerance);
            nlohmann::json j = {
                {"eps_min", c.epsMin},
                {"ratio", c.ratio},
                {"hits", o.hits},
                {"hit_rate", static_cast<double>(o.hits) / count},
                {"share_of_best",
                 bestHits > 0 ? static_cast<double>(o.hits) / static_cast<double>(bestHits) : 0.0},
                {"frames_over_tolerance", o.overTolerance},
                {"soft_max_error_pct_bbox", o.softMax / percent}};
            if (c.rule == CalibrationRule::Conformal) j["coverage"] = c.coverage;
            return j;
        };
        nlohmann::json conformal = nlohmann::json::array();
        for (const auto& c : conformalRules) conformal.push_back(rule(c));
        return nlohmann::json{{"frames", scores.size()},
                              {"best_single_threshold",
                               {{"threshold", threshold},
                                {"hits", bestHits},
                                {"hit_rate", static_cast<double>(bestHits) / count}}},
                              {"max_rule", rule(oldRule)},
                              {"conformal_rule", conformal}};
    };
    report["calibration"] = {{"held_out_frames", day1Report.calibration.keyRms.size()},
                             {"validation", compare(validation.day1)},
                             {"day1_shot", compare(day1Scores)},
                             {"day2_shot", compare(day2Scores.day1)}};
    report["day1"]["frames_over_tolerance"] =
        outcome(day1Scores, day1.epsMin, day1.epsMax, tolerance).overTolerance;
    report["day2"]["learned_model"]["frames_over_tolerance"] =
        outcome(day2Scores.day2, day2.epsMin, day2.epsMax, tolerance).overTolerance;
    report["validation"]["learned_model"]["frames_over_tolerance"] =
        outcome(validation.day2, day2.epsMin, day2.epsMax, tolerance).overTolerance;
    seconds["total"] = since(start);
    report["seconds"] = seconds;

    // frames.csv: one row per frame of day 1, day 2 and validation.
    std::ostringstream csv;
    csv << "set,frame,day1_key_rms,day1_pm_max_pct,day2_key_rms,day2_pm_max_pct,scratch_key_rms,scratch_pm_"
           "max_pct\n";
    char line[256];
    for (size_t i = 0; i < day1Frames.size(); ++i) {
        std::snprintf(line, sizeof line, "day1,%ld,%.6g,%.6g,,,,\n", static_cast<long>(day1Frames[i]),
                      day1Scores[i].keyRms, day1Scores[i].pmMax / percent);
        csv << line;
    }
    auto rows = [&](const char* name, const std::vector<Index>& frames, const Three& s) {
        for (size_t i = 0; i < frames.size(); ++i) {
            std::snprintf(line, sizeof line, "%s,%ld,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g\n", name,
                          static_cast<long>(frames[i]), s.day1[i].keyRms, s.day1[i].pmMax / percent,
                          s.day2[i].keyRms, s.day2[i].pmMax / percent, s.scratch[i].keyRms,
                          s.scratch[i].pmMax / percent);
            csv << line;
        }
    };
    rows("day2", day2Frames, day2Scores);
    rows("validation", validationFrames, validation);
    writeFileAtomically(out + "frames.csv", csv.str());
    writeFileAtomically(out + "report.json", report.dump(2) + "\n");
    return report;
}

}  // namespace pmsc::face
