// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/BulkAllocator.h"
#include "pmsc/Model.h"

#include <span>
#include <vector>

namespace pmsc {

/// The numbers a reconstruction reads the basis in.
enum class BasisPrecision {
    /// The model's doubles: the reconstruction every test compares against, and what a batch
    /// path whose output is double (.npy float64, the Python and C APIs) reads.
    Double,
    /// A float copy: half the memory a hit reads, the bound on its time for a large cache; sums
    /// are still accumulated in double. Values differ from Double's by about 1e-7 relative, the
    /// rounding of a float itself: for outputs stored in float (.vdb, .npy float32, `pmsc run`'s
    /// default there) and clients that display (`pmsc view` sends halves). The copy adds half
    /// the basis's bytes to the memory a model holds.
    Single,
    /// No copy: projecting, the key errors and reconstructPoints() read the model's own basis;
    /// reconstruct() and reconstructRange() throw std::logic_error. For a caller that measures
    /// whole frames in slabs of points (training's residual on its own frames, where a copy of a
    /// million points' basis was the peak's last 312 MB).
    None,
};

/// Sets the negative values of `values` (count of them) to 0, leaving NaN as it is: what every
/// reconstruction of a Model::nonNegative model applies to its output.
void clampAtZero(double* values, Index count);

/// The runtime of point multiplication (section 6): key values -> pose-space
/// coordinates by the precomputed least-squares projector, the key points'
/// residual, and the reconstruction of any set of points.
///
/// Thread safety: all methods are const and may run concurrently.
/// Buffers: key values are K*C doubles in model key order, channel-minor;
/// coordinates are Model::coordCount() doubles (M, or M x C channel-minor when the channels
/// share the basis); point values are channel-minor.
class PointMultiplier {
public:
    /// Keeps a reference to `model`, which must outlive this object.
    explicit PointMultiplier(const Model& model, BasisPrecision precision = BasisPrecision::Double);

    const Model& model() const { return model_; }

    /// Pose-space coordinates b = P (k - mean_K).
    void project(const double* keyValues, double* coords) const;

    /// The model's key error (Model::keyErrorNorm): the RMS over key points, or the largest, of
    /// the Euclidean norm (over channels) of each key's residual k - (mean_K + B_K b), each key row
    /// first divided by 1 - its leverage for KeyErrorNorm::LeaveOneOut; for KeyErrorNorm::Predicted
    /// both the RMS and the leave-one-out error, combined by predictedPointError. Data units.
    /// Returns NaN if any key value is not finite. `parts`, when given and the model's key error is
    /// KeyErrorNorm::Predicted, gets the two raw parts (the key RMS and the largest leave-one-out
    /// key error) the error was combined from (partsDisagree tells whether both certify).
    double keyError(const double* keyValues, const double* coords, PredictedParts* parts = nullptr) const;

    /// Each key's residual (K doubles): the Euclidean norm over its channels of k - (mean_K + B_K b),
    /// each row divided by 1 - its leverage when the model's key error reads leave-one-out
    /// residuals (KeyErrorNorm::LeaveOneOut, Predicted). For models whose channels do not share
    /// the basis. NaN for a key with a non-finite value.
    void keyResiduals(const double* keyValues, const double* coords, double* perKey) const;

    /// All N points: out = mean + B b (N*C doubles), clamped at 0 for a Model::nonNegative model
    /// (as every reconstruction below).
    void reconstruct(const double* coords, double* out) const;

    /// Only the given points (a query by point subset): out[i*C + c].
    void reconstructPoints(const double* coords, std::span<const Index> points, double* out) const;

    /// The largest Euclidean point error (over channels) of the reconstruction at `points` against
    /// their computed `values` (points.size()*C): a direct measure of PM's error where the calculation
    /// ran. NaN if a value is not finite.
    double largestErrorAt(const double* coords, std::span<const Index> points, const double* values) const;

    /// Points [first, first+count) into out (count*C doubles): one chunk.
    void reconstructRange(const double* coords, Index first, Index count, double* out) const;

private:
    const Model& model_;
    Eigen::VectorXd keyMean_;           // K*C
    Eigen::MatrixXd keyBasis_;          // (K*C) x M; K x M when the channels share the basis
    Eigen::VectorXd projectedKeyMean_;  // M (or M x C): P mean_K, so project() needs no temporary
    BasisPrecision precision_;          // which copy of the basis reconstruct() reads, if any
    // The basis in panels of rows (PointMultiplier.cpp): BasisPrecision::Double's, or Single's
    // (either layout) in float. As large as the basis: BulkAllocator's pages.
    std::vector<double, BulkAllocator<double>> panels_;
    std::vector<float, BulkAllocator<float>> singlePanels_;
    Eigen::VectorXd looScale_;  // KeyErrorNorm::LeaveOneOut: 1 / (1 - leverage) per key row
};

/// PM at `points`, which index the rows of `mean` (C values a point) and `basis` (column-major:
/// C rows a point, or one with shared channels): mean + basis * coords at each point, clamped at 0
/// when `nonNegative`, summed basis vector by basis vector. PointMultiplier::reconstructPoints on
/// the model's rows, and the hit check on its sentinels' rows gathered once (HitCheck), so both
/// compute the same values to the bit.
void reconstructAt(const Eigen::VectorXd& mean, const Eigen::MatrixXd& basis, Index channels,
                   bool sharedChannels, bool nonNegative, const double* coords, std::span<const Index> points,
                   double* out);

}  // namespace pmsc
