// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Calibration.h"  // CalibrationRule
#include "pmsc/KeyError.h"

#include <nlohmann/json.hpp>

#include <functional>
#include <optional>
#include <string>
#include <string_view>

namespace pmsc::face {

/// The settings of section 7's experiment as `pmsc demo face` runs it.
struct FaceDemoOptions {
    std::string dataDir;  ///< the ICT-FaceKit FaceXModel folder
    std::string outDir;   ///< created if missing; receives report.json, frames.csv, *.obj, *.png

    // --- animation (FaceAnimationOptions) ---
    unsigned seed = 7;
    long sequences = 36;      ///< ordinary sequences (paper: 137)
    long novelSequences = 8;  ///< sequences that move controls never moved in training
    long minFrames = 60;
    long maxFrames = 110;
    /// Share of the ordinary sequences used for training, the rest validates (paper: 44 of 137).
    double trainingFraction = 0.3;

    // --- model ---
    /// M. 48: past it the largest point residual of PM on the training frames barely falls
    /// (measured with this animation: 0.30% of the head diagonal at M = 40, 0.29% at 48, 0.24%
    /// at 64, 0.17% at 80, all far under the 1% goal) while the reconstruction, the largest
    /// part of a hit's cost after the key points, grows linearly with M (26,719 x 3 x M
    /// doubles). The paper used 85 for its 2,986 points.
    long basis = 48;
    long maxKeys = 170;  ///< K (paper: 170), Multi-PIE 68 fiducials included
    /// Regions of local fail-through (0 = none). Training learns them after the model's
    /// core, so every figure of the whole-frame soft cache is unchanged.
    long regions = 96;
    /// Regions learn from every regionStride-th training frame (RegionOptions::frameStride), as
    /// `pmsc train` does by default: neighbouring frames of an animation are nearly alike, and a
    /// region's calibration grows with the square and cube of its frames. On the demo's 941
    /// training frames, on 2 cores, the whole training takes 16 s with every 3rd frame and 70 s
    /// with every frame, and the demo's figures are the same.
    long regionStride = 3;
    /// The whole experiment (`--full`): report.json also gains "local_fail_through", the
    /// validation (first 4 sequences), novel and mixed sets measured both ways, each frame against
    /// its full pose (FaceLocalReport.h). Off by default: at the default size it takes about 380 s
    /// more on 2 cores, and the demo's first result should come in minutes. On at
    /// `--quick`, the smoke test of the whole pipeline.
    bool localFailThroughReport = false;
    /// Feather width of the regions, % of the head diagonal (RegionOptions::featherFraction).
    /// 0.75: with 96 regions of ~280 points a band of 3% (the first default) spans several
    /// regions, and every failing region dragged its neighbours into the full calculation.
    double featherPercent = 0.75;
    /// Fraction of the points above which a frame fails through whole
    /// (RegionOptions::maxLocalFraction). 0.8: a subset pose of the face costs about its share of
    /// a full pose plus the keys (pmsc_local_bench), so up to 80% of the points still pays.
    double maxLocalFraction = 0.8;
    /// Mixed sequences (FaceAnimationOptions::mixedSequences): ordinary shots of 5-8 s that move
    /// novel controls for 1-3 s only; measured only by the local fail-through report.
    long mixedSequences = 6;
    /// Calibration target T (TrainingOptions::tolerance) in % of the head's bounding-box
    /// diagonal: the largest point error a hit may have. 1%: the paper's own accuracy criterion
    /// ("less than 1% of the diagonal of the head bounding box"), so a hit is by construction
    /// as good as the paper calls good, and calibration (leave-one-slice-out, E <= r e) sets
    /// eps_min = T / r, eps_max = 2 eps_min, which keeps blends under T as well.
    double tolerancePercent = 1.0;
    /// The key error and the calibration rule (`pmsc train --key-error`, `--calibration`); unset:
    /// pmsc train's defaults (the key RMS, the largest held-out ratio).
    std::optional<KeyErrorNorm> keyErrorNorm;
    std::optional<CalibrationRule> calibrationRule;

    // --- measurement ---
    long timingFrames = 40;  ///< validation frames timed one by one, full pose vs PMSC, same run
    int threads = 0;         ///< 0 = every core (training poses, ground truth, the engine)
    bool quick = false;      ///< set by quickOptions()

    /// Progress hook: (stage, done, total); return false to cancel (throws pmsc::Cancelled).
    std::function<bool(std::string_view, double, double)> progress;

    /// `--quick`: 9 + 2 sequences of 26-36 frames (3 train: the model is undertrained, most
    /// validation frames fail through), 8 timed frames: a smoke test of the pipeline (~20 s).
    static FaceDemoOptions quickOptions();
};

/// Runs the whole experiment (section 7) and writes into options.outDir:
/// - report.json (returned too): points, key_points, basis, train_frames, test_frames,
///   full_seconds_per_frame, pmsc_seconds_per_frame, speedup, hit_rate, blend_rate, miss_rate,
///   max_error_pct_bbox_p995, soft_max_error_pct_bbox_max, novel_nonhit_rate, and the details
///   behind them (thresholds, error percentiles, timing breakdown, dependency closure, engine
///   stats);
/// - frames.csv: per test frame: sequence, key RMS error, decision, PM and soft-cached errors;
/// - keys.png: the neutral face with the key points (red) and the fiducials among them (blue);
/// - worst/typical/novel_{full,pm,soft}.obj and .png: three frames (the validation frame with
///   the largest PM error, the median one, a novel one) posed fully, by PM, and soft-cached,
///   rendered side by side and coloured by error (grey 0, yellow 0.5%, red >= 1% of the head
///   diagonal), with a close-up of the mouth underneath.
///
/// Steps: load the ICT face, build the rig, generate the animation, split by sequence; pose the
/// training sequences; pmsc::train (fiducials = Multi-PIE 68, tolerance calibrated); pose every
/// test frame fully (ground truth) and evaluate PM and the soft cache on it; run the test
/// sequences through the engine (pmsc::engine::Engine) with the rig as the evaluator and check
/// that its decisions equal the direct ones; time full poses against PMSC one frame at a time
/// on one thread; write the files.
/// @throws pmsc::InputError for a bad ICT folder or options, pmsc::IoError for outputs that
///         cannot be written, pmsc::Cancelled when the progress hook asks to stop.
nlohmann::json runFaceDemo(const FaceDemoOptions& options);

}  // namespace pmsc::face
