#include "pmsc/IncrementalSvd.h"

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
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
    const auto bad = [](const std::string& what) { throw std::invalid_argument("incremental subspace: " + what); };
    if (frames < 1) bad("no frames absorbed");
    if (u.rows() != mean.size()) bad("basis has " + std::to_string(u.rows()) + " rows, mean " + std::to_string(mean.size()));
    if (u.cols() != sigma.size()) bad("basis has " + std::to_string(u.cols()) + " columns, " + std::to_string(sigma.size()) + " singular values");
    for (Index i = 0; i < sigma.size(); ++i) {
        if (!(sigma[i] > 0) || !std::isfinite(sigma[i])) bad("singular value " + std::to_string(i) + " is not positive");
        if (i > 0 && sigma[i] > sigma[i - 1]) bad("singular values are not descending at " + std::to_string(i));
    }
    if (!std::isfinite(totalEnergy) || totalEnergy < 0) bad("total energy is not a non-negative number");
    if (!std::isfinite(discardedEnergy) || discardedEnergy < 0) bad("discarded energy is not a non-negative number");
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
    const Eigen::VectorXd meanNew = newFrames.rowwise().mean();
    Eigen::MatrixXd b(rows, m + 1);
    b.leftCols(m) = newFrames.colwise() - meanNew;
    b.col(m) = std::sqrt(n * md / (n + md)) * (meanNew - s.mean);
    const double addedEnergy = b.squaredNorm();

    // Component of B^ outside span(U), projected out twice (one classical Gram-Schmidt pass
    // leaves an O(eps cond) component in U's directions; the second brings it to rounding).
    Eigen::MatrixXd l = Eigen::MatrixXd::Zero(r, m + 1);
    Eigen::MatrixXd h = b;
    for (int pass = 0; pass < 2 && r > 0; ++pass) {
        const Eigen::MatrixXd c = s.u.transpose() * h;
        h.noalias() -= s.u * c;
        l += c;
    }
    // H = J K with a rank-revealing QR: only the columns of J that H really spans are kept, so
    // J stays orthogonal to U (a plain QR of a rank-deficient H fills the null part of J with
    // arbitrary directions that need not be).
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(h);
    const double scale = std::max(b.norm(), s.sigma.size() > 0 ? s.sigma[0] : 0.0);
    const double absoluteDrop = std::max(1e-14, options.dropRelative) * scale;
    Index k = 0;
    if (qr.maxPivot() > absoluteDrop) {
        qr.setThreshold(absoluteDrop / qr.maxPivot());
        k = qr.rank();
    }
    Eigen::MatrixXd j(rows, k);
    Eigen::MatrixXd kMat(k, m + 1);
    if (k > 0) {
        j = qr.householderQ() * Eigen::MatrixXd::Identity(rows, k);
        const Eigen::MatrixXd rTop = qr.matrixR().topRows(k).triangularView<Eigen::Upper>();
        kMat = rTop * qr.colsPermutation().transpose();
        // J from Householder reflections of H is orthogonal to U only up to H's own rounding;
        // one more projection keeps U' orthonormal over many nightly updates.
        if (r > 0) {
            j.noalias() -= s.u * (s.u.transpose() * j);
            Eigen::HouseholderQR<Eigen::MatrixXd> again(j);
            const Eigen::MatrixXd rj = again.matrixQR().topRows(k).triangularView<Eigen::Upper>();
            j = again.householderQ() * Eigen::MatrixXd::Identity(rows, k);
            kMat = rj * kMat;
        }
    }

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

    const Eigen::MatrixXd coreU = svd.matrixU().leftCols(keep);
    Eigen::MatrixXd u(rows, keep);
    u.noalias() = s.u * coreU.topRows(r);
    if (k > 0) u.noalias() += j * coreU.bottomRows(k);

    s.u = std::move(u);
    s.sigma = sv.head(keep);
    s.mean = (n * s.mean + md * meanNew) / (n + md);
    s.frames += m;
    s.totalEnergy += addedEnergy;
    s.discardedEnergy += discarded;
}

double largestPrincipalAngle(const Eigen::Ref<const Eigen::MatrixXd>& a, const Eigen::Ref<const Eigen::MatrixXd>& b) {
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
