// `pmsc demo cornell`: section 8's experiment — the measured Cornell box, indirect light by a final
// gather with Embree, a sparse OpenVDB lighting cache, PMSC through the engine, moving cameras.
// The experiment itself lives in examples/cornell (CornellDemo.h); this file parses options,
// shows progress and prints the summary.
#include "app/ExitCodes.h"
#include "cli/Args.h"
#include "cli/CommandRegistry.h"
#include "cli/Progress.h"
#include "examples/commands/DemoCommands.h"
#include "examples/cornell/CornellDemo.h"

#include <cstdio>
#include <iostream>
#include <optional>
#include <string>

namespace pmsc::demos {

using namespace pmsc::app;
using namespace pmsc::cli;

namespace {

// One line per set and way: hit rate, points gathered, errors over the tolerance, one-thread speedup.
void printCornellLocalFailThrough(const nlohmann::json& local) {
    std::printf(
        "  local fail-through: %ld regions, feather %.1f mm, errors as multiples of the tolerance %.3g\n",
        local.at("regions").get<long>(), local.at("feather_width_mm").get<double>(),
        local.at("tolerance").get<double>());
    for (const char* set : {"validation", "local_change"}) {
        if (!local.contains(set)) continue;
        const nlohmann::json& s = local.at(set);
        for (const char* way : {"local", "whole_frame", "regions_every_frame"}) {
            if (!s.contains(way)) continue;
            const nlohmann::json& w = s.at(way);
            const std::string speedup = std::string("speedup_") + way;
            std::printf(
                "    %-12s %-19s %s %5.1f%%, gathered %5.1f%% of the points, max error %.3f, RMS %.4f, "
                "speedup %.1fx\n",
                set, way, w.contains("frames_without_gathers") ? "no gather" : "hit rate ",
                100 * (w.contains("frames_without_gathers")
                           ? w.at("frames_without_gathers").get<double>() / s.at("frames").get<double>()
                           : s.at("hit_rate").get<double>()),
                100 * w.at("points_evaluated_fraction_mean").get<double>(),
                w.at("soft_max_error_over_tolerance").get<double>(),
                w.at("soft_rms_error_over_tolerance").get<double>(), s.at(speedup).get<double>());
        }
    }
}

}  // namespace

int runDemoCornell(const std::vector<std::string>& args) {
    std::string out;
    std::optional<Index> points, samples, threads, regions;
    std::optional<double> feather, localChange;
    bool quick = false, full = false, quiet = false;
    ArgParser parser(
        "demo cornell",
        "--out DIR [--points N] [--samples S] [--regions R] [--feather PCT] [--full] [--local-change MM] "
        "[--quick] [--threads T] [--quiet]",
        "Section 8 of the paper on the measured Cornell box: 144 training frames lit by a point\n"
        "light on a 12 x 12 grid below the ceiling, one-bounce indirect irradiance by a final\n"
        "gather (Embree) at the active voxels of a sparse OpenVDB grid, 32 basis vectors and 200\n"
        "key points, validation lights through the soft-cache engine, and renders from moving\n"
        "cameras. Writes DIR/report.json, DIR/*.vdb (vdb_print -l), DIR/*.png and DIR/*.pfm.");
    parser.option("--out", "DIR", "output folder (created if missing)", out, true);
    // Numbers go through Args' converters, as every other command's.
    parser.option("--points", "N", "active voxels of the lighting cache (default 160000; --quick 6000)",
                  [&](const std::string& v) { points = parseIndex("--points", v, 1000, 4000000); });
    parser.option("--samples", "S", "paths per point per frame (default 160; --quick 32)",
                  [&](const std::string& v) { samples = parseIndex("--samples", v, 2, 65536); });
    parser.option("--threads", "T", "worker threads (default: every core)",
                  [&](const std::string& v) { threads = parseIndex("--threads", v, 0, 1024); });
    parser.option("--regions", "R", "regions of local fail-through (default 48; 0 = none)",
                  [&](const std::string& v) { regions = parseIndex("--regions", v, 0, 1024); });
    parser.option("--feather", "PCT",
                  "feather width of the regions' borders, % of the box's diagonal (default 3)",
                  [&](const std::string& v) { feather = parseDouble("--feather", v, 0, 50); });
    parser.flag("--full",
                "the whole experiment: also local fail-through against whole-frame fail-through on the\n"
                "                     scattered lights and a local change (about a minute more)",
                full);
    parser.option(
        "--local-change", "MM",
        "edge of a cube on the floor by a wall, where key points see it, that training never saw;\n"
        "                     the scattered lights in that box, measured both ways (implies --full;\n"
        "                     default 100; 0 = none; else 10-150)",
        [&](const std::string& v) { localChange = parseDouble("--local-change", v, 0, 150); });
    parser.flag("--quick", "small settings, a smoke test of the whole pipeline (under 30 s)", quick);
    parser.flag("--quiet", "no progress display", quiet);
    if (!parser.parse(args)) return kExitOk;

    cornell::CornellDemoOptions options =
        quick ? cornell::CornellDemoOptions::quickOptions() : cornell::CornellDemoOptions{};
    options.outDir = out;
    if (points) options.points = static_cast<std::size_t>(*points);
    if (samples) options.samples = static_cast<int>(*samples);
    if (threads) options.threads = static_cast<int>(*threads);
    if (regions) options.regions = static_cast<int>(*regions);
    if (feather) options.featherPercent = *feather;
    if (localChange) options.localChangeMm = *localChange;
    if (full || (localChange && *localChange > 0)) options.localFailThroughReport = true;
    if (regions && *regions == 0 && !localChange)
        options.localChangeMm = 0;  // no regions: nothing to route locally

    Progress progress("demo cornell", !quiet);
    options.progress = [&](std::string_view stage, double done, double total) {
        return progress.update(stage, done, total);
    };
    const nlohmann::json r = cornell::runCornellDemo(options);
    progress.finish();

    auto num = [&](const char* key) { return r.at(key).get<double>(); };
    std::printf(
        "Cornell box (section 8): %ld points (voxel %.2f mm), %ld key points, %ld basis vectors, %d "
        "samples/point\n",
        r.at("points").get<long>(), num("voxel_size_mm"), r.at("key_points").get<long>(),
        r.at("basis").get<long>(), r.at("samples_per_point").get<int>());
    std::printf(
        "  training  %ld frames, validation %ld frames through the engine (hit rate %.1f%%: %ld hit, %ld "
        "blend, %ld miss)\n",
        r.at("train_frames").get<long>(), r.at("test_frames").get<long>(), 100.0 * num("hit_rate"),
        r.at("hits").get<long>(), r.at("blends").get<long>(), r.at("misses").get<long>());
    std::printf("  speed     full gather %.3f s/frame, PMSC %.4f s/frame: speedup %.0fx\n",
                num("full_seconds_per_frame"), num("pmsc_seconds_per_frame"), num("speedup"));
    std::printf("  error     PM vs full gather: %.2f%% RMS (soft-cached output %.2f%%)\n",
                100.0 * num("rms_rel_error"), 100.0 * num("soft_rms_rel_error"));
    std::printf("  converged reference (%ldx samples, %ld points): full gather %.2f%%, PMSC %.2f%%\n",
                r.at("reference_samples_per_point").get<long>() / r.at("samples_per_point").get<long>(),
                r.at("reference_points").get<long>(), 100.0 * num("reference_rms_rel_error_full"),
                100.0 * num("reference_rms_rel_error_pm"));
    if (r.contains("local_fail_through")) printCornellLocalFailThrough(r.at("local_fail_through"));
    std::printf(
        "  wrote     %s/report.json, %zu .vdb lighting caches, %zu images (full | PMSC | |diff| x 10)  [%.0f "
        "s]\n",
        out.c_str(), r.at("vdb_files").size(), r.at("images").size(),
        r.at("seconds").at("total").get<double>());
    return kExitOk;
}

// `pmsc demo cornell` and the line `pmsc --help` shows for it.
const cli::CommandRegistration kDemoCornell{
    {"demo cornell", "section 8: Cornell box indirect light, OpenVDB lighting cache, moving cameras",
     runDemoCornell}};

}  // namespace pmsc::demos
