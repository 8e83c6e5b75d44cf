#include "pmsc/Learning.h"

#include "pmsc/Errors.h"
#include "pmsc/KeyNeighbours.h"
#include "pmsc/KeyPointSelector.h"
#include "pmsc/LearningState.h"
#include "pmsc/QDeim.h"
#include "pmsc/RegionChoice.h"
#include "pmsc/RegionLearning.h"
#include "pmsc/RowBlocks.h"
#include "pmsc/Sentinels.h"
#include "pmsc/Subspace.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

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

// Key error (PointMultiplier::keyError, by `norm`) and largest point error of PM of every column
// of `frames` less `mean` under a basis and a key projector, appended to `out`. For
// KeyErrorNorm::Predicted the two parts: the key RMS to out.keyRms, the leave-one-out error to
// out.keyLoo (setPredictedThresholds, or predictedPointError, combines them).
//
// Decision: the frames are centred and their residual formed a slab of kSlabPoints points at a
// time, as training's folds score theirs, never as a whole (N*C) x m copy: at the ICT face's
// 26,719 points and 300 new frames each whole copy was 192 MB of fresh pages, and learn made four.
// A slab is whole points and a multiple of 24 rows (kScoreSlabPoints x channels), the row panel of
// Eigen's product kernel with AVX-512 (12 with AVX, 6 with SSE), so each slab's rows fall in the
// same panels as in one product over every row and each residual entry is the same sum, to the bit.
constexpr Index kScoreSlabPoints = kSlabPoints / 24 * 24;

void scoreFrames(const Eigen::Ref<const Eigen::MatrixXd>& frames, const Eigen::VectorXd& mean,
                 const Eigen::MatrixXd& basis, const Eigen::MatrixXd& projector, Index channels,
                 const std::vector<Index>& keys, KeyErrorNorm norm, CalibrationStats& out) {
    const Index k = static_cast<Index>(keys.size());
    const Eigen::MatrixXd coords = projector * (gatherKeyRows(frames, channels, keys).colwise() -
                                                gatherKeyRows(mean, channels, keys).col(0));

    // Key i's residual rows are filled from the slab that holds its point.
    std::vector<std::pair<Index, Index>> byPoint;  // (point, key index), in point order
    byPoint.reserve(static_cast<size_t>(k));
    for (Index i = 0; i < k; ++i) byPoint.emplace_back(keys[static_cast<size_t>(i)], i);
    std::sort(byPoint.begin(), byPoint.end());
    Eigen::MatrixXd keyResidual(k * channels, frames.cols());
    Eigen::VectorXd pointErr = Eigen::VectorXd::Zero(frames.cols());
    Eigen::MatrixXd residual;
    const Index slab = kScoreSlabPoints * channels;
    auto nextKey = byPoint.begin();
    for (Index r0 = 0; r0 < frames.rows(); r0 += slab) {
        const Index h = std::min(slab, frames.rows() - r0);
        residual = frames.middleRows(r0, h).colwise() - mean.segment(r0, h);
        residual.noalias() -= basis.middleRows(r0, h) * coords;
        const Eigen::VectorXd e = maxPointNormPerColumn(residual, channels);
        for (Index j = 0; j < frames.cols(); ++j)
            if (!(e[j] <= pointErr[j])) pointErr[j] = e[j];  // NaN wins
        for (; nextKey != byPoint.end() && nextKey->first * channels < r0 + h; ++nextKey)
            keyResidual.middleRows(nextKey->second * channels, channels) =
                residual.middleRows(nextKey->first * channels - r0, channels);
    }
    const Eigen::VectorXd looScale = usesLeaveOneOut(norm)
                                         ? leaveOneOutScale(gatherKeyRows(basis, channels, keys), projector)
                                         : Eigen::VectorXd();
    for (Index j = 0; j < frames.cols(); ++j) {
        appendKeyScore(out, keyResidual.col(j), channels, norm, looScale);
        out.maxPointError.push_back(pointErr[j]);
    }
}

