#include "pmsc/Varimax.h"

#include "pmsc/Parallel.h"

#include <Eigen/SVD>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace pmsc {

double varimaxCriterion(const Eigen::Ref<const Eigen::MatrixXd>& z) {
    const double p = static_cast<double>(z.rows());
    double total = 0;
    for (Index j = 0; j < z.cols(); ++j) {
        const double m2 = z.col(j).squaredNorm() / p;
        const double m4 = z.col(j).array().square().square().sum() / p;
        total += m4 - m2 * m2;
    }
    return total;
}

VarimaxResult varimax(const Eigen::Ref<const Eigen::MatrixXd>& loadings, const VarimaxOptions& options) {
    SingleProcess one;
    return varimax(loadings, options, one);
}

namespace {

/// The criterion of loadings left as they are (fewer than two columns, or no rows): from the
/// column moments summed over ranks (varimaxCriterion on one rank).
double unrotatedCriterion(const Eigen::Ref<const Eigen::MatrixXd>& loadings, Index p, Communicator& comm) {
    const Index k = loadings.cols();
    Eigen::VectorXd moments(2 * k);
    for (Index j = 0; j < k; ++j) {
        moments[j] = loadings.col(j).squaredNorm();
        moments[k + j] = loadings.col(j).array().square().square().sum();
    }
    comm.sum(moments.data(), static_cast<std::size_t>(moments.size()));
    double total = 0;
    for (Index j = 0; j < k && p > 0; ++j) {
        const double m2 = moments[j] / static_cast<double>(p);
        total += moments[k + j] / static_cast<double>(p) - m2 * m2;
    }
    return total;
}

/// The varimax gradient G = X^T (Z.^3 - Z diag(colSquares)/p) = X^T Z.^3 - (X^T X) T
/// diag(colSquares)/p, Z = X T, and the criterion, at a rotation T. The blocks are tall (N*C rows,
/// ~16 columns), so memory passes, not flops, set the cost of an iteration: each evaluation streams
/// X once, in row chunks small enough to stay in cache, making Z, Z.^3, the column moments
/// (criterion) and X^T Z.^3 from the chunk while it is hot; Z itself is never stored.
///
/// Decision: the rows are cut into fixed blocks of kBlockRows, each summed alone on whichever core
/// takes it, and the blocks' sums are added in block order. The rotation is the largest single cost
/// of training (200 iterations over the basis), so it uses every core; fixed blocks keep the sums,
/// and so the keys, the same whatever the number of cores.
class VarimaxGradient {
public:
    static constexpr Index kBlockRows = 16384;
    static constexpr Index kChunkRows = 512;

    VarimaxGradient(const Eigen::MatrixXd& x, Index p, Communicator& comm)
        : x_(x),
          comm_(comm),
          rows_(x.rows()),
          k_(x.cols()),
          blocks_(std::max<Index>(1, (rows_ + kBlockRows - 1) / kBlockRows)),
          partial_(static_cast<std::size_t>(blocks_)),
          inverseRows_(1.0 / static_cast<double>(p)) {
        xtx_ = x.transpose() * x;
        comm.sum(xtx_.data(), static_cast<std::size_t>(xtx_.size()));
    }

    /// Fills `g` for `rotation` and returns the criterion there (== varimaxCriterion(X T)).
    double evaluate(const Eigen::MatrixXd& rotation, Eigen::MatrixXd& g) {
        std::atomic<Index> next{0};
        runOnEveryCore(
            [&] {
                Eigen::MatrixXd z(kChunkRows, k_), cubes(kChunkRows, k_);
                for (Index b = next++; b < blocks_; b = next++) sumBlock(b, rotation, z, cubes);
            },
            blocks_);
        g.setZero(k_, k_);
        Eigen::VectorXd colSquares = Eigen::VectorXd::Zero(k_), colQuartics = Eigen::VectorXd::Zero(k_);
        for (const BlockSums& s : partial_) {
            g += s.g;
            colSquares += s.squares;
            colQuartics += s.quartics;
        }
        if (comm_.size() > 1) {
            // One reduction per step: G's partial sums and both column moments.
            Eigen::VectorXd sums(k_ * k_ + 2 * k_);
            sums.head(k_ * k_) = Eigen::Map<const Eigen::VectorXd>(g.data(), k_ * k_);
            sums.segment(k_ * k_, k_) = colSquares;
            sums.tail(k_) = colQuartics;
            comm_.sum(sums.data(), static_cast<std::size_t>(sums.size()));
            g = Eigen::Map<const Eigen::MatrixXd>(sums.data(), k_, k_);
            colSquares = sums.segment(k_ * k_, k_);
            colQuartics = sums.tail(k_);
        }
        g.noalias() -= xtx_ * rotation * (colSquares * inverseRows_).asDiagonal();
        const Eigen::ArrayXd m2 = colSquares.array() * inverseRows_;
        return (colQuartics.array() * inverseRows_ - m2 * m2).sum();
    }

private:
    struct BlockSums {
        Eigen::MatrixXd g;
        Eigen::VectorXd squares, quartics;
    };

