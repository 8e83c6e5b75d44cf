#include "pmsc/Subspace.h"

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>

namespace pmsc {

namespace {

// Thin Q of a Householder QR: the orthonormal basis of range(a) (a has full column rank in
// exact arithmetic; numerically, the Householder vectors stay orthonormal regardless).
void orthonormalize(Eigen::MatrixXd& a) {
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(a);
    Eigen::MatrixXd thin = Eigen::MatrixXd::Identity(a.rows(), a.cols());
    thin.applyOnTheLeft(qr.householderQ());
    a.swap(thin);
}

// Keeps the leading columns whose singular value is above `threshold`, at most `rank`.
void truncate(TruncatedSvd& s, Index rank, double threshold) {
    Index keep = 0;
    while (keep < std::min<Index>(rank, s.sigma.size()) && s.sigma[keep] > threshold) ++keep;
    s.u.conservativeResize(Eigen::NoChange, keep);
    s.v.conservativeResize(Eigen::NoChange, keep);
    s.sigma.conservativeResize(keep);
}

TruncatedSvd randomizedSvd(const Eigen::Ref<const Eigen::MatrixXd>& q, Index rank,
                           const SvdOptions& options) {
    const Index m = q.rows();
    const Index n = q.cols();
    const Index l = std::min({rank + options.oversampling, m, n});
    std::mt19937_64 rng(options.seed);
    std::normal_distribution<double> normal(0.0, 1.0);
    Eigen::MatrixXd omega(n, l);
    // Filled column by column in a fixed order so the sketch depends only on the seed.
    for (Index j = 0; j < l; ++j)
        for (Index i = 0; i < n; ++i) omega(i, j) = normal(rng);

    Eigen::MatrixXd y(m, l);
    y.noalias() = q * omega;
    orthonormalize(y);
    Eigen::MatrixXd z(n, l);
    for (int it = 0; it < options.powerIterations; ++it) {
        // Re-orthonormalising after every product keeps the small singular directions from being
        // swamped by rounding (Halko et al. algorithm 4.4).
        z.noalias() = q.transpose() * y;
        orthonormalize(z);
        y.noalias() = q * z;
        orthonormalize(y);
    }
    // B = Y^T Q is l x n: small. Its SVD gives Q ~= (Y U_B) S V_B^T.
    Eigen::MatrixXd b(l, n);
    b.noalias() = y.transpose() * q;
    // B is l x n with l small (the Auto route only sketches when l is far below n): a QR then
    // Jacobi on l x l. (JacobiSVD rather than BDCSVD: as fast at this size and much lighter to
    // compile, which matters for the sanitizer builds.)
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(b, Eigen::ComputeThinU | Eigen::ComputeThinV);
    TruncatedSvd s;
    const Index r = std::min(rank, svd.singularValues().size());
    s.sigma = svd.singularValues().head(r);
    s.v = svd.matrixV().leftCols(r);
    truncate(s, r, (s.sigma.size() > 0 ? s.sigma[0] : 0.0) * 1e-12);
    s.u.noalias() = y * svd.matrixU().leftCols(s.sigma.size());
    return s;
}

}  // namespace

TruncatedSvd truncatedSvd(const Eigen::Ref<const Eigen::MatrixXd>& q, Index rank, const SvdOptions& options) {
    if (rank < 1) throw std::invalid_argument("truncatedSvd: rank must be >= 1, got " + std::to_string(rank));
    if (q.rows() < 1 || q.cols() < 1) throw std::invalid_argument("truncatedSvd: empty matrix");
    if (options.oversampling < 0) throw std::invalid_argument("truncatedSvd: negative oversampling");
    if (options.powerIterations < 0) {
        throw std::invalid_argument("truncatedSvd: negative power iteration count");
    }
    rank = std::min({rank, q.rows(), q.cols()});
    const bool tall = q.cols() <= q.rows();
    SvdOptions::Route route = options.route;
    if (route == SvdOptions::Route::Auto) {
        // Flop counts of the two routes (see header); the constant factors of Eigen's GEMM and
        // Householder QR are close enough that the counts decide.
        const Index l = std::min({rank + options.oversampling, q.rows(), q.cols()});
        const Index r = options.leftVectors < 0 ? rank : std::min(rank, options.leftVectors);
        const double gram = gramRouteFlops(q.rows(), q.cols(), r);
        const double randomized = randomizedRouteFlops(q.rows(), q.cols(), l, options.powerIterations);
        route = tall && gram <= randomized ? SvdOptions::Route::Gram : SvdOptions::Route::Randomized;
    }
    if (route == SvdOptions::Route::Gram) {
        if (!tall) throw std::invalid_argument("truncatedSvd: the Gram route needs cols <= rows");
        Eigen::MatrixXd gram = gramMatrix(q);
        TruncatedSvd s = svdFromGram(q, gram, rank, options.leftVectors);
        s.gram = std::move(gram);
        return s;
    }
    return randomizedSvd(q, rank, options);
}

double gramRouteFlops(Index rows, Index cols, Index leftVectors) {
    const double m = static_cast<double>(rows);
    const double n = static_cast<double>(cols);
    return m * n * n + 9 * n * n * n + 2 * m * n * static_cast<double>(std::max<Index>(leftVectors, 0));
}

double randomizedRouteFlops(Index rows, Index cols, Index sketch, int powerIterations) {
    const double m = static_cast<double>(rows);
    const double n = static_cast<double>(cols);
    const double l = static_cast<double>(sketch);
    const double q = powerIterations;
    return 2 * m * n * l * (2 * q + 2) + 4 * m * l * l * (q + 1);
}

void formLeftVectors(const Eigen::Ref<const Eigen::MatrixXd>& q, TruncatedSvd& svd, Index count) {
    count = std::min(count, svd.sigma.size());
    const Index have = svd.u.cols();
    if (!svd.gramRoute || have >= count) return;
    svd.u.conservativeResize(q.rows(), count);
    svd.u.rightCols(count - have).noalias() = q * svd.v.middleCols(have, count - have);
    for (Index i = have; i < count; ++i) svd.u.col(i) /= svd.sigma[i];
}

Eigen::MatrixXd gramMatrix(const Eigen::Ref<const Eigen::MatrixXd>& q) {
    const Index n = q.cols();
    Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(n, n);
    gram.selfadjointView<Eigen::Lower>().rankUpdate(q.transpose());
    gram.triangularView<Eigen::StrictlyUpper>() = gram.transpose();
    return gram;
}

TruncatedSvd svdFromGram(const Eigen::Ref<const Eigen::MatrixXd>& q, const Eigen::MatrixXd& g, Index rank,
                         Index leftVectors, double dropBelow) {
    const Index n = g.cols();
    if (g.rows() != n || q.cols() != n) throw std::invalid_argument("svdFromGram: Gram matrix size mismatch");
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(g);
    if (eig.info() != Eigen::Success) throw std::runtime_error("svdFromGram: eigen solver failed");
    // Eigenvalues come ascending; reverse to descending.
    const Index r = std::min(rank, n);
    TruncatedSvd s;
    s.gramRoute = true;
    s.sigma.resize(r);
    s.v.resize(n, r);
    for (Index i = 0; i < r; ++i) {
        const Index j = n - 1 - i;
        s.sigma[i] = std::sqrt(std::max(0.0, eig.eigenvalues()[j]));
        s.v.col(i) = eig.eigenvectors().col(j);
    }
    const double largest =
        eig.eigenvalues().size() > 0 ? std::sqrt(std::max(0.0, eig.eigenvalues()[n - 1])) : 0.0;
    truncate(s, rank, std::max(dropBelow, largest * 1e-7));
    s.u.resize(q.rows(), 0);
    formLeftVectors(q, s, leftVectors < 0 ? s.sigma.size() : leftVectors);
    return s;
}

Eigen::VectorXd removeRowMean(const Eigen::Ref<const Eigen::MatrixXd>& raw, Eigen::MatrixXd& centered) {
    Eigen::VectorXd mean = raw.rowwise().mean();
    centered = raw.colwise() - mean;
    return mean;
}

double maxPointNorm(const Eigen::Ref<const Eigen::MatrixXd>& residual, Index channels) {
    return residual.cols() == 0 ? 0.0 : maxPointNormPerColumn(residual, channels).maxCoeff();
}

Eigen::VectorXd maxPointNormPerColumn(const Eigen::Ref<const Eigen::MatrixXd>& residual, Index channels) {
    const Index points = residual.rows() / channels;
    Eigen::VectorXd out(residual.cols());
    for (Index t = 0; t < residual.cols(); ++t) {
        const double* col = residual.col(t).data();
        double best = 0;
        for (Index p = 0; p < points; ++p) {
            double s = 0;
            for (Index c = 0; c < channels; ++c) s += col[p * channels + c] * col[p * channels + c];
            // NaN must win: a NaN residual is an unusable frame, not a small error.
            if (!(s <= best)) best = s;
        }
        out[t] = std::sqrt(best);
    }
    return out;
}

Index basisSizeForEnergy(const Eigen::VectorXd& sigma, double totalEnergy, double energy) {
    if (!(energy > 0 && energy <= 1)) {
        throw std::invalid_argument("energy fraction must be in (0, 1], got " + std::to_string(energy));
    }
    const double target = energy * totalEnergy;
    double captured = 0;
    for (Index i = 0; i < sigma.size(); ++i) {
        captured += sigma[i] * sigma[i];
        // A relative slack of a few ulps so energy = 1 on exactly low-rank data is reachable
        // despite rounding in sigma.
        if (captured >= target * (1 - 1e-12)) return i + 1;
    }
    return sigma.size();
}

void accumulateBasisErrors(const Eigen::Ref<const Eigen::MatrixXd>& qRows,
                           const Eigen::Ref<const Eigen::MatrixXd>& uRows, const TruncatedSvd& svd,
                           Index channels, std::vector<double>& worst) {
    const Index maxM = static_cast<Index>(worst.size());
    const Index n = qRows.cols();
    // Chunks of frames small enough that the residual chunk stays in cache while all maxM rank-one
    // downdates sweep over it; the coordinates of a frame are sigma_i v_i[t].
    const Index chunk = 4;
    Eigen::MatrixXd r;
    Eigen::MatrixXd coords;
    for (Index t0 = 0; t0 < n; t0 += chunk) {
        const Index w = std::min(chunk, n - t0);
        r = qRows.middleCols(t0, w);
        coords = (svd.v.middleRows(t0, w).leftCols(maxM) * svd.sigma.head(maxM).asDiagonal()).transpose();
        for (Index i = 0; i < maxM; ++i) {
            r.noalias() -= uRows.col(i) * coords.row(i);
            double e = maxPointNorm(r, channels);
            auto& slot = worst[static_cast<size_t>(i)];
            if (!(e <= slot)) slot = e;
        }
    }
}

Index basisSizeFromErrors(const std::vector<double>& worst, double maxError) {
    const Index maxM = static_cast<Index>(worst.size());
    for (Index i = 0; i < maxM; ++i)
        if (worst[static_cast<size_t>(i)] <= maxError) return i + 1;
    return maxM + 1;
}

Index basisSizeForMaxError(const Eigen::Ref<const Eigen::MatrixXd>& q, const TruncatedSvd& svd,
                           Index channels, double maxError, Index maxM, std::vector<double>* errors) {
    maxM = std::min<Index>(maxM, svd.sigma.size());
    std::vector<double> worst(static_cast<size_t>(maxM), 0.0);
    accumulateBasisErrors(q, svd.u, svd, channels, worst);
    if (errors) *errors = worst;
    return basisSizeFromErrors(worst, maxError);
}

}  // namespace pmsc