/// The model and the new frames learn can update, and the options, checked before any work.
void checkLearnInput(const Model& model, const FrameSet& newFrames, const LearnOptions& options) {
    model.validate();
    if (model.sharedChannels)
        throw InputError(
            "learn: the model's channels share one basis (train --shared-channels); pmsc learn updates "
            "models with a basis per channel in this version: retrain on all frames");
    checkFrames(model, newFrames);
    if (options.basis < 0 || options.maxRank < 0)
        throw std::invalid_argument("learn: basis and rank must be >= 0");
    if (!(options.energy >= 0 && options.energy <= 1))
        throw std::invalid_argument("learn: energy must be in (0, 1] (0 = the model's rule)");
    if (options.basis > 0 && options.energy > 0)
        throw std::invalid_argument("learn: a basis size and an energy rule both set M: give one");
    if (options.slices < 0 || options.slices == 1)
        throw std::invalid_argument("learn: slices must be >= 2 (0 = the training's slice size)");
    if (options.positions.size() == 0) return;
    if (options.positions.rows() != model.points || options.positions.cols() != 3)
        throw InputError("learn: positions are " + std::to_string(options.positions.rows()) + " x " +
                         std::to_string(options.positions.cols()) + ", the model has " +
                         std::to_string(model.points) + " points (expected " + std::to_string(model.points) +
                         " x 3)");
    if (!options.positions.allFinite()) throw InputError("learn: positions have a value that is not finite");
    // A silently ignored option would be a surprise: the positions must be what the model used.
    const bool sentinelsFromPositions = model.sentinels && model.sentinels->source == SentinelSource::Given;
    const bool neighboursFromPositions = model.keyNeighbours && !model.keyNeighbours->fromMean;
    if (!sentinelsFromPositions && !neighboursFromPositions)
        throw InputError(
            "learn: the model keeps nothing chosen from positions given to train (its sentinels and key "
            "neighbours, if any, came from its mean, a frame or the point order): give no positions");
}

/// The largest key RMS of the new frames under the old model (what made them misses).
double oldModelKeyRmsMax(const Model& model, const Eigen::Map<const Eigen::MatrixXd>& fresh) {
    CalibrationStats s;
    scoreFrames(fresh, model.mean, model.basis, model.projector, model.channels, model.keyPoints,
                model.keyErrorNorm, s);
    if (model.keyErrorNorm == KeyErrorNorm::Predicted)
        s.keyRms = predictedErrors(s.keyRms, s.keyLoo, model.partEps, model.tolerance);
    double largest = 0;
    for (double e : s.keyRms)
        if (!(e <= largest)) largest = e;  // NaN wins
    return largest;
}

/// The subspace before and after the update, and the basis taken from it.
struct SubspaceUpdate {
    IncrementalSubspace before;  ///< the model's stored state
    UpdateSpan span;             ///< the new frames in span [U J] of `before` and the update
    IncrementalSubspace state;   ///< `before` updated with the new frames
    IncrementalSvdOptions svdOptions;
    double energy = 0;     ///< the energy rule M was chosen by (0: M fixed)
    Index storedRank = 0;  ///< directions the learned model's state keeps (at least its M)
    Index basisSize = 0;
    Eigen::MatrixXd basis;
};

/// Every column index of m frames.
std::vector<Index> allColumns(Index m) {
    std::vector<Index> columns(static_cast<size_t>(m));
    for (Index j = 0; j < m; ++j) columns[static_cast<size_t>(j)] = j;
    return columns;
}

