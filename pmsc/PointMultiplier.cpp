#include "pmsc/PointMultiplier.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace pmsc {

PointMultiplier::PointMultiplier(const Model& model) : model_(model) {
    model_.validate();
    const Eigen::Map<const Eigen::MatrixXd> meanColumn(model_.mean.data(), model_.mean.size(), 1);
    keyMean_ = gatherKeyRows(meanColumn, model_.channels, model_.keyPoints).col(0);
    keyBasis_ = gatherKeyRows(model_.basis, model_.channels, model_.keyPoints);
    // b = P (k - mean_K) = P k - P mean_K: precomputing P mean_K lets project() write straight
    // into the caller's buffer with one GEMV and no temporary.
    projectedKeyMean_ = model_.projector * keyMean_;
}

void PointMultiplier::project(const double* keyValues, double* coords) const {
    const Index kc = keyMean_.size();
    const Index m = model_.basisSize();
    Eigen::Map<const Eigen::VectorXd> k(keyValues, kc);
    Eigen::Map<Eigen::VectorXd> b(coords, m);
    b.noalias() = model_.projector * k;
    b -= projectedKeyMean_;
}

double PointMultiplier::keyRmsError(const double* keyValues, const double* coords) const {
    const Index kc = keyMean_.size();
    const Index m = model_.basisSize();
    const Index keys = model_.keyCount();
    for (Index i = 0; i < kc; ++i) {
        if (!std::isfinite(keyValues[i])) return std::numeric_limits<double>::quiet_NaN();
    }
    // Decision (Model.h): RMS over key points of each point's Euclidean error over its channels,
    // so the number reads like a point error in data units and eps can be compared with the
    // point errors a user measures.
    // The key basis is column-major: a block of rows at a time, accumulated column by column,
    // reads it contiguously (a row-by-row dot product strides by K*C and was, after the
    // evaluator, the largest cost of a missed frame in the engine benchmark). The block lives
    // on the stack, so there is still no K*C temporary on the heap.
    constexpr Index kBlock = 256;
    double predicted[kBlock];
    const double* basis = keyBasis_.data();
    double sum = 0;
    for (Index x0 = 0; x0 < kc; x0 += kBlock) {
        const Index n = std::min(kBlock, kc - x0);
        for (Index i = 0; i < n; ++i) predicted[i] = keyMean_[x0 + i];
        for (Index j = 0; j < m; ++j) {
            const double bj = coords[j];
            const double* column = basis + j * kc + x0;
            for (Index i = 0; i < n; ++i) predicted[i] += column[i] * bj;
        }
        for (Index i = 0; i < n; ++i) {
            const double r = keyValues[x0 + i] - predicted[i];
            sum += r * r;
        }
    }
    return std::sqrt(sum / static_cast<double>(keys));
}

void PointMultiplier::reconstruct(const double* coords, double* out) const {
    const Index rows = model_.mean.size();
    Eigen::Map<const Eigen::VectorXd> b(coords, model_.basisSize());
    Eigen::Map<Eigen::VectorXd> o(out, rows);
    // One pass over the basis (a GEMV), the bandwidth-bound hot path of a hit.
    o = model_.mean;
    o.noalias() += model_.basis * b;
}

void PointMultiplier::reconstructRange(const double* coords, Index first, Index count,
                                       double* out) const {
    const Index c = model_.channels;
    Eigen::Map<const Eigen::VectorXd> b(coords, model_.basisSize());
    Eigen::Map<Eigen::VectorXd> o(out, count * c);
    o = model_.mean.segment(first * c, count * c);
    o.noalias() += model_.basis.middleRows(first * c, count * c) * b;
}

void PointMultiplier::reconstructPoints(const double* coords, std::span<const Index> points,
                                        double* out) const {
    const Index c = model_.channels;
    const Index m = model_.basisSize();
    const Index rows = model_.mean.size();
    const auto n = static_cast<Index>(points.size());
    for (Index i = 0; i < n; ++i) {
        const Index row = points[static_cast<size_t>(i)] * c;
        for (Index ch = 0; ch < c; ++ch) out[i * c + ch] = model_.mean[row + ch];
    }
    // Column-major basis: walking column by column reads each column's selected rows in order,
    // instead of striding by N*C for every row dot product.
    const double* basis = model_.basis.data();
    for (Index j = 0; j < m; ++j) {
        const double bj = coords[j];
        const double* column = basis + j * rows;
        for (Index i = 0; i < n; ++i) {
            const Index row = points[static_cast<size_t>(i)] * c;
            for (Index ch = 0; ch < c; ++ch) out[i * c + ch] += column[row + ch] * bj;
        }
    }
}

}  // namespace pmsc
