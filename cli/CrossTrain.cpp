// `pmsc train --targets`: cross point multiplication (paper section 7). Called by
// TrainCommand.cpp once the options are parsed; the joint training is pmsc::trainCross.
#include "cli/CrossTrain.h"
#include "app/ExitCodes.h"
#include "cli/Commands.h"
#include "cli/Format.h"
#include "cli/Progress.h"
#include "pmsc/AtomicFile.h"
#include "pmsc/Cross.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelIO.h"
#include "pmsc/NpyIO.h"

#include <chrono>
#include <iostream>

namespace pmsc::cli {

int runTrainCross(const std::string& controlPath, const std::string& targetsPath, const std::string& outPath,
                  const TrainingOptions& training, double coverage, Index slices, bool quiet) {
    // Fail on an unwritable destination, and on pairs that cannot match, before reading anything.
    AtomicFile(outPath).abandon();
    const auto start = std::chrono::steady_clock::now();
    const NpyInfo ci = readNpyInfo(controlPath), ti = readNpyInfo(targetsPath);
    if (ci.frames != ti.frames)
        throw InputError("train: " + controlPath + " has " + std::to_string(ci.frames) +
                         " control frames but " + targetsPath + " has " + std::to_string(ti.frames) +
                         " target frames: cross training needs one target frame per control frame");
    if (ci.channels != ti.channels)
        throw InputError("train: " + controlPath + " has " + std::to_string(ci.channels) + " channels but " +
                         targetsPath + " has " + std::to_string(ti.channels) +
                         ": cross training needs the same channels");
    const FrameSet control = readFrames(controlPath).frames;
    const FrameSet target = readFrames(targetsPath).frames;
    CrossOptions options;
    options.training = training;
    options.coverage = coverage;
    options.slices = slices;
    Progress progress("train", !quiet);
    options.training.progress = [&](std::string_view stage, double done, double total) {
        return progress.update(stage, done, total);
    };
    CrossReport report;
    const Model model = trainCross(control, target, options, &report);
    writeModel(outPath, model);
    progress.finish();
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const CrossState& st = *model.cross;
    std::cout << "trained " << outPath << " (cross point multiplication) from " << control.frames
              << " pairs: " << ci.points << " control points -> " << ti.points << " target points x "
              << ci.channels << " channels in " << fmt("%.2f", seconds) << " s (bound scoring "
              << fmt("%.2f", report.scoringSeconds) << " s)\n";
    std::cout << "  basis       M = " << model.basisSize()
              << " of the joint (control, target) subspace, captures "
              << fmt("%.4f", 100.0 * model.energyCaptured()) << "% of the training energy\n";
    std::cout << "  key points  K = " << model.keyCount() << " control points ("
              << (model.selector == Selector::QDeim ? "Q-DEIM" : "Varimax + teleconnection") << ")\n";
    std::cout << "  residual    largest point error of cross PM on the training pairs (control and target): "
              << fmt("%.6g", model.trainMaxPointResidual) << "\n";
    std::cout << "  fail-through impossible: replay gives every frame its control key RMS e and the bound\n";
    std::cout << "  bound       target's largest point error <= " << fmt("%.6g", st.quantile) << " x (e + "
              << fmt("%.6g", st.scale) << "): conformal quantile at coverage " << fmt("%.4g", st.coverage)
              << " of " << st.keyRms.size() << " held-out training pairs (" << st.slices << " slices; "
              << fmt("%.1f", 100.0 * report.heldOutCoverage) << "% of them inside)\n";
    if (model.tolerance > 0)
        std::cout << "  tolerance   " << fmt("%.6g", model.tolerance)
                  << ": replay flags frames whose bound exceeds it\n";
    for (const auto& w : report.training.warnings) std::cout << "  warning: " << w << "\n";
    return kExitOk;
}

}  // namespace pmsc::cli