/// M after the update: --basis, else the energy rule (the options', else the model's stored
/// one) on the updated state, else the model's M.
Index chooseLearnedBasis(const Model& model, const LearnOptions& options, LearnReport& report,
                         SubspaceUpdate& u) {
    if (options.basis > 0) return options.basis;
    u.energy = options.energy > 0 ? options.energy : (model.learning ? model.learning->basisEnergy : 0.0);
    if (u.energy <= 0) return model.basisSize();
    const Index m = basisSizeForEnergy(u.state.sigma, u.state.totalEnergy, u.energy);
    const double got = u.state.sigma.head(m).squaredNorm() / u.state.totalEnergy;
    if (got < u.energy * (1 - 1e-12)) {
        report.warnings.push_back("energy " + std::to_string(u.energy) + " not reached within the state's " +
                                  std::to_string(m) + " directions (captured " + std::to_string(got) +
                                  "): M = " + std::to_string(m) + "; a larger --rank keeps more");
    }
    return m;
}

/// Step 1 (mean and basis): Brand's update of the stored state.
void updateState(const Model& model, const Eigen::Map<const Eigen::MatrixXd>& fresh,
                 const LearnOptions& options, LearnReport& report, SubspaceUpdate& u) {
    u.before = subspaceOf(model);
    report.rankBefore = u.before.rank();
    if (!model.learning) {
        report.warnings.push_back(
            "the model has no learning state (train with --learn-rank): the old frames "
            "are represented by the model's " +
            std::to_string(model.basisSize()) + " basis vectors only");
    }
    // Decision: without --rank the update keeps up to kGrowth x M directions, and the state stored
    // afterwards keeps the model's rank (or the new M, if larger). Why: the energy rule picks M
    // within the state's directions, so a state of the model's rank (M, by default) could not take
    // in what the new frames add; on a take whose second half moves four controls the first half
    // left still, M stayed 24 and the point error p99.5 came out 1.6x retraining's, where 4 M lets
    // M grow to 39 (docs/learning-and-calibration.md). The larger state lives only during the update.
    constexpr Index kGrowth = 4;
    u.storedRank = options.maxRank > 0 ? options.maxRank
                                       : (model.learning ? model.learning->maxRank : model.basisSize());
    u.svdOptions.maxRank =
        options.maxRank > 0 ? options.maxRank : std::max(u.storedRank, kGrowth * model.basisSize());
    const Index fixedM = options.basis > 0 ? options.basis : model.basisSize();
    if (u.svdOptions.maxRank < fixedM) {
        throw std::invalid_argument("learn: rank " + std::to_string(u.svdOptions.maxRank) +
                                    " is below the basis size " + std::to_string(fixedM));
    }
    u.span = spanOfUpdate(u.before, fresh, u.svdOptions);
    u.state = updateInSpan(u.before, u.span, fresh, allColumns(fresh.cols()), u.svdOptions);
    const Index wantedM = chooseLearnedBasis(model, options, report, u);
    report.basisEnergy = u.energy;
    report.tailNorm = u.state.tailNorm();
    u.basisSize = std::min(wantedM, u.state.rank());
    if (u.basisSize < wantedM) {
        report.warnings.push_back("basis " + std::to_string(wantedM) + " reduced to " +
                                  std::to_string(u.basisSize) +
                                  ": the state holds only that many directions");
    }
    u.basis = u.state.u.leftCols(u.basisSize);
    report.rankAfter = std::min(u.state.rank(), std::max(u.storedRank, u.basisSize));  // what the model keeps
}

/// Step 2 (keys): the same selector, on the rank-r surrogate U_r diag(sigma) of every frame seen.
std::vector<Index> selectLearnedKeys(const Model& model, const SubspaceUpdate& u,
                                     const LearningState& settings, LearnReport& report) {
    const Index channels = model.channels;
    std::vector<Index> keys;
    if (model.selector == Selector::Teleconnection) {
        const Eigen::MatrixXd surrogate = u.state.u * u.state.sigma.asDiagonal();
        const Eigen::MatrixXd gram = u.state.sigma.array().square().matrix().asDiagonal();
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
            selectKeysTeleconnection(surrogate, u.basis, u.state.u, u.state.sigma, channels, to, &gram);
        keys = std::move(sel.keys);
    } else {
        KeySet check(model.points);
        seedKeys(check, settings.fiducials, settings.gridPoints);
        keys = selectKeysQDeim(u.basis, channels, settings.maxKeys, check.keys()).keys;
    }
    {
        std::vector<char> old(static_cast<size_t>(model.points), 0);
        for (Index k : model.keyPoints) old[static_cast<size_t>(k)] = 1;
        for (Index k : keys) report.keysKept += old[static_cast<size_t>(k)];
    }
    return keys;
}

