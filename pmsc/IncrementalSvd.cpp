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

namespace {

void checkUpdate(const IncrementalSubspace& s, const Eigen::Ref<const Eigen::MatrixXd>& newFrames,
                 const IncrementalSvdOptions& options) {
    if (newFrames.rows() != s.mean.size()) {
        throw std::invalid_argument("incremental SVD: new frames have " + std::to_string(newFrames.rows()) +
                                    " values each, the subspace " + std::to_string(s.mean.size()));
    }
    if (newFrames.cols() < 1) throw std::invalid_argument("incremental SVD: no new frames");
    if (options.maxRank < 0) throw std::invalid_argument("incremental SVD: max rank must be >= 0");
}

/// Projects span(U) out of h twice (one classical Gram-Schmidt pass leaves an O(eps cond)
/// component in U's directions; the second brings it to rounding); returns U^T h (before).
Eigen::MatrixXd projectOut(const Eigen::MatrixXd& u, Eigen::MatrixXd& h) {
    Eigen::MatrixXd l = Eigen::MatrixXd::Zero(u.cols(), h.cols());
    for (int pass = 0; pass < 2 && u.cols() > 0; ++pass) {
        const Eigen::MatrixXd c = u.transpose() * h;
        h.noalias() -= u * c;
        l += c;
    }
    return l;
}

/// H = J K from the eigen-decomposition of the small Gram matrix H^T H = V diag(lambda) V^T:
/// J = H V_k lambda_k^{-1/2} (= H * toJ), K = lambda_k^{1/2} V_k^T, keeping the k directions whose
/// singular value sqrt(lambda) exceeds 1e-7 of the data's scale (below that the Gram matrix's
/// rounding, ~1e-16 of the largest lambda, would make them noise; their energy is under 1e-14 of
/// the total). Decision: a Gram eigenproblem rather than a pivoted QR of the tall H: one symmetric
/// rank-k product (BLAS 3) instead of a column-by-column Householder sweep, about 10x faster at the
/// face's size; the orthogonality lost by squaring is restored by reorthonormalize().
struct GramFactor {
    Eigen::MatrixXd toJ;  ///< cols(H) x k
    Eigen::MatrixXd k;    ///< k x cols(H)
};

GramFactor factorOutside(const Eigen::MatrixXd& h, double sigmaMax, const IncrementalSvdOptions& options) {
    const Index c = h.cols();
    Eigen::MatrixXd gram(c, c);
    gram.setZero();
    gram.selfadjointView<Eigen::Lower>().rankUpdate(h.transpose());
    // (the eigensolver reads the lower triangle only)
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(gram);
    const Eigen::VectorXd& lambda = eig.eigenvalues();  // ascending
    const double scale = std::max(std::sqrt(std::max(0.0, lambda[c - 1])), sigmaMax);
    const double keepAbove = std::max(1e-7, options.dropRelative) * scale;
    Index k = 0;
    while (k < c && lambda[c - 1 - k] > 0 && std::sqrt(lambda[c - 1 - k]) > keepAbove) ++k;
    const Eigen::MatrixXd vk = eig.eigenvectors().rightCols(k).rowwise().reverse();  // descending
    Eigen::VectorXd rootLambda(k);
    for (Index i = 0; i < k; ++i) rootLambda[i] = std::sqrt(lambda[c - 1 - i]);
    GramFactor f;
    f.toJ = vk * rootLambda.cwiseInverse().asDiagonal();
    f.k = rootLambda.asDiagonal() * vk.transpose();
    return f;
}

/// The leading left singular vectors of the core (those over options.dropRelative of the largest,
/// at most options.maxRank), their singular values, and the energy of the rest.
struct CoreSvd {
    Eigen::MatrixXd u;
    Eigen::VectorXd sigma;
    double discarded = 0;
};

CoreSvd truncatedCoreSvd(const Eigen::MatrixXd& core, const IncrementalSvdOptions& options) {
    Eigen::BDCSVD<Eigen::MatrixXd> svd(core, Eigen::ComputeThinU);
    const Eigen::VectorXd& sv = svd.singularValues();
    const double drop = options.dropRelative * (sv.size() > 0 ? sv[0] : 0.0);
    Index keep = 0;
    while (keep < sv.size() && sv[keep] > drop) ++keep;
    if (options.maxRank > 0) keep = std::min(keep, options.maxRank);
    CoreSvd out;
    for (Index i = keep; i < sv.size(); ++i) out.discarded += sv[i] * sv[i];
    out.u = svd.matrixU().leftCols(keep);
    out.sigma = sv.head(keep);
    return out;
}

/// U' = [U J] U~ = U U~_top + H (toJ U~_bottom): J is applied, never stored.
Eigen::MatrixXd rotateInto(const Eigen::MatrixXd& u, const Eigen::MatrixXd& h, const Eigen::MatrixXd& toJ,
                           const Eigen::MatrixXd& coreU) {
    const Index r = u.cols(), k = toJ.cols();
    Eigen::MatrixXd out(u.rows(), coreU.cols());
    out.noalias() = u * coreU.topRows(r);
    if (k > 0) {
        const Eigen::MatrixXd toH = toJ * coreU.bottomRows(k);
        out.noalias() += h * toH;
    }
    return out;
}

/// Re-orthonormalizes U' (Cholesky QR, then the SVD of R diag(sigma)): keeps U' orthonormal to
/// rounding over many nightly updates whatever J lost to the Gram matrix.
void reorthonormalize(Eigen::MatrixXd& u, Eigen::VectorXd& sigma) {
    if (u.cols() == 0) return;
    Eigen::MatrixXd g = u.transpose() * u;
    Eigen::LLT<Eigen::MatrixXd> llt(g);
    if (llt.info() != Eigen::Success) return;
    const Eigen::MatrixXd rFactor = llt.matrixU();
    const Eigen::MatrixXd q = llt.matrixU().solve<Eigen::OnTheRight>(u);
    Eigen::JacobiSVD<Eigen::MatrixXd> small(rFactor * sigma.asDiagonal(), Eigen::ComputeFullU);
    u.noalias() = q * small.matrixU();
    sigma = small.singularValues();
}

}  // namespace

