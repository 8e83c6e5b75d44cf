#include "examples/face/LearnDemo.h"

#include "evaluators/face/FaceEvaluator.h"
#include "examples/common/DemoSetup.h"
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

using examples::createOutputFolder;
using examples::DemoClock;
using examples::DemoSetup;
using examples::FolderErrorWording;
using examples::secondsSince;

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
        s.keyRms = pm_.keyError(keys.data(), coords.data());
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
// (a blend mixes w of the full pose in, more where PM is over the tolerance: blendedError; a miss is
// the full pose).
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
        const double soft = blendedError(d.weight, s.pmMax, tolerance);
        o.softMax = std::max(o.softMax, soft);
        o.overTolerance += tolerance > 0 && soft > tolerance;
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
    const Outcome o = outcome(scores, model.epsMin, model.epsMax, model.tolerance);
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

// --- the steps of runLearnDemo, in the order it runs them ------------------------------------

/// Throws InputError unless the options are usable.
void checkOptions(const LearnDemoOptions& options) {
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
}

/// The face, its rig and the animation, and the units errors are stated in.
struct LearnScene {
    std::shared_ptr<const FaceRig> rig;
    std::shared_ptr<const ObjMesh> mesh;
    std::shared_ptr<const FaceAnimation> animation;
    FaceEvaluator evaluator;
    Index n = 0;           // points
    double percent = 0;    // model units per % of the head diagonal
    double tolerance = 0;  // T
};

/// Loads the face, builds the rig and generates the animation.
LearnScene loadScene(const DemoSetup& run, const LearnDemoOptions& options) {
    run.progress("load", 0, 1);
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
    const double percent = face.boundingBoxDiagonal() / 100.0;
    return LearnScene{rig,
                      mesh,
                      animation,
                      FaceEvaluator(rig, animation, mesh),
                      rig->pointCount(),
                      percent,
                      options.tolerancePercent * percent};
}

/// Sequences by use (day 1's shot: the first half of the novel ones, day 2's: the second) and
/// their frames.
struct Split {
    std::vector<Index> trainingSeqs, validationSeqs, day1Seqs, day2Seqs;
    std::vector<Index> trainingFrames, day1Frames, day2Frames, validationFrames;
};

/// Splits the sequences as `pmsc demo face` does, the novel ones between the two days.
Split splitSequences(const LearnDemoOptions& options, const FaceAnimation& animation) {
    Split s;
    animation.splitOrdinary(options.trainingFraction, options.seed + 4, s.trainingSeqs, s.validationSeqs);
    std::vector<Index> novel;
    for (Index q = 0; q < static_cast<Index>(animation.sequences().size()); ++q)
        if (animation.sequences()[q].novel) novel.push_back(q);
    const size_t half = novel.size() / 2;
    s.day1Seqs.assign(novel.begin(), novel.begin() + static_cast<std::ptrdiff_t>(half));
    s.day2Seqs.assign(novel.begin() + static_cast<std::ptrdiff_t>(half), novel.end());
    s.trainingFrames = animation.framesOf(s.trainingSeqs);
    s.day1Frames = animation.framesOf(s.day1Seqs);
    s.day2Frames = animation.framesOf(s.day2Seqs);
    s.validationFrames = animation.framesOf(s.validationSeqs);
    return s;
}

/// The training frames, fully posed.
FrameSet poseTrainingFrames(DemoSetup& run, const LearnScene& scene,
                            const std::vector<Index>& trainingFrames) {
    const DemoClock::time_point t = DemoClock::now();
    FrameSet training(static_cast<Index>(trainingFrames.size()), scene.n, 3);
    std::atomic<Index> posed{0};
    run.arena.execute([&] {
        tbb::parallel_for(size_t{0}, trainingFrames.size(), [&](size_t i) {
            scene.evaluator.evaluateAll(trainingFrames[i], training.frame(static_cast<Index>(i)));
            ++posed;
        });
    });
    run.progress("pose training", static_cast<double>(posed), static_cast<double>(trainingFrames.size()));
    run.lap("pose_training", t);
    return training;
}