    /// Block b's part of X^T Z.^3 and of the column moments, in chunks of kChunkRows rows.
    void sumBlock(Index b, const Eigen::MatrixXd& rotation, Eigen::MatrixXd& zc, Eigen::MatrixXd& cubes) {
        BlockSums& s = partial_[static_cast<std::size_t>(b)];
        s.g.setZero(k_, k_);
        s.squares.setZero(k_);
        s.quartics.setZero(k_);
        const Index end = std::min(rows_, (b + 1) * kBlockRows);
        for (Index r0 = b * kBlockRows; r0 < end; r0 += kChunkRows) {
            const Index h = std::min(kChunkRows, end - r0);
            auto z = zc.topRows(h);
            auto c = cubes.topRows(h);
            z.noalias() = x_.middleRows(r0, h) * rotation;
            for (Index j = 0; j < k_; ++j) {
                double s2 = 0, s4 = 0;
                for (Index i = 0; i < h; ++i) {
                    const double v = z(i, j);
                    const double v2 = v * v;
                    c(i, j) = v2 * v;
                    s2 += v2;
                    s4 += v2 * v2;
                }
                s.squares[j] += s2;
                s.quartics[j] += s4;
            }
            s.g.noalias() += x_.middleRows(r0, h).transpose() * c;
        }
    }

    const Eigen::MatrixXd& x_;
    Communicator& comm_;
    Index rows_, k_, blocks_;
    std::vector<BlockSums> partial_;
    Eigen::MatrixXd xtx_;
    double inverseRows_;
};

}  // namespace

VarimaxResult varimax(const Eigen::Ref<const Eigen::MatrixXd>& loadings, const VarimaxOptions& options,
                      Communicator& comm) {
    return varimax(Eigen::MatrixXd(loadings), options, comm);
}

VarimaxResult varimax(Eigen::MatrixXd&& loadings, const VarimaxOptions& options, Communicator& comm) {
    if (!(options.tolerance >= 0)) throw std::invalid_argument("varimax: tolerance must be >= 0");
    if (options.maxIterations < 0) throw std::invalid_argument("varimax: negative iteration cap");
    const Index localRows = loadings.rows();
    double rowCount = static_cast<double>(localRows);
    comm.sum(&rowCount, 1);
    const Index p = static_cast<Index>(rowCount);
    const Index k = loadings.cols();
    VarimaxResult result;
    result.rotation = Eigen::MatrixXd::Identity(k, k);
    if (k < 2 || p == 0) {
        result.converged = true;
        result.objective.push_back(unrotatedCriterion(loadings, p, comm));
        result.rotated = std::move(loadings);
        return result;
    }

    Eigen::MatrixXd x = std::move(loadings);  // rotated where it lies
    Eigen::VectorXd scale;
    if (options.normalize) {
        scale = x.rowwise().norm();
        // A zero row has no direction to normalise; leave it (it contributes nothing either way).
        for (Index i = 0; i < localRows; ++i)
            if (scale[i] > 0) x.row(i) /= scale[i];
    }
    VarimaxGradient gradient(x, p, comm);
    Eigen::MatrixXd g(k, k);
    double criterion = gradient.evaluate(result.rotation, g);
    result.objective.push_back(criterion);
    for (int it = 0; it < options.maxIterations; ++it) {
        Eigen::JacobiSVD<Eigen::MatrixXd> svd(g, Eigen::ComputeFullU | Eigen::ComputeFullV);
        result.rotation.noalias() = svd.matrixU() * svd.matrixV().transpose();
        const double next = gradient.evaluate(result.rotation, g);
        result.objective.push_back(next);
        ++result.iterations;
        // Relative gain of the criterion itself (R stops on the sum of G's singular values, a
        // proxy; at convergence both reach the same stationary rotation).
        const double gain = next - criterion;
        criterion = next;
        if (gain <= options.tolerance * std::abs(next)) {
            result.converged = true;
            break;
        }
    }
    // X T in place, a chunk of rows at a time: the loadings are tall (N*C rows), and a second
    // N*C x k array here was a third of key selection's peak at a million points.
    Eigen::MatrixXd chunk;
    for (Index first = 0; first < localRows; first += VarimaxGradient::kBlockRows) {
        const Index count = std::min(VarimaxGradient::kBlockRows, localRows - first);
        chunk.noalias() = x.middleRows(first, count) * result.rotation;
        x.middleRows(first, count) = chunk;
    }
    if (options.normalize) {
        for (Index i = 0; i < localRows; ++i)
            if (scale[i] > 0) x.row(i) *= scale[i];
    }
    result.rotated = std::move(x);
    return result;
}

}  // namespace pmsc