/// The learned model's core: the updated mean and basis, the new keys and their projector.
Model learnedCore(const Model& model, const SubspaceUpdate& u, const std::vector<Index>& keys) {
    Model out;
    out.points = model.points;
    out.channels = model.channels;
    out.trainFrames = u.state.frames;
    out.selector = model.selector;
    out.keyErrorNorm = model.keyErrorNorm;
    out.mean = u.state.mean;
    out.basis = u.basis;
    out.singularValues = u.state.sigma.head(u.basisSize);
    out.totalEnergy = u.state.totalEnergy;
    out.keyPoints = keys;
    out.projector = makeProjector(out.basis, model.channels, keys);
    out.tolerance = model.tolerance;
    return out;
}

/// The learned model's key neighbours (KeyNeighbours): the old ones when the keys are the same;
/// recomputed from the learned mean when they came from the mean (it is still a shape: learning
/// adds frames of the same calculation) and the keys changed; from the positions when they came
/// from positions the user gave and gives again (LearnOptions::positions); else none, with a
/// warning: the model does not keep the positions.
void learnedKeyNeighbours(const Model& model, Model& out, const LearnOptions& options, LearnReport& report) {
    if (!model.keyNeighbours || out.keyErrorNorm != KeyErrorNorm::Predicted) return;
    if (out.keyPoints == model.keyPoints) {
        out.keyNeighbours = model.keyNeighbours;
        return;
    }
    const Index perKey = model.keyNeighbours->perKey;
    const bool fromMean = model.keyNeighbours->fromMean;
    // The points they are the nearest in: the learned mean (a shape, 3 channels) or the positions.
    Eigen::MatrixXd where;
    if (fromMean && out.channels == 3) {
        where = Eigen::Map<const Eigen::MatrixXd>(out.mean.data(), 3, out.points).transpose();
    } else if (!fromMean) {
        where = options.positions;
    }
    if (where.size() > 0 && out.points - out.keyCount() >= perKey) {
        out.keyNeighbours = nearestToKeys(where, out.keyPoints, perKey, fromMean);
        return;
    }
    report.warnings.push_back(
        "the model's key neighbours came from positions given to train, which learn was not given (the "
        "keys change): the learned model has none, so nothing checks a hit one part of its key error alone "
        "certifies; learn with the same --positions to get them");
}

