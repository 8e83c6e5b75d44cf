// `pmsc demo cross`: cross point multiplication on the ICT face (paper section 7). The
// experiment lives in examples/face (CrossDemo.h); this file parses options and prints the summary.
#include "app/ExitCodes.h"
#include "cli/Args.h"
#include "cli/CommandRegistry.h"
#include "cli/Progress.h"
#include "examples/commands/DemoCommands.h"
#include "examples/face/CrossDemo.h"

#include <cstdio>
#include <string>

namespace pmsc::demos {

using namespace pmsc::app;
using namespace pmsc::cli;

int runDemoCross(const std::vector<std::string>& args) {
    std::string data, out;
    bool quick = false, quiet = false;
    int threads = 0;
    double coverage = 0;
    long basis = 0;
    ArgParser parser(
        "demo cross", "--data DIR --out DIR2 [--quick] [--basis M] [--coverage C] [--threads T] [--quiet]",
        "Cross point multiplication on the ICT face (paper section 7): the control face is the rig\n"
        "without its expensive stages (blendshapes, jaw, eyelids, eyes), the target the full rig\n"
        "(relax, flesh muscles, lip and lid contact). Trains on (control, full) pairs of the face\n"
        "demo's training sequences; on its validation and novel sequences poses the control at the\n"
        "key points only, reconstructs the full face, and measures the error against the full rig,\n"
        "the learned bound's coverage and the speedup. Writes DIR2/report.json, frames.csv, cross.pmsc.");
    parser.option("--data", "DIR", "the ICT-FaceKit FaceXModel folder", data, true);
    parser.option("--out", "DIR2", "output folder (created if missing)", out, true);
    parser.option("--basis", "M", "joint basis size (default 48; 12 with --quick)",
                  [&](const std::string& v) { basis = static_cast<long>(parseIndex("--basis", v, 1, 512)); });
    parser.option("--coverage", "C", "coverage of the error bound (default 0.9)", [&](const std::string& v) {
        coverage = parseDouble("--coverage", v, 0.0, 1.0);
        if (!(coverage > 0 && coverage < 1)) throw UsageError("--coverage: must be in (0, 1), got " + v);
    });
    parser.option("--threads", "T", "worker threads (default: every core)", [&](const std::string& v) {
        threads = static_cast<int>(parseIndex("--threads", v, 1, 1024));
    });
    parser.flag("--quick", "short sequences, smaller model: a smoke test", quick);
    parser.flag("--quiet", "no progress display", quiet);
    if (!parser.parse(args)) return kExitOk;
    face::CrossDemoOptions o = quick ? face::CrossDemoOptions::quickOptions() : face::CrossDemoOptions{};
    o.dataDir = data;
    o.outDir = out;
    o.threads = threads;
    if (basis > 0) o.basis = basis;
    if (coverage > 0) o.coverage = coverage;
    Progress progress("demo cross", !quiet);
    o.progress = [&](std::string_view stage, double done, double total) {
        return progress.update(stage, done, total);
    };
    const nlohmann::json r = face::runCrossDemo(o);
    progress.finish();

    const auto& m = r.at("model");
    const auto& b = r.at("bound");
    std::printf(
        "cross point multiplication on the ICT face: control = rig without relax/flesh/contact, target = "
        "full rig\n");
    std::printf("  model   %ld training pairs, M = %ld, K = %ld control keys; fail-through impossible\n",
                r.at("frames").at("training").get<long>(), m.at("basis").get<long>(),
                m.at("key_points").get<long>());
    std::printf("  bound   target error <= %.4g x (key RMS + %.4g) at coverage %.2f (%ld held-out pairs)\n",
                b.at("quantile").get<double>(), b.at("scale").get<double>(), b.at("coverage").get<double>(),
                b.at("held_out_pairs").get<long>());
    for (const char* set : {"validation", "novel"}) {
        const auto& s = r.at(set);
        const auto& e = s.at("error_pct_bbox");
        std::printf(
            "  %-10s %4ld frames: error %% of head diagonal p50 %.3f p95 %.3f p99 %.3f max %.3f; inside "
            "bound %.1f%%;"
            " control alone max %.3f%%\n",
            set, s.at("frames").get<long>(), e.at("p50").get<double>(), e.at("p95").get<double>(),
            e.at("p99").get<double>(), e.at("max").get<double>(),
            100 * s.at("inside_bound_rate").get<double>(),
            s.at("control_vs_full_pct_bbox").at("max").get<double>());
    }
    const auto& sp = r.at("speed");
    std::printf(
        "  speed   full rig %.2f ms, cross PM %.2f ms (control keys %.3f, projection %.3f, reconstruction "
        "%.3f)"
        " thread CPU per frame: %.1fx (wall %.1fx)\n",
        sp.at("full_rig_cpu_ms").get<double>(), sp.at("cross_cpu_ms").get<double>(),
        sp.at("control_keys_cpu_ms").get<double>(), sp.at("projection_cpu_ms").get<double>(),
        sp.at("reconstruction_cpu_ms").get<double>(), sp.at("speedup_cpu").get<double>(),
        sp.at("speedup_wall").get<double>());
    std::printf("  wrote   %s/report.json, frames.csv, cross.pmsc  [%.0f s]\n", out.c_str(),
                r.at("seconds").at("total").get<double>());
    return kExitOk;
}

// `pmsc demo cross` and the line `pmsc --help` shows for it.
const cli::CommandRegistration kDemoCross{
    {"demo cross", "section 7: cross point multiplication on the ICT face, cheap control face -> full rig",
     runDemoCross}};

}  // namespace pmsc::demos
