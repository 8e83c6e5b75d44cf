// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Calibration.h"
#include "pmsc/FrameSet.h"

#include <Eigen/Core>

#include <vector>

namespace pmsc {

/// What `pmsc learn` needs to update a model without its training frames (stored as
/// the model file's "LEARNSVD" section by `pmsc train --learn-rank R`).
///
/// The model's own mean, basis (M vectors), singular values, frame count and total energy are
/// the first M triplets of an IncrementalSubspace (IncrementalSvd.h); this holds the rest: the
/// next r - M left singular vectors of the training frames, so an update loses only the energy
/// beyond rank r instead of everything beyond M, and the settings to select keys again the same
/// way.
struct LearningState {
    Index maxRank = 0;           ///< r: the rank the state is kept at (>= M)
    Eigen::MatrixXd extraBasis;  ///< (N*C) x (r' - M), r' <= r: left singular vectors M+1 .. r'
    Eigen::VectorXd extraSigma;  ///< their singular values, descending, below the model's last
    double discardedEnergy = 0;  ///< sum of sigma^2 dropped by updates' truncations to r
    Index updates = 0;           ///< how many `pmsc learn` updates the model has had

    // --- key selection settings (TrainingOptions; the selector is Model::selector) ---
    Index maxKeys = 0;
    Index block = 16;
    double maxError = 0;
    std::vector<Index> fiducials;
    std::vector<Index> gridPoints;

    // --- basis size rule (TrainingOptions) ---
    /// The energy fraction the training chose M by (--energy, or the default energy rule), so that
    /// an update chooses M again by the same rule on all frames seen; 0 = M was fixed (--basis,
    /// --basis-max-error, or a file that does not store the rule): updates keep it.
    double basisEnergy = 0;

    /// Checks sizes against the model's N*C and M; throws std::invalid_argument.
    void validate(Index rows, Index basisSize, Index points) const;
};

/// The held-out scores eps were calibrated from, and how (the "CALIBRAT" section): so that
/// `pmsc learn` can re-calibrate by the same rule with its new frames' scores added, and
/// `pmsc inspect` can show them.
struct CalibrationRecord {
    CalibrationRule rule = CalibrationRule::MaxRatio;
    double coverage = 0;         ///< Conformal only
    Index slices = 0;            ///< leave-one-slice-out folds of the training (0 = none)
    std::vector<double> keyRms;  ///< e_f of each held-out frame (the key RMS part for Predicted)
    /// KeyErrorNorm::Predicted: each held-out frame's leave-one-out part (empty otherwise).
    std::vector<double> keyLoo;
    std::vector<double> maxPointError;  ///< E_f of each held-out frame

    static CalibrationRecord from(const CalibrationStats& s);
    /// The stored scores as held-out scores (keyRms, keyLoo, maxPointError) for setThresholds or
    /// setPredictedThresholds.
    CalibrationStats scores() const;
    /// Adds the raw scores of more held-out frames (keyRms, keyLoo when the record keeps them,
    /// maxPointError), as calibrate() or `pmsc learn`'s cross-fitting gives them.
    void append(const CalibrationStats& raw);
    void validate() const;
};

}  // namespace pmsc