/// The learned model's sentinels (Sentinels.h): chosen again, as many as before, when they came
/// from the mean or a training frame (from the learned mean or a new frame, sentinelShape; drawn in
/// point order when neither is a shape any more), from the point order (the new frames may move
/// what the old ones left still, and the sentinels must cover it), or from positions the user
/// gave and gives again (LearnOptions::positions). Without those positions: the old ones, less any
/// that became keys (withoutPoints), with a warning, as they cannot follow what the new frames move.
void learnedSentinels(const Model& model, Model& out, const Eigen::Map<const Eigen::MatrixXd>& fresh,
                      const LearnOptions& options, LearnReport& report) {
    if (!model.sentinels) return;
    const Index count = static_cast<Index>(model.sentinels->points.size());
    // The draw's seed: the frames seen, so a learn of other frames draws afresh and the same learn
    // draws the same points.
    const auto seed = static_cast<std::uint64_t>(out.trainFrames);
    const SentinelSource was = model.sentinels->source;
    Sentinels chosen;
    if (was == SentinelSource::Mean || was == SentinelSource::Frame) {
        SentinelSource source = was;
        // The new frames' coordinates in the learned (orthonormal) basis, B^T x - B^T mean: no
        // centred copy of the frames.
        const Eigen::MatrixXd shape = sentinelShape(out, source, [&] {
            Eigen::MatrixXd coordinates = out.basis.transpose() * fresh;
            coordinates.colwise() -= out.basis.transpose() * out.mean;
            return coordinates;
        });
        chosen = shape.size() > 0
                     ? farthestPointSentinels(shape, basisMotion(out), out.keyPoints, count, source)
                     : pointOrderSentinels(basisMotion(out), out.keyPoints,
                                           sentinelCount(kPointOrderFactor * count, out.points), seed);
    } else if (was == SentinelSource::PointOrder) {
        chosen = pointOrderSentinels(basisMotion(out), out.keyPoints, count, seed);
    } else if (options.positions.size() > 0) {
        chosen = farthestPointSentinels(options.positions, basisMotion(out), out.keyPoints, count,
                                        SentinelSource::Given);
    } else {
        chosen = withoutPoints(*model.sentinels, out.keyPoints);
        const auto lost = model.sentinels->points.size() - chosen.points.size();
        report.warnings.push_back(
            "the model's sentinels came from positions given to train, which learn was not given: the "
            "learned model keeps them" +
            (lost > 0
                 ? " less the " + std::to_string(lost) + " that became keys (their covering radius grows)"
                 : std::string()) +
            ", and they do not follow points the new frames move; learn with the same --positions to "
            "choose them again");
    }
    if (!chosen.points.empty()) out.sentinels = std::move(chosen);
}

/// The positions a model's regions were learned from, as learn knows them: the given ones, else the
/// learned mean when training took them from its mean (3 channels, and its sentinels or key
/// neighbours say no positions were given); empty when nothing says which.
Eigen::MatrixXd regionPositions(const Model& model, const Model& out, const LearnOptions& options) {
    if (options.positions.size() > 0) return options.positions;
    const bool fromMean = model.sentinels       ? model.sentinels->source != SentinelSource::Given
                          : model.keyNeighbours ? model.keyNeighbours->fromMean
                                                : false;
    if (model.channels != 3 || !fromMean) return {};
    return Eigen::Map<const Eigen::MatrixXd>(out.mean.data(), 3, out.points).transpose();
}

/// Step 3, cross-fitting: each slice of the new frames is scored by a model that never saw it
/// (the old state updated with the other slices, or the old state alone for one slice; the new
/// keys). `regionFolds`, when given, gets each fold's subspace, for the regions' calibration.
CalibrationStats crossFitNewFrames(const SubspaceUpdate& u, const Eigen::Map<const Eigen::MatrixXd>& fresh,
                                   Index channels, KeyErrorNorm norm, const std::vector<Index>& keys,
                                   Index slices, std::vector<RegionFold>* regionFolds, const auto& progress) {
    const Index m = fresh.cols();
    CalibrationStats scores;
    // Decision: each fold is the old state updated with the other slices in the span of the full
    // update (updateInSpan): the same subspace as an incremental update of the other slices (to
    // rounding; IncrementalSvd.UpdateInSpanEqualsTheIncrementalUpdate), without projecting and
    // factoring the (N*C) rows of the frames again per fold. docs/learning-and-calibration.md has
    // the measured time.
    for (Index slice = 0; slice < slices; ++slice) {
        const Index first = slice * m / slices, last = (slice + 1) * m / slices;
        std::vector<Index> others;
        others.reserve(static_cast<size_t>(m - (last - first)));
        for (Index j = 0; j < m; ++j)
            if (j < first || j >= last) others.push_back(j);
        IncrementalSvdOptions foldOptions = u.svdOptions;
        foldOptions.maxRank = u.basisSize;  // a fold needs only its M-basis: a smaller product for U'
        IncrementalSubspace fold;
        if (others.empty()) {  // one slice: the new frames are held out from the old state alone
            fold = u.before;
        } else {
            fold = updateInSpan(u.before, u.span, fresh, others, foldOptions);
        }
        const Index foldM = std::min(u.basisSize, fold.rank());
        const Eigen::MatrixXd foldBasis = fold.u.leftCols(foldM);
        const Eigen::MatrixXd foldProjector = makeProjector(foldBasis, channels, keys);
        scoreFrames(fresh.middleCols(first, last - first), fold.mean, foldBasis, foldProjector, channels,
                    keys, norm, scores);
        for (Index j = first; j < last; ++j) scores.frames.push_back(j);
        if (regionFolds) regionFolds->push_back({foldBasis, fold.sigma.head(foldM), fold.mean, first, last});
        progress("calibration", static_cast<double>(slice + 1), static_cast<double>(slices));
    }
    scores.slices = slices;
    return scores;
}

