// `pmsc train`: frames (.npy) -> model (.pmsc). Sections 3-5 of the paper, plus calibration.
#include "cli/Args.h"
#include "cli/Commands.h"
#include "cli/ExitCodes.h"
#include "cli/Interrupt.h"
#include "cli/Progress.h"
#include "cli/TrainSummary.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"
#include "pmsc/Training.h"

#include <chrono>
#include <iostream>

namespace pmsc::cli {

int runTrain(const std::vector<std::string>& args) {
    std::string framesPath, outPath, selector = "teleconnection";
    TrainingOptions options;
    bool quiet = false;
    ArgParser parser("train", "--frames TRAIN.npy --out MODEL.pmsc [options]",
                     "Trains a point-multiplication model: mean removal, a truncated SVD basis (section 3),\n"
                     "key points by Varimax + teleconnection or Q-DEIM (section 4), the least-squares\n"
                     "projector, and the soft-cache thresholds eps (section 5). With --tolerance, eps is\n"
                     "calibrated by leave-one-slice-out so that a hit's largest point error stays under it.");
    parser.option("--frames", "FILE.npy", "training frames, shape (frames, points, channels), float32/64",
                  framesPath, true);
    parser.option("--out", "MODEL.pmsc", "model file to write (atomically)", outPath, true);
    parser.option("--basis", "M", "basis size M",
                  [&](const std::string& v) { options.basis = parseIndex("--basis", v, 1); });
    parser.option("--energy", "E", "smallest M capturing this fraction of the energy, in (0, 1]",
                  [&](const std::string& v) {
                      options.energy = parseDouble("--energy", v, 0.0, 1.0);
                      if (options.energy <= 0) throw UsageError("--energy: must be in (0, 1]");
                  });
    parser.option(
        "--basis-error", "X", "smallest M whose largest point projection error <= X (data units)",
        [&](const std::string& v) { options.basisMaxError = parseDouble("--basis-error", v, 0.0); });
    parser.option("--max-basis", "M",
                  "cap on M whatever the rule (default " + std::to_string(options.maxBasis) + ")",
                  [&](const std::string& v) { options.maxBasis = parseIndex("--max-basis", v, 1); });
    parser.option("--max-error", "X", "stop adding keys once the largest training point residual <= X",
                  [&](const std::string& v) { options.maxError = parseDouble("--max-error", v, 0.0); });
    parser.option("--max-keys", "K", "key point budget (default " + std::to_string(options.maxKeys) + ")",
                  [&](const std::string& v) { options.maxKeys = parseIndex("--max-keys", v, 1); });
    parser.option(
        "--block", "B",
        "basis vectors per Varimax block (paper: 10-20; default " + std::to_string(options.block) + ")",
        [&](const std::string& v) { options.block = parseIndex("--block", v, 1); });
    parser.option("--fiducials", "i,j,...", "designer key points, seeded first",
                  [&](const std::string& v) { options.fiducials = parseIndexList("--fiducials", v); });
    parser.option("--grid-points", "i,j,...", "sparse grid of points seeded as keys (rendering)",
                  [&](const std::string& v) { options.gridPoints = parseIndexList("--grid-points", v); });
    parser.option("--selector", "NAME", "teleconnection (the paper's, default) or qdeim", selector);
    parser.option("--tolerance", "T", "largest point error a hit may have (data units): calibrates eps",
                  [&](const std::string& v) { options.tolerance = parseDouble("--tolerance", v, 0.0); });
    parser.option("--slices", "S",
                  "leave-one-slice-out folds for --tolerance (default " +
                      std::to_string(options.calibrationSlices) + ")",
                  [&](const std::string& v) { options.calibrationSlices = parseIndex("--slices", v, 2); });
    parser.option("--seed", "S", "seed of the randomized SVD (training is deterministic for a seed)",
                  [&](const std::string& v) {
                      options.seed = static_cast<unsigned>(parseIndex("--seed", v, 0, 0xffffffffll));
                  });
    parser.option("--power-iterations", "Q",
                  "randomized SVD power iterations (default " + std::to_string(options.powerIterations) + ")",
                  [&](const std::string& v) {
                      options.powerIterations = static_cast<int>(parseIndex("--power-iterations", v, 0, 20));
                  });
    parser.option("--regions", "R",
                  "learn R regions for local fail-through (issue 9; a version-2 model): only the regions\n"
                  "that blend or miss go to the full calculation. Needs 3-channel (position) data",
                  [&](const std::string& v) { options.regions.count = parseIndex("--regions", v, 1); });
    parser.option("--feather", "F",
                  "feather width of region borders, fraction of the bounding-box diagonal (default " +
                      std::to_string(options.regions.featherFraction) + ")",
                  [&](const std::string& v) { options.regions.featherFraction = parseDouble("--feather", v, 0.0, 0.5); });
    parser.flag("--quiet", "no progress display", quiet);
    if (!parser.parse(args)) return kExitOk;

    const int sizeRules = parser.given("--basis") + parser.given("--energy") + parser.given("--basis-error");
    if (sizeRules > 1) parser.fail("give at most one of --basis, --energy, --basis-error");
    if (selector == "teleconnection") {
        options.selector = Selector::Teleconnection;
    } else if (selector == "qdeim") {
        options.selector = Selector::QDeim;
    } else {
        parser.fail("--selector: '" + selector + "' is not teleconnection or qdeim");
    }

    // Fail on an unwritable destination now, not after a long training.
    AtomicFile(outPath).abandon();

    const auto start = std::chrono::steady_clock::now();
    const FrameFile frames = readFrames(framesPath);
    Progress progress("train", !quiet);
    options.progress = [&](std::string_view stage, double done, double total) {
        return progress.update(stage, done, total);
    };
    TrainingReport report;
    const Model model = train(frames.frames, options, &report);
    writeModel(outPath, model);
    progress.finish();
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    printTrainSummary(std::cout, outPath, frames.frames, model, report, seconds);
    return kExitOk;
}

}  // namespace pmsc::cli
