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

    Eigen::MatrixXd z = x;
    Eigen::MatrixXd target(p, k);
    Eigen::MatrixXd g(k, k);
    double criterion = varimaxCriterion(z);
    result.objective.push_back(criterion);
    for (int it = 0; it < options.maxIterations; ++it) {
        const Eigen::RowVectorXd colSquares = z.array().square().colwise().sum();
        target = z.array().cube().matrix() - z * (colSquares / static_cast<double>(p)).asDiagonal();
        g.noalias() = x.transpose() * target;
        Eigen::JacobiSVD<Eigen::MatrixXd> svd(g, Eigen::ComputeFullU | Eigen::ComputeFullV);
        result.rotation.noalias() = svd.matrixU() * svd.matrixV().transpose();
        z.noalias() = x * result.rotation;
        const double next = varimaxCriterion(z);
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
