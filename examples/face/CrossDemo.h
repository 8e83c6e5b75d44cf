// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/FaceAnimation.h"
#include "evaluators/face/FaceControlEvaluator.h"
#include "evaluators/face/FaceRig.h"
#include "pmsc/PointEvaluator.h"

#include <nlohmann/json.hpp>

#include <memory>

#include <functional>
#include <string>
#include <string_view>

namespace pmsc::face {

/// Cross point multiplication on the ICT face (paper section 7; `pmsc demo cross`):
/// the control face is the rig without its expensive stages (FaceRig::evaluateControl:
/// blendshapes, jaw, eyelids, eyes), the target the full rig (plus relax, the flesh's muscles and
/// the lip and lid contact). The animator poses the control; the target comes from the joint
/// subspace, with no fail-through and a learned error bound.
struct CrossDemoOptions {
    std::string dataDir;  ///< the ICT-FaceKit FaceXModel folder
    std::string outDir;   ///< created if missing

    // --- animation: the face demo's (same seed, same training / validation split, same novel set)
    unsigned seed = 7;
    long sequences = 36;
    long novelSequences = 8;
    long minFrames = 60;
    long maxFrames = 110;
    double trainingFraction = 0.3;

    // --- the cross model ---
    long basis = 48;         ///< M of the joint subspace (as `pmsc demo face`)
    long maxKeys = 170;      ///< K control keys, Multi-PIE 68 fiducials included
    double coverage = 0.9;   ///< of the bound
    long timingFrames = 40;  ///< validation frames timed one by one, full rig vs cross PM, same run
    int threads = 0;         ///< 0 = every core
    bool quick = false;

    std::function<bool(std::string_view, double, double)> progress;

    /// `--quick`: 6 + 1 short sequences (2 train), M = 12, K = 120, 8 timed frames (a smoke test).
    static CrossDemoOptions quickOptions();
};

/// Runs the experiment and writes DIR/report.json (returned), DIR/frames.csv and DIR/cross.pmsc:
/// 1. poses the training sequences twice, control and full rig (the pairs), and trains the cross
///    model (pmsc::trainCross: joint subspace, control keys, the bound from held-out pairs);
/// 2. validation and novel sequences: the control at the keys -> cross PM -> target, against the
///    full rig: the target's largest point error per frame (% of the head diagonal: p50, p95, p99,
///    max), the bound and how often it holds, and for scale what the expensive stages move (the
///    control face's own error against the full rig);
/// 3. speed: one thread, one frame at a time, interleaved on the same validation frames: the full
///    rig's pose against the control at the keys + projection + reconstruction of the target
///    (thread CPU time, and wall time).
/// @throws pmsc::InputError for a bad ICT folder or options, pmsc::IoError, pmsc::Cancelled.
nlohmann::json runCrossDemo(const CrossDemoOptions& options);

}  // namespace pmsc::face
