#include "pmsc/Cross.h"

#include "pmsc/ByteIO.h"
#include "pmsc/Calibration.h"
#include "pmsc/Communicator.h"
#include "pmsc/Errors.h"
#include "pmsc/RowBlockOps.h"
#include "pmsc/RowBlocks.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

namespace pmsc {

namespace {

/// The target's rows of an in-memory centred joint matrix, as RowBlocks (no copy): what the
/// held-out scoring measures E on.
class TargetRows final : public RowBlocks {
public:
    /// A view on `joint`'s target rows (a Map: no copy whose lifetime would end with the call).
    TargetRows(Eigen::Map<const Eigen::MatrixXd> joint, Index channels, Index controlPoints)
        : RowBlocks(joint.rows() / channels - controlPoints, channels, joint.cols(), 0,
                    joint.rows() / channels - controlPoints, joint.rows() / channels - controlPoints),
          q_(joint.bottomRows(joint.rows() - controlPoints * channels)) {}
    Eigen::Ref<const Eigen::MatrixXd> block(Index b) override {
        return q_.middleRows(blockFirstRow(b), blockRows(b));
    }
    void pointRows(Index point, Eigen::Ref<Eigen::MatrixXd> out) override {
        out = q_.middleRows(point * channels(), channels());
    }
    Eigen::VectorXd mean() override { return Eigen::VectorXd::Zero(ownedRows()); }

private:
    Eigen::Ref<const Eigen::MatrixXd> q_;
};

void checkFinite(const FrameSet& s, const char* what) {
    for (size_t i = 0; i < s.values.size(); ++i) {
        if (!std::isfinite(s.values[i])) {
            const Index at = static_cast<Index>(i);
            throw InputError(std::string("train: ") + what + " frame " + std::to_string(at / s.rows()) +
                             ", point " + std::to_string((at % s.rows()) / s.channels) + ", channel " +
                             std::to_string(at % s.channels) + " is not finite");
        }
    }
}

double median(std::vector<double> v) {
    if (v.empty()) return 0;
    const size_t mid = v.size() / 2;
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
    double m = v[mid];
    if (v.size() % 2 == 0)
        m = 0.5 * (m + *std::max_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid)));
    return m;
}

}  // namespace

namespace {

/// trainCross's preconditions: pairs that match, enough of them, settings a cross model takes.
void checkCrossInputs(const FrameSet& control, const FrameSet& target, const CrossOptions& options) {
    if (control.frames != target.frames) {
        throw InputError("train: the control has " + std::to_string(control.frames) +
                         " frames and the targets " + std::to_string(target.frames) +
                         ": cross training needs one target frame per control frame");
    }
    if (control.channels != target.channels) {
        throw InputError("train: the control has " + std::to_string(control.channels) +
                         " channels and the targets " + std::to_string(target.channels) +
                         ": cross training needs the same channels");
    }
    if (control.frames < 2)
        throw InputError("train: need at least 2 training pairs, got " + std::to_string(control.frames));
    if (control.points < 1 || target.points < 1 || control.channels < 1)
        throw InputError("train: control and targets need at least one point and one channel");
    if (!(options.coverage > 0 && options.coverage < 1))
        throw std::invalid_argument("train: cross coverage must be in (0, 1), got " +
                                    std::to_string(options.coverage));
    if (options.slices < 2 || options.slices > control.frames)
        throw std::invalid_argument("train: cross slices must be in [2, " + std::to_string(control.frames) +
                                    "], got " + std::to_string(options.slices));
    if (options.training.regions.count > 0)
        throw std::invalid_argument(
            "train: regions (local fail-through) do not apply to a cross model: it cannot fail through");
    if (options.training.learnRank > 0)
        throw std::invalid_argument(
            "train: --learn-rank does not apply to a cross model (pmsc learn updates plain models)");
    if (options.training.keyCandidates != 0)
        throw std::invalid_argument("train: key candidates are set by cross training (the control's points)");
    checkFinite(control, "control");
    checkFinite(target, "target");
}

/// The bound on a target's largest point error from the held-out pairs' scores (section CROSSPM):
/// error <= quantile x (key RMS + scale), the quantile conformal at the coverage asked.
CrossState crossBound(const CalibrationStats& s, Index controlPoints, const CrossOptions& options,
                      std::vector<std::string>& warnings) {
    CrossState st;
    st.controlPoints = controlPoints;
    st.coverage = options.coverage;
    st.slices = options.slices;
    st.keyRms = s.keyRms;
    st.targetError = s.maxPointError;
    st.scale = median(st.keyRms);
    if (!(st.scale > 0)) {
        // Every held-out key error is zero (K*C == M, or a target that is an exact function of
        // keys the basis holds): fall back to a scale from the target errors so scores exist.
        st.scale = std::max(1e-300, median(st.targetError));
        warnings.push_back(
            "cross: every held-out control key error is 0; the bound's scale is the median held-out target "
            "error");
    }
    std::vector<double> scores(st.keyRms.size());
    for (size_t i = 0; i < scores.size(); ++i) scores[i] = st.targetError[i] / (st.keyRms[i] + st.scale);
    st.quantile = conformalQuantile(scores, st.coverage);
    const double n = static_cast<double>(scores.size());
    if ((n + 1) * st.coverage > n * (1 + 1e-9)) {
        warnings.push_back("cross: " + std::to_string(scores.size()) +
                           " held-out pairs are too few for the quantile at coverage " +
                           std::to_string(st.coverage) + "; the bound uses the largest score");
    }
    return st;
}

}  // namespace