/// How the day-1 model (and the scratch one) is trained.
TrainingOptions trainingOptions(const LearnDemoOptions& options, double tolerance) {
    TrainingOptions to;
    to.basis = options.basis;
    to.maxKeys = options.maxKeys;
    to.fiducials.assign(IctFace::multiPie68().begin(), IctFace::multiPie68().end());
    to.tolerance = tolerance;
    to.calibrationRule = options.conformal ? CalibrationRule::Conformal : CalibrationRule::MaxRatio;
    // The nightly loop compares its calibration rules on the paper's key RMS
    // (docs/learning-and-calibration.md); `pmsc train` measures the largest key by default.
    to.keyErrorNorm = KeyErrorNorm::Rms;
    to.calibrationCoverage = options.coverage;
    to.learnRank = options.learnRank;
    return to;
}

/// The day-1 model and its eps by both calibration rules.
struct Day1Model {
    TrainingReport report;
    Model model;
    CalibrationStats oldRule;                      // the max rule
    std::vector<CalibrationStats> conformalRules;  // coverages 0.9, 0.95, 0.99
};

/// Training (the night before day 1): the day-1 model, written as day1.pmsc.
Day1Model trainDay1(DemoSetup& run, const FrameSet& training, const TrainingOptions& to, double tolerance,
                    const std::string& out) {
    const DemoClock::time_point t = DemoClock::now();
    Day1Model d;
    run.arena.execute([&] { d.model = train(training, to, &d.report); });
    run.lap("train_day1", t);
    run.progress("train", 1, 1);
    writeModel(out + "day1.pmsc", d.model);
    // Both rules' eps from the same held-out frames and the same model (only eps differ).
    d.oldRule = d.report.calibration;
    setThresholds(d.oldRule, tolerance, CalibrationRule::MaxRatio, 0);
    for (double coverage : {0.9, 0.95, 0.99}) {
        d.conformalRules.push_back(d.report.calibration);
        setThresholds(d.conformalRules.back(), tolerance, CalibrationRule::Conformal, coverage);
    }
    return d;
}

/// Day 1's shot: its scores and the frames that were kept (blends and misses).
struct Day1Shot {
    std::vector<Score> scores;
    std::string keptPath;  // day1-misses.npy
    Index keptCount = 0;
};

/// Day 1's kept frames into `shot.keptPath` (replacing an earlier run's); frees `keptValues`.
void writeKeptFrames(const LearnScene& scene, const std::vector<Index>& day1Frames,
                     const SoftCachePolicy& policy, std::vector<std::vector<double>>& keptValues,
                     Day1Shot& shot) {
    namespace fs = std::filesystem;
    std::error_code ec;
    fs::remove(shot.keptPath, ec);
    fs::remove(KeptFrames::sidecarPath(shot.keptPath), ec);
    KeptFrames kept(shot.keptPath, scene.n, 3, NpyDtype::Float32, "demo learn day 1, model=day1.pmsc");
    for (size_t i = 0; i < day1Frames.size(); ++i) {
        if (keptValues[i].empty()) continue;
        const CacheDecision d = policy.decide(shot.scores[i].keyRms);
        kept.add(day1Frames[i], d.state, shot.scores[i].keyRms, keptValues[i].data());
        std::vector<double>().swap(keptValues[i]);
    }
    shot.keptCount = kept.count();
    kept.commit();
}

/// Day 1: the shot through the soft cache, misses kept.
Day1Shot runDay1(DemoSetup& run, const LearnScene& scene, const Model& day1,
                 const std::vector<Index>& day1Frames, const std::string& out) {
    const DemoClock::time_point t = DemoClock::now();
    const Probe day1Probe(day1);
    Day1Shot shot;
    shot.scores.resize(day1Frames.size());
    std::vector<std::vector<double>> keptValues(day1Frames.size());
    const SoftCachePolicy day1Policy(day1.epsMin, day1.epsMax);
    run.arena.execute([&] {
        tbb::parallel_for(size_t{0}, day1Frames.size(), [&](size_t i) {
            std::vector<double> full(static_cast<size_t>(3 * scene.n));
            scene.evaluator.evaluateAll(day1Frames[i], full.data());
            shot.scores[i] = day1Probe.score(full.data());
            if (day1Policy.decide(shot.scores[i].keyRms).state != CacheState::Hit)
                keptValues[i] = std::move(full);
        });
    });
    shot.keptPath = out + "day1-misses.npy";
    writeKeptFrames(scene, day1Frames, day1Policy, keptValues, shot);
    run.lap("day1", t);
    run.progress("day 1", 1, 1);
    if (shot.keptCount == 0) throw InputError("demo learn: day 1 kept no frame; nothing to learn");
    return shot;
}

