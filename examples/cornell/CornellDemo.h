// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <nlohmann/json.hpp>

#include <cstddef>
#include <functional>
#include <string>
#include <string_view>

namespace pmsc::cornell {

/// The settings of section 8's experiment as `pmsc demo cornell` runs it.
struct CornellDemoOptions {
    std::string outDir;           ///< created if missing; receives *.vdb, *.png, *.pfm, report.json
    std::size_t points = 160000;  ///< active voxels of the lighting cache (the paper's 160,000 points)
    /// Paths per point per frame (half cosine gathers, half light paths). 160 keeps the gather's
    /// own noise (about 1.5% RMS, which 32 basis vectors cannot represent) well under the 2%
    /// error goal; at 128 the measured error was 1.91% (path frames 2.02%), too close. Training
    /// needs them too: the training frames gathered at 96 (validation still at 160) made the demo
    /// 60 s shorter and the error 3.23% (PM against the converged reference 2.76%, the full gather
    /// 1.70%): the basis keeps the training frames' noise.
    int samples = 160;
    int basis = 32;     ///< M (paper: 32 illumination basis functions)
    int keys = 200;     ///< K (paper: 200 control points), including the spatial grid
    int gridKeys = 48;  ///< about this many of the K from a sparse spatial grid (section 4)
    /// Largest point error a hit may have, as a fraction of the largest indirect irradiance
    /// (Euclidean over RGB) seen in training. 0.1: a hit never misses by more than a tenth of
    /// the brightest indirect light; where indirect light is that bright (next to the light)
    /// direct light is several times brighter still, so such an error stays under a few
    /// percent of the pixel. Calibrated into eps by pmsc::train (leave-one-slice-out).
    double toleranceFraction = 0.1;
    int scatteredLights = 16;      ///< validation lights near, never on, the training grid
    int pathFrames = 60;           ///< the light animation path
    int pathFullEvery = 4;         ///< full gathers on every n-th path frame (errors, images)
    int referenceMultiplier = 16;  ///< converged reference: this many times the samples
    int referencePoints = 2000;    ///< random subset of points for the reference
    int referenceFrames = 8;       ///< the first this many scattered lights get a reference
    int imageSize = 256;
    int renderFrames = 2;  ///< path frames rendered per camera (spread over the path)
    int threads = 0;       ///< 0 = every core; full gathers and the engine use the same
    /// Regions of local fail-through learned in training, from the voxels' positions;
    /// 0 = none (a version-1 model; no "local_fail_through" in the report). 48, measured at --quick
    /// on a 100 mm cube against the back wall at x 150-250 (its 2 frames that miss as a whole): 16 regions
    /// gathered 54% of the points of those frames, 32 sent one of them whole (77% on average), 48 routed both
    /// locally at 42% (speedup over full gathers 6.5x, whole-frame 3.5x), 64 gained nothing (41%, 6.2x).
    int regions = 48;
    /// Feather width of the regions' borders, % of the box's diagonal (965 mm): 29 mm, 1.6 voxels
    /// at --quick and 8 at the default size. 1.5% is under one --quick voxel (no feathering at
    /// all; it gathered 34% of the points); 5% gathered 48% for the same largest error.
    double featherPercent = 3;
    /// Edge (mm) of the local change (LocalChangeBox: a cube on the floor against the back
    /// wall, never seen in training); 0 = no local-change set. Needs regions > 0.
    double localChangeMm = 100;
    int localChangeLights = 8;  ///< the local-change set: the first this many scattered lights
    /// The whole experiment (`--full`): report.json also gains "local_fail_through", the
    /// scattered lights and the local change measured both ways against full gathers. Off by
    /// default: at the default size it takes 40-70 s of a demo that should finish within 3
    /// minutes on 2 cores. On at `--quick`, the smoke test of the whole pipeline.
    bool localFailThroughReport = false;
    bool quick = false;  ///< small settings for a smoke test (set by quickOptions)
    /// Progress hook: (stage, done, total); return false to cancel (throws pmsc::Cancelled).
    std::function<bool(std::string_view, double, double)> progress;

    /// `--quick`: 6,000 points, 32 samples, 8 scattered lights, 500 reference points, 128 px.
    static CornellDemoOptions quickOptions();
};

/// Runs the whole experiment (section 8) and writes into options.outDir:
/// - report.json (returned too): points, key_points, basis, train_frames, test_frames,
///   samples_per_point, full_seconds_per_frame, pmsc_seconds_per_frame, speedup,
///   rms_rel_error, hit_rate, reference_rms_rel_error_full, reference_rms_rel_error_pm, and more;
///   with regions, "local_fail_through" (CornellLocalChange.h: the scattered lights and the local
///   change, each with local and whole-frame fail-through);
/// - cache_{pmsc,full}_pathNNN.vdb: the lighting-cache grids of the rendered frames;
/// - CAMERA_pathNNN.png (full | PMSC | |diff| x 10) and .pfm (the same, linear).
///
/// Steps: voxelize the box; 144 training frames by full gathers; pmsc::train; full gathers of
/// the validation frames that are checked; the validation frames through the engine
/// (pmsc::engine::Engine, soft cache per frame); the converged reference on a subset; grids,
/// renders; with regions, local fail-through on the scattered lights and the local change; report.
/// @throws pmsc::InputError for bad options, pmsc::IoError for outputs that cannot be written,
///         pmsc::Cancelled when the progress hook asks to stop.
nlohmann::json runCornellDemo(const CornellDemoOptions& options);

}  // namespace pmsc::cornell
