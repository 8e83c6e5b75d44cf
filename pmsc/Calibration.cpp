#include "pmsc/Calibration.h"

#include "pmsc/Model.h"
#include "pmsc/RowBlockOps.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace pmsc {

Eigen::VectorXd leaveOneOutScale(const Eigen::MatrixXd& bk, const Eigen::MatrixXd& projector) {
    if (projector.rows() != bk.cols() || projector.cols() != bk.rows())
        throw std::invalid_argument("leaveOneOutScale: the projector is not pinv of these key rows");
    Eigen::VectorXd scale(bk.rows());
    for (Index j = 0; j < bk.rows(); ++j) {
        const double h = bk.row(j).dot(projector.col(j));
        scale[j] = 1.0 / std::max(1.0 - h, kMinOneMinusLeverage);
    }
    return scale;
}

void appendKeyScore(CalibrationStats& s, const Eigen::Ref<const Eigen::VectorXd>& residual, Index channels,
                    KeyErrorNorm norm, const Eigen::VectorXd& looScale) {
    if (norm == KeyErrorNorm::Predicted) {
        s.keyRms.push_back(keyErrorOfResidual(residual, channels, KeyErrorNorm::Rms));
        s.keyLoo.push_back(keyErrorOfResidual(residual, channels, KeyErrorNorm::LeaveOneOut, &looScale));
    } else {
        s.keyRms.push_back(keyErrorOfResidual(residual, channels, norm, &looScale));
    }
}

std::vector<double> predictedErrors(const std::vector<double>& rms, const std::vector<double>& loo,
                                    PredictedParts eps, double tolerance) {
    if (rms.size() != loo.size())
        throw std::invalid_argument("calibration: the predicted error's two parts differ in count");
    std::vector<double> e(rms.size());
    for (std::size_t f = 0; f < e.size(); ++f) e[f] = predictedPointError({rms[f], loo[f]}, eps, tolerance);
    return e;
}

double keyErrorOfResidual(const Eigen::Ref<const Eigen::VectorXd>& residual, Index channels,
                          KeyErrorNorm norm, const Eigen::VectorXd* looScale) {
    if (norm == KeyErrorNorm::Predicted)
        throw std::invalid_argument("keyErrorOfResidual: the predicted error needs its parts' thresholds");
    const Index keys = residual.size() / channels;  // rows are key x channel: exact
    if (norm == KeyErrorNorm::Rms) return std::sqrt(residual.squaredNorm() / static_cast<double>(keys));
    const bool loo = norm == KeyErrorNorm::LeaveOneOut;
    if (loo && (looScale == nullptr || looScale->size() != residual.size()))
        throw std::invalid_argument("keyErrorOfResidual: the leave-one-out error needs each key row's scale");
    double largest = 0;
    for (Index k = 0; k < keys; ++k) {
        double key = 0;
        for (Index ch = 0; ch < channels; ++ch) {
            const Index row = k * channels + ch;
            const double r = loo ? residual[row] * (*looScale)[row] : residual[row];
            key += r * r;
        }
        largest = std::max(largest, key);
    }
    return std::sqrt(largest);
}

Eigen::VectorXd keyRmsPerFrame(const Eigen::Ref<const Eigen::MatrixXd>& q, const Eigen::MatrixXd& basis,
                               Index channels, const std::vector<Index>& keys,
                               const Eigen::MatrixXd& projector, KeyErrorNorm norm) {
    return keyRmsFromKeyRows(gatherKeyRows(q, channels, keys), gatherKeyRows(basis, channels, keys), channels,
                             projector, norm);
}

Eigen::VectorXd keyRmsFromKeyRows(const Eigen::MatrixXd& qk, const Eigen::MatrixXd& bk, Index channels,
                                  const Eigen::MatrixXd& projector, KeyErrorNorm norm) {
    Eigen::MatrixXd coords = projector * qk;
    Eigen::MatrixXd r = qk;
    r.noalias() -= bk * coords;
    const Eigen::VectorXd scale = usesLeaveOneOut(norm) ? leaveOneOutScale(bk, projector) : Eigen::VectorXd();
    Eigen::VectorXd e(r.cols());
    for (Index j = 0; j < r.cols(); ++j) e[j] = keyErrorOfResidual(r.col(j), channels, norm, &scale);
    return e;
}

