// `pmsc learn`: a model + new frames (e.g. the misses `--keep-misses` kept) -> an updated model,
// without the original training frames (paper section 5, "training could be done each night").
#include "app/ExitCodes.h"
#include "app/Learn.h"
#include "cli/Args.h"
#include "cli/Commands.h"
#include "cli/Format.h"
#include "cli/Progress.h"
#include "pmsc/Learning.h"

#include <cmath>
#include <iostream>

namespace pmsc::cli {

namespace {

std::vector<std::string> splitPaths(const std::string& text) {
    std::vector<std::string> out;
    std::size_t start = 0;
    while (true) {
        const std::size_t comma = text.find(',', start);
        const std::string item =
            text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
        if (item.empty()) throw UsageError("--frames: empty file name in '" + text + "'");
        out.push_back(item);
        if (comma == std::string::npos) break;
        start = comma + 1;
    }
    return out;
}

/// What `pmsc learn` did, for the person who ran it: sizes, times, thresholds before and after.
void printLearnSummary(const std::string& modelPath, const std::string& outPath, const Model& model,
                       const Model& learned, const LearnReport& report, double seconds) {
    std::cout << "learned " << outPath << " from " << modelPath << " + " << report.newFrames
              << " new frames in " << fmt("%.2f", seconds) << " s (update " << fmt("%.2f", report.seconds)
              << " s: subspace " << fmt("%.2f", report.secondsSubspace) << ", keys "
              << fmt("%.2f", report.secondsKeys) << ", calibration " << fmt("%.2f", report.secondsCalibration)
              << ")\n";
    std::cout << "  frames      " << model.trainFrames << " -> " << learned.trainFrames << " (update "
              << learned.learning->updates << ")\n";
    std::cout << "  basis       M = " << report.basisBefore << " -> " << report.basisAfter
              << (report.basisEnergy > 0 ? " (energy rule " + fmt("%.6g", report.basisEnergy) + ")"
                                         : std::string(" (fixed)"))
              << ", state rank " << report.rankBefore << " -> " << report.rankAfter << ", captures "
              << fmt("%.4f", 100.0 * learned.energyCaptured()) << "% of all frames' energy; largest angle to "
              << "the old basis " << fmt("%.3g", report.largestAngle * 180.0 / 3.141592653589793) << " deg\n";
    std::cout << "  key points  K = " << learned.keyCount() << ", " << report.keysKept
              << " of them keys before\n";
    std::cout << "  new frames  largest " << describe(model.keyErrorNorm) << " under the old model "
              << fmt("%.6g", report.oldModelNewFramesKeyRmsMax) << ", largest point error of the new model "
              << fmt("%.6g", report.newFramesMaxPointError) << "\n";
    std::cout << "  eps         [" << fmt("%.6g", model.epsMin) << ", " << fmt("%.6g", model.epsMax)
              << "] -> [" << fmt("%.6g", learned.epsMin) << ", " << fmt("%.6g", learned.epsMax) << "]";
    if (learned.tolerance > 0) {
        std::cout << " for tolerance " << fmt("%.6g", learned.tolerance) << " ("
                  << toString(learned.calibrationRecord ? learned.calibrationRecord->rule
                                                        : CalibrationRule::MaxRatio)
                  << (learned.keyErrorNorm == KeyErrorNorm::Predicted ? " rule for the leave-one-out part"
                                                                      : " rule")
                  << "; ratio " << fmt("%.4g", report.calibrationRatioNew) << " on the new frames, "
                  << fmt("%.4g", report.calibrationRatioOld) << " on the stored scores)";
    }
    std::cout << "\n";
    if (learned.keyErrorNorm == KeyErrorNorm::Predicted)
        std::cout << "  parts       key RMS eps " << fmt("%.6g", model.partEps.rms) << " -> "
                  << fmt("%.6g", learned.partEps.rms) << ", leave-one-out eps "
                  << fmt("%.6g", model.partEps.loo) << " -> " << fmt("%.6g", learned.partEps.loo) << "\n";
    if (learned.regions)
        std::cout << "  regions     " << learned.regions->regionCount()
                  << " kept, each with its keys, basis and thresholds learned again (" << report.regionKeys
                  << " region keys)\n";
    for (const auto& w : report.warnings) std::cout << "  warning: " << w << "\n";
}

}  // namespace

int runLearn(const std::vector<std::string>& args) {
    app::LearnOptions request;
    std::string& modelPath = request.model;
    std::string framesText, &outPath = request.out, rule;
    pmsc::LearnOptions& options = request.learning;
    bool quiet = false;
    ArgParser parser(
        "learn", "--model MODEL.pmsc --frames NEW.npy[,MORE.npy...] --out NEW_MODEL.pmsc [options]",
        "Updates a model with new frames (typically the misses `replay`/`run --keep-misses` kept)\n"
        "without its training frames (paper section 5): mean and basis by Brand's incremental SVD,\n"
        "keys selected again by the model's selector, the projector, and eps re-calibrated on the\n"
        "new frames by cross-fitting. Exact and approximate parts: docs/learning-and-calibration.md.\n"
        "A model trained with --learn-rank R keeps R singular vectors and its calibration scores,\n"
        "so updates lose less; any model can learn.");
    parser.option("--model", "MODEL.pmsc", "model to update", modelPath, true);
    parser.option("--frames", "NEW.npy[,MORE.npy]", "new frames, one or more .npy files (comma-separated)",
                  framesText, true);
    parser.option("--out", "NEW_MODEL.pmsc", "updated model to write (atomically)", outPath, true);
    parser.option("--basis", "M",
                  "basis size after the update (default: by the training's energy rule on all frames seen, "
                  "when the model stores it; else the model's M)",
                  [&](const std::string& v) { options.basis = parseIndex("--basis", v, 1); });
    parser.option(
        "--energy", "E",
        "M after the update = the smallest capturing this fraction of all frames' energy, in (0, 1] "
        "(default: the training's rule)",
        [&](const std::string& v) {
            const double e = parseDouble("--energy", v, 0.0, 1.0);
            if (!(e > 0)) throw UsageError("--energy: must be in (0, 1], got " + v);
            options.energy = e;
        });
    parser.option("--rank", "R",
                  "rank the incremental state keeps (default: the model's, and up to 4 M during the update)",
                  [&](const std::string& v) { options.maxRank = parseIndex("--rank", v, 1); });
    parser.option("--calibration", "RULE",
                  "threshold, max or conformal (default: the rule the model was calibrated by)", rule);
    parser.option("--coverage", "C",
                  "coverage of the conformal rule, in (0, 1) (default: the model's, else 0.9)",
                  [&](const std::string& v) {
                      const double c = parseDouble("--coverage", v, 0.0, 1.0);
                      if (!(c > 0 && c < 1)) throw UsageError("--coverage: must be in (0, 1), got " + v);
                      options.coverage = c;
                  });
    parser.option(
        "--slices", "S",
        "cross-fitting folds over the new frames (default: slices as large as the training's on all frames "
        "seen, (n + m) / S frames, at least one)",
        [&](const std::string& v) { options.slices = parseIndex("--slices", v, 2); });
    parser.option("--positions", "POINTS.npy",
                  "the point positions the model was trained with (train --positions): its sentinels and "
                  "key neighbours are chosen again from them for the new keys and the points the new "
                  "frames move",
                  request.positions);
    bool noRegions = false;
    parser.flag(
        "--no-regions",
        "a model with regions of local fail-through: drop them (every frame that does not hit then fails "
        "through whole); by default they are kept, with their keys, bases and thresholds learned again",
        noRegions);
    parser.flag("--quiet", "no progress display", quiet);
    if (!parser.parse(args)) return kExitOk;
    try {
        request.frames = splitPaths(framesText);
        options.regions = !noRegions;
        options.rule = app::calibrationNamed(rule, app::Spelling::CommandLine);
        app::validate(request, app::Spelling::CommandLine);
    } catch (const std::invalid_argument& e) {  // UsageError, app::OptionError
        parser.fail(e.what());
    }

    Progress progress("learn", !quiet);
    const app::LearnOutcome outcome =
        app::learnFiles(request, [&](std::string_view stage, double done, double total) {
            return progress.update(stage, done, total);
        });
    progress.finish();
    printLearnSummary(modelPath, outPath, outcome.before, outcome.learned, outcome.report, outcome.seconds);
    return kExitOk;
}

}  // namespace pmsc::cli
