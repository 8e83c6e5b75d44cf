#include "pmsc/KeyPointSelector.h"

#include "pmsc/Model.h"
#include "pmsc/RowBlockOps.h"

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
    SingleProcess one;
    return addTeleconnectionPair(v, channels, keys, budget, one, 0);
}

Index addTeleconnectionPair(const Eigen::Ref<const Eigen::VectorXd>& v, Index channels, KeySet& keys,
                            Index budget, Communicator& comm, Index firstPoint) {
    if (keys.size() >= budget) return 0;
    const Index owned = v.size() / channels;
    const double* data = v.data();
    auto loadingDot = [&](const double* a, Index q) {
        double s = 0;
        for (Index c = 0; c < channels; ++c) s += a[c] * data[q * channels + c];
        return s;
    };
    // First: the non-key point with the largest loading (strict > keeps the lowest index on ties;
    // argMaxOverRanks keeps it across ranks).
    ValueIndex first{-1.0, -1};
    for (Index p = 0; p < owned; ++p) {
        if (keys.contains(firstPoint + p)) continue;
        const double s = loadingDot(data + p * channels, p);
        if (s > first.value) first = {s, firstPoint + p};
    }
    first = argMaxOverRanks(comm, first);
    if (first.index < 0) return 0;
    // The first point's loading, from the rank that owns it.
    std::vector<double> loading(static_cast<std::size_t>(channels), 0.0);
    if (first.index >= firstPoint && first.index < firstPoint + owned) {
        for (Index c = 0; c < channels; ++c)
            loading[static_cast<std::size_t>(c)] = data[(first.index - firstPoint) * channels + c];
    }
    comm.sum(loading.data(), loading.size());
    keys.add(first.index);
    Index added = 1;
    if (keys.size() >= budget) return added;

    // Second: the most negative inner product of loadings with the first point (as the largest
    // negated one, so the same arg-max and tie rule apply).
    ValueIndex second{0.0, -1};
    for (Index q = 0; q < owned; ++q) {
        if (keys.contains(firstPoint + q)) continue;
        const double d = loadingDot(loading.data(), q);
        if (d < 0 && (second.index < 0 || -d > second.value)) second = {-d, firstPoint + q};
    }
    second = argMaxOverRanks(comm, second);
    if (second.index < 0) {
        // No anti-correlated point under this vector: take the next largest magnitude instead, so
        // every vector still yields two keys.
        second = {-1.0, -1};
        for (Index q = 0; q < owned; ++q) {
            if (keys.contains(firstPoint + q)) continue;
            const double s = loadingDot(data + q * channels, q);
            if (s > second.value) second = {s, firstPoint + q};
        }
        second = argMaxOverRanks(comm, second);
    }
    if (second.index >= 0 && keys.add(second.index)) ++added;
    return added;
}

double pmResidual(const Eigen::Ref<const Eigen::MatrixXd>& q, const Eigen::MatrixXd& basis, Index channels,
                  const std::vector<Index>& keys, Eigen::MatrixXd& residual, Eigen::MatrixXd* coordsOut) {
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
        if (determined(mid))
            lo = mid;
        else
            hi = mid;
    }
    return lo;
}

double maxPointResidual(const Eigen::Ref<const Eigen::MatrixXd>& q,
                        const Eigen::Ref<const Eigen::MatrixXd>& basis, const Eigen::MatrixXd& coords,
                        Index channels) {
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
    if (channels < 1 || q.rows() % channels != 0) {
        throw std::invalid_argument("selectKeysTeleconnection: rows are not whole points");
    }
    MatrixBlocks blocks(q, channels, /*centre=*/false);
    SingleProcess one;
    if (gram && (gram->rows() != q.cols() || gram->cols() != q.cols())) {
        throw std::invalid_argument("selectKeysTeleconnection: Gram matrix is not F x F");
    }
    const Eigen::MatrixXd g = gram ? *gram : gramMatrix(q);
    return selectKeysTeleconnection(blocks, one, basis, firstBlock, firstSigma, options, g);
}