CalibrationStats thresholdsFromTraining(const Eigen::Ref<const Eigen::MatrixXd>& q,
                                        const Eigen::MatrixXd& basis, Index channels,
                                        const std::vector<Index>& keys, const Eigen::MatrixXd& projector,
                                        KeyErrorNorm norm) {
    return thresholdsFromKeyRows(gatherKeyRows(q, channels, keys), gatherKeyRows(basis, channels, keys),
                                 channels, projector, norm);
}

CalibrationStats thresholdsFromKeyRows(const Eigen::MatrixXd& qk, const Eigen::MatrixXd& bk, Index channels,
                                       const Eigen::MatrixXd& projector, KeyErrorNorm norm) {
    CalibrationStats s;
    const Eigen::VectorXd e = keyRmsFromKeyRows(qk, bk, channels, projector, norm);
    s.epsMin = e.size() > 0 ? e.maxCoeff() : 0.0;
    s.epsMax = 1.5 * s.epsMin;
    s.keyRms.assign(e.data(), e.data() + e.size());
    return s;
}

CalibrationStats calibrate(const Eigen::Ref<const Eigen::MatrixXd>& q, Index channels,
                           const std::vector<Index>& keys, Index basisSize, double tolerance, Index slices,
                           const SvdOptions&, const Eigen::MatrixXd* gram, CalibrationRule rule,
                           double coverage, KeyErrorNorm norm) {
    if (gram && (gram->rows() != q.cols() || gram->cols() != q.cols())) {
        throw std::invalid_argument("calibrate: Gram matrix is not F x F");
    }
    if (channels < 1 || q.rows() % channels != 0)
        throw std::invalid_argument("calibrate: rows are not whole points");
    MatrixBlocks blocks(q, channels, /*centre=*/false);
    SingleProcess one;
    return calibrate(blocks, one, gatherKeyRows(q, channels, keys), keys, basisSize, tolerance, slices,
                     gram ? *gram : gramMatrix(q), rule, coverage, 1, norm);
}

namespace {

/// The arguments of the cross-fitted calibration, checked before any work.
void checkCalibrationArguments(Index f, Index group, double tolerance, Index slices, Index basisSize,
                               const Eigen::MatrixXd& gram, CalibrationRule rule, double coverage) {
    if (group < 1 || f % group != 0)
        throw std::invalid_argument("calibrate: " + std::to_string(f) + " frames are not whole groups of " +
                                    std::to_string(group));
    const Index groups = f / group;
    if (!(tolerance > 0) || !std::isfinite(tolerance)) {
        throw std::invalid_argument("calibration tolerance must be a positive number, got " +
                                    std::to_string(tolerance));
    }
    if (slices < 2 || slices > groups) {
        throw std::invalid_argument("calibration slices must be in [2, " + std::to_string(groups) +
                                    "] (the frame count), got " + std::to_string(slices));
    }
    if (basisSize < 1) throw std::invalid_argument("calibration: basis size must be >= 1");
    if (rule != CalibrationRule::MaxRatio && !(coverage > 0 && coverage < 1)) {
        throw std::invalid_argument("calibration coverage must be in (0, 1), got " +
                                    std::to_string(coverage));
    }
    if (gram.rows() != f || gram.cols() != f)
        throw std::invalid_argument("calibrate: Gram matrix is not F x F");
}

/// The Gram matrix of the held-in frames (all but [first, last)), centred on their own mean.
Eigen::MatrixXd heldInGram(const Eigen::MatrixXd& gram, Index first, Index last) {
    const Index f = gram.rows();
    const Index in = f - (last - first);
    const Index right = f - last;
    Eigen::MatrixXd g(in, in);
    g.topLeftCorner(first, first) = gram.topLeftCorner(first, first);
    g.topRightCorner(first, right) = gram.topRightCorner(first, right);
    g.bottomLeftCorner(right, first) = gram.bottomLeftCorner(right, first);
    g.bottomRightCorner(right, right) = gram.bottomRightCorner(right, right);
    // J g J: subtract row and column means, add back the grand mean.
    const Eigen::VectorXd rowMean = g.rowwise().mean();
    const double grand = rowMean.mean();
    g.colwise() -= rowMean;
    g.rowwise() -= rowMean.transpose();
    g.array() += grand;
    return g;
}

/// The cross-fitting folds: what they share, and the tally of folds with a smaller basis.
struct Folds {
    KeyErrorNorm norm;
    RowBlocks& q;
    Communicator& comm;
    const Eigen::MatrixXd& keyRows;
    const std::vector<Index>& keys;
    const Eigen::MatrixXd& gram;
    Index basisSize;
    Index cappedFolds = 0;
    Index smallestM = basisSize;
    Eigen::MatrixXd uBlock, residual;  // buffers of one slab of rows, reused fold after fold

