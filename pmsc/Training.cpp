#include "pmsc/Training.h"

#include "pmsc/Calibration.h"
#include "pmsc/Errors.h"
#include "pmsc/KeyNeighbours.h"
#include "pmsc/KeyPointSelector.h"
#include "pmsc/Parallel.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/QDeim.h"
#include "pmsc/RegionChoice.h"
#include "pmsc/RowBlockOps.h"
#include "pmsc/Sentinels.h"
#include "pmsc/Subspace.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>

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
    if (!(o.varimaxTolerance >= 0))
        badOption("varimax tolerance must be >= 0, got " + num(o.varimaxTolerance));
    if (o.varimaxMaxIterations < 1) {
        badOption("varimax iteration cap must be >= 1, got " + std::to_string(o.varimaxMaxIterations));
    }
    if (!std::isfinite(o.tolerance) || o.tolerance < 0) {
        badOption("tolerance must be >= 0 (0 = no calibration), got " + num(o.tolerance));
    }
    if (o.calibrationGroup < 1 || frames % o.calibrationGroup != 0) {
        badOption("calibration group must divide the " + std::to_string(frames) + " frames, got " +
                  std::to_string(o.calibrationGroup));
    }
    const Index groups = frames / o.calibrationGroup;
    if (o.tolerance > 0 && (o.calibrationSlices < 2 || o.calibrationSlices > groups)) {
        badOption("calibration slices must be in [2, " + std::to_string(groups) + "], got " +
                  std::to_string(o.calibrationSlices));
    }
    if (o.calibrationRule && *o.calibrationRule != CalibrationRule::MaxRatio &&
        *o.calibrationRule != CalibrationRule::Conformal &&
        *o.calibrationRule != CalibrationRule::Threshold) {
        badOption("unknown calibration rule " + std::to_string(static_cast<int>(*o.calibrationRule)));
    }
    if (o.keyErrorNorm == KeyErrorNorm::Predicted && !(o.tolerance > 0))
        badOption("the predicted key error is calibrated for a tolerance: give one (or another key error)");
    if (resolvedCalibrationRule(o) != CalibrationRule::MaxRatio &&
        !(o.calibrationCoverage > 0 && o.calibrationCoverage < 1)) {
        badOption("calibration coverage must be in (0, 1), got " + num(o.calibrationCoverage));
    }
    if (o.learnRank < 0) badOption("learn rank must be >= 0 (0 = off), got " + std::to_string(o.learnRank));
    if (o.powerIterations < 0) {
        badOption("power iterations must be >= 0, got " + std::to_string(o.powerIterations));
    }
    if (o.keyCandidates < 0 || o.keyCandidates > points) {
        badOption("key candidates must be in [0, " + std::to_string(points) + "] (0 = every point), got " +
                  std::to_string(o.keyCandidates));
    }
    if (o.keyCandidates > 0 && o.maxKeys > o.keyCandidates) {
        badOption("max keys " + std::to_string(o.maxKeys) + " exceed the " + std::to_string(o.keyCandidates) +
                  " points keys may come from");
    }
    if (o.keyCandidates > 0) {
        for (const auto* list : {&o.fiducials, &o.gridPoints})
            for (Index p : *list)
                if (p >= o.keyCandidates)
                    badOption("designer key point " + std::to_string(p) + " is not among the " +
                              std::to_string(o.keyCandidates) + " points keys may come from");
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

/// Makes sure svd.u (owned rows) has at least `count` left singular vectors: U = Q V S^-1 for
/// the missing columns, one pass over q.
void formLeftVectors(RowBlocks& q, TruncatedSvd& svd, Index count) {
    count = std::min(count, svd.sigma.size());
    const Index have = svd.u.cols();
    if (have >= count) return;
    const Eigen::MatrixXd vs = svd.v.middleCols(have, count - have) *
                               svd.sigma.segment(have, count - have).cwiseInverse().asDiagonal();
    Eigen::MatrixXd more = timesRight(q, vs);
    if (have == 0) {  // taken, not copied: it is N*C x count
        svd.u = std::move(more);
        return;
    }
    svd.u.conservativeResize(q.ownedRows(), count);
    svd.u.rightCols(count - have) = more;
}

/// Turns `frames` (F frames of N points x C channels) into the F*C channel frames of one channel,
/// each point-channel's `mean` removed, where the values lie: frame t's N x C block becomes its C
/// rows of N through one frame of scratch. Why in place: the channel frames are as large as the
/// frames, and a copy doubled training's peak (a million voxels: 2.25 GB more).
FrameSet channelFramesInPlace(FrameSet&& frames, const Eigen::VectorXd& mean) {
    const Index n = frames.points, c = frames.channels, f = frames.frames;
    std::vector<double> scratch(static_cast<std::size_t>(n * c));
    for (Index t = 0; t < f; ++t) {
        double* values = frames.frame(t);
        std::copy(values, values + n * c, scratch.begin());
        for (Index ch = 0; ch < c; ++ch)
            for (Index p = 0; p < n; ++p)
                values[ch * n + p] = scratch[static_cast<std::size_t>(p * c + ch)] - mean[p * c + ch];
    }
    FrameSet split;
    split.frames = f * c;
    split.points = n;
    split.channels = 1;
    split.values = std::move(frames.values);
    frames = FrameSet();
    return split;
}

/// TrainingOptions::sharedChannels: the C=1 model of the channel frames, turned into a model of
/// C channels sharing its basis. Takes the frames: their values become the channel frames.
Model trainSharedChannels(FrameSet&& frames, const TrainingOptions& options, TrainingReport* reportOut) {
    if (options.regions.count > 0 || options.learnRank > 0)
        throw std::invalid_argument(
            std::string("train: channels sharing the basis do not combine with ") +
            (options.regions.count > 0 ? "regions (local fail-through)" : "a learning rank (pmsc learn)") +
            " in this version");
    if (options.keyErrorNorm && *options.keyErrorNorm != KeyErrorNorm::Rms)
        throw InputError(std::string("train: the ") + toString(*options.keyErrorNorm) +
                         " key error needs channels of their own (not --shared-channels)");
    const Index n = frames.points, c = frames.channels, f = frames.frames;
    // Each point-channel's mean over the frames, removed before the channels become frames, so
    // the C=1 training (whose mean is then zero) learns the variation alone and the model keeps
    // a mean per channel.
    Eigen::VectorXd mean = frames.matrix().rowwise().mean();
    const bool nonNegative =
        options.clampAtZero && frames.values.size() > 0 && frames.matrix().minCoeff() >= 0;
    MatrixBlocks q(channelFramesInPlace(std::move(frames), mean));
    TrainingOptions one = options;
    one.clampAtZero = false;  // the channel frames are centred: decided above from the frames
    one.learnable = false;    // `pmsc learn` does not take shared-channel models
    one.sharedChannels = false;
    // Positions serve the sentinels alone here (the C = 1 model of the channels has no regions).
    one.regions.automatic = false;
    one.regions.count = 0;
    one.keyErrorNorm = KeyErrorNorm::Rms;
    // A frame's channels are held out together: held in, its other channels would tell the fold
    // most of what it is asked to predict. (The C=1 training then checks --slices against the F
    // groups, with the same message as for any model.)
    one.calibrationGroup = c;
    TrainingReport localReport;
    TrainingReport& report = reportOut ? *reportOut : localReport;
    SingleProcess single;
    Model model = train(q, single, one, &report);
    for (Index p = 0; p < n; ++p)
        for (Index ch = 0; ch < c; ++ch) mean[p * c + ch] += model.mean[p];
    model.mean = std::move(mean);
    model.channels = c;
    model.trainFrames = f;
    model.sharedChannels = true;
    model.nonNegative =
        nonNegative;  // set last: the residual below measures PM unclamped, as calibration did
    // The largest point residual on the training frames, Euclidean over the channels like
    // everywhere else (the C=1 training measured it per channel). Frame t's channel ch is
    // column t*C + ch of the centred matrix plus the model's mean.
    // PM of every training frame at every point is mean + B X, X (M x F*C) the frames' coordinates
    // in the centred matrix's column order (frame t's channel ch at column t*C + ch), so its residual
    // is B X - Q for Q the centred matrix: one matrix product per slab of points, on every core.
    // Slabs of points and runs of frames keep each product small (the whole residual would be
    // training's peak); a point's error is the largest over the frames of its Euclidean norm over the
    // channels, which no slab or thread order changes.
    const Eigen::Map<const Eigen::MatrixXd> centred = static_cast<const MatrixBlocks&>(q).matrix();
    const PointMultiplier pm(model, BasisPrecision::None);
    const Index k = model.keyCount(), m = model.basisSize();
    std::vector<double> keys(static_cast<std::size_t>(k * c)),
        coords(static_cast<std::size_t>(model.coordCount()));
    Eigen::MatrixXd x(m, f * c);
    std::vector<double> keyErrors(static_cast<std::size_t>(f));
    for (Index t = 0; t < f; ++t) {
        for (Index i = 0; i < k; ++i)
            for (Index ch = 0; ch < c; ++ch) {
                const Index p = model.keyPoints[static_cast<std::size_t>(i)];
                keys[static_cast<std::size_t>(i * c + ch)] = centred(p, t * c + ch) + model.mean[p * c + ch];
            }
        pm.project(keys.data(), coords.data());
        for (Index j = 0; j < m; ++j)
            for (Index ch = 0; ch < c; ++ch) x(j, t * c + ch) = coords[static_cast<std::size_t>(j * c + ch)];
        keyErrors[static_cast<std::size_t>(t)] = pm.keyError(keys.data(), coords.data());
    }
    const Index slabs = (n + kSlabPoints - 1) / kSlabPoints;
    // Each product is at most 2^22 values (32 MB a thread), whatever the frame count.
    const Index framesPerProduct = std::max<Index>(1, (Index{1} << 22) / (kSlabPoints * c));
    std::vector<double> slabWorst(static_cast<std::size_t>(slabs), 0.0);
    std::atomic<Index> nextSlab{0};
    runOnEveryCore(
        [&] {
            Eigen::MatrixXd d;
            for (Index b = nextSlab++; b < slabs; b = nextSlab++) {
                const Index first = b * kSlabPoints, count = std::min(kSlabPoints, n - first);
                double w = 0;
                for (Index t0 = 0; t0 < f; t0 += framesPerProduct) {
                    const Index frames = std::min(framesPerProduct, f - t0);
                    d.noalias() = model.basis.middleRows(first, count) * x.middleCols(t0 * c, frames * c);
                    d -= centred.block(first, t0 * c, count, frames * c);
                    for (Index t = 0; t < frames; ++t)
                        for (Index i = 0; i < count; ++i) {
                            double e = 0;
                            for (Index ch = 0; ch < c; ++ch) e += d(i, t * c + ch) * d(i, t * c + ch);
                            w = std::max(w, e);
                        }
                }
                slabWorst[static_cast<std::size_t>(b)] = w;
            }
        },
        slabs);
    const double worst = *std::max_element(slabWorst.begin(), slabWorst.end());
    model.trainMaxPointResidual = std::sqrt(worst);
    if (!(options.tolerance > 0)) {
        // Uncalibrated eps are the training frames' largest key error (thresholdsFromKeyRows):
        // here the Euclidean one over the channels the runtime measures, not the C=1 training's
        // per channel, which is up to sqrt(C) smaller and would call training frames misses.
        model.epsMin = *std::max_element(keyErrors.begin(), keyErrors.end());
        model.epsMax = 1.5 * model.epsMin;
        report.calibration.epsMin = model.epsMin;
        report.calibration.epsMax = model.epsMax;
        report.calibration.keyRms = keyErrors;
    }
    model.validate();
    return model;
}

/// What train() checks before any work: the options against the data's sizes.
void checkTrainingInput(RowBlocks& q, Communicator& comm, const TrainingOptions& options) {
    if (options.sharedChannels && q.channels() > 1)
        throw std::invalid_argument(
            "channels sharing the basis are trained in memory on one process; drop the shared channels, "
            "or train in memory without MPI");
    if (options.regions.count > 0 && (comm.size() != 1 || dynamic_cast<const MatrixBlocks*>(&q) == nullptr))
        throw std::invalid_argument(
            "regions (local fail-through) are learned from the training matrix in memory on one process; "
            "drop --regions, or train in memory without MPI");
    const Index n = q.points();
    const Index f = q.frames();
    if (f < 2) throw InputError("train: need at least 2 training frames, got " + std::to_string(f));
    validateOptions(options, n, f);
    {
        // Every rank checks the designer points (a throw on one rank alone would leave the others
        // waiting in a collective).
        KeySet check(n);
        seedKeys(check, options.fiducials, options.gridPoints);
    }
}

/// The training of one model from the mean-removed rows of Q, step by step (the paper's
/// sections in order); each step reads what the ones before it left in the members.
struct Trainer {
    RowBlocks& q;
    Communicator& comm;
    const TrainingOptions& options;
    TrainingReport& report;
    const Index n, channels, f, rows;
    Model model;
    Eigen::MatrixXd gram;          ///< Q^T Q, F x F, replicated
    TruncatedSvd svd;              ///< of Q; U's owned rows, formed as far as needed
    Index cap = 0;                 ///< the largest basis the options and the data allow
    Index available = 0;           ///< basis vectors with non-negligible singular values, <= cap
    Index m = 0;                   ///< the basis size
    Eigen::MatrixXd basis;         ///< owned rows
    std::vector<Index> keys;       ///< the key points
    Eigen::MatrixXd keyRows;       ///< Q's rows at the keys, K*C x F, replicated
    Eigen::MatrixXd basisKeyRows;  ///< the basis's rows at the keys, K*C x M, replicated

    Trainer(RowBlocks& blocks, Communicator& communicator, const TrainingOptions& trainingOptions,
            TrainingReport& trainingReport)
        : q(blocks),
          comm(communicator),
          options(trainingOptions),
          report(trainingReport),
          n(blocks.points()),
          channels(blocks.channels()),
          f(blocks.frames()),
          rows(n * channels) {}

    /// Calls the caller's progress callback; cancels the training when it says stop.
    void progress(std::string_view stage, double done, double total) const;
    /// Q's Gram matrix and the model's sizes.
    void meanAndGram();
    /// The subspace (section 3): V and sigma from eig(Q^T Q).
    void subspace();
    /// M: the first rule that is set wins (TrainingOptions order); forms U's first M columns.
    void chooseBasisSize();
    /// M from the largest point error of each basis size (--basis-max-error).
    void basisSizeFromPointErrors();
    /// trainingMemoryBound() with r columns of U formed, at this block size; rank 0's, which every
    /// rank uses so that all take the same decisions.
    std::uint64_t memoryBound(Index r) const;
    /// The most columns of U (`wanted`, or fewer) that options.memoryLimit holds at this block
    /// size, with a warning when it is fewer. @throws InputError when not even the Varimax block fits.
    Index basisColumnsThatFit(Index wanted, const char* rule);
    /// Key points (section 4) by teleconnection.
    void teleconnectionKeys();
    /// Key points (section 4) by Q-DEIM, on rank 0.
    void qdeimKeys();
    /// Determinacy: never leave the key system unable to determine the basis; returns whether the
    /// residual the selection reported is the final one.
    bool determineBasis();
    /// The key projector and the training residual.
    void projector();
    /// eps (section 5; calibration beyond the paper).
    void thresholds();
    /// The learning state: the next left singular vectors after the basis, up to rank r.
    void learningState();
    /// Regions of local fail-through (paper section 9), on the final core.
    void regions();
    /// The positions of the points the hit check reads (key neighbours, sentinels), N x 3; empty
    /// when the model has no such check or no positions. `given`: they are the user's.
    Eigen::MatrixXd knownPositions(bool& given) const;
    /// The points nearest each key (KeyNeighbours), where a hit one part of the predicted error
    /// alone certifies is checked; rank 0, on the final core.
    void keyNeighbours();
    /// The sentinels (Sentinels.h), computed beside every hit; rank 0, on the final core.
    void sentinels();
    /// Model::nonNegative from every rank's smallest training value (a collective: all ranks).
    void nonNegative();
    /// U's columns are read after the keys: the learning state extends them.
    bool keepsLeftVectors() const { return options.learnRank > 0 || options.learnable; }
    /// Frees U once the keys are chosen, unless the learning state reads it: the folds of the
    /// calibration, training's largest working set, run without it.
    void releaseLeftVectors() {
        if (!keepsLeftVectors()) svd.u = Eigen::MatrixXd();
    }
};

void Trainer::progress(std::string_view stage, double done, double total) const {
    if (options.progress && !options.progress(stage, done, total)) {
        throw Cancelled("training cancelled during " + std::string(stage));
    }
}

void Trainer::meanAndGram() {
    // --- Q: mean-removed training matrix (paper footnote 1), rows x = p*C + c, columns frames;
    // each block is centred as it is read (RowBlocks). Its Gram matrix Q^T Q is the one pass every
    // later step reuses: the SVD (section 3), the residual blocks of key selection, calibration.
    progress("mean", 0, 1);
    model.points = n;
    model.channels = channels;
    model.trainFrames = f;
    model.selector = options.selector;
    model.keyErrorNorm = resolvedKeyErrorNorm(options);
    progress("mean", 1, 1);
    progress("svd", 0, 1);
    gram = gramOf(q, comm);
    model.totalEnergy = gram.trace();
    if (!(model.totalEnergy > 0)) {
        throw InputError("train: the training frames are all identical; there is no motion to learn");
    }
}

void Trainer::subspace() {
    // --- Subspace (section 3): eig(Q^T Q) gives V and sigma; U = Q V S^-1 is formed (one pass)
    // once it is known how many columns the M rule and key selection need. Decision: always this
    // Gram route (Subspace.h weighs it against a randomized SVD in memory): out of core and under
    // MPI it costs one pass over the data and one reduction of F x F, where the randomized route
    // needs 2q + 2 passes and a distributed tall QR.
    cap = std::min({options.maxBasis, f, rows});
    Index wanted = options.basis > 0 ? std::min(options.basis, cap) : cap;
    if (options.basis > cap) {
        report.warnings.push_back("basis " + std::to_string(options.basis) + " capped to " +
                                  std::to_string(cap) + " (min of max basis, frames, N*C)");
    }
    // The first key-selection block needs the top `block` vectors of Q even when M is smaller.
    const Index svdRank = std::min(std::max({wanted, options.block, options.learnRank}), std::min(f, rows));
    svd = svdFromGram(Eigen::MatrixXd(0, f), gram, svdRank, 0);
    svd.u.resize(q.ownedRows(), 0);
    available = std::min<Index>(cap, svd.sigma.size());
    if (available < 1) throw InputError("train: the training frames have no usable variation");
    progress("svd", 1, 1);
}

namespace {
std::string mebibytes(std::uint64_t bytes) {
    char text[32];
    std::snprintf(text, sizeof text, "%.1f MiB", static_cast<double>(bytes) / 1048576.0);
    return text;
}
}  // namespace

std::uint64_t Trainer::memoryBound(Index r) const {
    // In memory the frames are one block of every row (the bound counts them as such).
    const bool inMemory = dynamic_cast<const MatrixBlocks*>(&q) != nullptr;
    return trainingMemoryBound(n, channels, f, r, options.block, options.maxKeys,
                               inMemory ? 0 : q.blockPoints(), comm.size(), /*rootRank=*/true);
}

Index Trainer::basisColumnsThatFit(Index wanted, const char* rule) {
    if (options.memoryLimit == 0) return wanted;
    const Index least = std::min(std::max(options.block, options.learnRank), wanted);
    if (memoryBound(wanted) <= options.memoryLimit) return wanted;
    if (memoryBound(least) > options.memoryLimit)
        throw InputError("train: the memory limit " + mebibytes(options.memoryLimit) + " cannot hold even " +
                         std::to_string(least) + " basis vectors of " + std::to_string(n) + " points x " +
                         std::to_string(channels) + " channels (needs " + mebibytes(memoryBound(least)) +
                         "); lower --block, --learn-rank, --max-keys or --block-points, or raise the limit");
    Index lo = least, hi = wanted;  // memoryBound(lo) fits, memoryBound(hi) does not
    while (hi - lo > 1) {
        const Index mid = lo + (hi - lo) / 2;
        (memoryBound(mid) <= options.memoryLimit ? lo : hi) = mid;
    }
    report.warnings.push_back(std::string(rule) + " " + std::to_string(wanted) +
                              " basis vectors; the memory limit holds " + std::to_string(lo) +
                              " (raise it, or lower --block-points to leave the basis more)");
    return lo;
}

void Trainer::chooseBasisSize() {
    const char* rule = nullptr;  // the rule that chose M from the singular values alone
    if (options.basis > 0) {
        rule = "--basis asks for";
        m = std::min(options.basis, available);
        if (m < std::min(options.basis, cap)) {
            report.warnings.push_back("basis " + std::to_string(options.basis) + " reduced to " +
                                      std::to_string(m) +
                                      ": the training data has only that many "
                                      "non-negligible singular values");
        }
    } else if (options.energy > 0 || options.basisMaxError <= 0) {
        rule = "the energy rule asks for";
        const double e = options.energy > 0 ? options.energy : options.defaultEnergy;
        m = basisSizeForEnergy(svd.sigma.head(available), model.totalEnergy, e);
        const double got = svd.sigma.head(m).squaredNorm() / model.totalEnergy;
        if (got < e * (1 - 1e-12)) {
            report.warnings.push_back("energy " + num(e) + " not reached within " + std::to_string(m) +
                                      " basis vectors (captured " + num(got) + "); raise --max-basis?");
        }
    } else {
        available = basisColumnsThatFit(available, "--basis-max-error would measure up to");
        basisSizeFromPointErrors();
    }
    report.requestedBasis = m;
    // Decision: the memory is checked here, after the Gram pass has told M and before U and the
    // basis (the arrays of N*C x M) exist, so a limit that cannot hold --max-basis still holds the
    // basis the data need (the plan made before training then reserved only the Varimax block).
    if (rule) m = std::min(m, basisColumnsThatFit(std::max({m, options.block, options.learnRank}), rule));
    // --basis-max-error formed `available` columns of U to measure them.
    report.memoryBound =
        memoryBound(std::max({m, options.block, options.learnRank, rule ? Index{0} : available}));
    formLeftVectors(q, svd, std::max(m, options.block));
    // When U is the basis and nothing extends U later (the learning state), the basis takes U's
    // storage instead of a copy of it (at a million points 312 MB at M = 40).
    if (svd.u.cols() == m && !keepsLeftVectors())
        basis = std::move(svd.u);
    else
        basis = svd.u.leftCols(m);
}

void Trainer::basisSizeFromPointErrors() {
    progress("basis-error", 0, 1);
    formLeftVectors(q, svd, available);
    std::vector<double> errors(static_cast<std::size_t>(available), 0.0);
    for (Index b = 0; b < q.blockCount(); ++b) {
        accumulateBasisErrors(q.block(b), svd.u.middleRows(q.blockFirstRow(b), q.blockRows(b)), svd, channels,
                              errors);
    }
    maxOverRanks(comm, errors.data(), errors.size());
    m = basisSizeFromErrors(errors, options.basisMaxError);
    if (m > available) {
        m = available;
        report.warnings.push_back("basis max error " + num(options.basisMaxError) + " not reached within " +
                                  std::to_string(m) + " basis vectors (largest point error " +
                                  num(errors.empty() ? 0.0 : errors.back()) + ")");
    }
    progress("basis-error", 1, 1);
}

void Trainer::teleconnectionKeys() {
    TeleconnectionOptions t;
    t.maxKeys = options.maxKeys;
    t.maxError = options.maxError;
    t.block = options.block;
    t.fiducials = options.fiducials;
    t.gridPoints = options.gridPoints;
    t.candidates = options.keyCandidates;
    t.varimax.tolerance = options.varimaxTolerance;
    t.varimax.maxIterations = options.varimaxMaxIterations;
    t.svd.seed = options.seed;
    t.svd.powerIterations = options.powerIterations;
    t.onRound = [&](Index, Index k, double) {
        progress("keys", static_cast<double>(k), static_cast<double>(options.maxKeys));
    };
    progress("keys", 0, static_cast<double>(options.maxKeys));
    KeySelection sel =
        selectKeysTeleconnection(q, comm, basis, svd.u.cols() > 0 ? svd.u : basis, svd.sigma, t, gram);
    keys = std::move(sel.keys);
    keyRows = std::move(sel.keyRows);
    report.iterations = sel.rounds;
    report.residualPerRound = std::move(sel.residualPerRound);
}

void Trainer::qdeimKeys() {
    progress("keys", 0, static_cast<double>(options.maxKeys));
    // Q-DEIM pivots over every row at once: it runs on rank 0 on the gathered basis (which
    // rank 0 holds anyway to write the model) and the keys are sent to the others.
    const Eigen::MatrixXd full = gatherRowsTo(comm, basis, rows, 0);
    std::vector<double> picked;
    double passes = 0;
    if (comm.rank() == 0) {
        KeySet check(n);
        seedKeys(check, options.fiducials, options.gridPoints);
        QDeimSelection sel =
            selectKeysQDeim(full, channels, options.maxKeys, check.keys(), options.keyCandidates);
        picked.assign(sel.keys.begin(), sel.keys.end());
        passes = static_cast<double>(sel.passes);
    }
    double count[2] = {static_cast<double>(picked.size()), passes};
    comm.broadcast(count, 2, 0);
    picked.resize(static_cast<std::size_t>(count[0]));
    comm.broadcast(picked.data(), picked.size(), 0);
    for (double k : picked) keys.push_back(static_cast<Index>(k));
    report.iterations = static_cast<Index>(count[1]);
    keyRows = keyRowsOfQ(q, comm, keys);
    progress("keys", static_cast<double>(keys.size()), static_cast<double>(options.maxKeys));
}

bool Trainer::determineBasis() {
    const Index kc = static_cast<Index>(keys.size()) * channels;
    basisKeyRows = keyRowsOf(q, comm, basis, keys);
    std::vector<Index> keyOrder(keys.size());
    for (std::size_t i = 0; i < keys.size(); ++i) keyOrder[i] = static_cast<Index>(i);
    const Index determined = determinedBasisSize(basisKeyRows, channels, keyOrder);
    if (determined < 1) {
        throw InputError("train: the " + std::to_string(keys.size()) +
                         " key points determine no basis vector (their basis rows are all zero)");
    }
    const bool reportedResidualIsFinal =
        options.selector == Selector::Teleconnection && determined >= m && !report.residualPerRound.empty();
    if (determined < m) {
        const std::string why = kc < m ? "the " + std::to_string(keys.size()) +
                                             " keys give only K*C = " + std::to_string(kc) + " values"
                                       : "the key system B_K is rank deficient or ill-conditioned "
                                         "(condition number > 1e8)";
        report.warnings.push_back("reduced M from " + std::to_string(m) + " to " +
                                  std::to_string(determined) + ": " + why);
        m = determined;
        basis.conservativeResize(Eigen::NoChange, m);
        basisKeyRows.conservativeResize(Eigen::NoChange, m);
    }
    if (kc == m) {
        report.warnings.push_back("K*C == M (" + std::to_string(kc) +
                                  "): the key residual is identically zero, so the soft-cache error "
                                  "monitor is blind; add keys or reduce M");
    }
    return reportedResidualIsFinal;
}

void Trainer::projector() {
    progress("projector", 0, 1);
    const bool reportedResidualIsFinal = determineBasis();
    model.singularValues = svd.sigma.head(m);
    model.keyPoints = keys;
    model.projector = projectorFromKeyRows(basisKeyRows, channels);
    if (reportedResidualIsFinal) {
        // The last selection round already approximated the training set with exactly these keys
        // and this basis; recomputing would cost another (N*C) x M x F product.
        model.trainMaxPointResidual = report.residualPerRound.back();
    } else {
        // The residual is reduced block by block, never formed.
        model.trainMaxPointResidual = maxPointResidualOf(q, comm, basis, model.projector * keyRows);
    }
    if (options.selector == Selector::QDeim) report.residualPerRound.push_back(model.trainMaxPointResidual);
    progress("projector", 1, 1);
}

void Trainer::thresholds() {
    progress("calibration", 0, 1);
    if (options.tolerance > 0) {
        report.calibration =
            calibrate(q, comm, keyRows, keys, m, options.tolerance, options.calibrationSlices, gram,
                      resolvedCalibrationRule(options), options.calibrationCoverage, options.calibrationGroup,
                      model.keyErrorNorm);
        model.tolerance = options.tolerance;
        model.partEps = report.calibration.partEps;
    } else {
        report.calibration =
            thresholdsFromKeyRows(keyRows, basisKeyRows, channels, model.projector, model.keyErrorNorm);
    }
    for (const auto& note : report.calibration.notes) report.warnings.push_back(note);
    model.epsMin = report.calibration.epsMin;
    model.epsMax = report.calibration.epsMax;
    progress("calibration", 1, 1);
}

void Trainer::learningState() {
    LearningState learning;
    learning.maxRank = std::max(options.learnRank, m);
    if (options.learnRank > 0 && options.learnRank < m) {
        report.warnings.push_back("learn rank " + std::to_string(options.learnRank) +
                                  " raised to M = " + std::to_string(m));
    }
    const Index stored = std::min<Index>(learning.maxRank, svd.sigma.size());
    formLeftVectors(q, svd, stored);
    // Owned rows on each rank; rank 0, which writes the model, gathers them.
    learning.extraBasis = gatherRowsTo(comm, Eigen::MatrixXd(svd.u.middleCols(m, stored - m)), rows, 0);
    learning.extraSigma = svd.sigma.segment(m, stored - m);
    learning.maxKeys = options.maxKeys;
    learning.block = options.block;
    learning.maxError = options.maxError;
    learning.fiducials = options.fiducials;
    learning.gridPoints = options.gridPoints;
    // The rule chooseBasisSize() took M by, when it is one an update can apply again: the energy
    // of the singular values against the exact total (a point-error rule needs the frames).
    if (options.basis <= 0 && (options.energy > 0 || options.basisMaxError <= 0))
        learning.basisEnergy = options.energy > 0 ? options.energy : options.defaultEnergy;
    model.learning = std::move(learning);
    if (options.tolerance > 0) model.calibrationRecord = CalibrationRecord::from(report.calibration);
}

void Trainer::regions() {
    // They are learned from the whole mean-removed matrix, so only in-memory, one-process
    // training learns them (checked before any work, at the top, when asked for by count).
    RegionOptions chosen = options.regions;
    if (chosen.count == 0) {  // automatic
        const auto* inMemory = dynamic_cast<const MatrixBlocks*>(&q);
        if (comm.size() != 1 || inMemory == nullptr) {
            report.regions = "none: regions are learned in memory on one process";
            return;
        }
        const RegionChoice choice = chooseRegions(model, chosen, options.tolerance, rmsMotion(model));
        report.regions = choice.reason;
        if (choice.count == 0) return;
        chosen.count = choice.count;
        if (chosen.automaticFeather) chosen.featherFraction = choice.featherFraction;
    }
    progress("regions", 0, 1);
    const auto& inMemory = dynamic_cast<const MatrixBlocks&>(q);
    SvdOptions svdOptions;
    svdOptions.seed = options.seed;
    svdOptions.powerIterations = options.powerIterations;
    model.regions = learnRegions(inMemory.matrix(), model, chosen, options.tolerance,
                                 options.calibrationSlices, svdOptions, &report.warnings);
    progress("regions", 1, 1);
}

Eigen::MatrixXd Trainer::knownPositions(bool& given) const {
    // The positions the regions take, or the training mean when it is a shape (channels of their
    // own); empty when there are none.
    given = options.regions.positions.size() > 0;
    Eigen::MatrixXd positions =
        given ? options.regions.positions
              : (model.sharedChannels ? Eigen::MatrixXd() : meanShape(model, rmsMotion(model)));
    if (positions.rows() != model.points || positions.cols() != 3) return {};
    return positions;
}

void Trainer::keyNeighbours() {
    // Only the predicted error's partial check reads them (HitCheck).
    if (model.points - model.keyCount() < kNeighboursPerKey) return;
    if (model.keyErrorNorm != KeyErrorNorm::Predicted || model.sharedChannels) return;
    bool given = false;
    const Eigen::MatrixXd positions = knownPositions(given);
    if (positions.size() == 0) return;
    model.keyNeighbours = nearestToKeys(positions, model.keyPoints, kNeighboursPerKey, !given);
}

void Trainer::sentinels() {
    // Whatever the key error: the check needs only the tolerance and the computed points. Spread
    // over positions when there are any (given, the mean when it is a shape, or a training frame
    // when that is), else over the point order (Sentinels.h says what each promises).
    if (options.sentinels <= 0 || !(options.tolerance > 0)) return;
    const Index count = sentinelCount(options.sentinels, model.points);
    bool given = options.regions.positions.size() > 0;
    SentinelSource source = SentinelSource::Given;
    Eigen::MatrixXd positions;
    if (given) {
        positions = knownPositions(given);
    } else {
        // The training frames' coordinates in the basis: frame f is mean + basis * sigma * V^T e_f
        // (U = Q V / sigma).
        positions = sentinelShape(model, source, [&] {
            const Index m = model.basisSize();
            return Eigen::MatrixXd(model.singularValues.head(m).asDiagonal() * svd.v.leftCols(m).transpose());
        });
    }
    Sentinels chosen =
        positions.size() > 0
            ? farthestPointSentinels(positions, basisMotion(model), model.keyPoints, count, source)
            : pointOrderSentinels(basisMotion(model), model.keyPoints,
                                  sentinelCount(kPointOrderFactor * options.sentinels, model.points),
                                  options.seed);
    if (!chosen.points.empty()) model.sentinels = std::move(chosen);
}

void Trainer::nonNegative() {
    // Decided after calibration, which measures PM unclamped: its held-out errors are then at
    // least the clamped ones, so eps stay on the safe side of what a hit hands back.
    const double mine = q.smallestValue();
    std::vector<double> all;
    comm.allGather(&mine, 1, all);
    model.nonNegative = !all.empty() && *std::min_element(all.begin(), all.end()) >= 0;
}

}  // namespace

