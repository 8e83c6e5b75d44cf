// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Calibration.h"
#include "pmsc/Communicator.h"
#include "pmsc/Errors.h"  // Cancelled
#include "pmsc/FrameSet.h"
#include "pmsc/Model.h"
#include "pmsc/RegionLearning.h"
#include "pmsc/RowBlocks.h"

#include <cstdint>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace pmsc {

/// Progress hook for long operations: (stage, done, total). Return false to
/// cancel (training then throws pmsc::Cancelled).
using ProgressFn = std::function<bool(std::string_view stage, double done, double total)>;

/// Everything `pmsc train` can set. Zero means "not set" where noted.
struct TrainingOptions {
    // --- subspace size M (section 3): the first of these that is set wins ---
    Index basis = 0;                ///< M explicitly
    double energy = 0;              ///< smallest M capturing this fraction of the energy, in (0, 1]
    double basisMaxError = 0;       ///< smallest M whose largest point projection error <= this (data units)
    Index maxBasis = 256;           ///< cap on M, whatever the rule (and the SVD's target rank)
    double defaultEnergy = 0.9999;  ///< used when none of the three above is set
    /// Bytes training may hold (per rank, trainingMemoryBound()); 0 = none. Once the Gram pass has
    /// told how many basis vectors the rule above needs, M is capped (with a warning) where the
    /// bound at M would pass it: the memory follows the basis the data need, not maxBasis.
    std::uint64_t memoryLimit = 0;

    // --- key points (section 4) ---
    Selector selector = Selector::Teleconnection;
    double maxError = 0;  ///< stop when the largest point residual on the training set <= this; 0 = off
    Index maxKeys = 200;  ///< key budget K
    Index block = 16;     ///< basis vectors per Varimax block (paper: 10 to 20)
    std::vector<Index> fiducials;   ///< designer points, seeded into the first batch
    std::vector<Index> gridPoints;  ///< sparse spatial grid of points (rendering), seeded too
    /// Only points [0, keyCandidates) may be keys; 0 = every point. Cross point multiplication
    /// (pmsc/Cross.h) trains on (control, target) pairs with the control's points first.
    Index keyCandidates = 0;

    // --- Varimax ---
    double varimaxTolerance = 1e-8;
    int varimaxMaxIterations = 200;

    // --- calibration of eps (beyond the paper) ---
    double tolerance = 0;         ///< largest point error a hit may have (data units); 0 = no calibration
    Index calibrationSlices = 5;  ///< leave-one-slice-out folds
    /// How the held-out ratios E/e become eps (Calibration.h). Unset: resolvedCalibrationRule.
    std::optional<CalibrationRule> calibrationRule;
    /// The key error eps apply to (Model::keyErrorNorm). Unset: resolvedKeyErrorNorm. The largest
    /// key, the leave-one-out error and the predicted error are for models whose channels do not
    /// share the basis (a shared-channel frame's C channel frames are calibrated as one, which a
    /// largest key does not allow). Local fail-through regions measure their keys by the RMS.
    std::optional<KeyErrorNorm> keyErrorNorm;
    double calibrationCoverage =
        0.9;  ///< 1 - alpha of CalibrationRule::Conformal (docs/learning-and-calibration.md: 0.9 measured)

    /// Points spread over what training saw move, computed beside every hit of a model with the
    /// predicted key error and point positions (Sentinels.h, HitCheck.h), at most one point in
    /// kSentinelSpacing (sentinelCount); 0 = none.
    Index sentinels = kDefaultSentinels;
    /// When every training value is >= 0, the model's output is clamped at 0 (Model::nonNegative).
    /// Why on by default: a quantity that never went negative in training (light, density) cannot
    /// be negative, and max(PM, 0) is then never further from the truth than PM. On the quick light
    /// novelty suite the one frame over T without it is a point where a light outside the trained
    /// range makes PM ring to -0.83 where the light is 0.14; with it, none (docs/calibration.md).
    /// false: PM stays linear (a quantity that may go negative on frames training never saw).
    bool clampAtZero = true;

    // --- learning from misses (`pmsc learn`) ---
    /// r > 0: store what `pmsc learn` needs in the model (Model::learning: the left singular
    /// vectors M+1 .. r and the key-selection settings; Model::calibrationRecord: the held-out
    /// scores), so updates lose only the energy beyond rank r. 0 = a plain model.
    /// @pre 0 or >= the final M (it is raised to M with a warning otherwise).
    Index learnRank = 0;
    /// Store what `pmsc learn` needs even with learnRank 0: the key-selection settings, the rule M
    /// was chosen by and the held-out calibration scores (section LEARNING without extra vectors:
    /// a few kilobytes, learn rank M). Why: without them `pmsc learn` keeps M fixed and calibrates
    /// from the new frames alone, and on a take whose second half moves controls the first half
    /// left still its point error p99.5 came out 1.6x retraining's (docs/learning-and-calibration.md).
    /// `pmsc train`'s default (app::defaultTrainingOptions); ignored with sharedChannels.
    bool learnable = false;

