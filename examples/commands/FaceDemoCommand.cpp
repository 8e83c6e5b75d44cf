// `pmsc demo face`: section 7's experiment — a face rig with nonlinear deformers on the ICT face,
// trained on a third of the animation's sequences, the rest (and sequences that move controls
// never seen in training) through the soft-cache engine with the rig as the evaluator.
// The experiment itself lives in examples/face (FaceDemo.h); this file parses options, shows
// progress and prints the summary.
#include "app/ExitCodes.h"
#include "app/Train.h"
#include "cli/Args.h"
#include "cli/CommandRegistry.h"
#include "cli/Progress.h"
#include "examples/commands/DemoCommands.h"
#include "examples/face/FaceDemo.h"
#include "pmsc/Calibration.h"
#include "pmsc/KeyError.h"

#include <cstdio>
#include <optional>
#include <string>

namespace pmsc::demos {

using namespace pmsc::app;
using namespace pmsc::cli;

namespace {

// report.json's "local_fail_through" (FaceLocalReport.h), one line per set and way.
void printFaceLocalFailThrough(const nlohmann::json& local) {
    std::printf("  local fail-through: %ld regions, %ld region keys, feather %.2f%% of the head diagonal\n",
                local.at("regions").get<long>(), local.at("region_keys").get<long>(),
                local.at("feather_width_pct_bbox").get<double>());
    for (const char* set : {"validation", "novel", "mixed"}) {
        if (!local.contains(set)) continue;
        const nlohmann::json& s = local.at(set);
        for (const char* way : {"local", "whole_frame"}) {
            const nlohmann::json& w = s.at(way);
            std::printf(
                "    %-10s %-11s %4ld frames, hit %5.1f%%: points evaluated %5.1f%% (non-hit frames "
                "%5.1f%%), "
                "soft-cached max error %.3f%%, speedup %.2fx\n",
                set, way, s.at("frames").get<long>(), 100 * s.at("hit_rate").get<double>(),
                100 * w.at("points_evaluated_fraction_mean").get<double>(),
                100 * w.at("points_evaluated_fraction_non_hit_mean").get<double>(),
                w.at("soft_max_error_pct_bbox_max").get<double>(),
                s.at(std::string("local") == way ? "speedup_local" : "speedup_whole_frame").get<double>());
        }
    }
}

/// What the face demo did, from its report: sizes, calibration, validation, novel frames, speed.
void printFaceDemoSummary(const nlohmann::json& r, const std::string& out) {
    auto num = [&](const char* key) { return r.at(key).get<double>(); };
    std::printf(
        "ICT face (section 7): %ld points, %ld key points (%ld Multi-PIE fiducials), %ld basis vectors\n",
        r.at("points").get<long>(), r.at("key_points").get<long>(), r.at("fiducials").get<long>(),
        r.at("basis").get<long>());
    std::printf(
        "  training   %ld frames (%ld sequences); eps [%.4f, %.4f] for a tolerance of %.2f%% of the head "
        "diagonal\n",
        r.at("train_frames").get<long>(), r.at("sequences").at("training").get<long>(), num("eps_min"),
        num("eps_max"), num("tolerance_pct_bbox"));
    std::printf("  validation %ld frames through the engine: hit %.1f%%, blend %.1f%%, miss %.1f%%\n",
                r.at("test_frames").get<long>(), 100 * num("hit_rate"), 100 * num("blend_rate"),
                100 * num("miss_rate"));
    std::printf(
        "  error      PM largest point error, 99.5th percentile of frames: %.3f%% of the head diagonal;\n"
        "             soft-cached, worst frame of all: %.3f%%\n",
        num("max_error_pct_bbox_p995"), num("soft_max_error_pct_bbox_max"));
    std::printf("  novel      %ld frames moving controls never trained: %.1f%% caught (blend or miss)\n",
                r.at("novel_frames").get<long>(), 100 * num("novel_nonhit_rate"));
    std::printf(
        "  speed      full pose %.1f ms/frame, PMSC %.2f ms/frame (keys and sentinels %.2f, projection "
        "%.3f, check %.2f, reconstruction %.2f): speedup %.1fx\n",
        1e3 * num("full_seconds_per_frame"), 1e3 * num("pmsc_seconds_per_frame"),
        1e3 * r.at("timing").at("key_and_sentinel_posing").get<double>(),
        1e3 * r.at("timing").at("projection").get<double>(),
        1e3 * r.at("timing").at("hit_check").get<double>(),
        1e3 * r.at("timing").at("reconstruction").get<double>(), num("speedup"));
    if (r.contains("local_fail_through")) printFaceLocalFailThrough(r.at("local_fail_through"));
    std::printf(
        "  wrote      %s/report.json, frames.csv, keys.png, worst/typical/novel .png and .obj  [%.0f s]\n",
        out.c_str(), r.at("seconds").at("total").get<double>());
}

}  // namespace

int runDemoFace(const std::vector<std::string>& args) {
    std::string data, out;
    std::optional<Index> threads, basis, regions, seed;
    std::optional<double> tolerance;
    std::string keyError, calibration;
    bool quick = false, full = false, quiet = false;
    ArgParser parser(
        "demo face",
        "--data DIR --out DIR2 [--quick] [--full] [--threads T] [--tolerance PCT] [--basis M] [--regions R] "
        "[--seed "
        "S] [--key-error NORM] [--calibration RULE] [--quiet]",
        "Section 7 of the paper on the ICT face (26,719 points): a rig with a jaw rotating about its\n"
        "hinge, eyelids rotating over the eyeballs, eyes that aim, correctives, relax, muscle flesh\n"
        "and lip and eyelid contact poses 36 animated sequences (speech, emotions, blinks, gaze);\n"
        "30% of them train the model (170 key points seeded by the Multi-PIE 68 landmarks), the rest\n"
        "and 8 sequences moving controls never seen in training go through the soft-cache engine.\n"
        "Writes DIR2/report.json, frames.csv, face.pmsc, keys.png and full/PM/soft-cached .obj and .png of\n"
        "three frames (error colours: grey 0, yellow 0.5%, red >= 1% of the head diagonal).");
    parser.option("--data", "DIR",
                  "the ICT-FaceKit FaceXModel folder (generic_neutral_mesh.obj + 57 expressions)", data,
                  true);
    parser.option("--out", "DIR2", "output folder (created if missing)", out, true);
    // Numbers go through Args' converters: "--threads 2.5" is an error, not 2 threads.
    parser.option("--threads", "T", "worker threads (default: every core)",
                  [&](const std::string& v) { threads = parseIndex("--threads", v, 0, 1024); });
    parser.option("--tolerance", "PCT", "largest error of a hit, % of the head diagonal (default 1)",
                  [&](const std::string& v) { tolerance = parseDouble("--tolerance", v, 0.001, 100); });
    parser.option("--basis", "M", "basis vectors (default 48)",
                  [&](const std::string& v) { basis = parseIndex("--basis", v, 1, 500); });
    parser.option("--regions", "R", "regions of local fail-through (default 96, quick 8; 0 = none)",
                  [&](const std::string& v) { regions = parseIndex("--regions", v, 0, 1000); });
    parser.option("--seed", "S",
                  "seed of the animation (default 7): another seed is another take, training and test sets\n"
                  "(novel and mixed sequences included), to check that settings chosen on one take hold",
                  [&](const std::string& v) { seed = parseIndex("--seed", v, 0, 4294967295LL); });
    parser.option("--key-error", "NORM",
                  "the key error eps apply to, as pmsc train's: predicted (default), rms, largest or loo",
                  keyError);
    parser.option("--calibration", "RULE",
                  "as pmsc train's: threshold (default for the predicted key error), max (default for the "
                  "others) or conformal",
                  calibration);
    parser.flag("--quick", "9 + 2 short sequences: a smoke test of the whole pipeline (about 20 s)", quick);
    parser.flag("--full",
                "the whole experiment: also local fail-through against whole-frame fail-through on\n"
                "                     validation, novel and mixed sequences (about 6 minutes more)",
                full);
    parser.flag("--quiet", "no progress display", quiet);
    if (!parser.parse(args)) return kExitOk;

    face::FaceDemoOptions options = quick ? face::FaceDemoOptions::quickOptions() : face::FaceDemoOptions{};
    options.dataDir = data;
    options.outDir = out;
    if (threads) options.threads = static_cast<int>(*threads);
    if (tolerance) options.tolerancePercent = *tolerance;
    if (basis) options.basis = static_cast<long>(*basis);
    if (regions) options.regions = static_cast<long>(*regions);
    if (seed) options.seed = static_cast<unsigned>(*seed);
    if (full) options.localFailThroughReport = true;
    try {
        options.keyErrorNorm = app::keyErrorNamed(keyError, app::Spelling::CommandLine);
        options.calibrationRule = app::calibrationNamed(calibration, app::Spelling::CommandLine);
    } catch (const app::OptionError& e) {
        parser.fail(e.what());
    }

    Progress progress("demo face", !quiet);
    options.progress = [&](std::string_view stage, double done, double total) {
        return progress.update(stage, done, total);
    };
    const nlohmann::json r = face::runFaceDemo(options);
    progress.finish();

    printFaceDemoSummary(r, out);
    return kExitOk;
}

// `pmsc demo face` and the line `pmsc --help` shows for it.
const cli::CommandRegistration kDemoFace{
    {"demo face", "section 7: a nonlinear face rig on the ICT face, 170 key points, novel-control detection",
     runDemoFace}};

}  // namespace pmsc::demos