/// The night's two models: learned from the kept frames, and trained from scratch for comparison.
struct NightModels {
    LearnReport learnReport;
    Model day2;
    double learnSeconds = 0;
    Model scratch;
    double scratchSeconds = 0;
};

/// The night: learn from the kept frames; and, for comparison, train from scratch on the training
/// frames and the kept ones (frees `training`).
NightModels learnAtNight(DemoSetup& run, const LearnScene& scene, const Model& day1, const FrameSet& misses,
                         FrameSet& training, const TrainingOptions& to, const std::string& out) {
    NightModels night;
    DemoClock::time_point t = DemoClock::now();
    run.arena.execute([&] { night.day2 = learn(day1, misses, {}, &night.learnReport); });
    night.learnSeconds = secondsSince(t);
    writeModel(out + "day2.pmsc", night.day2);
    run.progress("learn", 1, 1);
    FrameSet all(training.frames + misses.frames, scene.n, 3);
    std::copy(training.values.begin(), training.values.end(), all.values.begin());
    std::copy(misses.values.begin(), misses.values.end(),
              all.values.begin() + static_cast<std::ptrdiff_t>(training.values.size()));
    decltype(training.values)().swap(training.values);
    t = DemoClock::now();
    TrainingReport scratchReport;
    run.arena.execute([&] { night.scratch = train(all, to, &scratchReport); });
    night.scratchSeconds = secondsSince(t);
    decltype(all.values)().swap(all.values);
    writeModel(out + "scratch.pmsc", night.scratch);
    run.progress("train from scratch", 1, 1);
    return night;
}

/// One set of frames scored by the three models.
struct Three {
    std::vector<Score> day1, day2, scratch;
};

/// Poses `frames` fully and scores them with the day-1, day-2 and scratch models; the seconds
/// taken go to timings[timing].
Three scoreWithThree(DemoSetup& run, const LearnScene& scene, const Probe& day1Probe, const Probe& day2Probe,
                     const Probe& scratchProbe, const std::vector<Index>& frames, const char* stage,
                     const char* timing) {
    const DemoClock::time_point t = DemoClock::now();
    Three r;
    r.day1.resize(frames.size());
    r.day2.resize(frames.size());
    r.scratch.resize(frames.size());
    std::atomic<Index> done{0};
    run.arena.execute([&] {
        tbb::parallel_for(size_t{0}, frames.size(), [&](size_t i) {
            std::vector<double> full(static_cast<size_t>(3 * scene.n));
            scene.evaluator.evaluateAll(frames[i], full.data());
            r.day1[i] = day1Probe.score(full.data());
            r.day2[i] = day2Probe.score(full.data());
            r.scratch[i] = scratchProbe.score(full.data());
            const Index k = ++done;
            if (k % 64 == 0) run.progress(stage, static_cast<double>(k), static_cast<double>(frames.size()));
        });
    });
    run.lap(timing, t);
    return r;
}

/// The report's table of the novel sequences of both days.
nlohmann::json novelSequences(const FaceAnimation& animation, const Split& split) {
    nlohmann::json novel = nlohmann::json::array();
    for (const auto* set : {&split.day1Seqs, &split.day2Seqs})
        for (Index s : *set) {
            nlohmann::json controls = nlohmann::json::array();
            for (int c : animation.sequences()[s].novelControls)
                controls.push_back(std::string(controlName(c)));
            novel.push_back({{"sequence", animation.sequences()[s].name},
                             {"day", set == &split.day1Seqs ? 1 : 2},
                             {"frames", animation.sequences()[s].frameCount},
                             {"novel_controls", controls}});
        }
    return novel;
}

/// A model's size and calibration, for the report.
nlohmann::json modelJson(const Model& m) {
    return nlohmann::json{{"basis", m.basisSize()},        {"key_points", m.keyCount()},
                          {"train_frames", m.trainFrames}, {"eps_min", m.epsMin},
                          {"eps_max", m.epsMax},           {"energy_captured", m.energyCaptured()}};
}

