// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/volume/VolumeEvaluator.h"

#include <nlohmann/json.hpp>

#include <cstddef>
#include <functional>
#include <string>
#include <string_view>

namespace pmsc::volume {

/// The settings of `pmsc demo volume` (the volumetric lighting cache).
struct VolumeDemoOptions {
    std::string outDir;  ///< created if missing; receives density.vdb, cache_*.vdb, *.png, report.json
    /// The mesh the smoke is made of (Debian's assimp-testmodels; any format Assimp reads).
    std::string mesh = "/usr/share/assimp/models/OBJ/WusonOBJ.obj";
    /// A user's density .vdb instead of the mesh (its float grid `grid`, or "density" / the first).
    std::string density;
    std::string grid;
    FogOptions fog;  ///< targetVoxels: active voxels of the demo's smoke (260,000)
    MediumSettings medium;
    VolumeRig rig;  ///< 16 azimuths x 6 elevations = 96 training frames
    /// M and K: 40 and 250. With 96 training frames and the basis shared by R, G,
    /// B the validation frames are 0.8% from the basis; M and K are what PMSC pays per frame
    /// (reconstruction reads N M doubles of basis, each key voxel costs a full calculation): 142x,
    /// reference ratio 1.34 (README, "The volumetric lighting cache").
    int basis = 40;
    int keys = 250;     ///< K, including the spatial grid's
    int gridKeys = 48;  ///< about this many of the K from a sparse spatial grid (section 4)
    /// Red, green and blue share one basis over the voxels (Model::sharedChannels; false:
    /// `--separate-channels`, the basis over (voxel, channel) rows every other demo uses).
    bool sharedChannels = true;
    /// Largest point error a hit may have, as a fraction of the largest in-scattered radiance
    /// (Euclidean over RGB) seen in training; calibrated into eps by pmsc::train.
    double toleranceFraction = 0.1;
    int betweenLights = 8;        ///< validation settings between the training ones
    int pathFrames = 48;          ///< the light's animation path (validation)
    int pathFullEvery = 8;        ///< full calculations on every n-th path frame (errors, images)
    int referenceMultiplier = 8;  ///< converged reference: this many times the light samples, 1/4 the step
    int referencePoints = 2000;   ///< random subset of voxels for the reference
    int referenceFrames = 4;      ///< the first this many "between" settings get a reference
    int imageSize = 256;
    int renderFrames = 1;   ///< path frames rendered per camera
    bool vdbRender = true;  ///< also render the density with OpenVDB's vdb_render (if on PATH)
    int threads = 0;        ///< 0 = every core; full calculations and the engine use the same
    bool quick = false;
    /// Progress hook: (stage, done, total); return false to cancel (throws pmsc::Cancelled).
    std::function<bool(std::string_view, double, double)> progress;

    /// `--quick`: 12,000 voxels, 8 x 3 training lights, 4 light samples, 96 px, no vdb_render.
    static VolumeDemoOptions quickOptions();
};

/// Runs the experiment and writes into options.outDir: density.vdb (grid "density"),
/// cache_{full,pmsc}_pathNNN.vdb (grid "inscatter", the density's topology), CAMERA_pathNNN.png
/// (full | PMSC | |diff| x 10), vdb_render_density.png, report.json (returned too).
/// @throws pmsc::InputError for bad options or inputs, pmsc::IoError for outputs that cannot be
///         written, pmsc::Cancelled when the progress hook asks to stop.
nlohmann::json runVolumeDemo(const VolumeDemoOptions& options);

}  // namespace pmsc::volume