    Folds(RowBlocks& blocks, Communicator& communicator, const Eigen::MatrixXd& rowsAtKeys,
          const std::vector<Index>& keyPoints, const Eigen::MatrixXd& gramMatrix, Index m, KeyErrorNorm n)
        : norm(n),
          q(blocks),
          comm(communicator),
          keyRows(rowsAtKeys),
          keys(keyPoints),
          gram(gramMatrix),
          basisSize(m) {}

    /// One fold: the model of the frames outside [first, last) scores the held-out frames, whose
    /// key RMS and largest point error are appended to `s`.
    void score(Index first, Index last, CalibrationStats& s);
};

void Folds::score(Index first, Index last, CalibrationStats& s) {
    const Index f = q.frames();
    const Index channels = q.channels();
    const Index out = last - first;
    const Index in = f - out;
    const Index right = f - last;
    // A centered matrix of `in` frames has rank <= in - 1.
    Index m = std::min(basisSize, in - 1);
    if (m < 1) {
        ++cappedFolds;
        return;
    }
    const Eigen::MatrixXd g = heldInGram(gram, first, last);
    TruncatedSvd fold = svdFromGram(Eigen::MatrixXd(0, in), g, m, 0);
    if (fold.sigma.size() < basisSize) ++cappedFolds;
    m = fold.sigma.size();
    smallestM = std::min(smallestM, m);
    if (m < 1) return;
    // U = Q_I (J V) S^-1; J V removes each column's mean. Only its key rows are formed whole
    // (for the projector); the other rows are formed block by block below.
    Eigen::MatrixXd jv = fold.v;
    jv.rowwise() -= jv.colwise().mean();
    for (Index i = 0; i < jv.cols(); ++i) jv.col(i) /= fold.sigma[i];
    auto heldInTimes = [&](const Eigen::Ref<const Eigen::MatrixXd>& rows, Eigen::MatrixXd& u) {
        u.resize(rows.rows(), m);
        u.noalias() = rows.leftCols(first) * jv.topRows(first);
        u.noalias() += rows.rightCols(right) * jv.bottomRows(right);
    };
    auto heldInMean = [&](const Eigen::Ref<const Eigen::MatrixXd>& rows) -> Eigen::VectorXd {
        return (rows.leftCols(first).rowwise().sum() + rows.rightCols(right).rowwise().sum()) /
               static_cast<double>(in);
    };
    Eigen::MatrixXd uk;
    heldInTimes(keyRows, uk);
    const Eigen::MatrixXd projector = projectorFromKeyRows(uk, channels);
    const Eigen::VectorXd looScale =
        usesLeaveOneOut(norm) ? leaveOneOutScale(uk, projector) : Eigen::VectorXd();
    Eigen::MatrixXd heldOutK = keyRows.middleCols(first, out).colwise() - heldInMean(keyRows);
    const Eigen::MatrixXd coords = projector * heldOutK;
    heldOutK.noalias() -= uk * coords;  // the PM residual at the keys

    Eigen::VectorXd pointErr = Eigen::VectorXd::Zero(out);
    // Slabs of kSlabPoints points: a fold's held-in basis and residual exist for one
    // slab at a time, not for a whole block (in memory the block is every row: at a million
    // points they were 0.8 GB beside the frames). A point's error is the same in any slab.
    const Index slab = kSlabPoints * channels;
    for (Index b = 0; b < q.blockCount(); ++b) {
        const Eigen::Ref<const Eigen::MatrixXd> block = q.block(b);
        for (Index r0 = 0; r0 < block.rows(); r0 += slab) {
            const Eigen::Ref<const Eigen::MatrixXd> rows =
                block.middleRows(r0, std::min(slab, block.rows() - r0));
            heldInTimes(rows, uBlock);
            residual = rows.middleCols(first, out).colwise() - heldInMean(rows);
            residual.noalias() -= uBlock * coords;  // the PM residual of the held-out frames
            const Eigen::VectorXd e = maxPointNormPerColumn(residual, channels);
            for (Index j = 0; j < out; ++j)
                if (!(e[j] <= pointErr[j])) pointErr[j] = e[j];  // NaN wins
        }
    }
    maxOverRanks(comm, pointErr.data(), static_cast<std::size_t>(out));
    for (Index j = 0; j < out; ++j) {
        s.frames.push_back(first + j);
        appendKeyScore(s, heldOutK.col(j), channels, norm, looScale);
        s.maxPointError.push_back(pointErr[j]);
    }
}

/// Folds the scores of a group's members (shared channels: a frame's C channel frames) into one
/// score per frame.
void foldGroups(CalibrationStats& s, Index group) {
    // One entry per frame, not per member of its group (shared channels: a frame's C channel
    // frames), in the measures the runtime uses: e_f = sqrt(sum_c e_c^2) is exactly the
    // frame's key error (RMS over keys of the Euclidean error over channels, PointMultiplier),
    // and E_f = sqrt(sum_c E_c^2) bounds its largest Euclidean point error from above (each
    // E_c is the largest over points of that channel's error). Decision: so the conformal
    // rule's coverage counts frames, as its users read it, and both rules bound the point
    // error a user measures; per channel the max rule would be a little more conservative
    // (max_c E_c / e_c >= E_f / e_f) at the price of counting each frame C times.
    // Folded in place: group f is read from entries f*g.. before entry f is written.
    const std::size_t g = static_cast<std::size_t>(group), groups = s.frames.size() / g;
    for (std::size_t f = 0; f < groups; ++f) {
        double k2 = 0, e2 = 0;
        for (std::size_t j = f * g; j < (f + 1) * g; ++j) {
            k2 += s.keyRms[j] * s.keyRms[j];
            e2 += s.maxPointError[j] * s.maxPointError[j];  // NaN stays NaN
        }
        s.frames[f] = s.frames[f * g] / group;
        s.keyRms[f] = std::sqrt(k2);
        s.maxPointError[f] = std::sqrt(e2);
    }
    s.frames.resize(groups);
    s.keyRms.resize(groups);
    s.maxPointError.resize(groups);
}

}  // namespace

