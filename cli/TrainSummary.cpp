#include "cli/TrainSummary.h"
#include "cli/Format.h"
#include "pmsc/Sentinels.h"

#include <cstdio>

namespace pmsc::cli {

namespace {

/// How the rule set eps from the held-out frames of `c`, one line.
std::string ruleLine(const CalibrationStats& c, double tolerance) {
    const auto underMax = [&] {
        return "largest ratio " + fmt("%.4g", c.maxRatio) + ", eps_min would be " +
               fmt("%.6g", c.maxRatio > 0 ? tolerance / c.maxRatio : 0.0) + " under --calibration max)\n";
    };
    if (c.rule == CalibrationRule::Conformal)
        return "conformal: ratio quantile at coverage " + fmt("%.4g", c.coverage) + " of " +
               std::to_string(c.usableFrames) + " held-out frames (" + underMax();
    if (c.rule == CalibrationRule::Threshold)
        return "threshold: no frame over the tolerance at or below eps_min among " +
               std::to_string(c.usableFrames) + " held-out frames (" + underMax();
    std::string line = "max: the largest ratio of " + std::to_string(c.usableFrames) + " held-out frames";
    if (c.usableFrames > 0) {
        const double q = conformalQuantile(heldOutRatios(c), 0.95);
        line += " (conformal 95% quantile " + fmt("%.4g", q) + ", eps_min would be " +
                fmt("%.6g", q > 0 ? tolerance / q : 0.0) + ")";
    }
    return line + "\n";
}

}  // namespace

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
    const CalibrationStats& c = report.calibration;
    if (model.tolerance > 0 && model.keyErrorNorm == KeyErrorNorm::Predicted && c.parts.size() == 2) {
        out << "  eps         [" << fmt("%.6g", model.epsMin) << ", " << fmt("%.6g", model.epsMax) << "] "
            << measure << ", calibrated for tolerance " << fmt("%.6g", model.tolerance) << " (" << c.slices
            << " held-out slices; a hit when either part is at or under its threshold; blend band "
            << fmt("%.3g", model.epsMax / model.epsMin) << "x)\n";
        out << "  key RMS     eps " << fmt("%.6g", model.partEps.rms)
            << ", point error <= " << fmt("%.4g", c.parts[0].ratio) << " x key RMS error; "
            << ruleLine(c.parts[0], model.tolerance);
        out << "  leave-out   eps " << fmt("%.6g", model.partEps.loo)
            << ", point error <= " << fmt("%.4g", c.parts[1].ratio) << " x largest leave-one-out key error; "
            << ruleLine(c.parts[1], model.tolerance);
    } else if (model.tolerance > 0) {
        out << "  eps         [" << fmt("%.6g", model.epsMin) << ", " << fmt("%.6g", model.epsMax) << "] "
            << measure << ", calibrated for tolerance " << fmt("%.6g", model.tolerance) << " (" << c.slices
            << " held-out slices, point error <= " << fmt("%.4g", c.ratio) << " x " << measure
            << "; blend band " << fmt("%.3g", model.epsMax / model.epsMin) << "x)\n";
        out << "  rule        " << ruleLine(c, model.tolerance);
    } else {
        out << "  eps         [" << fmt("%.6g", model.epsMin) << ", " << fmt("%.6g", model.epsMax) << "] "
            << measure << ", from the training frames (no --tolerance: not calibrated)\n";
    }
    if (model.sentinels) {
        const Sentinels& s = *model.sentinels;
        out << "  sentinels   " << s.points.size() << ", computed beside every hit: ";
        if (s.source == SentinelSource::PointOrder)
            out << "drawn in point order (no positions given, and neither the training mean nor its frames "
                   "are a shape; "
                   "--positions POINTS.npy spreads them over space)\n";
        else
            out << "spread over the " << describe(s.source) << ", every moving point within "
                << fmt("%.6g", s.coveringRadius) << " of one\n";
    }
    if (model.nonNegative)
        out << "  output      clamped at 0: every training value is >= 0 (--no-clamp keeps PM linear)\n";
    if (!report.regions.empty()) out << "  regions     " << report.regions << "\n";
    for (const auto& w : report.warnings) out << "  warning: " << w << "\n";
}

}  // namespace pmsc::cli
