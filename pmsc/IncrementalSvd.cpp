#include "pmsc/IncrementalSvd.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace pmsc {

double IncrementalSubspace::tailNorm() const {
    return std::sqrt(std::max(0.0, totalEnergy - sigma.squaredNorm()));
}

void IncrementalSubspace::validate() const {
    const auto bad = [](const std::string& what) {
        throw std::invalid_argument("incremental subspace: " + what);
    };
    if (frames < 1) bad("no frames absorbed");
    if (u.rows() != mean.size())
        bad("basis has " + std::to_string(u.rows()) + " rows, mean " + std::to_string(mean.size()));
    if (u.cols() != sigma.size())
        bad("basis has " + std::to_string(u.cols()) + " columns, " + std::to_string(sigma.size()) +
            " singular values");
    for (Index i = 0; i < sigma.size(); ++i) {
        if (!(sigma[i] > 0) || !std::isfinite(sigma[i]))
            bad("singular value " + std::to_string(i) + " is not positive");
        if (i > 0 && sigma[i] > sigma[i - 1])
            bad("singular values are not descending at " + std::to_string(i));
    }
    if (!std::isfinite(totalEnergy) || totalEnergy < 0) bad("total energy is not a non-negative number");
    if (!std::isfinite(discardedEnergy) || discardedEnergy < 0)
        bad("discarded energy is not a non-negative number");
    if (!mean.allFinite() || !u.allFinite()) bad("mean or basis holds NaN or Inf");
}

