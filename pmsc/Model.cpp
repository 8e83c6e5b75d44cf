#include "pmsc/Model.h"

#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace pmsc {

namespace {

[[noreturn]] void invalid(const std::string& what) { throw std::invalid_argument("model: " + what); }

bool allFinite(const Eigen::Ref<const Eigen::MatrixXd>& m) { return m.allFinite(); }

}  // namespace

const char* toString(KeyErrorNorm norm) {
    switch (norm) {
        case KeyErrorNorm::Largest:
            return "largest";
        case KeyErrorNorm::LeaveOneOut:
            return "loo";
        case KeyErrorNorm::Predicted:
            return "predicted";
        case KeyErrorNorm::Rms:
            break;
    }
    return "rms";
}

const char* describe(KeyErrorNorm norm) {
    switch (norm) {
        case KeyErrorNorm::Largest:
            return "largest key error";
        case KeyErrorNorm::LeaveOneOut:
            return "largest leave-one-out key error";
        case KeyErrorNorm::Predicted:
            return "predicted point error";
        case KeyErrorNorm::Rms:
            break;
    }
    return "key RMS error";
}

std::optional<KeyErrorNorm> keyErrorNormNamed(std::string_view name) {
    for (KeyErrorNorm n :
         {KeyErrorNorm::Predicted, KeyErrorNorm::Rms, KeyErrorNorm::Largest, KeyErrorNorm::LeaveOneOut})
        if (name == toString(n)) return n;
    return std::nullopt;
}

double predictedPointError(PredictedParts error, PredictedParts eps, double tolerance) {
    if (std::isnan(error.rms) || std::isnan(error.loo)) return std::numeric_limits<double>::quiet_NaN();
    const auto over = [](double e, double threshold) {
        if (threshold > 0) return e / threshold;
        return e > 0 ? std::numeric_limits<double>::infinity() : 0.0;
    };
    return tolerance * std::min(over(error.rms, eps.rms), over(error.loo, eps.loo));
}

bool partsDisagree(PredictedParts error, PredictedParts eps) {
    if (std::isnan(error.rms) || std::isnan(error.loo)) return false;
    return (error.rms <= eps.rms) != (error.loo <= eps.loo);
}

double Model::energyCaptured() const {
    // An all-zero training set has nothing to capture; reporting 1 keeps "fraction captured"
    // meaningful (nothing was lost) instead of dividing by zero.
    if (!(totalEnergy > 0)) return 1.0;
    return singularValues.squaredNorm() / totalEnergy;
}