CalibrationStats calibrate(RowBlocks& q, Communicator& comm, const Eigen::MatrixXd& keyRows,
                           const std::vector<Index>& keys, Index basisSize, double tolerance, Index slices,
                           const Eigen::MatrixXd& gram, CalibrationRule rule, double coverage, Index group,
                           KeyErrorNorm norm) {
    const Index f = q.frames();
    checkCalibrationArguments(f, group, tolerance, slices, basisSize, gram, rule, coverage);
    // A frame's largest key over its C channel frames is not a function of their own largest keys.
    if (group > 1 && norm != KeyErrorNorm::Rms)
        throw std::invalid_argument(
            "calibrate: the largest-key errors are for models whose channels do not share the basis");
    const Index groups = f / group;
    CalibrationStats s;
    s.tolerance = tolerance;
    s.slices = slices;
    s.frames.reserve(static_cast<size_t>(f));
    Folds folds(q, comm, keyRows, keys, gram, basisSize, norm);
    for (Index slice = 0; slice < slices; ++slice) {
        const Index first = group * (slice * groups / slices);
        const Index last = group * ((slice + 1) * groups / slices);  // exclusive
        folds.score(first, last, s);
    }
    if (folds.cappedFolds > 0) {
        s.notes.push_back("calibration: " + std::to_string(folds.cappedFolds) + " of " +
                          std::to_string(slices) + " folds had fewer than M = " + std::to_string(basisSize) +
                          " usable basis vectors (down to " + std::to_string(folds.smallestM) + ")");
    }
    if (group > 1) foldGroups(s, group);
    if (norm == KeyErrorNorm::Predicted)
        setPredictedThresholds(s, tolerance, rule, coverage);
    else
        setThresholds(s, tolerance, rule, coverage);
    return s;
}

const char* toString(CalibrationRule rule) {
    switch (rule) {
        case CalibrationRule::Conformal:
            return "conformal";
        case CalibrationRule::Threshold:
            return "threshold";
        case CalibrationRule::MaxRatio:
            break;
    }
    return "max";
}

std::optional<CalibrationRule> calibrationRuleNamed(const std::string& name) {
    for (CalibrationRule r :
         {CalibrationRule::MaxRatio, CalibrationRule::Conformal, CalibrationRule::Threshold})
        if (name == toString(r)) return r;
    return std::nullopt;
}