void updateSubspace(IncrementalSubspace& s, const Eigen::Ref<const Eigen::MatrixXd>& newFrames,
                    const IncrementalSvdOptions& options) {
    const Index rows = s.mean.size();
    const Index m = newFrames.cols();
    if (newFrames.rows() != rows) {
        throw std::invalid_argument("incremental SVD: new frames have " + std::to_string(newFrames.rows()) +
                                    " values each, the subspace " + std::to_string(rows));
    }
    if (m < 1) throw std::invalid_argument("incremental SVD: no new frames");
    if (options.maxRank < 0) throw std::invalid_argument("incremental SVD: max rank must be >= 0");
    const Index r = s.rank();
    const double n = static_cast<double>(s.frames);
    const double md = static_cast<double>(m);

    // B^: the new frames about their own mean, plus the column that moves the old mean to the new
    // one (Ross et al. 2008): the union's scatter about its mean is the old scatter + B^ B^^T.
    // Built in place as H, which becomes the part of B^ outside span(U) (no second copy of the
    // new frames: at the face's size each copy of 700 frames is 450 MB).
    const Eigen::VectorXd meanNew = newFrames.rowwise().mean();
    Eigen::MatrixXd h(rows, m + 1);
    h.leftCols(m) = newFrames.colwise() - meanNew;
    h.col(m) = std::sqrt(n * md / (n + md)) * (meanNew - s.mean);
    const double addedEnergy = h.squaredNorm();

    // Component of B^ outside span(U), projected out twice (one classical Gram-Schmidt pass
    // leaves an O(eps cond) component in U's directions; the second brings it to rounding).
    Eigen::MatrixXd l = Eigen::MatrixXd::Zero(r, m + 1);
    for (int pass = 0; pass < 2 && r > 0; ++pass) {
        const Eigen::MatrixXd c = s.u.transpose() * h;
        h.noalias() -= s.u * c;
        l += c;
    }
    // H = J K from the eigen-decomposition of the small Gram matrix H^T H = V diag(lambda) V^T:
    // J = H V_k lambda_k^{-1/2} (never formed), K = lambda_k^{1/2} V_k^T, keeping the k directions
    // whose singular value sqrt(lambda) exceeds 1e-7 of the data's scale (below that the Gram
    // matrix's rounding, ~1e-16 of the largest lambda, would make them noise; their energy is
    // under 1e-14 of the total). Decision: a Gram eigenproblem rather than a pivoted QR of the
    // tall H: one symmetric rank-k product (BLAS 3) instead of a column-by-column Householder
    // sweep, about 10x faster at the face's size; the orthogonality lost by squaring is restored
    // by the final re-orthonormalization below.
    Eigen::MatrixXd gram(m + 1, m + 1);
    gram.setZero();
    gram.selfadjointView<Eigen::Lower>().rankUpdate(h.transpose());
    // (the eigensolver reads the lower triangle only)
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(gram);
    const Eigen::VectorXd& lambda = eig.eigenvalues();  // ascending
    const double scale = std::max(std::sqrt(std::max(0.0, lambda[m])), s.sigma.size() > 0 ? s.sigma[0] : 0.0);
    const double keepAbove = std::max(1e-7, options.dropRelative) * scale;
    Index k = 0;
    while (k < m + 1 && lambda[m - k] > 0 && std::sqrt(lambda[m - k]) > keepAbove) ++k;
    const Eigen::MatrixXd vk = eig.eigenvectors().rightCols(k).rowwise().reverse();  // descending
    Eigen::VectorXd rootLambda(k);
    for (Index i = 0; i < k; ++i) rootLambda[i] = std::sqrt(lambda[m - i]);
    const Eigen::MatrixXd kMat = rootLambda.asDiagonal() * vk.transpose();  // k x (m + 1)

    // The small core: [diag(sigma) L; 0 K].
    Eigen::MatrixXd core = Eigen::MatrixXd::Zero(r + k, r + m + 1);
    core.topLeftCorner(r, r) = s.sigma.asDiagonal();
    core.topRightCorner(r, m + 1) = l;
    if (k > 0) core.bottomRightCorner(k, m + 1) = kMat;
    Eigen::BDCSVD<Eigen::MatrixXd> svd(core, Eigen::ComputeThinU);
    const Eigen::VectorXd& sv = svd.singularValues();
    const double drop = options.dropRelative * (sv.size() > 0 ? sv[0] : 0.0);
    Index keep = 0;
    while (keep < sv.size() && sv[keep] > drop) ++keep;
    if (options.maxRank > 0) keep = std::min(keep, options.maxRank);
    double discarded = 0;
    for (Index i = keep; i < sv.size(); ++i) discarded += sv[i] * sv[i];

    // U' = [U J] U~ = U U~_top + H (V_k lambda_k^{-1/2} U~_bottom): J is applied, never stored.
    const Eigen::MatrixXd coreU = svd.matrixU().leftCols(keep);
    Eigen::MatrixXd u(rows, keep);
    u.noalias() = s.u * coreU.topRows(r);
    if (k > 0) {
        const Eigen::MatrixXd toH = vk * rootLambda.cwiseInverse().asDiagonal() * coreU.bottomRows(k);
        u.noalias() += h * toH;
    }
    Eigen::VectorXd sigma = sv.head(keep);
    // Re-orthonormalize (Cholesky QR of U', then the SVD of R diag(sigma)): keeps U' orthonormal
    // to rounding over many nightly updates whatever J lost to the Gram matrix.
    if (keep > 0) {
        Eigen::MatrixXd g = u.transpose() * u;
        Eigen::LLT<Eigen::MatrixXd> llt(g);
        if (llt.info() == Eigen::Success) {
            const Eigen::MatrixXd rFactor = llt.matrixU();
            const Eigen::MatrixXd q = llt.matrixU().solve<Eigen::OnTheRight>(u);
            Eigen::JacobiSVD<Eigen::MatrixXd> small(rFactor * sigma.asDiagonal(), Eigen::ComputeFullU);
            u.noalias() = q * small.matrixU();
            sigma = small.singularValues();
        }
    }

    s.u = std::move(u);
    s.sigma = std::move(sigma);
    s.mean = (n * s.mean + md * meanNew) / (n + md);
    s.frames += m;
    s.totalEnergy += addedEnergy;
    s.discardedEnergy += discarded;
}

double largestPrincipalAngle(const Eigen::Ref<const Eigen::MatrixXd>& a,
                             const Eigen::Ref<const Eigen::MatrixXd>& b) {
    if (a.rows() != b.rows()) throw std::invalid_argument("principal angles: row counts differ");
    if (b.cols() == 0) return 0;
    // sin(theta_max) = ||(I - A A^T) B||_2, from the small Gram matrix of the residual: accurate
    // for small angles, where acos of the cosines would lose half the digits.
    Eigen::MatrixXd residual = b;
    residual.noalias() -= a * (a.transpose() * b);
    const Eigen::MatrixXd g = residual.transpose() * residual;
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(g, Eigen::EigenvaluesOnly);
    const double s2 = std::max(0.0, eig.eigenvalues().maxCoeff());
    return std::asin(std::min(1.0, std::sqrt(s2)));
}

}  // namespace pmsc
