#include "pmsc/Varimax.h"

#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <stdexcept>

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

VarimaxResult varimax(const Eigen::Ref<const Eigen::MatrixXd>& loadings, const VarimaxOptions& options,
                      Communicator& comm) {
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
        result.rotated = loadings;
        result.converged = true;
        // The criterion from the column moments summed over ranks (varimaxCriterion on one rank).
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
        result.objective.push_back(total);
        return result;
    }

    Eigen::MatrixXd x = loadings;
    Eigen::VectorXd scale;
    if (options.normalize) {
        scale = x.rowwise().norm();
        // A zero row has no direction to normalise; leave it (it contributes nothing either way).
        for (Index i = 0; i < localRows; ++i)
            if (scale[i] > 0) x.row(i) /= scale[i];
    }

    // G = X^T (Z.^3 - Z diag(colSquares)/p) = X^T Z.^3 - (X^T X) T diag(colSquares)/p, Z = X T.
    // The blocks are tall (N*C rows, ~16 columns), so memory passes, not flops, set the cost of an
    // iteration. Each iteration therefore streams X once, in row chunks small enough to stay in
    // cache: Z, Z.^3, the column moments (criterion) and X^T Z.^3 are all made from the chunk
    // while it is hot, and Z itself is never stored until the end.
    Eigen::MatrixXd xtx = x.transpose() * x;
    comm.sum(xtx.data(), static_cast<std::size_t>(xtx.size()));
    const Index chunk = std::max<Index>(1, std::min<Index>(localRows, 512));
    Eigen::MatrixXd zc(chunk, k);
    Eigen::MatrixXd cubes(chunk, k);
    Eigen::VectorXd colSquares(k);
    Eigen::VectorXd colQuartics(k);
    Eigen::MatrixXd g(k, k);
    const double inverseRows = 1.0 / static_cast<double>(p);
    // Fills g (the gradient matrix) for the current rotation and returns the criterion there.
    auto evaluate = [&]() {
        g.setZero();
        colSquares.setZero();
        colQuartics.setZero();
        for (Index r0 = 0; r0 < localRows; r0 += chunk) {
            const Index h = std::min(chunk, localRows - r0);
            auto z = zc.topRows(h);
            auto c = cubes.topRows(h);
            z.noalias() = x.middleRows(r0, h) * result.rotation;
            for (Index j = 0; j < k; ++j) {
                double s2 = 0, s4 = 0;
                for (Index i = 0; i < h; ++i) {
                    const double v = z(i, j);
                    const double v2 = v * v;
                    c(i, j) = v2 * v;
                    s2 += v2;
                    s4 += v2 * v2;
                }
                colSquares[j] += s2;
                colQuartics[j] += s4;
            }
            g.noalias() += x.middleRows(r0, h).transpose() * c;
        }
        if (comm.size() > 1) {
            // One reduction per step: G's partial sums and both column moments.
            Eigen::VectorXd sums(k * k + 2 * k);
            sums.head(k * k) = Eigen::Map<const Eigen::VectorXd>(g.data(), k * k);
            sums.segment(k * k, k) = colSquares;
            sums.tail(k) = colQuartics;
            comm.sum(sums.data(), static_cast<std::size_t>(sums.size()));
            g = Eigen::Map<const Eigen::MatrixXd>(sums.data(), k, k);
            colSquares = sums.segment(k * k, k);
            colQuartics = sums.tail(k);
        }
        g.noalias() -= xtx * result.rotation * (colSquares * inverseRows).asDiagonal();
        const Eigen::ArrayXd m2 = colSquares.array() * inverseRows;
        return (colQuartics.array() * inverseRows - m2 * m2).sum();  // == varimaxCriterion(X T)
    };
    double criterion = evaluate();
    result.objective.push_back(criterion);
    for (int it = 0; it < options.maxIterations; ++it) {
        Eigen::JacobiSVD<Eigen::MatrixXd> svd(g, Eigen::ComputeFullU | Eigen::ComputeFullV);
        result.rotation.noalias() = svd.matrixU() * svd.matrixV().transpose();
        const double next = evaluate();
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
    Eigen::MatrixXd z = x * result.rotation;
    if (options.normalize) {
        for (Index i = 0; i < localRows; ++i)
            if (scale[i] > 0) z.row(i) *= scale[i];
    }
    result.rotated = std::move(z);
    return result;
}

}  // namespace pmsc
