// `pmsc train --targets`: cross point multiplication (paper section 7). Called by
// TrainCommand.cpp once the options are parsed; the joint training is pmsc::trainCross.
#include "cli/CrossTrain.h"
#include "app/ExitCodes.h"
#include "cli/Commands.h"
#include "cli/Format.h"
#include "cli/Progress.h"
#include "pmsc/Cross.h"

#include <iostream>

namespace pmsc::cli {

int runTrainCross(const app::TrainOptions& request, bool quiet) {
    Progress progress("train", !quiet);
    const app::CrossOutcome outcome =
        app::trainCrossFiles(request, [&](std::string_view stage, double done, double total) {
            return progress.update(stage, done, total);
        });
    progress.finish();
    const Model& model = outcome.model;
    const CrossReport& report = outcome.report;
    const CrossState& st = *model.cross;
    std::cout << "trained " << request.out << " (cross point multiplication) from " << outcome.pairs
              << " pairs: " << outcome.controlPoints << " control points -> " << outcome.targetPoints
              << " target points x " << outcome.channels << " channels in " << fmt("%.2f", outcome.seconds)
              << " s (bound scoring " << fmt("%.2f", report.scoringSeconds) << " s)\n";
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
