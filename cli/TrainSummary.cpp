#include "cli/TrainSummary.h"
#include "cli/Format.h"

#include <cstdio>

namespace pmsc::cli {

void printTrainSummary(std::ostream& out, const std::string& modelPath, const FrameSet& frames,
                       const Model& model, const TrainingReport& report, double seconds) {
    out << "trained " << modelPath << " from " << frames.frames << " frames x " << frames.points
        << " points x " << frames.channels << " channels in " << fmt("%.2f", seconds) << " s (training "
        << fmt("%.2f", report.seconds) << " s)\n";
    out << "  ranks       " << report.ranks
        << (report.ranks > 1 ? " MPI processes, each reading only its share of the points\n"
                             : " (one process)\n");
    out << "  basis       M = " << model.basisSize() << ", captures "
        << fmt("%.4f", 100.0 * model.energyCaptured()) << "% of the training energy\n";
    out << "  key points  K = " << model.keyCount() << " ("
        << (model.selector == Selector::QDeim ? "Q-DEIM" : "Varimax + teleconnection") << ", "
        << report.iterations << " rounds)\n";
    out << "  residual    largest point error of PM on the training frames: "
        << fmt("%.6g", model.trainMaxPointResidual) << "\n";
    const std::string measure = describe(model.keyErrorNorm);
    if (model.tolerance > 0) {
        out << "  eps         [" << fmt("%.6g", model.epsMin) << ", " << fmt("%.6g", model.epsMax) << "] "
            << measure << ", calibrated for tolerance " << fmt("%.6g", model.tolerance) << " ("
            << report.calibration.slices
            << " held-out slices, point error <= " << fmt("%.4g", report.calibration.ratio) << " x "
            << measure << "; blend band " << fmt("%.3g", model.epsMax / model.epsMin) << "x)\n";
        const CalibrationStats& c = report.calibration;
        if (c.rule == CalibrationRule::Conformal) {
            out << "  rule        conformal: ratio quantile at coverage " << fmt("%.4g", c.coverage) << " of "
                << c.usableFrames << " held-out frames (largest ratio " << fmt("%.4g", c.maxRatio)
                << ", eps_min would be " << fmt("%.6g", c.maxRatio > 0 ? model.tolerance / c.maxRatio : 0.0)
                << " under --calibration max)\n";
        } else if (c.rule == CalibrationRule::Threshold) {
            out << "  rule        threshold: no frame over the tolerance at or below eps_min among "
                << c.usableFrames << " held-out frames (largest ratio " << fmt("%.4g", c.maxRatio)
                << ", eps_min would be " << fmt("%.6g", c.maxRatio > 0 ? model.tolerance / c.maxRatio : 0.0)
                << " under --calibration max)\n";
        } else {
            out << "  rule        max: the largest ratio of " << c.usableFrames << " held-out frames";
            if (c.usableFrames > 0) {
                const double q = conformalQuantile(heldOutRatios(c), 0.95);
                out << " (conformal 95% quantile " << fmt("%.4g", q) << ", eps_min would be "
                    << fmt("%.6g", q > 0 ? model.tolerance / q : 0.0) << ")";
            }
            out << "\n";
        }
    } else {
        out << "  eps         [" << fmt("%.6g", model.epsMin) << ", " << fmt("%.6g", model.epsMax) << "] "
            << measure << ", from the training frames (no --tolerance: not calibrated)\n";
    }
    if (!report.regions.empty()) out << "  regions     " << report.regions << "\n";
    for (const auto& w : report.warnings) out << "  warning: " << w << "\n";
}

}  // namespace pmsc::cli