namespace {

/// One round's keys (section 4): the block's vectors Varimax-rotated, visited by the variance they
/// carry (column j of the rotated block carries ||diag(sigma) t_j||^2 of the block's energy), a
/// teleconnection pair from each until the budget is met.
void addRoundKeys(Eigen::MatrixXd&& blockU, const Eigen::VectorXd& blockSigma,
                  const TeleconnectionOptions& options, Index channels, KeySet& keys, Communicator& comm,
                  Index firstPoint) {
    const Index b = blockU.cols();
    const VarimaxResult rotated = varimax(std::move(blockU), options.varimax, comm);
    Eigen::VectorXd variance(b);
    for (Index j = 0; j < b; ++j)
        variance[j] = (blockSigma.array() * rotated.rotation.col(j).array()).matrix().squaredNorm();
    std::vector<Index> order(static_cast<size_t>(b));
    std::iota(order.begin(), order.end(), Index{0});
    std::stable_sort(order.begin(), order.end(), [&](Index a, Index c) { return variance[a] > variance[c]; });
    for (Index j : order) {
        if (keys.size() >= options.maxKeys) break;
        addTeleconnectionPair(rotated.rotated.col(j), channels, keys, options.maxKeys, comm, firstPoint);
    }
}

/// The next block of the residual R = Q - B C: its leading `block` singular values, and its left
/// vectors in `blockU` (this rank's rows). From R^T R = G - W^T C - C^T W + C^T C, an F x F
/// eigenproblem with no pass over Q, unless the residual is too small for that subtraction.
TruncatedSvd nextResidualBlock(RowBlocks& q, Communicator& comm, const Eigen::MatrixXd& basis,
                               const Eigen::MatrixXd& projected, const Eigen::MatrixXd& coords,
                               const Eigen::MatrixXd& gram, Index block, double sigmaQ,
                               Eigen::MatrixXd& blockU) {
    Eigen::MatrixXd rtr = gram;
    {
        const Eigen::MatrixXd cross = projected.transpose() * coords;  // W^T C
        rtr -= cross;
        rtr -= cross.transpose();
        rtr.noalias() += coords.transpose() * coords;
    }
    TruncatedSvd next = svdFromGram(Eigen::MatrixXd(0, q.frames()), rtr, block, 0, 1e-6 * sigmaQ);
    Eigen::MatrixXd vs;
    if (next.sigma.size() > 0) {
        // U_R = R V_R S^-1 = Q (V_R S^-1) - B (C V_R S^-1): one pass, the residual never formed.
        vs = next.v * next.sigma.cwiseInverse().asDiagonal();
        blockU = timesRight(q, vs);
        blockU.noalias() -= basis * (coords * vs);
        return next;
    }
    // The residual is too small for the subtraction above (sigma_R <= 1e-6 sigma_1(Q): it cancels
    // to rounding). Decision: form R = Q - B C block by block and take the Gram of R itself (one
    // pass), then U_R = R V S^-1 (another). Replaces the randomized SVD of the explicit residual,
    // which needs 2q + 2 passes and a distributed tall QR out of core. As that SVD did, it keeps
    // every vector above 1e-7 of the residual's own largest (so rounding-level residuals still cue
    // keys until the budget is met); only an exactly zero residual ends the selection.
    Eigen::MatrixXd gr = Eigen::MatrixXd::Zero(q.frames(), q.frames());
    Eigen::MatrixXd r;
    for (Index bl = 0; bl < q.blockCount(); ++bl) {
        r = q.block(bl);
        r.noalias() -= basis.middleRows(q.blockFirstRow(bl), q.blockRows(bl)) * coords;
        gr.selfadjointView<Eigen::Lower>().rankUpdate(r.transpose());
    }
    comm.sum(gr.data(), static_cast<std::size_t>(gr.size()));
    gr.triangularView<Eigen::StrictlyUpper>() = gr.transpose();
    next = svdFromGram(Eigen::MatrixXd(0, q.frames()), gr, block, 0, 0.0);
    blockU.resize(q.ownedRows(), next.sigma.size());
    if (next.sigma.size() > 0) {
        vs = next.v * next.sigma.cwiseInverse().asDiagonal();
        for (Index bl = 0; bl < q.blockCount(); ++bl) {
            r = q.block(bl);
            r.noalias() -= basis.middleRows(q.blockFirstRow(bl), q.blockRows(bl)) * coords;
            blockU.middleRows(q.blockFirstRow(bl), q.blockRows(bl)).noalias() = r * vs;
        }
    }
    return next;
}

}  // namespace

