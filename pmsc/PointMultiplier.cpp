#include "pmsc/PointMultiplier.h"

#include "pmsc/Calibration.h"  // leaveOneOutScale

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

namespace pmsc {

namespace {
using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using RowMajorMap = Eigen::Map<RowMajor>;
using ConstRowMajorMap = Eigen::Map<const RowMajor>;

/// The basis, copied in panels of kPanel rows (rows of N points when the channels share it, of
/// N*C point channels otherwise): panel p holds
/// rows [p*kPanel, (p+1)*kPanel) column-major (kPanel x M, the last one padded with zeros), one
/// contiguous block, read front to back. Decisions, measured at N = 254,000, M = 40, C = 3
/// (`pmsc_volume_bench --benchmark_filter=Reconstruct`):
/// - Eigen's GEMM packs the (N x M) operand before multiplying it by the M x C coordinates and
///   ran slower than the (N*C) x M GEMV it replaces; a loop over the column-major basis reads M
///   streams 8*N bytes apart.
/// - Panels of 256 rows with per-channel accumulator rows stored every sum M times: 5.0-5.5 ms
///   a frame on one core, in double or float alike.
/// - Panels of 16 rows whose C x 16 sums stay in registers over all M columns (tileRows):
///   4.3-4.8 ms in double, 2.2-3.2 ms in float, 4.5 ms either way built without -march=native;
///   16 rows beat 8 and 32.
constexpr Index kPanel = 16;

template <typename Scalar>
std::vector<Scalar, BulkAllocator<Scalar>> panelsOf(const Eigen::MatrixXd& basis) {
    const Index n = basis.rows(), m = basis.cols();
    const Index panels = (n + kPanel - 1) / kPanel;
    std::vector<Scalar, BulkAllocator<Scalar>> out(static_cast<std::size_t>(panels * kPanel * m));
    for (Index p = 0; p < panels; ++p) {
        const Index rows = std::min(kPanel, n - p * kPanel);
        for (Index j = 0; j < m; ++j) {
            Scalar* column = out.data() + (p * m + j) * kPanel;
            for (Index i = 0; i < rows; ++i) column[i] = static_cast<Scalar>(basis(p * kPanel + i, j));
            std::fill(column + rows, column + kPanel, Scalar(0));  // the last panel's padding
        }
    }
    return out;
}

/// A panel for any C: acc (C rows of kPanel) = mean, plus every basis column times its
/// coordinate, in the order tileRows adds them.
template <typename Scalar>
void panelRows(const Scalar* block, Index m, Index c, const double* coords, const double* mu, double* acc) {
    for (Index ch = 0; ch < c; ++ch)
        for (Index i = 0; i < kPanel; ++i) acc[ch * kPanel + i] = mu[i * c + ch];
    for (Index j = 0; j < m; ++j) {
        const Scalar* column = block + j * kPanel;
        for (Index ch = 0; ch < c; ++ch) {
            const double bc = coords[j * c + ch];
            double* a = acc + ch * kPanel;
            for (Index i = 0; i < kPanel; ++i) a[i] += static_cast<double>(column[i]) * bc;
        }
    }
}

/// A whole panel with C fixed: its kC x kPanel sums stay in registers for the whole pass over
/// the M columns, so the loop reads the panel once and stores only the results.
template <int kC, typename Scalar>
void tileRows(const Scalar* block, Index m, const double* coords, const double* mu, bool clamp, double* o) {
    using Column = Eigen::Matrix<double, kPanel, 1>;
    // The sums of a tile, channel by channel, in Eigen's fixed-size vectors (registers).
    Column acc[kC];
    const Eigen::Map<const Eigen::Matrix<double, kC, kPanel>> mean(mu);
    for (int ch = 0; ch < kC; ++ch) acc[ch] = mean.row(ch).transpose();
    for (Index j = 0; j < m; ++j) {
        const Column column =
            Eigen::Map<const Eigen::Matrix<Scalar, kPanel, 1>>(block + j * kPanel).template cast<double>();
        for (int ch = 0; ch < kC; ++ch) acc[ch] += column * coords[j * kC + ch];
    }
    Eigen::Map<Eigen::Matrix<double, kC, kPanel>> result(o);
    // The clamp at 0 (Model::nonNegative) while the sums are in registers; a NaN stays a NaN.
    if (clamp)
        for (int ch = 0; ch < kC; ++ch) acc[ch] = (acc[ch].array() < 0.0).select(0.0, acc[ch]);
    for (int ch = 0; ch < kC; ++ch) result.row(ch) = acc[ch].transpose();
}

/// The rows a panel reconstruction reads: the mean (rows x c, channel-minor) of `rows` basis
/// rows of `m` columns. A model whose channels share the basis has rows = N and c = C; a model
/// whose channels have rows of their own has rows = N*C and c = 1 (each channel is a row).
struct PanelRows {
    const double* mean;
    Index rows, m, c;
    bool clamp = false;  ///< clamp the values at 0 (Model::nonNegative)
};

/// Rows [first, first+count) of `rows`, from their panels.
/// kC > 0 fixes C at compile time (and takes whole tiles in registers); Scalar is the panels'
/// (BasisPrecision), the sums are double. Every panel is computed whole, the same instructions
/// for the same row whatever the range: a range that starts or ends inside a panel computes it
/// into a scratch panel (the mean's rows past N zero) and keeps its rows. So a point's value is
/// the same bits in any chunking, in any build (FMA contraction may differ between a vectorized
/// loop and a scalar remainder, never between two runs of one loop).
template <int kC, typename Scalar>
void panelReconstruct(const PanelRows& rows_, const Scalar* panels, const double* coords, Index first,
                      Index count, double* out) {
    const Index c = kC > 0 ? kC : rows_.c;
    const Index m = rows_.m;
    // Scratch for any C (acc) and for a panel a range cuts (its mean and its values); a range of
    // whole panels, the engine's blocks, needs none.
    std::vector<double> acc, scratchMean, scratchOut;
    const auto panelValues = static_cast<std::size_t>(c * kPanel);
    if (kC == 0) acc.resize(panelValues);
    if (first % kPanel != 0 || (first + count) % kPanel != 0) {
        scratchMean.resize(panelValues);
        scratchOut.resize(panelValues);
    }
    const double* mean = rows_.mean;
    for (Index at = first; at < first + count;) {
        const Index panel = at / kPanel, start = panel * kPanel, lo = at - start;
        const Index rows = std::min(kPanel - lo, first + count - at);
        const bool whole = rows == kPanel;
        const double* mu = mean + start * c;
        if (!whole) {
            const Index valid = std::min(kPanel, rows_.rows - start);
            std::fill(scratchMean.begin(), scratchMean.end(), 0.0);
            std::copy(mu, mu + valid * c, scratchMean.begin());
            mu = scratchMean.data();
        }
        double* o = whole ? out + (at - first) * c : scratchOut.data();
        const Scalar* block = panels + panel * m * kPanel;
        if constexpr (kC > 0) {
            tileRows<kC>(block, m, coords, mu, rows_.clamp, o);
        } else {
            panelRows(block, m, c, coords, mu, acc.data());
            for (Index ch = 0; ch < c; ++ch)
                for (Index i = 0; i < kPanel; ++i) o[i * c + ch] = acc[ch * kPanel + i];
            if (rows_.clamp) clampAtZero(o, kPanel * c);
        }
        if (!whole) std::copy(o + lo * c, o + (lo + rows) * c, out + (at - first) * c);
        at += rows;
    }
}

template <typename Scalar>
void panelReconstructC(const PanelRows& rows, const Scalar* panels, const double* coords, Index first,
                       Index count, double* out) {
    switch (rows.c) {
        case 1:
            panelReconstruct<1>(rows, panels, coords, first, count, out);
            break;
        case 2:
            panelReconstruct<2>(rows, panels, coords, first, count, out);
            break;
        case 3:
            panelReconstruct<3>(rows, panels, coords, first, count, out);
            break;
        case 4:
            panelReconstruct<4>(rows, panels, coords, first, count, out);
            break;
        default:
            panelReconstruct<0>(rows, panels, coords, first, count, out);
            break;
    }
}
}  // namespace

void clampAtZero(double* values, Index count) {
    // max(v, 0) keeps a NaN a NaN (the soft cache reads a NaN as a miss), as std::max would not.
    for (Index i = 0; i < count; ++i)
        if (values[i] < 0) values[i] = 0;
}

PointMultiplier::PointMultiplier(const Model& model, BasisPrecision precision)
    : model_(model), precision_(precision) {
    model_.validate();
    const Eigen::Map<const Eigen::MatrixXd> meanColumn(model_.mean.data(), model_.mean.size(), 1);
    keyMean_ = gatherKeyRows(meanColumn, model_.channels, model_.keyPoints).col(0);
    keyBasis_ = gatherKeyRows(model_.basis, model_.basisChannels(), model_.keyPoints);
    if (usesLeaveOneOut(model_.keyErrorNorm)) looScale_ = leaveOneOutScale(keyBasis_, model_.projector);
    // b = P (k - mean_K) = P k - P mean_K: precomputing P mean_K lets project() write straight
    // into the caller's buffer with one GEMV and no temporary.
    // The basis in panels, in the precision asked for, for either layout: a copy (the model keeps
    // its column-major basis for training, learning and the subset queries), paid back on every
    // hit. The panels' pass ran 3x faster than Eigen's GEMV over the column-major (N*C) x M
    // basis at N = 160,000, C = 3, M = 32 (`pmsc_engine_bench --benchmark_filter=Reconstruct`):
    // one stream read front to back against M streams N*C*8 bytes apart.
    if (precision == BasisPrecision::Single)
        singlePanels_ = panelsOf<float>(model_.basis);
    else if (precision == BasisPrecision::Double)
        panels_ = panelsOf<double>(model_.basis);
    if (model_.sharedChannels) {
        projectedKeyMean_.resize(model_.coordCount());
        RowMajorMap(projectedKeyMean_.data(), model_.basisSize(), model_.channels).noalias() =
            model_.projector * ConstRowMajorMap(keyMean_.data(), model_.keyCount(), model_.channels);
    } else {
        projectedKeyMean_ = model_.projector * keyMean_;
    }
}

void PointMultiplier::project(const double* keyValues, double* coords) const {
    const Index kc = keyMean_.size();
    if (model_.sharedChannels) {
        // The same K x M system for every channel: coords (M x C) = P keys (K x C) - P mean_K.
        const Index c = model_.channels;
        RowMajorMap b(coords, model_.basisSize(), c);
        b.noalias() = model_.projector * ConstRowMajorMap(keyValues, model_.keyCount(), c);
        b -= ConstRowMajorMap(projectedKeyMean_.data(), model_.basisSize(), c);
        return;
    }
    const Index m = model_.basisSize();
    Eigen::Map<const Eigen::VectorXd> k(keyValues, kc);
    Eigen::Map<Eigen::VectorXd> b(coords, m);
    b.noalias() = model_.projector * k;
    b -= projectedKeyMean_;
}

double PointMultiplier::keyError(const double* keyValues, const double* coords, PredictedParts* parts) const {
    const Index kc = keyMean_.size();
    const Index m = model_.basisSize();
    const Index keys = model_.keyCount();
    for (Index i = 0; i < kc; ++i) {
        if (!std::isfinite(keyValues[i])) return std::numeric_limits<double>::quiet_NaN();
    }
    if (model_.sharedChannels) {
        // Same measure as below (RMS over keys of the Euclidean error over channels); the key
        // basis is K x M, shared by the channels, and the coordinates are M x C.
        const Index c = model_.channels;
        double sum = 0, largest = 0;
        for (Index i = 0; i < keys; ++i) {
            double key = 0;
            const double scale = looScale_.size() > 0 ? looScale_[i] : 1.0;  // one leverage per key
            for (Index ch = 0; ch < c; ++ch) {
                double predicted = keyMean_[i * c + ch];
                for (Index j = 0; j < m; ++j) predicted += keyBasis_(i, j) * coords[j * c + ch];
                const double r = (keyValues[i * c + ch] - predicted) * scale;
                key += r * r;
            }
            sum += key;
            largest = std::max(largest, key);
        }
        return model_.keyErrorNorm == KeyErrorNorm::Rms ? std::sqrt(sum / static_cast<double>(keys))
                                                        : std::sqrt(largest);
    }
    // Decision (Model.h): RMS over key points of each point's Euclidean error over its channels,
    // so the number reads like a point error in data units and eps can be compared with the
    // point errors a user measures.
    // The key basis is column-major: a block of rows at a time, accumulated column by column,
    // reads it contiguously (a row-by-row dot product strides by K*C and would be, after the
    // evaluator, the largest cost of a missed frame in the engine benchmark). The block lives
    // on the stack, so there is still no K*C temporary on the heap.
    constexpr Index kBlock = 256;
    double predicted[kBlock];
    const double* basis = keyBasis_.data();
    // The largest key needs whole keys: a key's C residuals are summed (across blocks when a
    // block boundary splits them) before the max.
    const Index c = model_.channels;
    const bool largestKey = model_.keyErrorNorm != KeyErrorNorm::Rms;
    const double* scale = looScale_.size() > 0 ? looScale_.data() : nullptr;
    double sum = 0, largest = 0, key = 0;
    for (Index x0 = 0; x0 < kc; x0 += kBlock) {
        const Index n = std::min(kBlock, kc - x0);
        for (Index i = 0; i < n; ++i) predicted[i] = keyMean_[x0 + i];
        for (Index j = 0; j < m; ++j) {
            const double bj = coords[j];
            const double* column = basis + j * kc + x0;
            for (Index i = 0; i < n; ++i) predicted[i] += column[i] * bj;
        }
        if (!largestKey) {  // the default measure: no per-key bookkeeping on the hot path
            for (Index i = 0; i < n; ++i) {
                const double r = keyValues[x0 + i] - predicted[i];
                sum += r * r;
            }
            continue;
        }
        for (Index i = 0; i < n; ++i) {
            const double raw = keyValues[x0 + i] - predicted[i];
            sum += raw * raw;  // the predicted error's RMS part
            const double r = scale ? raw * scale[x0 + i] : raw;
            key += r * r;
            if ((x0 + i + 1) % c == 0) {
                largest = std::max(largest, key);
                key = 0;
            }
        }
    }
    const double rms = std::sqrt(sum / static_cast<double>(keys));
    switch (model_.keyErrorNorm) {
        case KeyErrorNorm::Rms:
            return rms;
        case KeyErrorNorm::Predicted:
            if (parts) *parts = {rms, std::sqrt(largest)};
            return predictedPointError({rms, std::sqrt(largest)}, model_.partEps, model_.tolerance);
        case KeyErrorNorm::Largest:
        case KeyErrorNorm::LeaveOneOut:
            break;
    }
    return std::sqrt(largest);
}

void PointMultiplier::reconstruct(const double* coords, double* out) const {
    reconstructRange(coords, 0, model_.points, out);
}

void PointMultiplier::reconstructRange(const double* coords, Index first, Index count, double* out) const {
    // One pass over the basis rows of the range, the bandwidth-bound hot path of a hit.
    const Index c = model_.channels, m = model_.basisSize();
    // Shared channels: out (count x C) = mean + basis rows (count x M) * coords (M x C), one pass
    // over the N x M basis for all channels, a third of the (N*C) x M one's memory traffic at
    // C = 3. Channels with rows of their own: each channel's row is a row of the panels, one
    // channel each.
    const PanelRows rows = model_.sharedChannels
                               ? PanelRows{model_.mean.data(), model_.points, m, c, model_.nonNegative}
                               : PanelRows{model_.mean.data(), model_.points * c, m, 1, model_.nonNegative};
    const Index scale = model_.sharedChannels ? 1 : c;
    if (precision_ == BasisPrecision::None)
        throw std::logic_error(
            "PointMultiplier::reconstruct: made with BasisPrecision::None (no basis copy)");
    if (precision_ == BasisPrecision::Single)
        panelReconstructC(rows, singlePanels_.data(), coords, first * scale, count * scale, out);
    else
        panelReconstructC(rows, panels_.data(), coords, first * scale, count * scale, out);
}

void PointMultiplier::keyResiduals(const double* keyValues, const double* coords, double* perKey) const {
    if (model_.sharedChannels)
        throw std::logic_error("PointMultiplier::keyResiduals: a model whose channels share the basis");
    const Index c = model_.channels;
    const Index m = model_.basisSize();
    const Index kc = keyMean_.size();
    const Eigen::VectorXd predicted = keyMean_ + keyBasis_ * Eigen::Map<const Eigen::VectorXd>(coords, m);
    for (Index x = 0; x < kc; x += c) {
        double squared = 0;
        for (Index ch = 0; ch < c; ++ch) {
            const double scale = looScale_.size() > 0 ? looScale_[x + ch] : 1.0;
            const double r = (keyValues[x + ch] - predicted[x + ch]) * scale;
            squared += r * r;
        }
        perKey[x / c] = std::sqrt(squared);
    }
}

double PointMultiplier::largestErrorAt(const double* coords, std::span<const Index> points,
                                       const double* values) const {
    const Index c = model_.channels;
    thread_local std::vector<double> rec;
    rec.resize(points.size() * static_cast<size_t>(c));
    reconstructPoints(coords, points, rec.data());
    double largest = 0;
    for (size_t i = 0; i < points.size(); ++i) {
        double squared = 0;
        for (Index ch = 0; ch < c; ++ch) {
            const double d = rec[i * size_t(c) + size_t(ch)] - values[i * size_t(c) + size_t(ch)];
            squared += d * d;
        }
        if (!(squared <= largest * largest)) largest = std::sqrt(squared);  // NaN wins
        if (std::isnan(largest)) return largest;
    }
    return largest;
}

void reconstructAt(const Eigen::VectorXd& mean, const Eigen::MatrixXd& basis, Index channels,
                   bool sharedChannels, bool nonNegative, const double* coords, std::span<const Index> points,
                   double* out) {
    const Index c = channels;
    const Index m = basis.cols();
    const auto n = static_cast<Index>(points.size());
    for (Index i = 0; i < n; ++i) {
        const Index row = points[static_cast<size_t>(i)] * c;
        for (Index ch = 0; ch < c; ++ch) out[i * c + ch] = mean[row + ch];
    }
    // Column-major basis: walking column by column reads each column's selected rows in order,
    // instead of striding by N*C for every row dot product.
    for (Index j = 0; j < m; ++j) {
        const double* column = basis.col(j).data();
        if (sharedChannels) {
            const double* bj = coords + j * c;
            for (Index i = 0; i < n; ++i) {
                const double a = column[points[static_cast<size_t>(i)]];
                for (Index ch = 0; ch < c; ++ch) out[i * c + ch] += a * bj[ch];
            }
        } else {
            const double bj = coords[j];
            for (Index i = 0; i < n; ++i) {
                const Index row = points[static_cast<size_t>(i)] * c;
                for (Index ch = 0; ch < c; ++ch) out[i * c + ch] += column[row + ch] * bj;
            }
        }
    }
    if (nonNegative) clampAtZero(out, n * c);
}

void PointMultiplier::reconstructPoints(const double* coords, std::span<const Index> points,
                                        double* out) const {
    reconstructAt(model_.mean, model_.basis, model_.channels, model_.sharedChannels, model_.nonNegative,
                  coords, points, out);
}

}  // namespace pmsc
