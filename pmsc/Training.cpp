#include "pmsc/Training.h"

#include "pmsc/Calibration.h"
#include "pmsc/Errors.h"
#include "pmsc/KeyPointSelector.h"
#include "pmsc/QDeim.h"
#include "pmsc/Subspace.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace pmsc {

namespace {

std::string num(double v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.6g", v);
    return buf;
}

[[noreturn]] void badOption(const std::string& what) { throw std::invalid_argument("train: " + what); }

void validateOptions(const TrainingOptions& o, Index points, Index frames) {
    if (o.basis < 0) badOption("basis size must be >= 0 (0 = not set), got " + std::to_string(o.basis));
    if (std::isnan(o.energy) || o.energy < 0 || o.energy > 1) {
        badOption("energy must be in (0, 1] (0 = not set), got " + num(o.energy));
    }
    if (!std::isfinite(o.basisMaxError) || o.basisMaxError < 0) {
        badOption("basis max error must be >= 0 (0 = not set), got " + num(o.basisMaxError));
    }
    if (o.maxBasis < 1) badOption("max basis must be >= 1, got " + std::to_string(o.maxBasis));
    if (!(o.defaultEnergy > 0 && o.defaultEnergy <= 1)) {
        badOption("default energy must be in (0, 1], got " + num(o.defaultEnergy));
    }
    if (o.selector != Selector::Teleconnection && o.selector != Selector::QDeim) {
        badOption("unknown selector " + std::to_string(static_cast<int>(o.selector)));
    }
    if (!std::isfinite(o.maxError) || o.maxError < 0) {
        badOption("max error must be >= 0 (0 = off), got " + num(o.maxError));
    }
    if (o.maxKeys < 1 || o.maxKeys > points) {
        badOption("max keys must be in [1, " + std::to_string(points) + "] (the point count), got " +
                  std::to_string(o.maxKeys));
    }
    if (o.block < 1) badOption("block must be >= 1, got " + std::to_string(o.block));
    if (!(o.varimaxTolerance >= 0)) badOption("varimax tolerance must be >= 0, got " + num(o.varimaxTolerance));
    if (o.varimaxMaxIterations < 1) {
        badOption("varimax iteration cap must be >= 1, got " + std::to_string(o.varimaxMaxIterations));
    }
    if (!std::isfinite(o.tolerance) || o.tolerance < 0) {
        badOption("tolerance must be >= 0 (0 = no calibration), got " + num(o.tolerance));
    }
    if (o.tolerance > 0 && (o.calibrationSlices < 2 || o.calibrationSlices > frames)) {
        badOption("calibration slices must be in [2, " + std::to_string(frames) + "], got " +
                  std::to_string(o.calibrationSlices));
    }
    if (o.powerIterations < 0) {
        badOption("power iterations must be >= 0, got " + std::to_string(o.powerIterations));
    }
    const size_t seeds = o.fiducials.size() + o.gridPoints.size();
    if (static_cast<Index>(seeds) > o.maxKeys) {
        badOption(std::to_string(seeds) + " fiducial and grid points exceed the key budget " +
                  std::to_string(o.maxKeys));
    }
}

void validateFrames(const FrameSet& frames) {
    if (frames.points < 1 || frames.channels < 1) {
        throw InputError("train: frames need at least one point and one channel");
    }
    if (frames.frames < 2) {
        throw InputError("train: need at least 2 training frames, got " + std::to_string(frames.frames));
    }
    if (static_cast<Index>(frames.values.size()) != frames.frames * frames.rows()) {
        throw InputError("train: frame storage holds " + std::to_string(frames.values.size()) +
                         " values, expected F*N*C = " + std::to_string(frames.frames * frames.rows()));
    }
    for (size_t i = 0; i < frames.values.size(); ++i) {
        if (!std::isfinite(frames.values[i])) {
            const Index at = static_cast<Index>(i);
            const Index f = at / frames.rows();
            const Index p = (at % frames.rows()) / frames.channels;
            const Index c = at % frames.channels;
            throw InputError("train: frame " + std::to_string(f) + ", point " + std::to_string(p) +
                             ", channel " + std::to_string(c) + " is " + num(frames.values[i]));
        }
    }
}

}  // namespace