KeySelection selectKeysTeleconnection(RowBlocks& q, Communicator& comm, const Eigen::MatrixXd& basis,
                                      const Eigen::Ref<const Eigen::MatrixXd>& firstBlock,
                                      const Eigen::VectorXd& firstSigma, const TeleconnectionOptions& options,
                                      const Eigen::MatrixXd& gram) {
    if (options.block < 1) {
        throw std::invalid_argument("block must be >= 1, got " + std::to_string(options.block));
    }
    const Index n = q.points();
    const Index channels = q.channels();
    if (options.maxKeys < 1 || options.maxKeys > n) {
        throw std::invalid_argument("key budget " + std::to_string(options.maxKeys) + " must be in [1, " +
                                    std::to_string(n) + "]");
    }
    if (gram.rows() != q.frames() || gram.cols() != q.frames()) {
        throw std::invalid_argument("selectKeysTeleconnection: Gram matrix is not F x F");
    }
    KeySet keys(n, options.candidates);
    seedKeys(keys, options.fiducials, options.gridPoints);
    if (keys.size() > options.maxKeys) {
        throw std::invalid_argument(std::to_string(keys.size()) +
                                    " fiducial and grid points exceed the key budget " +
                                    std::to_string(options.maxKeys));
    }

    KeySelection result;
    Eigen::MatrixXd coords;
    // W = B^T Q, for the frame-space residual Gram. firstSigma are Q's leading singular values:
    // the scale the cancellation is relative to.
    const Eigen::MatrixXd projected = transposeTimes(q, comm, basis);
    const double sigmaQ = firstSigma.size() > 0 ? firstSigma[0] : 0.0;
    Eigen::MatrixXd qk(0, q.frames());  // Q's key rows, in key order, fetched as keys are added
    Eigen::MatrixXd blockU = firstBlock.leftCols(std::min(options.block, firstBlock.cols()));
    Eigen::VectorXd blockSigma = firstSigma.head(blockU.cols());
    for (Index round = 1;; ++round) {
        const Index before = keys.size();
        if (blockU.cols() > 0 && keys.size() < options.maxKeys)
            addRoundKeys(std::move(blockU), blockSigma, options, channels, keys, comm, q.firstPoint());
        {
            const std::vector<Index> added(keys.keys().begin() + qk.rows() / channels, keys.keys().end());
            const Eigen::MatrixXd rows = keyRowsOfQ(q, comm, added);
            qk.conservativeResize(qk.rows() + rows.rows(), Eigen::NoChange);
            qk.bottomRows(rows.rows()) = rows;
        }
        coords = projectorFromKeyRows(keyRowsOf(q, comm, basis, keys.keys()), channels) * qk;
        const double worst = maxPointResidualOf(q, comm, basis, coords);
        result.residualPerRound.push_back(worst);
        result.rounds = round;
        if (options.onRound) options.onRound(round, keys.size(), worst);

        const bool progressed = keys.size() > before;
        if (!progressed || keys.size() >= options.maxKeys || keys.size() >= n) break;
        if (options.maxError > 0 && worst <= options.maxError) break;

        // Next block: the residual's leading vectors (cueing + projection error left over).
        TruncatedSvd next =
            nextResidualBlock(q, comm, basis, projected, coords, gram, options.block, sigmaQ, blockU);
        blockSigma = std::move(next.sigma);
        if (blockU.cols() == 0) break;  // the residual is numerically zero: nothing left to cue
    }
    result.keys = keys.keys();
    result.keyRows = std::move(qk);
    return result;
}

}  // namespace pmsc
