// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <Eigen/Core>

#include <vector>

namespace pmsc {

/// Options of the truncated SVD (section 3; randomized route after Halko, Martinsson & Tropp
/// 2011, "Finding structure with randomness", algorithms 4.4 and 5.1).
struct SvdOptions {
    Index oversampling = 10;   ///< extra test vectors p: the sketch has l = rank + p columns
    int powerIterations = 2;   ///< subspace iterations q (each one a Q^T and a Q product)
    unsigned seed = 20070101;  ///< seed of the Gaussian test matrix (std::mt19937_64): deterministic
};

/// A truncated SVD Q ~= U diag(sigma) V^T with sigma descending.
struct TruncatedSvd {
    Eigen::MatrixXd u;      ///< rows x r, orthonormal columns: the basis vectors a_i[x]
    Eigen::VectorXd sigma;  ///< r singular values, descending, all > the drop threshold
    Eigen::MatrixXd v;      ///< cols x r, orthonormal columns: b_i[t] / sigma_i
    bool gramRoute = false; ///< true if computed from Q^T Q (see truncatedSvd)
};

/// The leading `rank` singular triplets of `q` (section 3: the EOF / SVD basis).
///
/// Decision: with l = rank + oversampling >= cols/2 the randomized sketch would be nearly as
/// wide as Q, so the exact Gram route is cheaper: eig(Q^T Q) (cols x cols), U = Q V S^-1.
/// Otherwise the randomized range finder with power iterations and QR re-orthonormalisation
/// between steps, then the SVD of the small l x cols matrix. Columns whose singular value is at
/// or below a drop threshold are removed (Gram route: 1e-7 sigma_max, because squaring Q leaves
/// only ~sqrt(machine eps) relative accuracy on sigma and U = Q V / sigma amplifies the error;
/// randomized route: 1e-12 sigma_max, numerical zero), so r <= rank and exactly rank-deficient
/// data gives exactly its rank.
/// @pre rank >= 1. Deterministic for a given options.seed.
TruncatedSvd truncatedSvd(const Eigen::Ref<const Eigen::MatrixXd>& q, Index rank,
                          const SvdOptions& options = {});

/// Removes the per-row mean (paper footnote 1): returns the mean and writes Q - mean 1^T.
Eigen::VectorXd removeRowMean(const Eigen::Ref<const Eigen::MatrixXd>& raw, Eigen::MatrixXd& centered);

/// Largest point error of a residual: max over columns (frames) and points of the Euclidean norm
/// over the point's `channels` rows. Rows are x = p*C + c.
double maxPointNorm(const Eigen::Ref<const Eigen::MatrixXd>& residual, Index channels);

/// Per column (frame) largest point norm, as maxPointNorm but one value per column.
Eigen::VectorXd maxPointNormPerColumn(const Eigen::Ref<const Eigen::MatrixXd>& residual,
                                      Index channels);

/// Smallest M with sum_{i<M} sigma_i^2 >= energy * totalEnergy, capped by sigma.size().
/// @pre 0 < energy <= 1.
Index basisSizeForEnergy(const Eigen::VectorXd& sigma, double totalEnergy, double energy);

/// Smallest M in [1, maxM] whose largest point projection error over the training frames,
/// max_{t,p} ||(Q - U_M U_M^T Q)_{p,t}||, is <= maxError. Returns maxM + 1 if none is.
/// Computed incrementally (rank-one downdates of the residual, a few frames at a time so the
/// working set stays in cache), never forming an (N*C) x (N*C) matrix.
/// @param errors if not null, receives the error for M = 1..maxM (as far as computed).
Index basisSizeForMaxError(const Eigen::Ref<const Eigen::MatrixXd>& q, const TruncatedSvd& svd,
                           Index channels, double maxError, Index maxM,
                           std::vector<double>* errors = nullptr);

}  // namespace pmsc
