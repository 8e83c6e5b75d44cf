// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include <optional>
#include <string_view>

namespace pmsc {

/// How the key points' residual becomes the one number the soft cache compares with eps
/// (section 5's "error at the key points"). Both are in data units, like a point error.
enum class KeyErrorNorm : int {
    /// RMS over the key points of each key's Euclidean residual over its channels: the paper's
    /// measure and `pmsc train`'s default (docs/calibration.md: with it and the largest-ratio rule
    /// the face's novel controls never hit; the largest key trades a little of that margin for
    /// hits on motion capture).
    Rms = 0,
    /// The largest key's Euclidean residual (`--key-error largest`, for models whose channels do
    /// not share the basis). Why it exists: the soft cache promises a bound on the largest POINT
    /// error, and an error confined to a few points (a limb or a lip the training never moved
    /// that way) shows at the few keys near it; the RMS divides it by sqrt(K / keys that see it),
    /// so the ratio point error / key error varies with how local the error is, and the
    /// calibration must take the most local case for every frame. Measured on motion capture
    /// (docs/calibration.md): held-out ratio spread p50..max 3.5..12.9 for the RMS against
    /// 1.1..1.9 for the largest key, and the largest key calibrated on held-out range-of-motion
    /// slices still bounds the real takes' errors.
    Largest = 1,
    /// The largest key's leave-one-out residual (`--key-error loo`, for models whose channels do
    /// not share the basis): each key row's residual divided by 1 - h, h its leverage (the
    /// diagonal of the key rows' hat matrix B_K pinv(B_K)), then the largest Euclidean norm over
    /// a key's channels. r / (1 - h) is exactly what that row would miss were it left out of the
    /// fit (PRESS). Why: the least-squares fit bends most towards high-leverage keys, so motion the
    /// basis never saw hides in their small residuals; undoing that makes the key error read like
    /// a point error the fit did not see. Measured (docs/calibration.md): with the `threshold`
    /// rule the quick face's novel frames stay under the tolerance where the largest key lets 11
    /// of them over it, and the motion-capture takes keep 96-100% of the best single threshold's
    /// hits at 3% of the diagonal.
    LeaveOneOut = 2,
    /// The predicted largest point error (`--key-error predicted`, `pmsc train --tolerance`'s
    /// default for models whose channels do not share the basis): T * min(e_rms / eps_rms,
    /// e_loo / eps_loo), the key RMS and the leave-one-out error each over its own calibrated
    /// threshold (Model::partEps; the RMS part by the largest held-out ratio, the leave-one-out part
    /// by the calibration rule, `threshold` unless told), so eps_min is T itself. A frame is a hit
    /// when either part certifies it. Why: each part is blind where the other sees. The RMS part
    /// alone throws away real motion capture's hits (one frame of each CMU take), the
    /// leave-one-out part alone loses the full face's validation hits to one held-out outlier;
    /// each was measured safe on the face's novel controls, so their union is (a frame over T
    /// would be over T under the part that certified it), and it keeps the larger hit count of
    /// the two on every case measured (docs/calibration.md).
    Predicted = 3,
};

/// KeyErrorNorm::Predicted's two parts: a key RMS and a largest leave-one-out key error, or the
/// thresholds each is compared with (data units).
struct PredictedParts {
    double rms = 0;
    double loo = 0;
};

/// KeyErrorNorm::Predicted of a frame whose parts are `error`: tolerance * min(error.rms / eps.rms,
/// error.loo / eps.loo), a part whose threshold is 0 certifying only a zero error (its ratio is 0
/// for a zero error, infinite otherwise). NaN in either part gives NaN (a miss).
double predictedPointError(PredictedParts error, PredictedParts eps, double tolerance);

/// KeyErrorNorm::Predicted: exactly one of the two parts `error` is at or under its threshold in
/// `eps`. Such a hit rests on one measure while the other says the frame is off what training
/// saw; on the novelty suite (docs/calibration.md) every hit over the tolerance at the defaults was
/// one (each part was fooled on one set of controls), so these hits are checked where the calculation runs
/// (HitCheck.h). False for NaN parts.
bool partsDisagree(PredictedParts error, PredictedParts eps);

/// "rms" / "largest" / "loo" / "predicted"
const char* toString(KeyErrorNorm norm);
/// What the command line prints for it: "key RMS error", "largest key error", "largest
/// leave-one-out key error", "predicted point error".
const char* describe(KeyErrorNorm norm);
/// The measure of a name ("predicted", "rms", "largest" or "loo"); std::nullopt for any other. The command
/// line and Python parse the same names with it, and list them in their messages as
/// kKeyErrorNormChoices.
std::optional<KeyErrorNorm> keyErrorNormNamed(std::string_view name);
constexpr const char* kKeyErrorNormChoices = "predicted, rms, largest or loo";

}  // namespace pmsc