void updateSubspace(IncrementalSubspace& s, const Eigen::Ref<const Eigen::MatrixXd>& newFrames,
                    const IncrementalSvdOptions& options) {
    checkUpdate(s, newFrames, options);
    const Index rows = s.mean.size();
    const Index m = newFrames.cols();
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

    const Eigen::MatrixXd l = projectOut(s.u, h);
    const GramFactor jk = factorOutside(h, s.sigma.size() > 0 ? s.sigma[0] : 0.0, options);
    const Index k = jk.k.rows();

    // The small core: [diag(sigma) L; 0 K].
    Eigen::MatrixXd core = Eigen::MatrixXd::Zero(r + k, r + m + 1);
    core.topLeftCorner(r, r) = s.sigma.asDiagonal();
    core.topRightCorner(r, m + 1) = l;
    if (k > 0) core.bottomRightCorner(k, m + 1) = jk.k;
    CoreSvd c = truncatedCoreSvd(core, options);
    Eigen::MatrixXd u = rotateInto(s.u, h, jk.toJ, c.u);
    reorthonormalize(u, c.sigma);

    s.u = std::move(u);
    s.sigma = std::move(c.sigma);
    s.mean = (n * s.mean + md * meanNew) / (n + md);
    s.frames += m;
    s.totalEnergy += addedEnergy;
    s.discardedEnergy += c.discarded;
}

UpdateSpan spanOfUpdate(const IncrementalSubspace& state, const Eigen::Ref<const Eigen::MatrixXd>& newFrames,
                        const IncrementalSvdOptions& options) {
    checkUpdate(state, newFrames, options);
    UpdateSpan span;
    span.h = newFrames.colwise() - state.mean;
    const Eigen::MatrixXd l = projectOut(state.u, span.h);
    GramFactor jk = factorOutside(span.h, state.sigma.size() > 0 ? state.sigma[0] : 0.0, options);
    span.toJ = std::move(jk.toJ);
    span.coords.resize(l.rows() + jk.k.rows(), newFrames.cols());
    span.coords.topRows(l.rows()) = l;
    span.coords.bottomRows(jk.k.rows()) = jk.k;
    return span;
}

IncrementalSubspace updateInSpan(const IncrementalSubspace& state, const UpdateSpan& span,
                                 const Eigen::Ref<const Eigen::MatrixXd>& newFrames,
                                 const std::vector<Index>& columns, const IncrementalSvdOptions& options) {
    checkUpdate(state, newFrames, options);
    const Index r = state.rank(), w = span.coords.rows();
    const Index mo = static_cast<Index>(columns.size());
    if (mo < 1) throw std::invalid_argument("incremental SVD: no frames chosen");
    if (span.coords.cols() != newFrames.cols() || w != r + span.toJ.cols())
        throw std::invalid_argument("incremental SVD: the span is not of these frames and this state");
    Eigen::MatrixXd z(w, mo);
    Eigen::VectorXd meanChosen = Eigen::VectorXd::Zero(state.mean.size());
    for (Index j = 0; j < mo; ++j) {
        const Index c = columns[static_cast<size_t>(j)];
        if (c < 0 || c >= newFrames.cols())
            throw std::invalid_argument("incremental SVD: column out of range");
        z.col(j) = span.coords.col(c);
        meanChosen += newFrames.col(c);
    }
    meanChosen /= static_cast<double>(mo);
    const double n = static_cast<double>(state.frames), md = static_cast<double>(mo);
    // B^ of updateSubspace in W's coordinates: the chosen frames about their mean, and the column
    // sqrt(n m / (n + m)) (mu_B - mu_A), whose coordinates are the chosen coordinates' mean.
    const Eigen::VectorXd zMean = z.rowwise().mean();
    Eigen::MatrixXd core = Eigen::MatrixXd::Zero(w, r + mo + 1);
    core.topLeftCorner(r, r) = state.sigma.asDiagonal();
    core.middleCols(r, mo) = z.colwise() - zMean;
    core.col(r + mo) = std::sqrt(n * md / (n + md)) * zMean;
    CoreSvd small = truncatedCoreSvd(core, options);
    IncrementalSubspace out;
    out.u = rotateInto(state.u, span.h, span.toJ, small.u);
    reorthonormalize(out.u, small.sigma);
    out.sigma = std::move(small.sigma);
    // The mean and energy exactly, from the frames (W holds them only to its dropped directions).
    double added = n * md / (n + md) * (meanChosen - state.mean).squaredNorm();
    for (Index col : columns) added += (newFrames.col(col) - meanChosen).squaredNorm();
    out.mean = (n * state.mean + md * meanChosen) / (n + md);
    out.frames = state.frames + mo;
    out.totalEnergy = state.totalEnergy + added;
    out.discardedEnergy = state.discardedEnergy + small.discarded;
    return out;
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