KeyErrorNorm resolvedKeyErrorNorm(const TrainingOptions& options) {
    if (options.keyErrorNorm) return *options.keyErrorNorm;
    return options.tolerance > 0 && !options.sharedChannels ? KeyErrorNorm::Predicted : KeyErrorNorm::Rms;
}

CalibrationRule resolvedCalibrationRule(const TrainingOptions& options) {
    if (options.calibrationRule) return *options.calibrationRule;
    return resolvedKeyErrorNorm(options) == KeyErrorNorm::Predicted ? CalibrationRule::Threshold
                                                                    : CalibrationRule::MaxRatio;
}

Model train(const FrameSet& frames, const TrainingOptions& options, TrainingReport* reportOut) {
    validateFrames(frames);
    if (options.sharedChannels && frames.channels > 1) {
        FrameSet copy = frames;  // the channel frames are made from a copy: the caller keeps its frames
        return trainSharedChannels(std::move(copy), options, reportOut);
    }
    MatrixBlocks q(frames);
    SingleProcess one;
    return train(q, one, options, reportOut);
}

Model train(FrameSet&& frames, const TrainingOptions& options, TrainingReport* reportOut) {
    validateFrames(frames);
    if (options.sharedChannels && frames.channels > 1)
        return trainSharedChannels(std::move(frames), options, reportOut);
    MatrixBlocks q(std::move(frames));
    SingleProcess one;
    return train(q, one, options, reportOut);
}

