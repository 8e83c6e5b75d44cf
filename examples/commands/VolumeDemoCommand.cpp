// `pmsc demo volume`: light scattered inside smoke, cached at the active voxels of an
// OpenVDB grid, PMSC through the engine, moving cameras. The experiment lives in examples/volume
// (VolumeDemo.h); this file parses options, shows progress and prints the summary.
#include "app/ExitCodes.h"
#include "cli/Args.h"
#include "cli/CommandRegistry.h"
#include "cli/Progress.h"
#include "examples/commands/DemoCommands.h"
#include "examples/volume/VolumeDemo.h"

#include <cstdio>
#include <optional>
#include <string>

namespace pmsc::demos {

using namespace pmsc::app;
using namespace pmsc::cli;

namespace {

/// What `pmsc demo volume` was asked; a negative number or an empty list is "not given".
struct VolumeArgs {
    std::string out, mesh, density, grid;
    bool quick = false, quiet = false, noVdbRender = false, separateChannels = false;
    long spiral = -1, colours = -1, gridKeys = -1;
    long voxels = -1, samples = -1, threads = -1, basis = -1, keys = -1, azimuths = -1;
    std::vector<double> elevations, kelvin;
    double fogDensity = -1, fogFloor = -1, fogExponent = -1;
};

/// Declares the options, parses and checks them; std::nullopt when --help was asked for.
std::optional<VolumeArgs> parseVolumeArgs(const std::vector<std::string>& args) {
    VolumeArgs a;
    volume::VolumeDemoOptions defaults;
    ArgParser parser(
        "demo volume", "--out DIR [--mesh FILE | --density FILE.vdb [--grid NAME]] [options]",
        "Smoke made from a mesh with OpenVDB (meshToLevelSet, fog volume, noise), lit\n"
        "by a spherical light moving around and over it with a changing colour temperature.\n"
        "The light scattered at every active voxel (soft shadows through the heterogeneous\n"
        "density, multiple scattering) is the expensive calculation; training frames on a\n"
        "rig as fine as the medium needs (96 for the smoke), a basis and key voxels sized\n"
        "from them, validation between the training lights and on a path through\n"
        "the soft-cache engine, renders from three moving cameras (one inside the smoke).\n"
        "Writes DIR/report.json, DIR/density.vdb, DIR/cache_*.vdb (grid 'inscatter'), DIR/*.png.");
    parser.option("--out", "DIR", "output folder (created if missing)", a.out, true);
    parser.option("--mesh", "FILE", "mesh to make smoke of (default " + defaults.mesh + ")", a.mesh);
    parser.option("--density", "FILE.vdb", "a density grid of your own instead of the mesh", a.density);
    parser.option("--grid", "NAME", "its float grid (default 'density', else the file's only float grid)",
                  a.grid);
    parser.option("--voxels", "N",
                  "active voxels of the smoke made from the mesh (default 260000; --quick 12000)",
                  [&](const std::string& v) { a.voxels = parseIndex("--voxels", v, 1000, 8000000); });
    parser.option("--fog-density", "D", "the mesh's smoke: density scale (default 1)",
                  [&](const std::string& v) { a.fogDensity = parseDouble("--fog-density", v, 1e-6, 1e6); });
    parser.option("--fog-floor", "F",
                  "the mesh's smoke: density where the noise is 0, in [0, 1] (default 0.15; 1 = uniform)",
                  [&](const std::string& v) { a.fogFloor = parseDouble("--fog-floor", v, 0, 1); });
    parser.option("--fog-exponent", "P",
                  "the mesh's smoke: density ~ noise^P above the floor (default 2; higher = sparser wisps)",
                  [&](const std::string& v) { a.fogExponent = parseDouble("--fog-exponent", v, 0.1, 64); });
    parser.option("--samples", "S", "shadow rays per voxel to the light (default 6; --quick 4)",
                  [&](const std::string& v) { a.samples = parseIndex("--samples", v, 1, 4096); });
    parser.option("--basis", "M",
                  "basis vectors (default: the fewest capturing 99.98% of the training frames' energy, at "
                  "most " +
                      std::to_string(defaults.maxBasis) + ")",
                  [&](const std::string& v) { a.basis = parseIndex("--basis", v, 1, 512); });
    parser.option("--keys", "K", "key voxels (default: 6.25 x M, at most a tenth of the voxels)",
                  [&](const std::string& v) { a.keys = parseIndex("--keys", v, 1, 100000); });
    parser.option("--azimuths", "A",
                  "training light azimuths per elevation (default " + std::to_string(defaults.rig.azimuths) +
                      " x 6 elevations, refined for the medium; given: this rig as it is)",
                  [&](const std::string& v) { a.azimuths = parseIndex("--azimuths", v, 2, 360); });
    parser.option("--elevations", "E1,E2,..", "training light elevations in degrees, each in [0, 89]",
                  [&](const std::string& v) {
                      a.elevations.clear();
                      for (Index e : parseIndexList("--elevations", v)) {
                          if (e > 89)
                              throw UsageError("--elevations: " + std::to_string(e) +
                                               " is out of range (must be in [0, 89])");
                          a.elevations.push_back(static_cast<double>(e));
                      }
                  });
    parser.option(
        "--spiral", "P",
        "training light positions on a spiral over the band of elevations (0 = the azimuth x elevation grid)",
        [&](const std::string& v) { a.spiral = parseIndex("--spiral", v, 0, 4096); });
    parser.option("--colours", "C", "training colour temperatures along the spiral (2 or 3)",
                  [&](const std::string& v) { a.colours = parseIndex("--colours", v, 1, 8); });
    parser.option("--kelvin", "LOW,HIGH",
                  "the light's colour temperatures: training from LOW to HIGH, validation between (default " +
                      std::to_string(static_cast<int>(defaults.rig.kelvinLow)) + "," +
                      std::to_string(static_cast<int>(defaults.rig.kelvinHigh)) + "; LOW = HIGH: one colour)",
                  [&](const std::string& v) {
                      a.kelvin.clear();
                      for (Index k : parseIndexList("--kelvin", v)) {
                          if (k < 1000 || k > 40000)
                              throw UsageError("--kelvin: " + std::to_string(k) +
                                               " K is out of range (must be in [1000, 40000])");
                          a.kelvin.push_back(static_cast<double>(k));
                      }
                      if (a.kelvin.size() != 2 || a.kelvin[0] > a.kelvin[1])
                          throw UsageError("--kelvin: give LOW,HIGH with LOW <= HIGH, not '" + v + "'");
                  });
    parser.option("--grid-keys", "G", "key voxels seeded from a sparse spatial grid (at most K; default K/5)",
                  [&](const std::string& v) { a.gridKeys = parseIndex("--grid-keys", v, 0, 100000); });
    parser.option("--threads", "T", "worker threads (default: every core)",
                  [&](const std::string& v) { a.threads = parseIndex("--threads", v, 0, 1024); });
    parser.flag("--separate-channels",
                "a basis over (voxel, channel) rows instead of one shared by red, green and blue",
                a.separateChannels);
    parser.flag("--no-vdb-render", "skip OpenVDB's vdb_render view of the density", a.noVdbRender);
    parser.flag("--quick", "small settings, a smoke test of the whole pipeline (under 30 s)", a.quick);
    parser.flag("--quiet", "no progress display", a.quiet);
    if (!parser.parse(args)) return std::nullopt;
    if (!a.density.empty() && !a.mesh.empty()) parser.fail("--mesh and --density exclude each other");
    if (a.density.empty() && !a.grid.empty()) parser.fail("--grid needs --density");
    if (!a.density.empty() && (a.fogDensity >= 0 || a.fogFloor >= 0 || a.fogExponent >= 0))
        parser.fail("--fog-density, --fog-floor and --fog-exponent shape the mesh's smoke, not --density's");
    return a;
}

/// The experiment's settings: the defaults (or --quick's) with what was given on top.
volume::VolumeDemoOptions demoOptions(const VolumeArgs& a) {
    volume::VolumeDemoOptions options =
        a.quick ? volume::VolumeDemoOptions::quickOptions() : volume::VolumeDemoOptions{};
    options.outDir = a.out;
    if (!a.mesh.empty()) options.mesh = a.mesh;
    options.density = a.density;
    options.grid = a.grid;
    if (a.voxels > 0) options.fog.targetVoxels = static_cast<std::size_t>(a.voxels);
    if (a.fogDensity >= 0) options.fog.densityScale = a.fogDensity;
    if (a.fogFloor >= 0) options.fog.noiseFloor = a.fogFloor;
    if (a.fogExponent >= 0) options.fog.noiseExponent = a.fogExponent;
    if (a.samples > 0) options.medium.lightSamples = static_cast<int>(a.samples);
    if (a.basis > 0) options.basis = static_cast<int>(a.basis);
    if (a.keys > 0) options.keys = static_cast<int>(a.keys);
    // A rig asked for is used as it is; otherwise the demo refines the default for the medium.
    if (a.azimuths > 0 || !a.elevations.empty() || a.spiral >= 0) options.rigFromMedium = false;
    if (a.azimuths > 0) options.rig.azimuths = static_cast<int>(a.azimuths);
    if (!a.elevations.empty()) options.rig.elevations = a.elevations;
    if (a.spiral >= 0) options.rig.spiral = static_cast<int>(a.spiral);
    if (a.colours > 0) options.rig.colours = static_cast<int>(a.colours);
    if (!a.kelvin.empty()) {
        options.rig.kelvinLow = a.kelvin[0];
        options.rig.kelvinHigh = a.kelvin[1];
    }
    if (a.gridKeys >= 0) options.gridKeys = static_cast<int>(a.gridKeys);
    if (options.keys > 0 && options.gridKeys > options.keys) options.gridKeys = options.keys;
    if (a.threads >= 0) options.threads = static_cast<int>(a.threads);
    if (a.noVdbRender) options.vdbRender = false;
    if (a.separateChannels) options.sharedChannels = false;
    return options;
}

/// The summary of the demo's report, on stdout.
void printVolumeSummary(const nlohmann::json& r, const std::string& out) {
    auto num = [&](const char* key) { return r.at(key).get<double>(); };
    std::printf(
        "Volume lighting cache: %ld active voxels (voxel %.4f m, sigma_t %.3g/m), %ld key voxels, "
        "%ld basis vectors (%s), %d shadow rays/voxel, %d scattering octaves\n",
        r.at("points").get<long>(), num("voxel_size_m"), num("sigma_t_per_m"), r.at("key_points").get<long>(),
        r.at("basis").get<long>(),
        r.at("shared_channels").get<bool>() ? "shared by R, G, B" : "over voxel-channel rows",
        r.at("light_samples").get<int>(), r.at("multiple_scattering_octaves").get<int>());
    std::printf(
        "  training  %ld frames, validation %ld frames through the engine (hit rate %.1f%%: %ld hit, %ld "
        "blend, %ld miss)\n",
        r.at("train_frames").get<long>(), r.at("test_frames").get<long>(), 100.0 * num("hit_rate"),
        r.at("hits").get<long>(), r.at("blends").get<long>(), r.at("misses").get<long>());
    std::printf("  speed     full calculation %.3f s/frame, PMSC %.4f s/frame: speedup %.0fx (%d threads)\n",
                num("full_seconds_per_frame"), num("pmsc_seconds_per_frame"), num("speedup"),
                r.at("threads").get<int>());
    std::printf(
        "  error     PM vs full calculation: %.2f%% RMS (between %.2f%%, path %.2f%%; soft-cached output "
        "%.2f%%)\n",
        100.0 * num("rms_rel_error"), 100.0 * num("rms_rel_error_between"), 100.0 * num("rms_rel_error_path"),
        100.0 * num("soft_rms_rel_error"));
    std::printf(
        "  basis     distance of frames from the basis (best possible with every voxel known): training "
        "%.2f%%, validation %.2f%%\n",
        100.0 * num("train_projection_rel_error"), 100.0 * num("projection_rel_error"));
    std::printf(
        "  converged reference (%ld shadow rays, step %.2g voxel, %ld voxels; %.2f%% from one with 2x the "
        "rays and half the step):\n"
        "            full %.2f%%, PMSC %.2f%% (ratio %.2f)\n",
        r.at("reference_light_samples").get<long>(), num("reference_step_voxels"),
        r.at("reference_points").get<long>(), 100.0 * num("reference_self_rel_error"),
        100.0 * num("reference_rms_rel_error_full"), 100.0 * num("reference_rms_rel_error_pm"),
        num("reference_ratio_pm_to_full"));
    std::printf(
        "  wrote     %s/report.json, density.vdb, %zu caches, %zu images (full | PMSC | |diff| x 10)  [%.0f "
        "s, peak %.0f MB]\n",
        out.c_str(), r.at("vdb_files").size(), r.at("images").size(),
        r.at("seconds").at("total").get<double>(), num("peak_rss_mb"));
}

}  // namespace

int runDemoVolume(const std::vector<std::string>& args) {
    const std::optional<VolumeArgs> a = parseVolumeArgs(args);
    if (!a) return kExitOk;
    volume::VolumeDemoOptions options = demoOptions(*a);
    Progress progress("demo volume", !a->quiet);
    options.progress = [&](std::string_view stage, double done, double total) {
        return progress.update(stage, done, total);
    };
    const nlohmann::json r = volume::runVolumeDemo(options);
    progress.finish();
    printVolumeSummary(r, a->out);
    return kExitOk;
}

// `pmsc demo volume` and the line `pmsc --help` shows for it.
const cli::CommandRegistration kDemoVolume{
    {"demo volume", "light scattered in smoke, a sparse volumetric lighting cache in OpenVDB",
     runDemoVolume}};

}  // namespace pmsc::demos