    // --- channels ---
    /// The channels share one basis over the points (Model::sharedChannels): training sees each
    /// channel of each frame as a frame of its own (F*C columns of N rows, each point-channel's
    /// mean removed), so M vectors of N values serve every channel. For light (RGB): a light's
    /// colour is reproduced exactly (when the training varies colour or intensity: Model.h) and
    /// reconstruction reads N*M values instead of N*C*M. Keys
    /// are points as before. eps are calibrated per frame, not per channel frame: a frame's
    /// channels stay in one calibration slice (calibrationGroup), and each held-out frame has one
    /// ratio, the bound sqrt(sum_c E_c^2) on its Euclidean point error over its Euclidean key
    /// error (PointMultiplier::keyError, what the runtime compares with eps), so the conformal
    /// rule's coverage counts frames; without a tolerance eps are the training frames' largest
    /// Euclidean key error.
    /// In memory and on one process only, without regions, learning or cross targets.
    bool sharedChannels = false;
    /// Consecutive training frames that stay together in one calibration slice (set by the
    /// shared-channel training to C, so no frame's channels are held in and out at once); 1 =
    /// every frame on its own. The frame count must be a multiple of it.
    Index calibrationGroup = 1;

    // --- local fail-through: regions.count = 0 keeps the model a version-1 model ---
    RegionOptions regions;

    // --- SVD ---
    unsigned seed = 20070101;  ///< randomized SVD test matrices; training is deterministic for a seed
    int powerIterations = 2;

    ProgressFn progress;  ///< optional
};

/// What training did besides the model: decisions a user must hear about.
struct TrainingReport {
    std::vector<std::string> warnings;  ///< e.g. "reduced M from 40 to 30: ..."
    Index requestedBasis = 0;           ///< M before any reduction
    Index iterations = 0;               ///< key-selection rounds
    double seconds = 0;
    /// Largest point residual on the training set after each round (data units).
    std::vector<double> residualPerRound;
    /// How eps was set: the calibration's ratio r and per-frame key RMS / largest point error on
    /// held-out frames (options.tolerance > 0), or the training frames' key RMS otherwise.
    CalibrationStats calibration;
    int ranks = 1;          ///< processes the rows of Q were split across (MPI ranks)
    Index blockPoints = 0;  ///< points per block of Q read at a time (this rank)
    /// trainingMemoryBound() at the basis vectors formed (max(M, block, learn rank)), rank 0's.
    std::uint64_t memoryBound = 0;
    /// RegionOptions::automatic: the regions chosen and why (RegionChoice::reason); empty otherwise.
    std::string regions;
};

/// The key error a training with `options` gives its model: the options' own, else
/// KeyErrorNorm::Predicted for a calibrated model (tolerance > 0) whose channels do not share the
/// basis, else the RMS. Decision (docs/calibration.md): the predicted error finds 96-100% of the
/// best single threshold's hits on real motion capture at 3% of the diagonal where the RMS finds
/// one frame per take, and keeps every hit of the RMS on the face with its novel controls out.
KeyErrorNorm resolvedKeyErrorNorm(const TrainingOptions& options);
/// The calibration rule: the options' own, else Threshold for the predicted error (the rule of its
/// leave-one-out part; its RMS part is always MaxRatio) and MaxRatio for the other measures.
CalibrationRule resolvedCalibrationRule(const TrainingOptions& options);

/// Trains a model from frames: mean removal, truncated SVD, key-point selection,
/// projector, and eps. With options.tolerance > 0, eps is calibrated by
/// leave-one-slice-out (Calibration.h). Without it, epsMin is the largest key
/// RMS error seen on the training frames and epsMax = 1.5 x epsMin (the ratio of
/// the paper's hand-picked [0.1, 0.15]); `pmsc replay --eps` can override both.
/// @throws std::invalid_argument for unusable data or options (message names the value).
/// @throws pmsc::InputError (also bad input, exit code 2 on the command line) for training data
///         that cannot be used: a NaN or Inf (message names frame, point and channel), fewer than
///         2 frames, or frames that do not vary.
Model train(const FrameSet& frames, const TrainingOptions& options, TrainingReport* report = nullptr);
/// The same, consuming `frames` (left empty): the training matrix is centred where the frames
/// lie, so training holds one copy of them fewer (a frame set of many points is most of the
/// memory training needs). Channels sharing the basis make their channel frames where the
/// frames lie too.
Model train(FrameSet&& frames, const TrainingOptions& options, TrainingReport* report = nullptr);

/// Training over the rows of Q this process owns: the one implementation, which the
/// overload above runs on one in-memory block. Out of core (NpyBlocks) every product with Q is a
/// pass over its blocks; under MPI (a Communicator of P ranks) each rank owns a contiguous share
/// of the points and every reduction (Gram matrix, Varimax sums, the key arg-max, residual and
/// calibration maxima) goes through `comm`, so all ranks take the same decisions.
///
/// Memory bound (per rank; trainingMemoryBound() in RowBlocks.h computes it), in doubles, with
/// F frames, r = min(max(max basis, block), F), B the Varimax block, K the key budget, R the owned
/// rows (N*C/P) and b the rows of one block of Q:
///   5 F^2 (Q^T Q, its eigensolver, a round's residual Gram)  + 3 r F  (V, B^T Q, coordinates)
///   + 2 R r (U and the basis) + 4 R B (Varimax block, its rotation, the next block)
///   + K C (F + r) (key rows of Q and of the basis) + 3 b F (the block read, a residual block)
///   + on rank 0: 3 N C (r + 1) (the gathered basis and mean, the model written)
/// plus N bytes of key flags; in memory (one block of every row) also N C F, the frames themselves.
/// Streaming, nothing is of size N*C*F: a training set far larger than memory trains as long as
/// this fits.
///
/// The returned model is complete on rank 0 only: the other ranks' model has no mean and basis
/// (they are gathered to rank 0).
Model train(RowBlocks& q, Communicator& comm, const TrainingOptions& options,
            TrainingReport* report = nullptr);

}  // namespace pmsc
