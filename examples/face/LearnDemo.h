// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <nlohmann/json.hpp>

#include <functional>
#include <string>
#include <string_view>

namespace pmsc::face {

/// The nightly loop of paper section 5 on the ICT face (`pmsc demo learn`): "poses
/// identified as cache misses can be tagged and used as additional training ... training could be
/// done each night".
struct LearnDemoOptions {
    std::string dataDir;  ///< the ICT-FaceKit FaceXModel folder
    std::string outDir;   ///< created if missing

    // --- animation: the face demo's ordinary sequences (same seed: same training and validation
    // split as `pmsc demo face`) and twice as many novel ones, split between the two days.
    unsigned seed = 7;
    long sequences = 36;
    long novelSequences = 16;  ///< day 1's shot: the first half, day 2's: the second half
    long minFrames = 60;
    long maxFrames = 110;
    double trainingFraction = 0.3;

    // --- model (as `pmsc demo face`) ---
    long basis = 48;
    long maxKeys = 170;
    double tolerancePercent = 1.0;  ///< T in % of the head diagonal
    long learnRank = 96;            ///< TrainingOptions::learnRank (2M)
    /// The rule the loop's models are calibrated by. Decision: the largest ratio (MaxRatio) by
    /// default: day 1's shot moves controls training never saw, whose error ratios lie beyond any
    /// quantile of the held-out training frames, and the loop must keep every frame under T.
    bool conformal = false;
    double coverage = 0.9;  ///< of the conformal rule, when chosen
    int threads = 0;
    bool quick = false;

    std::function<bool(std::string_view, double, double)> progress;

    /// `--quick`: 9 ordinary + 4 novel short sequences (a smoke test, ~30 s).
    static LearnDemoOptions quickOptions();
};

/// Runs the loop and writes DIR/report.json (returned), DIR/frames.csv, DIR/day1.pmsc, DIR/day2.pmsc,
/// DIR/scratch.pmsc and DIR/day1-misses.npy (+ .frames sidecar):
/// 1. train the day-1 model on the training sequences (conformal calibration, learning state);
/// 2. day 1: the first half of the novel sequences through the soft cache; every blend or miss
///    is kept (pmsc::KeptFrames, as `--keep-misses` does);
/// 3. night: pmsc::learn(day-1 model, kept frames) -> day-2 model, timed; and, for comparison,
///    pmsc::train on the training frames + the kept frames (training from scratch), timed;
/// 4. day 2: the second half of the novel sequences (the same kind of motion: the same novel
///    controls, other performances) through the day-1, day-2 and scratch models;
/// 5. validation (the face demo's validation sequences) through the three models, and the
///    calibration comparison on it: hits and worst soft-cached error with eps from the largest
///    held-out ratio (the max rule) and from the conformal quantile (the conformal rule), and the best
///    single threshold that keeps every frame under T (an oracle that sees the errors), for the
///    conformal rule at coverages 0.9, 0.95 and 0.99, with the frames each puts over T.
/// @throws pmsc::InputError for a bad ICT folder or options, pmsc::IoError, pmsc::Cancelled.
nlohmann::json runLearnDemo(const LearnDemoOptions& options);

}  // namespace pmsc::face
