// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Communicator.h"
#include "pmsc/FrameSet.h"
#include "pmsc/KeyError.h"
#include "pmsc/RowBlocks.h"
#include "pmsc/Subspace.h"

#include <Eigen/Core>

#include <optional>
#include <string>
#include <vector>

namespace pmsc {

/// How calibration turns the held-out frames' scores (key error e_f, largest point error E_f) into
/// the ratio r of the bound E <= r e, and so eps_min = T / r.
enum class CalibrationRule : int {
    /// r = max_f E_f / e_f. Promise: every held-out frame under eps_min had
    /// E <= T. One extreme pose sets r for every frame, so on real motion it throws hits away.
    MaxRatio = 0,
    /// r = the split-conformal quantile of E_f / e_f at `coverage` 1 - alpha: the
    /// ceil((n + 1)(1 - alpha))-th smallest of the n held-out ratios (Vovk, Gammerman & Shafer
    /// 2005; Lei et al. 2018). Promise: for a frame exchangeable with the held-out frames,
    /// P(E > r e) <= alpha, so P(a frame is a hit or a blend AND its soft-cached error exceeds T)
    /// <= alpha (a hit has e <= T / r; a blend's (1 - w) E stays under T when E <= r e, as for
    /// MaxRatio). With n < 1/alpha - 1 the quantile does not exist and r = the largest ratio.
    Conformal = 1,
    /// The held-out frames' own best threshold where they show it, the linear bound where they do
    /// not: eps_min = the largest held-out key error e_f such that every held-out frame with a key
    /// error at or below it had E <= T, kept between the MaxRatio answer (T / max E/e, which no
    /// held-out frame over T is below) and the Conformal one (T / the ratios' quantile at
    /// `coverage`, a margin for frames the held-out ones did not show); when no held-out frame
    /// exceeded T, the MaxRatio answer. Why: within the errors
    /// the held-out frames reached, their own crossing says where hits stop being safe; beyond
    /// them only the worst ratio seen is a bound, since the ratio does not change with an error's
    /// size (a blind motion at small amplitude predicts it at large amplitude). Measured
    /// (docs/calibration.md): with the largest key, on real motion capture replayed through a
    /// range-of-motion model it gets 78-100% of the best single threshold's hits from 2% of the
    /// diagonal, where MaxRatio on the key RMS gets 0-65%; on the face demo's full training it
    /// keeps the novel controls out, on its quick training (fewer frames) it lets half of them hit,
    /// which is why it is not the default.
    Threshold = 2,
};

/// "max" / "conformal" / "threshold"
const char* toString(CalibrationRule rule);

/// The rule a name gives ("max", "conformal", "threshold"), or nothing.
std::optional<CalibrationRule> calibrationRuleNamed(const std::string& name);
/// The names calibrationRuleNamed takes, as the command line and Python list them in messages.
constexpr const char* kCalibrationRuleChoices = "threshold, max or conformal";

/// What calibration measured, so a user (and `pmsc train`) can see why eps came out as it did.
struct CalibrationStats {
    double epsMin = 0;
    double epsMax = 0;
    double tolerance = 0;  ///< T; 0 for the uncalibrated rule
    /// r = max_f E_f / e_f over held-out frames with a usable key error: the linear bound E <= r e.
    double ratio = 0;
    Index slices = 0;
    CalibrationRule rule = CalibrationRule::MaxRatio;
    double coverage = 0;                ///< 1 - alpha of the conformal rule; 0 for MaxRatio
    double maxRatio = 0;                ///< max_f E_f / e_f, whatever the rule (the MaxRatio answer)
    Index usableFrames = 0;             ///< n: held-out frames whose ratio entered the rule
    double band = 2;                    ///< eps_max / eps_min (blendBand)
    std::vector<Index> frames;          ///< held-out frame indices, ascending
    std::vector<double> keyRms;         ///< e_f: key RMS error of each held-out frame
    std::vector<double> maxPointError;  ///< E_f: largest point error of PM on it
    /// KeyErrorNorm::Predicted: each held-out frame's largest leave-one-out key error (keyRms holds
    /// its key RMS until setPredictedThresholds combines the two into the predicted error).
    std::vector<double> keyLoo;
    /// KeyErrorNorm::Predicted, after setPredictedThresholds: the thresholds of the two parts and
    /// each part's own calibration (parts[0] the key RMS by MaxRatio, parts[1] the leave-one-out
    /// error by the rule), whose keyRms are the raw part errors.
    PredictedParts partEps;
    std::vector<CalibrationStats> parts;
    /// Held-out frames whose key error is rounding noise (e_f <= 1e-9 max E) while E_f is not:
    /// errors the key monitor cannot see (typically K*C == M).
    Index blindFrames = 0;
    std::vector<std::string> notes;  ///< decisions worth a warning
};

/// Calibrates the soft-cache thresholds for a largest point error `tolerance` T (beyond the
/// paper, whose authors picked eps by hand; see section 5).
///
/// Leave-one-slice-out over `slices` contiguous slices of frames. Contiguous because neighbouring
/// frames are correlated: holding out a slice approximates holding out a whole sequence, as a
/// random split would not. For each slice the mean and the M-basis are recomputed from the other
/// frames, the keys are kept, and each held-out frame f gives its key RMS e_f
/// (PointMultiplier::keyError) and the largest point error E_f of PM.
///
/// Model: E <= r e with r = max_f E_f / e_f. eps_min = T / r, so every held-out frame under
/// eps_min had error <= T. eps_max = 2 eps_min: under the same bound the soft-cached error
/// (1 - w) r e with w = (e - eps_min)/(eps_max - eps_min) is largest at e = eps_min whenever
/// eps_max <= 2 eps_min, so 2 is the widest blend zone that still keeps blends under T.
///
/// Speed: with `gram` = Q^T Q (F x F) each fold's SVD comes from the held-in block of it,
/// centred in frame space (J G_II J with J = I - 11^T/n: the held-in mean removed without
/// touching the (N*C)-row data), and U = Q_I J V S^-1 is one product: no per-fold copy of Q and no
/// per-fold (N*C) x F^2 Gram product.
/// The ratio r comes from the held-out scores by `rule` (setThresholds); MaxRatio by default.
/// @param q training matrix (N*C) x F, raw or mean-removed (means are recomputed per fold)
/// @param basisSize M (capped per fold by the held-in rank, with a note)
/// @param gram Q^T Q of exactly this q, or null
/// @throws std::invalid_argument unless tolerance > 0, 2 <= slices <= F and 0 < coverage < 1.
CalibrationStats calibrate(const Eigen::Ref<const Eigen::MatrixXd>& q, Index channels,
                           const std::vector<Index>& keys, Index basisSize, double tolerance, Index slices,
                           const SvdOptions& svd = {}, const Eigen::MatrixXd* gram = nullptr,
                           CalibrationRule rule = CalibrationRule::MaxRatio, double coverage = 0.9,
                           KeyErrorNorm norm = KeyErrorNorm::Rms);

/// The width eps_max / eps_min of the blend band from the held-out ratios and the rule's ratio r:
/// r / (their median), within [1.5, 2] (the reasons are next to the code); 2 without ratios.
double blendBand(std::vector<double> ratios, double ratio);

/// KeyErrorNorm::LeaveOneOut's factor per key row: 1 / (1 - h), h = the row's leverage, the diagonal
/// of bk * projector (bk: the key rows of the basis, projector: pinv(bk)). 1 - h is kept at least
/// kMinOneMinusLeverage: a row the fit passes through exactly (h = 1) would divide by zero.
Eigen::VectorXd leaveOneOutScale(const Eigen::MatrixXd& bk, const Eigen::MatrixXd& projector);
constexpr double kMinOneMinusLeverage = 1e-3;

/// The key error of one frame's key residual (K*C rows, key-major, channel-minor) by `norm`, as
/// PointMultiplier::keyError computes it at run time. `looScale` (leaveOneOutScale of the same
/// fit) is needed by KeyErrorNorm::LeaveOneOut alone. KeyErrorNorm::Predicted needs its parts'
/// thresholds: keyErrorParts, then predictedPointError (this throws std::invalid_argument for it).
double keyErrorOfResidual(const Eigen::Ref<const Eigen::VectorXd>& residual, Index channels,
                          KeyErrorNorm norm, const Eigen::VectorXd* looScale = nullptr);

/// Sets s.ratio, s.epsMin, s.epsMax (and s.rule, s.coverage, s.tolerance, s.maxRatio,
/// s.usableFrames, s.blindFrames, notes) from the held-out scores s.keyRms / s.maxPointError:
/// eps_min = T / r, eps_max = band * eps_min (blendBand), r by `rule` (CalibrationRule). Frames whose key
/// error is at rounding level (e <= 1e-9 max E) say nothing and are left out (counted as blind when their E >
/// 0). Used by calibrate() and by `pmsc learn`, which scores frames of its own.
/// @throws std::invalid_argument unless tolerance > 0 and 0 < coverage < 1 (Conformal).
void setThresholds(CalibrationStats& s, double tolerance, CalibrationRule rule, double coverage);

/// KeyErrorNorm::Predicted: calibrates its parts from the held-out scores s.keyRms (key RMS) and
/// s.keyLoo (leave-one-out), the key RMS by MaxRatio whatever `looRule` (the paper's linear bound,
/// the measure every case was measured safe with) and the leave-one-out error by `looRule`, then
/// sets s.partEps, s.parts, s.keyRms = each frame's predicted point error (predictedPointError),
/// eps_min = T (a frame is a hit when either part is at or under its threshold, so every held-out
/// frame at or under it was at or under T in the part that certified it), eps_max = the narrower of
/// the parts' bands times T, s.ratio = 1 and s.maxRatio = the largest E_f / predicted error.
/// @throws std::invalid_argument as setThresholds, or when keyLoo and keyRms differ in count
void setPredictedThresholds(CalibrationStats& s, double tolerance, CalibrationRule looRule, double coverage);

/// Appends one frame's key error by `norm` to s.keyRms, or for KeyErrorNorm::Predicted its two
/// parts (the key RMS and the largest leave-one-out key error, as keyErrorOfResidual computes
/// them) to s.keyRms and s.keyLoo: the held-out scores calibration and `pmsc learn` keep.
/// `looScale` as for keyErrorOfResidual (leaveOneOutScale when usesLeaveOneOut(norm)).
void appendKeyScore(CalibrationStats& s, const Eigen::Ref<const Eigen::VectorXd>& residual, Index channels,
                    KeyErrorNorm norm, const Eigen::VectorXd& looScale);
/// Whether `norm` reads the key rows' leverages (LeaveOneOut, Predicted).
inline bool usesLeaveOneOut(KeyErrorNorm norm) {
    return norm == KeyErrorNorm::LeaveOneOut || norm == KeyErrorNorm::Predicted;
}

/// Each frame's predicted point error (predictedPointError) from its raw parts `rms` and `loo`
/// (the same length) under the part thresholds `eps`.
std::vector<double> predictedErrors(const std::vector<double>& rms, const std::vector<double>& loo,
                                    PredictedParts eps, double tolerance);

/// The held-out ratios E_f / e_f that setThresholds() uses (frames with a usable key error).
std::vector<double> heldOutRatios(const CalibrationStats& s);

/// The conformal quantile of a sample: the ceil((n + 1) coverage)-th smallest value, or the
/// largest when that rank exceeds n (and +0 for an empty sample).
double conformalQuantile(std::vector<double> values, double coverage);

/// The calibration above over the rows this process owns (the one implementation: the
/// overload above wraps q in MatrixBlocks, computing Q^T Q when `gram` is null, so every fold
/// takes the frame-space route; `svd` is not used). One pass over q's blocks per fold; the
/// per-frame largest point errors are reduced over ranks.
/// @param keyRows Q's rows at the keys (K*C x F), the same q as `gram` (centred or not)
/// @param group   frames that belong together and stay in one slice: consecutive runs of
///                `group` columns (shared channels: the C channel frames of one frame; F must be
///                a multiple of it, and slices at most F / group). The returned stats have one
///                entry per group: e = sqrt(sum e^2), E = sqrt(sum E^2) over its members (the
///                frame's Euclidean key error and a bound on its Euclidean point error)
CalibrationStats calibrate(RowBlocks& q, Communicator& comm, const Eigen::MatrixXd& keyRows,
                           const std::vector<Index>& keys, Index basisSize, double tolerance, Index slices,
                           const Eigen::MatrixXd& gram, CalibrationRule rule = CalibrationRule::MaxRatio,
                           double coverage = 0.9, Index group = 1, KeyErrorNorm norm = KeyErrorNorm::Rms);

/// Key RMS error (PointMultiplier::keyError) of every column of a mean-removed matrix `q`
/// under the model's basis and key projector: e_t = sqrt((1/K) ||(I - B_K P) Q_K[:,t]||^2).
Eigen::VectorXd keyRmsPerFrame(const Eigen::Ref<const Eigen::MatrixXd>& q, const Eigen::MatrixXd& basis,
                               Index channels, const std::vector<Index>& keys,
                               const Eigen::MatrixXd& projector, KeyErrorNorm norm = KeyErrorNorm::Rms);

/// The uncalibrated rule (Training.h): eps_min = the largest key RMS seen on the training frames,
/// eps_max = 1.5 eps_min, the ratio of the paper's hand-picked [0.1, 0.15] (section 7).
CalibrationStats thresholdsFromTraining(const Eigen::Ref<const Eigen::MatrixXd>& q,
                                        const Eigen::MatrixXd& basis, Index channels,
                                        const std::vector<Index>& keys, const Eigen::MatrixXd& projector,
                                        KeyErrorNorm norm = KeyErrorNorm::Rms);

/// The two above from the key rows alone (Q_K: K*C x F, B_K: K*C x M), which is all they read:
/// the distributed training has them replicated on every rank.
Eigen::VectorXd keyRmsFromKeyRows(const Eigen::MatrixXd& qk, const Eigen::MatrixXd& bk, Index channels,
                                  const Eigen::MatrixXd& projector, KeyErrorNorm norm = KeyErrorNorm::Rms);
CalibrationStats thresholdsFromKeyRows(const Eigen::MatrixXd& qk, const Eigen::MatrixXd& bk, Index channels,
                                       const Eigen::MatrixXd& projector,
                                       KeyErrorNorm norm = KeyErrorNorm::Rms);

}  // namespace pmsc