/// The report's comparison of the learned model with the one trained from scratch.
nlohmann::json learnVersusScratch(const NightModels& night) {
    const Model &day2 = night.day2, &scratch = night.scratch;
    const LearnReport& learnReport = night.learnReport;
    const Index commonM = std::min(day2.basisSize(), scratch.basisSize());
    Index shared = 0;
    for (Index k : day2.keyPoints)
        shared += std::find(scratch.keyPoints.begin(), scratch.keyPoints.end(), k) != scratch.keyPoints.end();
    return {{"largest_principal_angle_deg",
             largestPrincipalAngle(scratch.basis.leftCols(commonM), day2.basis.leftCols(commonM)) * 180.0 /
                 3.141592653589793},
            {"keys_shared", shared},
            {"learn_seconds", night.learnSeconds},
            {"scratch_train_seconds", night.scratchSeconds},
            {"learn_stage_seconds",
             {{"subspace", learnReport.secondsSubspace},
              {"keys", learnReport.secondsKeys},
              {"calibration", learnReport.secondsCalibration}}},
            {"state_rank", learnReport.rankAfter},
            {"state_tail_norm", learnReport.tailNorm},
            {"calibration_ratio_new_frames", learnReport.calibrationRatioNew},
            {"calibration_ratio_stored", learnReport.calibrationRatioOld},
            {"warnings", learnReport.warnings}};
}

/// Calibration: the max rule and the conformal one on the same model and held-out frames, against
/// the oracle threshold, on one set of frames.
nlohmann::json compareCalibration(const std::vector<Score>& scores, const Day1Model& d, double tolerance,
                                  double percent) {
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
    for (const auto& c : d.conformalRules) conformal.push_back(rule(c));
    return nlohmann::json{
        {"frames", scores.size()},
        {"best_single_threshold",
         {{"threshold", threshold}, {"hits", bestHits}, {"hit_rate", static_cast<double>(bestHits) / count}}},
        {"max_rule", rule(d.oldRule)},
        {"conformal_rule", conformal}};
}

/// What the three models made of day 1, day 2 and the validation frames.
struct Scores {
    const std::vector<Score>& day1;
    const Three& day2;
    const Three& validation;
};

/// The report: frames, novel sequences, models, their scores, learning against training, calibration.
nlohmann::json makeReport(const LearnDemoOptions& options, const LearnScene& scene, const Split& split,
                          Index keptCount, const Day1Model& d1, const NightModels& night, const Scores& s) {
    const double percent = scene.percent, tolerance = scene.tolerance;
    const Model &day1 = d1.model, &day2 = night.day2, &scratch = night.scratch;
    nlohmann::json report;
    report["points"] = scene.n;
    report["tolerance"] = tolerance;
    report["tolerance_pct_bbox"] = options.tolerancePercent;
    report["frames"] = {{"training", split.trainingFrames.size()},
                        {"day1", split.day1Frames.size()},
                        {"day1_kept", keptCount},
                        {"day2", split.day2Frames.size()},
                        {"validation", split.validationFrames.size()}};
    report["novel_sequences"] = novelSequences(*scene.animation, split);
    report["models"] = {
        {"day1", modelJson(day1)}, {"day2_learned", modelJson(day2)}, {"scratch", modelJson(scratch)}};
    report["day1"] = summarize(s.day1, day1, percent);
    report["day2"] = {{"day1_model", summarize(s.day2.day1, day1, percent)},
                      {"learned_model", summarize(s.day2.day2, day2, percent)},
                      {"scratch_model", summarize(s.day2.scratch, scratch, percent)}};
    report["validation"] = {{"day1_model", summarize(s.validation.day1, day1, percent)},
                            {"learned_model", summarize(s.validation.day2, day2, percent)},
                            {"scratch_model", summarize(s.validation.scratch, scratch, percent)}};
    report["learn_vs_scratch"] = learnVersusScratch(night);
    report["calibration"] = {{"held_out_frames", d1.report.calibration.keyRms.size()},
                             {"validation", compareCalibration(s.validation.day1, d1, tolerance, percent)},
                             {"day1_shot", compareCalibration(s.day1, d1, tolerance, percent)},
                             {"day2_shot", compareCalibration(s.day2.day1, d1, tolerance, percent)}};
    report["day1"]["frames_over_tolerance"] =
        outcome(s.day1, day1.epsMin, day1.epsMax, tolerance).overTolerance;
    report["day2"]["learned_model"]["frames_over_tolerance"] =
        outcome(s.day2.day2, day2.epsMin, day2.epsMax, tolerance).overTolerance;
    report["validation"]["learned_model"]["frames_over_tolerance"] =
        outcome(s.validation.day2, day2.epsMin, day2.epsMax, tolerance).overTolerance;
    return report;
}

