#include "pmsc/KeyPointSelector.h"

#include "pmsc/Model.h"

#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

namespace pmsc {

void seedKeys(KeySet& keys, const std::vector<Index>& fiducials, const std::vector<Index>& gridPoints) {
    const Index n = keys.points();
    auto seed = [&](const std::vector<Index>& list, const char* what) {
        for (Index p : list) {
            if (p < 0 || p >= n) {
                throw std::invalid_argument(std::string(what) + " point " + std::to_string(p) +
                                            " is outside [0, " + std::to_string(n) + ")");
            }
            if (!keys.add(p)) {
                throw std::invalid_argument(std::string(what) + " point " + std::to_string(p) +
                                            " is listed twice (or is already a fiducial)");
            }
        }
    };
    seed(fiducials, "fiducial");
    seed(gridPoints, "grid");
}

Index addTeleconnectionPair(const Eigen::Ref<const Eigen::VectorXd>& v, Index channels, KeySet& keys,
                            Index budget) {
    const Index n = keys.points();
    if (keys.size() >= budget) return 0;
    const double* data = v.data();
    auto loadingDot = [&](Index p, Index q) {
        double s = 0;
        for (Index c = 0; c < channels; ++c) s += data[p * channels + c] * data[q * channels + c];
        return s;
    };
    // First: the non-key point with the largest loading (strict > keeps the lowest index on ties).
    Index first = -1;
    double firstNorm = -1;
    for (Index p = 0; p < n; ++p) {
        if (keys.contains(p)) continue;
        const double s = loadingDot(p, p);
        if (s > firstNorm) {
            firstNorm = s;
            first = p;
        }
    }
    if (first < 0) return 0;
    keys.add(first);
    Index added = 1;
    if (keys.size() >= budget) return added;

    // Second: the most negative inner product of loadings with the first point.
    Index second = -1;
    double mostNegative = 0;
    for (Index q = 0; q < n; ++q) {
        if (keys.contains(q)) continue;
        const double d = loadingDot(first, q);
        if (d < mostNegative) {
            mostNegative = d;
            second = q;
        }
    }
    if (second < 0) {
        // No anti-correlated point under this vector: take the next largest magnitude instead, so
        // every vector still yields two keys.
        double best = -1;
        for (Index q = 0; q < n; ++q) {
            if (keys.contains(q)) continue;
            const double s = loadingDot(q, q);
            if (s > best) {
                best = s;
                second = q;
            }
        }
    }
    if (second >= 0 && keys.add(second)) ++added;
    return added;
}

double pmResidual(const Eigen::Ref<const Eigen::MatrixXd>& q, const Eigen::MatrixXd& basis,
                  Index channels, const std::vector<Index>& keys, Eigen::MatrixXd& residual,
                  Eigen::MatrixXd* coordsOut) {
    const Eigen::MatrixXd projector = makeProjector(basis, channels, keys);
    const Eigen::MatrixXd qk = gatherKeyRows(q, channels, keys);
    Eigen::MatrixXd coords = projector * qk;  // M x F
    residual.resize(q.rows(), q.cols());
    residual = q;
    residual.noalias() -= basis * coords;
    if (coordsOut) *coordsOut = std::move(coords);
    return maxPointNorm(residual, channels);
}

Index determinedBasisSize(const Eigen::MatrixXd& basis, Index channels, const std::vector<Index>& keys,
                          double maxCondition) {
    const Eigen::MatrixXd bk = gatherKeyRows(basis, channels, keys);
    auto determined = [&](Index m) {
        if (m > bk.rows()) return false;
        // B_K is small ((K*C) x M, a few hundred square): one-sided Jacobi after a QR is fast and
        // the most accurate for small singular values, which is what the condition number needs.
        const Eigen::VectorXd s = Eigen::JacobiSVD<Eigen::MatrixXd>(bk.leftCols(m)).singularValues();
        return s[m - 1] > 0 && s[0] / s[m - 1] <= maxCondition;
    };
    Index lo = 0;  // largest size known determined (0 trivially)
    Index hi = std::min(basis.cols(), bk.rows());
    if (hi > 0 && determined(hi)) return hi;
    // Invariant: lo determined (or 0), hi not determined.
    while (hi - lo > 1) {
        const Index mid = (lo + hi) / 2;
        if (determined(mid)) lo = mid;
        else hi = mid;
    }
    return lo;
}

double maxPointResidual(const Eigen::Ref<const Eigen::MatrixXd>& q, const Eigen::MatrixXd& basis,
                        const Eigen::MatrixXd& coords, Index channels) {
    // 96 points per block: 288 x F doubles (~1.4 MB at F = 600) stays in L2 while the GEMM writes
    // it and the norms read it back.
    const Index rowsPerBlock = 96 * channels;
    const Index rows = q.rows();
    Eigen::MatrixXd block(std::min(rowsPerBlock, rows), q.cols());
    double worst = 0;
    for (Index r0 = 0; r0 < rows; r0 += rowsPerBlock) {
        const Index h = std::min(rowsPerBlock, rows - r0);
        auto b = block.topRows(h);
        b = q.middleRows(r0, h);
        b.noalias() -= basis.middleRows(r0, h) * coords;
        const double w = maxPointNorm(b, channels);
        if (!(w <= worst)) worst = w;  // NaN wins
    }
    return worst;
}

KeySelection selectKeysTeleconnection(const Eigen::Ref<const Eigen::MatrixXd>& q,
                                      const Eigen::MatrixXd& basis,
                                      const Eigen::Ref<const Eigen::MatrixXd>& firstBlock,
                                      const Eigen::VectorXd& firstSigma, Index channels,
                                      const TeleconnectionOptions& options, const Eigen::MatrixXd* gram) {
    if (options.block < 1) {
        throw std::invalid_argument("block must be >= 1, got " + std::to_string(options.block));
    }
    const Index n = q.rows() / channels;
    if (options.maxKeys < 1 || options.maxKeys > n) {
        throw std::invalid_argument("key budget " + std::to_string(options.maxKeys) +
                                    " must be in [1, " + std::to_string(n) + "]");
    }
    KeySet keys(n);
    seedKeys(keys, options.fiducials, options.gridPoints);
    if (keys.size() > options.maxKeys) {
        throw std::invalid_argument(std::to_string(keys.size()) +
                                    " fiducial and grid points exceed the key budget " +
                                    std::to_string(options.maxKeys));
    }

    KeySelection result;
    Eigen::MatrixXd residual;
    Eigen::MatrixXd coords;
    Eigen::MatrixXd projected;  // W = B^T Q, for the frame-space residual Gram
    double sigmaQ = 0;
    // The frame-space route costs an F x F eigensolver per round: worth it only while that is
    // cheaper than the randomized SVD of the explicit residual (true for hundreds of frames, not
    // for thousands).
    {
        const double f = static_cast<double>(q.cols());
        const double frameSpace = 9 * f * f * f + 2 * static_cast<double>(q.rows()) * f * static_cast<double>(options.block);
        const Index sketch = std::min({options.block + options.svd.oversampling, q.rows(), q.cols()});
        if (frameSpace > randomizedRouteFlops(q.rows(), q.cols(), sketch, options.svd.powerIterations)) gram = nullptr;
    }
    if (gram) {
        if (gram->rows() != q.cols() || gram->cols() != q.cols()) {
            throw std::invalid_argument("selectKeysTeleconnection: Gram matrix is not F x F");
        }
        projected.noalias() = basis.transpose() * q;
        // firstSigma are Q's leading singular values: the scale the cancellation is relative to.
        sigmaQ = firstSigma.size() > 0 ? firstSigma[0] : 0.0;
    }
    Eigen::MatrixXd blockU = firstBlock.leftCols(std::min(options.block, firstBlock.cols()));
    Eigen::VectorXd blockSigma = firstSigma.head(blockU.cols());
    for (Index round = 1;; ++round) {
        const Index before = keys.size();
        if (blockU.cols() > 0 && keys.size() < options.maxKeys) {
            const VarimaxResult rotated = varimax(blockU, options.varimax);
            // Visit rotated vectors by the variance they carry: column j of the rotated block
            // carries ||diag(sigma) t_j||^2 of the block's energy.
            const Index b = blockU.cols();
            Eigen::VectorXd variance(b);
            for (Index j = 0; j < b; ++j)
                variance[j] = (blockSigma.array() * rotated.rotation.col(j).array()).matrix().squaredNorm();
            std::vector<Index> order(static_cast<size_t>(b));
            std::iota(order.begin(), order.end(), Index{0});
            std::stable_sort(order.begin(), order.end(),
                             [&](Index a, Index c) { return variance[a] > variance[c]; });
            for (Index j : order) {
                if (keys.size() >= options.maxKeys) break;
                addTeleconnectionPair(rotated.rotated.col(j), channels, keys, options.maxKeys);
            }
        }
        coords = makeProjector(basis, channels, keys.keys()) * gatherKeyRows(q, channels, keys.keys());
        const double worst = maxPointResidual(q, basis, coords, channels);
        result.residualPerRound.push_back(worst);
        result.rounds = round;
        if (options.onRound) options.onRound(round, keys.size(), worst);

        const bool progressed = keys.size() > before;
        if (!progressed || keys.size() >= options.maxKeys || keys.size() >= n) break;
        if (options.maxError > 0 && worst <= options.maxError) break;

        // Next block: the residual's leading vectors (cueing + projection error left over).
        TruncatedSvd next;
        if (gram) {
            Eigen::MatrixXd rtr = *gram;
            Eigen::MatrixXd cross = projected.transpose() * coords;  // W^T C
            rtr -= cross;
            rtr -= cross.transpose();
            rtr.noalias() += coords.transpose() * coords;
            next = svdFromGram(Eigen::MatrixXd(0, q.cols()), rtr, options.block, 0, 1e-6 * sigmaQ);
            if (next.sigma.size() > 0) {
                // U_R = R V_R S^-1 = Q (V_R S^-1) - B (C V_R S^-1): two skinny products, and the
                // residual itself is never formed.
                const Eigen::MatrixXd vs = next.v * next.sigma.cwiseInverse().asDiagonal();
                next.u.resize(q.rows(), vs.cols());
                next.u.noalias() = q * vs;
                next.u.noalias() -= basis * (coords * vs);
            }
        }
        if (next.sigma.size() == 0) {
            residual.resize(q.rows(), q.cols());
            residual = q;
            residual.noalias() -= basis * coords;
            SvdOptions svdOptions = options.svd;
            svdOptions.seed = options.svd.seed + static_cast<unsigned>(round);
            next = truncatedSvd(residual, options.block, svdOptions);
        }
        blockU = std::move(next.u);
        blockSigma = std::move(next.sigma);
        if (blockU.cols() == 0) break;  // the residual is numerically zero: nothing left to cue
    }
    result.keys = keys.keys();
    return result;
}

}  // namespace pmsc