/// How many slices the new frames are cross-fitted in. Decision: by default each slice holds as
/// many frames as a slice of `pmsc train` on all n + m frames, (n + m) / S with S the training's
/// folds (so m / ((n + m) / S) slices, at least 1): a held-out new frame is then scored by a model
/// that lacks as large a share of the frames as training's folds lack, and its score is as
/// pessimistic as retraining's. Fixed 5 slices of the new frames score them with models that saw
/// 80% of them, which grows less cautious than retraining as n grows (soft-cached p99.5 1.10x
/// scratch's at 1200 + 300 frames of the ICT take; docs/learning-and-calibration.md).
Index newFrameSlices(const Model& model, const CalibrationRecord& record, Index m,
                     const LearnOptions& options) {
    if (options.slices > 0) return std::min(options.slices, m);
    const Index trainingSlices = record.slices > 0 ? record.slices : 5;
    const double sliceFrames =
        static_cast<double>(model.trainFrames + m) / static_cast<double>(trainingSlices);
    const Index slices = static_cast<Index>(std::llround(static_cast<double>(m) / sliceFrames));
    return std::clamp<Index>(slices, 1, std::min(m, trainingSlices));
}

/// Step 3, calibrated, for KeyErrorNorm::Predicted: each part's threshold is the smaller of its
/// answers on the new frames' scores and on the stored ones (as the other measures take the larger
/// ratio of the two), eps_max from the narrower band; the new scores' raw parts are added to
/// `record`. Decision: the smaller of the two answers, not the rule on the scores pooled. The
/// threshold rule's answer moves with the frame that first crosses T; on the ICT take
/// (bench/learn_vs_scratch.py, 1,200 + 300 frames) the pooled scores gave a leave-one-out threshold
/// 41% above retraining's, the smaller answer 26% above it, and at 600 + 300 a soft-cached p99.5
/// 1.11x retraining's against 0.96x (docs/learning-and-calibration.md).
void calibratePredicted(const Model& model, const CalibrationStats& scores, CalibrationRule rule,
                        double coverage, CalibrationRecord& record, Model& out, LearnReport& report) {
    const double t = model.tolerance;
    CalibrationStats fresh = scores;
    setPredictedThresholds(fresh, t, rule, coverage);
    report.calibrationRatioNew = fresh.parts[1].ratio;  // the leave-one-out part's, its rule's
    for (const auto& note : fresh.notes) report.warnings.push_back(note);
    PredictedParts eps = fresh.partEps;
    double band = fresh.band;
    if (!record.keyRms.empty() && record.keyLoo.size() == record.keyRms.size()) {
        CalibrationStats stored = record.scores();
        setPredictedThresholds(stored, t, rule, coverage);
        report.calibrationRatioOld = stored.parts[1].ratio;
        eps = {std::min(eps.rms, stored.partEps.rms), std::min(eps.loo, stored.partEps.loo)};
        band = std::min(band, stored.band);
    } else {
        record.keyRms.clear();  // an RMS-only record (or none): the new frames' scores start it
        record.maxPointError.clear();
        record.keyLoo.clear();
        report.warnings.push_back(
            "the model stores no predicted-error calibration scores (train with --learn-rank): eps from "
            "the new frames' scores only");
    }
    out.partEps = eps;
    out.epsMin = t;
    out.epsMax = band * t;
    record.append(scores);
    // The report keeps the new frames' scores, in the learned model's measure and thresholds.
    fresh.keyRms = predictedErrors(scores.keyRms, scores.keyLoo, eps, t);
    fresh.partEps = eps;
    fresh.epsMin = out.epsMin;
    fresh.epsMax = out.epsMax;
    fresh.band = band;
    report.calibration = std::move(fresh);
}

