#include "pmsc/Varimax.h"

#include <Eigen/SVD>

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
    if (!(options.tolerance >= 0)) throw std::invalid_argument("varimax: tolerance must be >= 0");
    if (options.maxIterations < 0) throw std::invalid_argument("varimax: negative iteration cap");
    const Index p = loadings.rows();
    const Index k = loadings.cols();
    VarimaxResult result;
    result.rotation = Eigen::MatrixXd::Identity(k, k);
    if (k < 2 || p == 0) {
        result.rotated = loadings;
        result.converged = true;
        result.objective.push_back(varimaxCriterion(loadings));
        return result;
    }

    Eigen::MatrixXd x = loadings;
    Eigen::VectorXd scale;
    if (options.normalize) {
        scale = x.rowwise().norm();
        // A zero row has no direction to normalise; leave it (it contributes nothing either way).
        for (Index i = 0; i < p; ++i)
            if (scale[i] > 0) x.row(i) /= scale[i];
    }

    // Per iteration: two (p x k)(k x k) products and ONE pass over Z that yields Z.^3 and both
    // column moments (criterion and the diag term of G at once). The blocks are tall (N*C rows
    // of 16 columns), so passes over Z, not flops, are what an iteration costs.
    // G = X^T (Z.^3 - Z diag(colSquares)/p) = X^T Z.^3 - (X^T X) T diag(colSquares)/p.
    const Eigen::MatrixXd xtx = x.transpose() * x;
    Eigen::MatrixXd z = x;
    Eigen::MatrixXd cubes(p, k);
    Eigen::VectorXd colSquares(k);
    Eigen::MatrixXd g(k, k);
    const double inverseRows = 1.0 / static_cast<double>(p);
    auto moments = [&]() {
        double total = 0;
        for (Index j = 0; j < k; ++j) {
            const double* zc = z.col(j).data();
            double* cc = cubes.col(j).data();
            double s2 = 0, s4 = 0;
            for (Index i = 0; i < p; ++i) {
                const double v = zc[i];
                const double v2 = v * v;
                cc[i] = v2 * v;
                s2 += v2;
                s4 += v2 * v2;
            }
            colSquares[j] = s2;
            const double m2 = s2 * inverseRows;
            total += s4 * inverseRows - m2 * m2;
        }
        return total;  // == varimaxCriterion(z)
    };
    double criterion = moments();
    result.objective.push_back(criterion);
    for (int it = 0; it < options.maxIterations; ++it) {
        g.noalias() = x.transpose() * cubes;
        g.noalias() -= xtx * result.rotation * (colSquares * inverseRows).asDiagonal();
        Eigen::JacobiSVD<Eigen::MatrixXd> svd(g, Eigen::ComputeFullU | Eigen::ComputeFullV);
        result.rotation.noalias() = svd.matrixU() * svd.matrixV().transpose();
        z.noalias() = x * result.rotation;
        const double next = moments();
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
    if (options.normalize) {
        for (Index i = 0; i < p; ++i)
            if (scale[i] > 0) z.row(i) *= scale[i];
    }
    result.rotated = std::move(z);
    return result;
}

}  // namespace pmsc