namespace {

// A key error at rounding level says nothing about the frame: it is left out of the ratios.
double blindLevel(const CalibrationStats& s) {
    const double largestError =
        s.maxPointError.empty() ? 0.0 : *std::max_element(s.maxPointError.begin(), s.maxPointError.end());
    return 1e-9 * largestError;
}

}  // namespace

std::vector<double> heldOutRatios(const CalibrationStats& s) {
    const double blind = blindLevel(s);
    std::vector<double> ratios;
    for (size_t i = 0; i < s.keyRms.size() && i < s.maxPointError.size(); ++i)
        if (s.keyRms[i] > blind && s.keyRms[i] > 0) ratios.push_back(s.maxPointError[i] / s.keyRms[i]);
    return ratios;
}

double conformalQuantile(std::vector<double> values, double coverage) {
    if (values.empty()) return 0;
    std::sort(values.begin(), values.end());
    const double n = static_cast<double>(values.size());
    // rank = ceil((n + 1) coverage), guarded against (n + 1) coverage landing a rounding error
    // above an integer.
    const double exact = (n + 1) * coverage;
    double rank = std::ceil(exact - 1e-9 * exact);
    if (rank < 1) rank = 1;
    if (rank > n) return values.back();
    return values[static_cast<std::size_t>(rank) - 1];
}

namespace {

/// CalibrationRule::Threshold: the largest held-out key error with no frame over T at or below it,
/// at most `cap` (the conformal quantile's eps_min) and at least `floor` (the MaxRatio eps_min,
/// which no frame over T is below); `floor` itself when no held-out frame crossed T.
double heldOutThreshold(const CalibrationStats& s, double tolerance, double floor, double cap, double blind) {
    double crossing = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < s.keyRms.size(); ++i)
        if (s.keyRms[i] > blind && !(s.maxPointError[i] <= tolerance))
            crossing = std::min(crossing, s.keyRms[i]);
    if (!std::isfinite(crossing)) return floor;  // no held-out frame crossed T: the linear bound extrapolates
    double eps = floor;
    for (double e : s.keyRms)
        if (e < crossing) eps = std::max(eps, e);
    return std::max(floor, std::min(eps, cap));
}

}  // namespace

double blendBand(std::vector<double> ratios, double ratio) {
    // Decision: the band spans the key errors over which held-out frames cross the tolerance:
    // from eps_min = T / r, where the frame of ratio r (the rule's) reaches T, to where the median
    // frame does, T / r_50 = (r / r_50) eps_min. Below 1.5 (the paper's hand-picked [0.1, 0.15])
    // a frame would jump from PM to the full calculation over a key error change too small to
    // hide in an animation; above 2 a blend's (1 - w) E could exceed T under the bound E <= r e
    // (Calibration.h). With the largest-key error the spread is narrow (motion capture: 1.75).
    if (ratios.empty() || !(ratio > 0)) return 2.0;
    std::nth_element(ratios.begin(), ratios.begin() + static_cast<std::ptrdiff_t>(ratios.size() / 2),
                     ratios.end());
    const double median = ratios[ratios.size() / 2];
    if (!(median > 0)) return 2.0;
    return std::clamp(ratio / median, 1.5, 2.0);
}