/// frames.csv: one row per frame of day 1, day 2 and validation.
void writeFramesCsv(const std::string& path, const Split& split, const Scores& s, double percent) {
    std::ostringstream csv;
    csv << "set,frame,day1_key_rms,day1_pm_max_pct,day2_key_rms,day2_pm_max_pct,scratch_key_rms,scratch_pm_"
           "max_pct\n";
    char line[256];
    for (size_t i = 0; i < split.day1Frames.size(); ++i) {
        std::snprintf(line, sizeof line, "day1,%ld,%.6g,%.6g,,,,\n", static_cast<long>(split.day1Frames[i]),
                      s.day1[i].keyRms, s.day1[i].pmMax / percent);
        csv << line;
    }
    auto rows = [&](const char* name, const std::vector<Index>& frames, const Three& t) {
        for (size_t i = 0; i < frames.size(); ++i) {
            std::snprintf(line, sizeof line, "%s,%ld,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g\n", name,
                          static_cast<long>(frames[i]), t.day1[i].keyRms, t.day1[i].pmMax / percent,
                          t.day2[i].keyRms, t.day2[i].pmMax / percent, t.scratch[i].keyRms,
                          t.scratch[i].pmMax / percent);
            csv << line;
        }
    };
    rows("day2", split.day2Frames, s.day2);
    rows("validation", split.validationFrames, s.validation);
    writeFileAtomically(path, csv.str());
}

}  // namespace

nlohmann::json runLearnDemo(const LearnDemoOptions& options) {
    const DemoClock::time_point start = DemoClock::now();
    checkOptions(options);
    DemoSetup run(options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency(),
                  options.progress, "demo learn", start);

    // --- the face, the rig, the animation -------------------------------------------------------
    const DemoClock::time_point t = DemoClock::now();
    const LearnScene scene = loadScene(run, options);
    createOutputFolder(options.outDir, FolderErrorWording::OutputFolder);
    const std::string out = options.outDir + "/";
    const Split split = splitSequences(options, *scene.animation);
    run.lap("load", t);

    // --- training (the night before day 1), day 1, the night ---------------------------------------
    FrameSet training = poseTrainingFrames(run, scene, split.trainingFrames);
    const TrainingOptions to = trainingOptions(options, scene.tolerance);
    const Day1Model d1 = trainDay1(run, training, to, scene.tolerance, out);
    const Day1Shot day1Shot = runDay1(run, scene, d1.model, split.day1Frames, out);
    const FrameSet misses = readFrames(day1Shot.keptPath).frames;  // what `pmsc learn --frames` would read
    const NightModels night = learnAtNight(run, scene, d1.model, misses, training, to, out);

    // --- day 2 and validation through the three models ------------------------------------------
    const Probe day1Probe(d1.model), day2Probe(night.day2), scratchProbe(night.scratch);
    const Three day2Scores =
        scoreWithThree(run, scene, day1Probe, day2Probe, scratchProbe, split.day2Frames, "day 2", "day2");
    const Three validation = scoreWithThree(run, scene, day1Probe, day2Probe, scratchProbe,
                                            split.validationFrames, "validation", "validation");

    const Scores scores{day1Shot.scores, day2Scores, validation};
    nlohmann::json report = makeReport(options, scene, split, day1Shot.keptCount, d1, night, scores);
    report["seconds"] = run.finish();
    writeFramesCsv(out + "frames.csv", split, scores, scene.percent);
    writeFileAtomically(out + "report.json", report.dump(2) + "\n");
    return report;
}

}  // namespace pmsc::face