Model train(const FrameSet& frames, const TrainingOptions& options, TrainingReport* reportOut) {
    const auto start = std::chrono::steady_clock::now();
    TrainingReport localReport;
    TrainingReport& report = reportOut ? *reportOut : localReport;
    report = TrainingReport{};

    auto progress = [&](std::string_view stage, double done, double total) {
        if (options.progress && !options.progress(stage, done, total)) {
            throw Cancelled("training cancelled during " + std::string(stage));
        }
    };

    validateFrames(frames);
    const Index n = frames.points;
    const Index channels = frames.channels;
    const Index f = frames.frames;
    validateOptions(options, n, f);

    // --- Q: mean-removed training matrix (paper footnote 1), rows x = p*C + c, columns frames.
    progress("mean", 0, 1);
    Model model;
    model.points = n;
    model.channels = channels;
    model.trainFrames = f;
    model.selector = options.selector;
    Eigen::MatrixXd q;
    model.mean = removeRowMean(frames.matrix(), q);
    model.totalEnergy = q.squaredNorm();
    if (!(model.totalEnergy > 0)) {
        throw InputError("train: the training frames are all identical; there is no motion to learn");
    }
    progress("mean", 1, 1);

    // --- Subspace (section 3).
    progress("svd", 0, 1);
    SvdOptions svdOptions;
    svdOptions.seed = options.seed;
    svdOptions.powerIterations = options.powerIterations;
    const Index cap = std::min({options.maxBasis, f, q.rows()});
    Index wanted = options.basis > 0 ? std::min(options.basis, cap) : cap;
    if (options.basis > cap) {
        report.warnings.push_back("basis " + std::to_string(options.basis) + " capped to " +
                                  std::to_string(cap) + " (min of max basis, frames, N*C)");
    }
    // The first key-selection block needs the top `block` vectors of Q even when M is smaller.
    const Index svdRank = std::min(std::max(wanted, options.block), std::min(f, q.rows()));
    // U = Q V S^-1 costs a full product per column on the Gram route: form only what the M rule
    // needs now (the max-error rule scans all of U) and the rest once M is known.
    const bool needAllU = options.basis <= 0 && options.energy <= 0 && options.basisMaxError > 0;
    svdOptions.leftVectors = needAllU ? -1 : std::min(svdRank, options.block);
    TruncatedSvd svd = truncatedSvd(q, svdRank, svdOptions);
    svdOptions.leftVectors = -1;
    const Index available = std::min<Index>(cap, svd.sigma.size());
    if (available < 1) throw InputError("train: the training frames have no usable variation");
    progress("svd", 1, 1);

    // --- M: the first rule that is set wins (TrainingOptions order).
    Index m = 0;
    if (options.basis > 0) {
        m = std::min(options.basis, available);
        if (m < std::min(options.basis, cap)) {
            report.warnings.push_back("basis " + std::to_string(options.basis) + " reduced to " +
                                      std::to_string(m) + ": the training data has only that many "
                                      "non-negligible singular values");
        }
    } else if (options.energy > 0 || options.basisMaxError <= 0) {
        const double e = options.energy > 0 ? options.energy : options.defaultEnergy;
        m = basisSizeForEnergy(svd.sigma.head(available), model.totalEnergy, e);
        const double got = svd.sigma.head(m).squaredNorm() / model.totalEnergy;
        if (got < e * (1 - 1e-12)) {
            report.warnings.push_back("energy " + num(e) + " not reached within " + std::to_string(m) +
                                      " basis vectors (captured " + num(got) + "); raise --max-basis?");
        }
    } else {
        progress("basis-error", 0, 1);
        std::vector<double> errors;
        m = basisSizeForMaxError(q, svd, channels, options.basisMaxError, available, &errors);
        if (m > available) {
            m = available;
            report.warnings.push_back("basis max error " + num(options.basisMaxError) + " not reached within " +
                                      std::to_string(m) + " basis vectors (largest point error " +
                                      num(errors.empty() ? 0.0 : errors.back()) + ")");
        }
        progress("basis-error", 1, 1);
    }
    report.requestedBasis = m;
    formLeftVectors(q, svd, std::max(m, options.block));
    Eigen::MatrixXd basis = svd.u.leftCols(m);

    // --- Key points (section 4).
    std::vector<Index> keys;
    if (options.selector == Selector::Teleconnection) {
        TeleconnectionOptions t;
        t.maxKeys = options.maxKeys;
        t.maxError = options.maxError;
        t.block = options.block;
        t.fiducials = options.fiducials;
        t.gridPoints = options.gridPoints;
        t.varimax.tolerance = options.varimaxTolerance;
        t.varimax.maxIterations = options.varimaxMaxIterations;
        t.svd = svdOptions;
        t.onRound = [&](Index, Index k, double) {
            progress("keys", static_cast<double>(k), static_cast<double>(options.maxKeys));
        };
        progress("keys", 0, static_cast<double>(options.maxKeys));
        KeySelection sel = selectKeysTeleconnection(q, basis, svd.u, svd.sigma, channels, t,
                                                    svd.gramRoute ? &svd.gram : nullptr);
        keys = std::move(sel.keys);
        report.iterations = sel.rounds;
        report.residualPerRound = std::move(sel.residualPerRound);
    } else {
        progress("keys", 0, static_cast<double>(options.maxKeys));
        // Validate here so a bad grid point is named as a grid point, not as a fiducial.
        KeySet check(n);
        seedKeys(check, options.fiducials, options.gridPoints);
        const std::vector<Index> seeds = check.keys();
        QDeimSelection sel = selectKeysQDeim(basis, channels, options.maxKeys, seeds);
        keys = std::move(sel.keys);
        report.iterations = sel.passes;
        progress("keys", static_cast<double>(keys.size()), static_cast<double>(options.maxKeys));
    }
    if (static_cast<Index>(keys.size()) < options.maxKeys && options.maxError <= 0) {
        report.warnings.push_back("selected " + std::to_string(keys.size()) + " keys of the budget " +
                                  std::to_string(options.maxKeys) + ": no further candidate improved the basis");
    }

    // --- Determinacy: never leave the key system unable to determine the basis (issue 2).
    progress("projector", 0, 1);
    const Index kc = static_cast<Index>(keys.size()) * channels;
    const Index determined = determinedBasisSize(basis, channels, keys);
    if (determined < 1) {
        throw InputError("train: the " + std::to_string(keys.size()) +
                         " key points determine no basis vector (their basis rows are all zero)");
    }
    const bool reportedResidualIsFinal =
        options.selector == Selector::Teleconnection && determined >= m && !report.residualPerRound.empty();
    if (determined < m) {
        const std::string why = kc < m ? "the " + std::to_string(keys.size()) + " keys give only K*C = " +
                                             std::to_string(kc) + " values"
                                       : "the key system B_K is rank deficient or ill-conditioned "
                                         "(condition number > 1e8)";
        report.warnings.push_back("reduced M from " + std::to_string(m) + " to " + std::to_string(determined) +
                                  ": " + why);
        m = determined;
        basis.conservativeResize(Eigen::NoChange, m);
    }
    if (kc == m) {
        report.warnings.push_back("K*C == M (" + std::to_string(kc) +
                                  "): the key residual is identically zero, so the soft-cache error "
                                  "monitor is blind; add keys or reduce M");
    }
    model.basis = std::move(basis);
    model.singularValues = svd.sigma.head(m);
    model.keyPoints = keys;
    model.projector = makeProjector(model.basis, channels, keys);
    if (reportedResidualIsFinal) {
        // The last selection round already approximated the training set with exactly these keys
        // and this basis; recomputing would cost another (N*C) x M x F product.
        model.trainMaxPointResidual = report.residualPerRound.back();
    } else {
        // The projector just made gives the coordinates; the residual is reduced block by block,
        // never formed (at the ICT face's size it would be 80,157 x 600 doubles, 385 MB).
        model.trainMaxPointResidual =
            maxPointResidual(q, model.basis, model.projector * gatherKeyRows(q, channels, keys), channels);
    }
    if (options.selector == Selector::QDeim) report.residualPerRound.push_back(model.trainMaxPointResidual);
    progress("projector", 1, 1);

    // --- eps (section 5; calibration beyond the paper).
    progress("calibration", 0, 1);
    if (options.tolerance > 0) {
        report.calibration =
            calibrate(q, channels, keys, m, options.tolerance, options.calibrationSlices, svdOptions,
                      svd.gramRoute ? &svd.gram : nullptr);
        model.tolerance = options.tolerance;
    } else {
        report.calibration = thresholdsFromTraining(q, model.basis, channels, keys, model.projector);
    }
    for (const auto& note : report.calibration.notes) report.warnings.push_back(note);
    model.epsMin = report.calibration.epsMin;
    model.epsMax = report.calibration.epsMax;
    progress("calibration", 1, 1);

    // --- regions of local fail-through (paper section 9; issue 9), on the final core.
    if (options.regions.count > 0) {
        progress("regions", 0, 1);
        model.regions = learnRegions(q, model, options.regions, options.tolerance, options.calibrationSlices,
                                     svdOptions, &report.warnings);
        progress("regions", 1, 1);
    }

    model.validate();
    report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return model;
}

}  // namespace pmsc