void setThresholds(CalibrationStats& s, double tolerance, CalibrationRule rule, double coverage) {
    if (!(tolerance > 0) || !std::isfinite(tolerance)) {
        throw std::invalid_argument("calibration tolerance must be a positive number, got " +
                                    std::to_string(tolerance));
    }
    if (rule != CalibrationRule::MaxRatio && !(coverage > 0 && coverage < 1)) {
        throw std::invalid_argument("calibration coverage must be in (0, 1), got " +
                                    std::to_string(coverage));
    }
    if (s.keyRms.size() != s.maxPointError.size()) {
        throw std::invalid_argument("calibration: key errors and point errors differ in count");
    }
    s.tolerance = tolerance;
    s.rule = rule;
    s.coverage = rule != CalibrationRule::MaxRatio ? coverage : 0.0;
    s.blindFrames = 0;
    const double largestError =
        s.maxPointError.empty() ? 0.0 : *std::max_element(s.maxPointError.begin(), s.maxPointError.end());
    const double blind = blindLevel(s);
    const std::vector<double> ratios = heldOutRatios(s);
    double largestKeyRms = 0;
    for (size_t i = 0; i < s.keyRms.size(); ++i) {
        largestKeyRms = std::max(largestKeyRms, s.keyRms[i]);
        if (!(s.keyRms[i] > blind && s.keyRms[i] > 0) && s.maxPointError[i] > 0) ++s.blindFrames;
    }
    s.usableFrames = static_cast<Index>(ratios.size());
    s.maxRatio = ratios.empty() ? 0.0 : *std::max_element(ratios.begin(), ratios.end());
    double ratio = s.maxRatio;
    if (rule != CalibrationRule::MaxRatio && !ratios.empty()) {
        ratio = conformalQuantile(ratios, coverage);
        const double n = static_cast<double>(ratios.size());
        if ((n + 1) * coverage > n * (1 + 1e-9)) {
            s.notes.push_back("calibration: " + std::to_string(ratios.size()) +
                              " held-out frames are too few for a conformal quantile at coverage " +
                              std::to_string(coverage) + "; used the largest ratio");
        }
    }
    if (rule == CalibrationRule::Threshold && !ratios.empty() && ratio > 0)
        ratio = tolerance / heldOutThreshold(s, tolerance, tolerance / s.maxRatio, tolerance / ratio, blind);
    s.ratio = ratio;
    if (s.blindFrames > 0) {
        s.notes.push_back("calibration: " + std::to_string(s.blindFrames) +
                          " held-out frames had point errors the key error cannot see (key RMS at "
                          "rounding level); add keys or reduce M");
    }
    if (ratios.empty() || !(ratio > 0)) {
        if (largestError == 0) {
            // Every held-out frame was reconstructed exactly: any key error seen is harmless.
            s.epsMin = largestKeyRms;
            s.epsMax = 2 * s.epsMin;
            s.notes.push_back(
                "calibration: PM was exact on every held-out frame; eps_min set to the "
                "largest held-out key error");
        } else {
            // Errors exist but the key error never moves: no threshold separates good from bad.
            s.epsMin = 0;
            s.epsMax = 0;
            s.notes.push_back(
                "calibration: the key error is identically zero on held-out frames, so no "
                "threshold can bound the point error; every frame with any key error fails "
                "through");
        }
        return;
    }
    s.epsMin = tolerance / ratio;
    s.band = blendBand(ratios, ratio);
    s.epsMax = s.band * s.epsMin;
}

void setPredictedThresholds(CalibrationStats& s, double tolerance, CalibrationRule looRule, double coverage) {
    if (s.keyLoo.size() != s.keyRms.size())
        throw std::invalid_argument("calibration: the predicted error's two parts differ in count");
    CalibrationStats rms, loo;
    rms.keyRms = s.keyRms;
    loo.keyRms = s.keyLoo;
    rms.maxPointError = loo.maxPointError = s.maxPointError;
    setThresholds(rms, tolerance, CalibrationRule::MaxRatio, coverage);
    setThresholds(loo, tolerance, looRule, coverage);
    s.partEps = {rms.epsMin, loo.epsMin};
    s.keyRms = predictedErrors(rms.keyRms, loo.keyRms, s.partEps, tolerance);
    s.tolerance = tolerance;
    s.rule = looRule;
    s.coverage = loo.coverage;
    s.usableFrames = std::max(rms.usableFrames, loo.usableFrames);
    s.blindFrames = std::min(rms.blindFrames, loo.blindFrames);
    const std::vector<double> ratios = heldOutRatios(s);
    s.maxRatio = ratios.empty() ? 0.0 : *std::max_element(ratios.begin(), ratios.end());
    s.ratio = 1;
    s.epsMin = tolerance;
    // Decision: the narrower band of the two parts. Either keeps a blend under T under its own
    // linear bound (blendBand), and the narrower one leaves the cache sooner.
    s.band = std::min(rms.band, loo.band);
    s.epsMax = s.band * s.epsMin;
    const std::string prefix = "calibration: ";
    for (const CalibrationStats* part : {&rms, &loo})
        for (const std::string& note : part->notes) {
            const std::string name =
                part == &rms ? "calibration (key RMS part): " : "calibration (leave-one-out part): ";
            s.notes.push_back(name + (note.starts_with(prefix) ? note.substr(prefix.size()) : note));
        }
    s.parts = {std::move(rms), std::move(loo)};
}

}  // namespace pmsc