Model train(RowBlocks& q, Communicator& comm, const TrainingOptions& options, TrainingReport* reportOut) {
    const auto start = std::chrono::steady_clock::now();
    TrainingReport localReport;
    TrainingReport& report = reportOut ? *reportOut : localReport;
    report = TrainingReport{};
    report.ranks = comm.size();
    report.blockPoints = q.blockPoints();
    checkTrainingInput(q, comm, options);

    Trainer t(q, comm, options, report);
    t.meanAndGram();
    t.subspace();
    t.chooseBasisSize();
    // --- Key points (section 4).
    if (options.selector == Selector::Teleconnection) {
        t.teleconnectionKeys();
    } else {
        t.qdeimKeys();
    }
    t.releaseLeftVectors();
    if (static_cast<Index>(t.keys.size()) < options.maxKeys && options.maxError <= 0) {
        report.warnings.push_back("selected " + std::to_string(t.keys.size()) + " keys of the budget " +
                                  std::to_string(options.maxKeys) +
                                  ": no further candidate improved the basis");
    }
    t.projector();
    t.thresholds();
    if (options.learnRank > 0 || options.learnable) t.learningState();

    // --- The (N*C)-row arrays go to rank 0, which writes the model.
    // One process: the model takes the basis's storage (a copy would be N*C x M more at the peak).
    t.model.basis = comm.size() == 1 ? std::move(t.basis) : gatherRowsTo(comm, t.basis, t.rows, 0);
    t.model.mean = gatherRowsTo(comm, q.mean(), t.rows, 0);
    if (options.regions.count > 0 || options.regions.automatic) t.regions();
    if (options.clampAtZero) t.nonNegative();
    if (comm.rank() == 0) t.keyNeighbours();
    if (comm.rank() == 0) t.sentinels();
    if (comm.rank() == 0) t.model.validate();
    report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return std::move(t.model);
}

}  // namespace pmsc