Model trainCross(const FrameSet& control, const FrameSet& target, const CrossOptions& options,
                 CrossReport* reportOut) {
    const auto start = std::chrono::steady_clock::now();
    CrossReport local;
    CrossReport& report = reportOut ? *reportOut : local;
    report = CrossReport{};
    checkCrossInputs(control, target, options);
    const Index nc = control.points, nt = target.points, c = control.channels, f = control.frames;
    report.controlPoints = nc;
    report.targetPoints = nt;
    // The joint matrix, centred: each pair's control rows above its target rows.
    std::unique_ptr<MatrixBlocks> q;
    {
        FrameSet joint(f, nc + nt, c);
        for (Index i = 0; i < f; ++i) {
            std::copy(control.frame(i), control.frame(i) + nc * c, joint.frame(i));
            std::copy(target.frame(i), target.frame(i) + nt * c, joint.frame(i) + nc * c);
        }
        q = std::make_unique<MatrixBlocks>(joint);
    }
    TrainingOptions to = options.training;
    to.keyCandidates = nc;
    to.tolerance = 0;  // no eps: a cross model has no fail-through to calibrate
    to.regions.count = 0;
    to.keyErrorNorm = KeyErrorNorm::Rms;  // the bound below is calibrated on the key RMS
    SingleProcess one;
    Model model = train(*q, one, to, &report.training);
    model.tolerance = options.training.tolerance;

    // --- The bound, from held-out training pairs.
    const auto scoring = std::chrono::steady_clock::now();
    if (options.training.progress) options.training.progress("cross bound", 0, 1);
    const Eigen::MatrixXd gram = gramOf(*q, one);
    const Eigen::MatrixXd keyRows = keyRowsOfQ(*q, one, model.keyPoints);
    TargetRows targetRows(q->matrix(), c, nc);
    const CalibrationStats s = calibrate(targetRows, one, keyRows, model.keyPoints, model.basisSize(),
                                         /*tolerance, unused here=*/1.0, options.slices, gram);
    for (const auto& note : s.notes) report.training.warnings.push_back(note);
    CrossState st = crossBound(s, nc, options, report.training.warnings);
    const double n = static_cast<double>(st.keyRms.size());
    Index inside = 0;
    for (size_t i = 0; i < st.keyRms.size(); ++i) inside += st.targetError[i] <= st.bound(st.keyRms[i]);
    report.heldOutCoverage = st.keyRms.empty() ? 0.0 : static_cast<double>(inside) / n;
    model.cross = std::move(st);
    model.validate();
    model.cross->validate(model.points, model.keyPoints);
    if (options.training.progress) options.training.progress("cross bound", 1, 1);
    const auto end = std::chrono::steady_clock::now();
    report.scoringSeconds = std::chrono::duration<double>(end - scoring).count();
    report.seconds = std::chrono::duration<double>(end - start).count();
    return model;
}

CrossMultiplier::CrossMultiplier(const Model& model)
    : model_(model),
      state_(model.cross ? *model.cross
                         : throw std::invalid_argument(
                               "not a cross point-multiplication model (no CROSSPM section)")),
      pm_(model) {}

CrossMultiplier::Result CrossMultiplier::apply(const double* keyValues, double* target) const {
    Eigen::VectorXd coords(model_.coordCount());
    pm_.project(keyValues, coords.data());
    Result r;
    r.keyRms = pm_.keyError(keyValues, coords.data());
    r.bound = state_.bound(r.keyRms);
    pm_.reconstructRange(coords.data(), state_.controlPoints, targetPoints(), target);
    return r;
}

CrossMultiplier::Result CrossMultiplier::applyFrame(const double* control, double* target) const {
    const Index c = model_.channels;
    std::vector<double> keys(static_cast<size_t>(model_.keyCount() * c));
    for (Index i = 0; i < model_.keyCount(); ++i)
        for (Index j = 0; j < c; ++j)
            keys[static_cast<size_t>(i * c + j)] = control[model_.keyPoints[static_cast<size_t>(i)] * c + j];
    return apply(keys.data(), target);
}

// --- section CROSSPM -----------------------------------------------------------------------------

}  // namespace pmsc
