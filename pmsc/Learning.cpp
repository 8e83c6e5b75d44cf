#include "pmsc/Learning.h"

#include "pmsc/Errors.h"
#include "pmsc/KeyPointSelector.h"
#include "pmsc/LearningState.h"
#include "pmsc/QDeim.h"
#include "pmsc/Subspace.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

namespace pmsc {

namespace {

using Clock = std::chrono::steady_clock;

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

void checkFrames(const Model& model, const FrameSet& frames) {
    if (frames.frames < 1) throw InputError("learn: no new frames");
    if (frames.points != model.points || frames.channels != model.channels) {
        throw InputError("learn: new frames have " + std::to_string(frames.points) + " points x " +
                         std::to_string(frames.channels) + " channels, the model " +
                         std::to_string(model.points) + " x " + std::to_string(model.channels));
    }
    if (static_cast<Index>(frames.values.size()) != frames.frames * frames.rows()) {
        throw InputError("learn: frame storage does not hold F*N*C values");
    }
    for (size_t i = 0; i < frames.values.size(); ++i) {
        if (!std::isfinite(frames.values[i])) {
            const Index at = static_cast<Index>(i);
            throw InputError("learn: frame " + std::to_string(at / frames.rows()) + ", point " +
                             std::to_string((at % frames.rows()) / frames.channels) + ", channel " +
                             std::to_string(at % frames.channels) + " is not finite");
        }
    }
}

// Key RMS (PointMultiplier::keyRmsError) and largest point error of PM of every column of a
// mean-removed matrix under a basis and a key projector.
void scoreFrames(const Eigen::Ref<const Eigen::MatrixXd>& centered, const Eigen::MatrixXd& basis,
                 const Eigen::MatrixXd& projector, Index channels, const std::vector<Index>& keys,
                 std::vector<double>& keyRms, std::vector<double>& maxPointError) {
    const Eigen::MatrixXd coords = projector * gatherKeyRows(centered, channels, keys);
    Eigen::MatrixXd residual = centered;
    residual.noalias() -= basis * coords;
    const Eigen::VectorXd pointErr = maxPointNormPerColumn(residual, channels);
    const Eigen::MatrixXd keyResidual = gatherKeyRows(residual, channels, keys);
    for (Index j = 0; j < centered.cols(); ++j) {
        keyRms.push_back(std::sqrt(keyResidual.col(j).squaredNorm() / static_cast<double>(keys.size())));
        maxPointError.push_back(pointErr[j]);
    }
}

}  // namespace

IncrementalSubspace subspaceOf(const Model& model) {
    IncrementalSubspace s;
    s.frames = model.trainFrames;
    s.mean = model.mean;
    s.totalEnergy = model.totalEnergy;
    const Index m = model.basisSize();
    const Index extra = model.learning ? model.learning->extraBasis.cols() : 0;
    s.u.resize(model.basis.rows(), m + extra);
    s.u.leftCols(m) = model.basis;
    s.sigma.resize(m + extra);
    s.sigma.head(m) = model.singularValues;
    if (extra > 0) {
        s.u.rightCols(extra) = model.learning->extraBasis;
        s.sigma.tail(extra) = model.learning->extraSigma;
        s.discardedEnergy = model.learning->discardedEnergy;
    }
    return s;
}

Model learn(const Model& model, const FrameSet& newFrames, const LearnOptions& options,
            LearnReport* reportOut) {
    const Clock::time_point start = Clock::now();
    LearnReport localReport;
    LearnReport& report = reportOut ? *reportOut : localReport;
    report = LearnReport{};
    auto progress = [&](std::string_view stage, double done, double total) {
        if (options.progress && !options.progress(stage, done, total)) {
            throw Cancelled("learning cancelled during " + std::string(stage));
        }
    };
    model.validate();
    if (model.sharedChannels)
        throw InputError(
            "learn: the model's channels share one basis (train --shared-channels); pmsc learn updates "
            "models with a basis per channel in this version: retrain on all frames");
    checkFrames(model, newFrames);
    if (options.basis < 0 || options.maxRank < 0)
        throw std::invalid_argument("learn: basis and rank must be >= 0");
    if (options.slices < 2) throw std::invalid_argument("learn: slices must be >= 2");
    const Index channels = model.channels;
    const Index m = newFrames.frames;
    const Eigen::Map<const Eigen::MatrixXd> fresh = newFrames.matrix();
    report.newFrames = m;
    report.basisBefore = model.basisSize();

    // How the new frames looked to the old model (what made them misses).
    {
        std::vector<double> e, E;
        const Eigen::MatrixXd centered = fresh.colwise() - model.mean;
        scoreFrames(centered, model.basis, model.projector, channels, model.keyPoints, e, E);
        report.oldModelNewFramesKeyRmsMax = *std::max_element(e.begin(), e.end());
    }

    // --- 1. mean and basis: Brand's update of the stored state.
    progress("subspace", 0, 1);
    Clock::time_point t = Clock::now();
    const IncrementalSubspace before = subspaceOf(model);
    report.rankBefore = before.rank();
    if (model.regions) {
        report.warnings.push_back(
            "the model's local fail-through regions are not updated by learn (the keys "
            "change): the learned model has none; train again to get them");
    }
    if (!model.learning) {
        report.warnings.push_back(
            "the model has no learning state (train with --learn-rank): the old frames "
            "are represented by the model's " +
            std::to_string(model.basisSize()) + " basis vectors only");
    }
    IncrementalSvdOptions svdOptions;
    svdOptions.maxRank = options.maxRank > 0 ? options.maxRank
                                             : (model.learning ? model.learning->maxRank : model.basisSize());
    const Index wantedM = options.basis > 0 ? options.basis : model.basisSize();
    if (svdOptions.maxRank < wantedM) {
        throw std::invalid_argument("learn: rank " + std::to_string(svdOptions.maxRank) +
                                    " is below the basis size " + std::to_string(wantedM));
    }
    IncrementalSubspace state = before;
    updateSubspace(state, fresh, svdOptions);
    report.rankAfter = state.rank();
    report.tailNorm = state.tailNorm();
    Index basisSize = std::min(wantedM, state.rank());
    if (basisSize < wantedM) {
        report.warnings.push_back("basis " + std::to_string(wantedM) + " reduced to " +
                                  std::to_string(basisSize) + ": the state holds only that many directions");
    }
    Eigen::MatrixXd basis = state.u.leftCols(basisSize);
    report.secondsSubspace = since(t);
    progress("subspace", 1, 1);

    // --- 2. keys: the same selector, on the rank-r surrogate U_r diag(sigma) of every frame seen.
    progress("keys", 0, 1);
    t = Clock::now();
    LearningState settings;
    if (model.learning) {
        settings = *model.learning;
    } else {
        settings.maxKeys = model.keyCount();
    }
    std::vector<Index> keys;
    if (model.selector == Selector::Teleconnection) {
        const Eigen::MatrixXd surrogate = state.u * state.sigma.asDiagonal();
        const Eigen::MatrixXd gram = state.sigma.array().square().matrix().asDiagonal();
        TeleconnectionOptions to;
        to.maxKeys = settings.maxKeys;
        // The residual stop compares a point error over frames; the surrogate's columns are
        // scaled singular vectors, not frames, so only the key budget stops the selection.
        to.maxError = 0;
        if (settings.maxError > 0) {
            report.warnings.push_back("--max-error of the training is not used by learn: the key budget " +
                                      std::to_string(settings.maxKeys) + " is filled");
        }
        to.block = settings.block;
        to.fiducials = settings.fiducials;
        to.gridPoints = settings.gridPoints;
        KeySelection sel =
            selectKeysTeleconnection(surrogate, basis, state.u, state.sigma, channels, to, &gram);
        keys = std::move(sel.keys);
    } else {
        KeySet check(model.points);
        seedKeys(check, settings.fiducials, settings.gridPoints);
        keys = selectKeysQDeim(basis, channels, settings.maxKeys, check.keys()).keys;
    }
    {
        std::vector<char> old(static_cast<size_t>(model.points), 0);
        for (Index k : model.keyPoints) old[static_cast<size_t>(k)] = 1;
        for (Index k : keys) report.keysKept += old[static_cast<size_t>(k)];
    }
    const Index determined = determinedBasisSize(basis, channels, keys);
    if (determined < 1) throw InputError("learn: the selected keys determine no basis vector");
    if (determined < basisSize) {
        report.warnings.push_back("reduced M from " + std::to_string(basisSize) + " to " +
                                  std::to_string(determined) + ": the key system cannot determine more");
        basisSize = determined;
        basis.conservativeResize(Eigen::NoChange, basisSize);
    }
    Model out;
    out.points = model.points;
    out.channels = channels;
    out.trainFrames = state.frames;
    out.selector = model.selector;
    out.mean = state.mean;
    out.basis = basis;
    out.singularValues = state.sigma.head(basisSize);
    out.totalEnergy = state.totalEnergy;
    out.keyPoints = keys;
    out.projector = makeProjector(out.basis, channels, keys);
    out.tolerance = model.tolerance;
    report.basisAfter = basisSize;
    report.largestAngle =
        largestPrincipalAngle(basis, model.basis.leftCols(std::min(basisSize, model.basisSize())));
    report.secondsKeys = since(t);
    progress("keys", 1, 1);

    // --- 3. eps.
    progress("calibration", 0, 1);
    t = Clock::now();
    const Eigen::MatrixXd centeredNew = fresh.colwise() - out.mean;
    std::vector<double> eNew, bigENew;
    scoreFrames(centeredNew, out.basis, out.projector, channels, keys, eNew, bigENew);
    report.newFramesMaxPointError = *std::max_element(bigENew.begin(), bigENew.end());
    // Decision: the training residual field becomes the largest point error on the frames of
    // this update (the old frames are gone; the README says so).
    out.trainMaxPointResidual = report.newFramesMaxPointError;
    const CalibrationRule rule = options.rule.value_or(model.calibrationRecord ? model.calibrationRecord->rule
                                                                               : CalibrationRule::MaxRatio);
    const double coverage = options.coverage.value_or(
        model.calibrationRecord && model.calibrationRecord->coverage > 0 ? model.calibrationRecord->coverage
                                                                         : 0.9);
    CalibrationRecord record;
    if (model.calibrationRecord) record = *model.calibrationRecord;
    record.rule = rule;
    record.coverage = rule == CalibrationRule::Conformal ? coverage : 0.0;
    if (model.tolerance > 0) {
        // Cross-fitting: each slice of the new frames is scored by a model that never saw it (the
        // old state updated with the other slices; the new keys).
        CalibrationStats scores;
        const Index slices = std::min(options.slices, m);
        if (slices >= 2) {
            for (Index slice = 0; slice < slices; ++slice) {
                const Index first = slice * m / slices, last = (slice + 1) * m / slices;
                IncrementalSubspace fold = before;
                Eigen::MatrixXd others(fresh.rows(), m - (last - first));
                others.leftCols(first) = fresh.leftCols(first);
                others.rightCols(m - last) = fresh.rightCols(m - last);
                IncrementalSvdOptions foldOptions = svdOptions;
                foldOptions.maxRank = basisSize;  // a fold needs only its M-basis: a smaller product for U'
                updateSubspace(fold, others, foldOptions);
                const Index foldM = std::min(basisSize, fold.rank());
                const Eigen::MatrixXd foldBasis = fold.u.leftCols(foldM);
                const Eigen::MatrixXd foldProjector = makeProjector(foldBasis, channels, keys);
                const Eigen::MatrixXd heldOut = fresh.middleCols(first, last - first).colwise() - fold.mean;
                scoreFrames(heldOut, foldBasis, foldProjector, channels, keys, scores.keyRms,
                            scores.maxPointError);
                for (Index j = first; j < last; ++j) scores.frames.push_back(j);
                progress("calibration", static_cast<double>(slice + 1), static_cast<double>(slices));
            }
            scores.slices = slices;
            setThresholds(scores, model.tolerance, rule, coverage);
            report.calibrationRatioNew = scores.ratio;
        } else {
            report.warnings.push_back(
                "one new frame cannot be cross-fitted: eps from the stored scores only");
        }
        double ratio = report.calibrationRatioNew;
        if (!record.keyRms.empty()) {
            CalibrationStats stored;
            stored.keyRms = record.keyRms;
            stored.maxPointError = record.maxPointError;
            setThresholds(stored, model.tolerance, rule, coverage);
            report.calibrationRatioOld = stored.ratio;
            ratio = std::max(ratio, stored.ratio);
        } else {
            report.warnings.push_back(
                "the model stores no calibration scores (train with --learn-rank): eps from "
                "the new frames' scores only");
        }
        for (const auto& note : scores.notes) report.warnings.push_back(note);
        if (ratio > 0) {
            out.epsMin = model.tolerance / ratio;
            out.epsMax = 2 * out.epsMin;
        } else {
            out.epsMin = model.epsMin;
            out.epsMax = model.epsMax;
            report.warnings.push_back("no usable held-out score: eps kept from the old model");
        }
        scores.ratio = ratio;
        scores.epsMin = out.epsMin;
        scores.epsMax = out.epsMax;
        record.keyRms.insert(record.keyRms.end(), scores.keyRms.begin(), scores.keyRms.end());
        record.maxPointError.insert(record.maxPointError.end(), scores.maxPointError.begin(),
                                    scores.maxPointError.end());
        report.calibration = std::move(scores);
    } else {
        // Uncalibrated, as training: the largest key error seen on frames it learned from.
        out.epsMin = std::max(model.epsMin, *std::max_element(eNew.begin(), eNew.end()));
        out.epsMax = 1.5 * out.epsMin;
        report.calibration.epsMin = out.epsMin;
        report.calibration.epsMax = out.epsMax;
    }
    report.secondsCalibration = since(t);
    progress("calibration", 1, 1);

    // --- 4. what the next update needs.
    LearningState next = settings;
    next.maxRank = svdOptions.maxRank;
    const Index extra = state.rank() - basisSize;
    next.extraBasis = state.u.rightCols(extra);
    next.extraSigma = state.sigma.tail(extra);
    next.discardedEnergy = state.discardedEnergy;
    next.updates = settings.updates + 1;
    out.learning = std::move(next);
    if (model.tolerance > 0) out.calibrationRecord = std::move(record);
    out.validate();
    report.seconds = since(start);
    return out;
}

}  // namespace pmsc
