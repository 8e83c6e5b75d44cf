// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/volume/VolumeEvaluator.h"
#include "pmsc/FrameSet.h"

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
    VolumeRig rig;  ///< 16 azimuths x 6 elevations = 96 training frames, refined for the medium:
    /// true: VolumeRig::forMedium(rig): more azimuths and elevations over the same band where the
    /// medium's lighting changes faster between neighbouring lights than the smoke's (the `volume:`
    /// evaluator's training lights are the same). false: `rig` as it is (the CLI's --azimuths,
    /// --elevations, --spiral).
    bool rigFromMedium = true;
    /// M: 0 = the smallest basis whose vectors capture basisEnergy of the training frames' energy
    /// (measured on the frames, so the medium decides: the demo's smoke needs 40 for 99.98%, a
    /// uniform or dense medium with sharper shadows more), at most maxBasis. > 0: exactly that.
    int basis = 0;
    double basisEnergy = 0.9998;
    int maxBasis = 160;
    /// K: 0 = keysPerBasis x M (the smoke's 250 keys for 40 vectors), at most a tenth of the voxels.
    /// Each key voxel costs a full calculation per frame; K = 6 M leaves the K x M system of the
    /// key values well over-determined.
    int keys = 0;
    double keysPerBasis = 6.25;
    /// About this many of the K from a sparse spatial grid (section 4); -1 = a fifth of K.
    int gridKeys = -1;
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

/// The size of the model the demo trains for a medium.
struct ModelSize {
    int basis = 0, keys = 0, gridKeys = 0;
    double energy = 0;  ///< fraction of the training frames' energy the basis captures
    /// The energy the basis leaves out: the squared distance of the training frames from the
    /// mean plus the span of the M principal directions, summed over frames.
    double discardedEnergy = 0;
};

/// M, K and the grid keys for these training frames (the options' explicit basis, keys and
/// gridKeys win): M the fewest basis vectors capturing options.basisEnergy of the frames'
/// energy (eigenvalues of the Gram matrix of the mean-removed columns, as pmsc::train forms
/// them), at most maxBasis; K = keysPerBasis x M, at most a tenth of the voxels; grid keys K/5.
ModelSize chooseModelSize(const VolumeDemoOptions& options, const FrameSet& frames);

/// Runs the experiment and writes into options.outDir: density.vdb (grid "density"),
/// cache_{full,pmsc}_pathNNN.vdb (grid "inscatter", the density's topology), CAMERA_pathNNN.png
/// (full | PMSC | |diff| x 10), vdb_render_density.png, report.json (returned too).
/// @throws pmsc::InputError for bad options or inputs, pmsc::IoError for outputs that cannot be
///         written, pmsc::Cancelled when the progress hook asks to stop.
nlohmann::json runVolumeDemo(const VolumeDemoOptions& options);

}  // namespace pmsc::volume