void Model::validate() const {
    if (points <= 0) invalid("point count must be positive, got " + std::to_string(points));
    if (channels <= 0) invalid("channel count must be positive, got " + std::to_string(channels));
    if (trainFrames < 0) invalid("negative training frame count " + std::to_string(trainFrames));
    const Index rows = points * channels;
    if (mean.size() != rows) {
        invalid("mean has " + std::to_string(mean.size()) +
                " values, expected N*C = " + std::to_string(rows));
    }
    const Index basisRows = points * basisChannels();
    if (basis.rows() != basisRows) {
        invalid("basis has " + std::to_string(basis.rows()) + " rows, expected " +
                (sharedChannels ? "N = " : "N*C = ") + std::to_string(basisRows));
    }
    const Index m = basis.cols();
    if (m < 1) invalid("basis is empty (M = 0)");
    if (singularValues.size() != m) {
        invalid("singular values count " + std::to_string(singularValues.size()) +
                " differs from basis size M = " + std::to_string(m));
    }
    if (!(totalEnergy >= 0) || !std::isfinite(totalEnergy)) {
        invalid("total energy must be finite and >= 0, got " + std::to_string(totalEnergy));
    }
    if (keyPoints.empty()) invalid("no key points");
    std::vector<char> seen(static_cast<size_t>(points), 0);
    for (size_t i = 0; i < keyPoints.size(); ++i) {
        const Index p = keyPoints[i];
        if (p < 0 || p >= points) {
            invalid("key point #" + std::to_string(i) + " = " + std::to_string(p) + " is outside [0, " +
                    std::to_string(points) + ")");
        }
        if (seen[static_cast<size_t>(p)]) invalid("key point " + std::to_string(p) + " repeated");
        seen[static_cast<size_t>(p)] = 1;
    }
    const Index kc = keyCount() * basisChannels();
    if (projector.rows() != m || projector.cols() != kc) {
        invalid("projector is " + std::to_string(projector.rows()) + " x " +
                std::to_string(projector.cols()) + ", expected " +
                (sharedChannels ? "M x K = " : "M x K*C = ") + std::to_string(m) + " x " +
                std::to_string(kc));
    }
    if (sharedChannels && (regions || learning || cross)) {
        invalid(std::string("a model whose channels share the basis has no ") +
                (regions    ? "regions (local fail-through)"
                 : learning ? "learning state (pmsc learn)"
                            : "cross section") +
                " in this version");
    }
    if (selector != Selector::Teleconnection && selector != Selector::QDeim) {
        invalid("unknown selector " + std::to_string(static_cast<int>(selector)));
    }
    if (!std::isfinite(epsMin) || !std::isfinite(epsMax) || epsMin < 0 || epsMax < epsMin) {
        invalid("soft-cache thresholds must satisfy 0 <= eps_min <= eps_max, got [" + std::to_string(epsMin) +
                ", " + std::to_string(epsMax) + "]");
    }
    if (!std::isfinite(tolerance) || tolerance < 0) {
        invalid("tolerance must be finite and >= 0, got " + std::to_string(tolerance));
    }
    if (keyErrorNorm == KeyErrorNorm::Predicted) {
        if (!(tolerance > 0)) invalid("the predicted key error needs a calibration tolerance");
        if (sharedChannels) invalid("the predicted key error needs channels of their own");
        if (!std::isfinite(partEps.rms) || !std::isfinite(partEps.loo) || partEps.rms < 0 || partEps.loo < 0)
            invalid("the predicted key error's part thresholds must be finite and >= 0, got [" +
                    std::to_string(partEps.rms) + ", " + std::to_string(partEps.loo) + "]");
    }
    if (!allFinite(mean)) invalid("mean contains NaN or Inf");
    if (!allFinite(basis)) invalid("basis contains NaN or Inf");
    if (!singularValues.allFinite()) invalid("singular values contain NaN or Inf");
    if (!allFinite(projector)) invalid("projector contains NaN or Inf");
    if (regions) regions->validate(*this);
    if (keyNeighbours) keyNeighbours->validate(*this);
    if (sentinels) sentinels->validate(*this);
    if (learning) learning->validate(rows, m, points);
    if (calibrationRecord) calibrationRecord->validate();
}

Eigen::MatrixXd gatherKeyRows(const Eigen::Ref<const Eigen::MatrixXd>& m, Index channels,
                              const std::vector<Index>& keyPoints) {
    const Index k = static_cast<Index>(keyPoints.size());
    Eigen::MatrixXd out(k * channels, m.cols());
    for (Index j = 0; j < m.cols(); ++j) {
        for (Index i = 0; i < k; ++i) {
            const Index row = keyPoints[static_cast<size_t>(i)] * channels;
            for (Index c = 0; c < channels; ++c) out(i * channels + c, j) = m(row + c, j);
        }
    }
    return out;
}

Eigen::MatrixXd makeProjector(const Eigen::MatrixXd& basis, Index channels,
                              const std::vector<Index>& keyPoints) {
    // Decision: pinv(B_K) by a complete orthogonal decomposition rather than normal equations
    // (B_K^T B_K squares the condition number) or an SVD (slower, same answer). When the key
    // system cannot determine every coordinate (K*C < M or dependent keys), the COD's
    // pseudo-inverse gives the minimum-norm coordinates, which is what training wants while
    // keys are still being added; the final model is checked for determinacy by train().
    const Eigen::MatrixXd bk = gatherKeyRows(basis, channels, keyPoints);
    Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod(bk);
    return cod.pseudoInverse();
}

}  // namespace pmsc