/// Step 3, calibrated: eps from the new frames' cross-fitted scores and the stored ones; the
/// new scores are added to `record`.
void calibrateLearned(const Model& model, const SubspaceUpdate& u,
                      const Eigen::Map<const Eigen::MatrixXd>& fresh, const std::vector<Index>& keys,
                      const LearnOptions& options, CalibrationRule rule, double coverage,
                      CalibrationRecord& record, Model& out, LearnReport& report,
                      std::vector<RegionFold>* regionFolds, const auto& progress) {
    const Index m = fresh.cols();
    const Index slices = newFrameSlices(model, record, m, options);
    CalibrationStats scores =
        crossFitNewFrames(u, fresh, model.channels, model.keyErrorNorm, keys, slices, regionFolds, progress);
    if (model.keyErrorNorm == KeyErrorNorm::Predicted) {
        calibratePredicted(model, scores, rule, coverage, record, out, report);
        return;
    }
    setThresholds(scores, model.tolerance, rule, coverage);
    report.calibrationRatioNew = scores.ratio;
    double ratio = report.calibrationRatioNew;
    if (!record.keyRms.empty()) {
        CalibrationStats stored = record.scores();
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
    record.append(scores);
    report.calibration = std::move(scores);
}

/// Step 3 (eps): the learned model's thresholds; returns the calibration record it keeps.
CalibrationRecord learnThresholds(const Model& model, const SubspaceUpdate& u,
                                  const Eigen::Map<const Eigen::MatrixXd>& fresh,
                                  const std::vector<Index>& keys, const LearnOptions& options, Model& out,
                                  LearnReport& report, std::vector<RegionFold>* regionFolds,
                                  const auto& progress) {
    CalibrationStats fit;
    scoreFrames(fresh, out.mean, out.basis, out.projector, model.channels, keys, model.keyErrorNorm, fit);
    const std::vector<double>& eNew = fit.keyRms;  // read only by an uncalibrated model's rule
    report.newFramesMaxPointError = *std::max_element(fit.maxPointError.begin(), fit.maxPointError.end());
    // Decision: the training residual field becomes the largest point error on the frames of
    // this update (the earlier frames are not kept; docs/learning-and-calibration.md says so).
    out.trainMaxPointResidual = report.newFramesMaxPointError;
    const CalibrationRule rule =
        options.rule.value_or(model.calibrationRecord                         ? model.calibrationRecord->rule
                              : model.keyErrorNorm == KeyErrorNorm::Predicted ? CalibrationRule::Threshold
                                                                              : CalibrationRule::MaxRatio);
    const double coverage = options.coverage.value_or(
        model.calibrationRecord && model.calibrationRecord->coverage > 0 ? model.calibrationRecord->coverage
                                                                         : 0.9);
    CalibrationRecord record;
    if (model.calibrationRecord) record = *model.calibrationRecord;
    record.rule = rule;
    record.coverage = rule != CalibrationRule::MaxRatio ? coverage : 0.0;
    if (model.tolerance > 0) {
        calibrateLearned(model, u, fresh, keys, options, rule, coverage, record, out, report, regionFolds,
                         progress);
    } else {
        // Uncalibrated, as training: the largest key error seen on frames it learned from.
        out.epsMin = std::max(model.epsMin, *std::max_element(eNew.begin(), eNew.end()));
        out.epsMax = 1.5 * out.epsMin;
        report.calibration.epsMin = out.epsMin;
        report.calibration.epsMax = out.epsMax;
    }
    return record;
}

/// Step 4: what the next update needs: the state's directions after the basis.
LearningState nextLearningState(const LearningState& settings, const SubspaceUpdate& u) {
    LearningState next = settings;
    next.maxRank = std::max(u.storedRank, u.basisSize);
    next.basisEnergy = u.energy;
    const Index extra = std::min(u.state.rank(), next.maxRank) - u.basisSize;
    next.extraBasis = u.state.u.middleCols(u.basisSize, extra);
    next.extraSigma = u.state.sigma.segment(u.basisSize, extra);
    const Index dropped = u.state.rank() - u.basisSize - extra;  // beyond the stored rank
    next.discardedEnergy = u.state.discardedEnergy + u.state.sigma.tail(dropped).squaredNorm();
    next.updates = settings.updates + 1;
    return next;
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
    checkLearnInput(model, newFrames, options);
    const Index channels = model.channels;
    const Eigen::Map<const Eigen::MatrixXd> fresh = newFrames.matrix();
    report.newFrames = newFrames.frames;
    report.basisBefore = model.basisSize();
    report.oldModelNewFramesKeyRmsMax = oldModelKeyRmsMax(model, fresh);

    // --- 1. mean and basis: Brand's update of the stored state.
    progress("subspace", 0, 1);
    Clock::time_point t = Clock::now();
    SubspaceUpdate u;
    updateState(model, fresh, options, report, u);
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
    const std::vector<Index> keys = selectLearnedKeys(model, u, settings, report);
    const Index determined = determinedBasisSize(u.basis, channels, keys);
    if (determined < 1) throw InputError("learn: the selected keys determine no basis vector");
    if (determined < u.basisSize) {
        report.warnings.push_back("reduced M from " + std::to_string(u.basisSize) + " to " +
                                  std::to_string(determined) + ": the key system cannot determine more");
        u.basisSize = determined;
        u.basis.conservativeResize(Eigen::NoChange, u.basisSize);
    }
    Model out = learnedCore(model, u, keys);
    learnedKeyNeighbours(model, out, options, report);
    learnedSentinels(model, out, fresh, options, report);
    report.basisAfter = u.basisSize;
    report.largestAngle =
        largestPrincipalAngle(u.basis, model.basis.leftCols(std::min(u.basisSize, model.basisSize())));
    report.secondsKeys = since(t);
    progress("keys", 1, 1);

    // --- 3. eps.
    progress("calibration", 0, 1);
    t = Clock::now();
    std::vector<RegionFold> regionFolds;
    const bool regions = model.regions && options.regions;
    CalibrationRecord record = learnThresholds(model, u, fresh, keys, options, out, report,
                                               regions ? &regionFolds : nullptr, progress);
    // The regions: the old partition, each region's keys, basis and thresholds learned again
    // (relearnRegions says how and why).
    if (regions) {
        out.regions = relearnRegions(*model.regions, model, out, u.state.u, u.state.sigma, fresh, regionFolds,
                                     SvdOptions{}, regionPositions(model, out, options), &report.warnings);
        report.regionKeys = static_cast<Index>(out.regions->extraKeyPoints.size());
    }
    report.secondsCalibration = since(t);
    progress("calibration", 1, 1);

    // --- 4. what the next update needs.
    out.learning = nextLearningState(settings, u);
    if (model.tolerance > 0) out.calibrationRecord = std::move(record);
    // The clamp at 0 stays while every frame seen is >= 0 (set last: calibration measured PM
    // unclamped, as training's does).
    out.nonNegative = model.nonNegative && (fresh.size() == 0 || fresh.minCoeff() >= 0);
    if (model.nonNegative && !out.nonNegative)
        report.warnings.push_back(
            "the new frames have negative values: the output is no longer clamped at 0");
    out.validate();
    report.seconds = since(start);
    return out;
}

}  // namespace pmsc
