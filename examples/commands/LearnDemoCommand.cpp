// `pmsc demo learn`: the nightly loop of paper section 5 on the ICT face. The experiment
// lives in examples/face (LearnDemo.h); this file parses options, shows progress and prints the summary.
#include "app/ExitCodes.h"
#include "cli/Args.h"
#include "cli/CommandRegistry.h"
#include "cli/Progress.h"
#include "examples/commands/DemoCommands.h"
#include "examples/face/LearnDemo.h"

#include <cstdio>
#include <string>

namespace pmsc::demos {

using namespace pmsc::app;
using namespace pmsc::cli;

namespace {

/// What the nightly loop did, from its report: day 1, day 2 through the three models, the
/// validation sequences, learn against retraining, the calibration rules.
void printLearnDemoSummary(const nlohmann::json& r, const std::string& out) {
    auto rate = [](const nlohmann::json& s) { return 100.0 * s.at("hit_rate").get<double>(); };
    auto soft = [](const nlohmann::json& s) { return s.at("soft_max_error_pct_bbox").get<double>(); };
    auto pm = [](const nlohmann::json& s, const char* q) {
        return s.at("pm_max_error_pct_bbox").at(q).get<double>();
    };
    const auto& f = r.at("frames");
    std::printf("nightly loop on the ICT face: tolerance %.2f%% of the head diagonal, %ld training frames\n",
                r.at("tolerance_pct_bbox").get<double>(), f.at("training").get<long>());
    std::printf(
        "  day 1   %4ld frames, day-1 model:   hit %5.1f%%, soft-cached max %.3f%%; kept %ld frames\n",
        f.at("day1").get<long>(), rate(r.at("day1")), soft(r.at("day1")), f.at("day1_kept").get<long>());
    const auto& d2 = r.at("day2");
    std::printf(
        "  day 2   %4ld frames, day-1 model:   hit %5.1f%%, soft-cached max %.3f%%, PM max p50 %.3f%%\n",
        f.at("day2").get<long>(), rate(d2.at("day1_model")), soft(d2.at("day1_model")),
        pm(d2.at("day1_model"), "p50"));
    std::printf(
        "                        learned model: hit %5.1f%%, soft-cached max %.3f%%, PM max p50 %.3f%% max "
        "%.3f%%\n",
        rate(d2.at("learned_model")), soft(d2.at("learned_model")), pm(d2.at("learned_model"), "p50"),
        pm(d2.at("learned_model"), "max"));
    std::printf(
        "                        scratch model: hit %5.1f%%, soft-cached max %.3f%%, PM max p50 %.3f%% max "
        "%.3f%%\n",
        rate(d2.at("scratch_model")), soft(d2.at("scratch_model")), pm(d2.at("scratch_model"), "p50"),
        pm(d2.at("scratch_model"), "max"));
    const auto& v = r.at("validation");
    std::printf(
        "  valid.  %4ld frames: hit day-1 %.1f%%, learned %.1f%%, scratch %.1f%%; soft-cached max %.3f%% / "
        "%.3f%% / %.3f%%\n",
        f.at("validation").get<long>(), rate(v.at("day1_model")), rate(v.at("learned_model")),
        rate(v.at("scratch_model")), soft(v.at("day1_model")), soft(v.at("learned_model")),
        soft(v.at("scratch_model")));
    const auto& ls = r.at("learn_vs_scratch");
    std::printf(
        "  learn   %.2f s vs training from scratch %.2f s (%.1fx); largest angle between the bases %.2f "
        "deg\n",
        ls.at("learn_seconds").get<double>(), ls.at("scratch_train_seconds").get<double>(),
        ls.at("scratch_train_seconds").get<double>() / ls.at("learn_seconds").get<double>(),
        ls.at("largest_principal_angle_deg").get<double>());
    for (const char* set : {"validation", "day1_shot", "day2_shot"}) {
        const auto& c = r.at("calibration").at(set);
        std::printf(
            "  calibration, day-1 model, %-10s best single threshold %4ld hits; max rule %4ld (%ld over T)",
            set, c.at("best_single_threshold").at("hits").get<long>(),
            c.at("max_rule").at("hits").get<long>(),
            c.at("max_rule").at("frames_over_tolerance").get<long>());
        for (const auto& k : c.at("conformal_rule"))
            std::printf("; conformal %.2f %4ld (%ld over T)", k.at("coverage").get<double>(),
                        k.at("hits").get<long>(), k.at("frames_over_tolerance").get<long>());
        std::printf("\n");
    }
    std::printf(
        "  wrote   %s/report.json, frames.csv, day1.pmsc, day2.pmsc, scratch.pmsc, day1-misses.npy  [%.0f "
        "s]\n",
        out.c_str(), r.at("seconds").at("total").get<double>());
}

}  // namespace

int runDemoLearn(const std::vector<std::string>& args) {
    std::string data, out;
    bool quick = false, quiet = false;
    face::LearnDemoOptions o;
    int threads = 0;
    double tolerance = 0, coverage = 0;
    ArgParser parser(
        "demo learn",
        "--data DIR --out DIR2 [--quick] [--threads T] [--tolerance PCT] [--coverage C] [--quiet]",
        "The nightly loop of paper section 5 on the ICT face: a model trained on the face demo's\n"
        "training sequences runs day 1's shot (sequences moving controls training never saw) and keeps\n"
        "its misses; `pmsc learn` updates the model with them overnight (timed against training from\n"
        "scratch on everything); day 2's shot (the same controls, other performances) runs through the\n"
        "day-1, learned and scratch models. Also compares the calibration rules on the validation\n"
        "sequences. Writes DIR2/report.json, frames.csv, day1/day2/scratch.pmsc, day1-misses.npy.");
    parser.option("--data", "DIR", "the ICT-FaceKit FaceXModel folder", data, true);
    parser.option("--out", "DIR2", "output folder (created if missing)", out, true);
    parser.option("--threads", "T", "worker threads (default: every core)", [&](const std::string& v) {
        threads = static_cast<int>(parseIndex("--threads", v, 1, 1024));
    });
    parser.option("--tolerance", "PCT", "largest error of a hit, % of the head diagonal (default 1)",
                  [&](const std::string& v) { tolerance = parseDouble("--tolerance", v, 0.001, 100); });
    std::string rule;
    parser.option("--calibration", "RULE", "rule of the loop's models: max (default) or conformal", rule);
    parser.option("--coverage", "C", "coverage of --calibration conformal (default 0.9)",
                  [&](const std::string& v) {
                      coverage = parseDouble("--coverage", v, 0.0, 1.0);
                      if (!(coverage > 0 && coverage < 1))
                          throw UsageError("--coverage: must be in (0, 1), got " + v);
                  });
    parser.flag("--quick", "short sequences, smaller model: a smoke test of the whole loop", quick);
    parser.flag("--quiet", "no progress display", quiet);
    if (!parser.parse(args)) return kExitOk;
    if (quick) o = face::LearnDemoOptions::quickOptions();
    if (!rule.empty() && rule != "max" && rule != "conformal")
        parser.fail("--calibration: '" + rule + "' is not max or conformal");
    o.conformal = rule == "conformal";
    o.dataDir = data;
    o.outDir = out;
    o.threads = threads;
    if (tolerance > 0) o.tolerancePercent = tolerance;
    if (coverage > 0) o.coverage = coverage;
    Progress progress("demo learn", !quiet);
    o.progress = [&](std::string_view stage, double done, double total) {
        return progress.update(stage, done, total);
    };
    const nlohmann::json r = face::runLearnDemo(o);
    progress.finish();

    printLearnDemoSummary(r, out);
    return kExitOk;
}

// `pmsc demo learn` and the line `pmsc --help` shows for it.
const cli::CommandRegistration kDemoLearn{
    {"demo learn", "section 5: the nightly loop on the ICT face, misses kept and learned, day 1 vs day 2",
     runDemoLearn}};

}  // namespace pmsc::demos
