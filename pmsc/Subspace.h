// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <Eigen/Core>

#include <vector>

namespace pmsc {

/// Options of the truncated SVD (section 3; randomized route after Halko, Martinsson & Tropp
/// 2011, "Finding structure with randomness", algorithms 4.4 and 5.1).
struct SvdOptions {
    /// Which algorithm computes the SVD (see truncatedSvd).
    enum class Route : int { Auto = 0, Gram = 1, Randomized = 2 };
    Index oversampling = 10;    ///< extra test vectors p: the sketch has l = rank + p columns
    int powerIterations = 2;    ///< subspace iterations q (each one a Q^T and a Q product)
    unsigned seed = 20070101;   ///< seed of the Gaussian test matrix (std::mt19937_64): deterministic
    Route route = Route::Auto;  ///< Auto picks the cheaper route by flop count; tests force one
    /// Gram route only: left singular vectors to form, -1 = all `rank`. U = Q V S^-1 costs a
    /// rows x cols product per column, so a caller that needs only the leading ones (or learns how
    /// many later: formLeftVectors) saves it. sigma and V are always complete; the randomized
    /// route always forms all of U (there U = Y U_B is cheap).
    Index leftVectors = -1;
};

/// A truncated SVD Q ~= U diag(sigma) V^T with sigma descending.
struct TruncatedSvd {
    Eigen::MatrixXd u;       ///< rows x r, orthonormal columns: the basis vectors a_i[x]
    Eigen::VectorXd sigma;   ///< r singular values, descending, all > the drop threshold
    Eigen::MatrixXd v;       ///< cols x r, orthonormal columns: b_i[t] / sigma_i
    bool gramRoute = false;  ///< true if computed from Q^T Q (see truncatedSvd)
    /// Q^T Q (cols x cols) when the Gram route ran, else empty. Training reuses it: the residual
    /// blocks of key selection and the calibration folds are then solved in frame space.
    Eigen::MatrixXd gram;
};

/// Flop estimates of the two routes for a rows x cols matrix (see truncatedSvd), shared by the
/// callers that choose between a frame-space (Gram) and a randomized computation.
/// gramRouteFlops includes the cols x cols symmetric eigensolver (~9 cols^3), which dominates
/// when there are thousands of frames.
double gramRouteFlops(Index rows, Index cols, Index leftVectors);
double randomizedRouteFlops(Index rows, Index cols, Index sketch, int powerIterations);

/// Makes sure a Gram-route result has at least `count` left singular vectors (U = Q V S^-1 for
/// the missing columns, capped by sigma.size()). A randomized-route result already has all.
/// @param q the same matrix the SVD was computed from
void formLeftVectors(const Eigen::Ref<const Eigen::MatrixXd>& q, TruncatedSvd& svd, Index count);

/// Q^T Q by a symmetric rank-k update (half the flops of a general product), both triangles filled.
Eigen::MatrixXd gramMatrix(const Eigen::Ref<const Eigen::MatrixXd>& q);

/// The leading `rank` singular triplets of q from its Gram matrix g = Q^T Q: eig(g) gives V and
/// sigma^2, U = Q V S^-1 (the first `leftVectors` columns; -1 = all). Singular values at or below
/// max(dropBelow, 1e-7 sigma_max) are dropped (squaring Q leaves ~sqrt(machine eps) relative
/// accuracy, and dividing by a tiny sigma would amplify the error into U).
TruncatedSvd svdFromGram(const Eigen::Ref<const Eigen::MatrixXd>& q, const Eigen::MatrixXd& g, Index rank,
                         Index leftVectors = -1, double dropBelow = 0);

/// The leading `rank` singular triplets of `q` (section 3: the EOF / SVD basis).
///
/// Two routes. Gram: eig(Q^T Q) (cols x cols, a symmetric rank-k update), U = Q V S^-1.
/// Randomized: the range finder with q power iterations and Householder QR re-orthonormalisation
/// between steps, then the SVD of the small l x cols matrix B = Y^T Q, l = rank + oversampling.
///
/// Decision (revised from "Gram iff l >= cols/2" after profiling the face-scale training): Auto
/// takes the route with fewer flops. For a tall m x n matrix, Gram costs about m n^2 + 9 n^3 +
/// 2 m n r and randomized about 2 m n l (2q + 2) + 4 m l^2 (q + 1); with n = 600 frames and q = 2 the
/// randomized route is cheaper only for l below ~50, not below n/2 = 300: at l = 266 (the default
/// basis cap) it measured 8 s of CPU against under 1 s for the Gram route on 80,157 x 600. The
/// randomized route keeps its place for narrow sketches (residual blocks of B ~ 16 vectors) and for
/// matrices with many more columns than the rank. Gram is only used for tall matrices (n <= m). Columns whose
/// singular value is at or below a drop threshold are removed (Gram route: 1e-7 sigma_max, because squaring Q
/// leaves only ~sqrt(machine eps) relative accuracy on sigma and U = Q V / sigma amplifies the error;
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
Eigen::VectorXd maxPointNormPerColumn(const Eigen::Ref<const Eigen::MatrixXd>& residual, Index channels);

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

/// The scan of basisSizeForMaxError over some rows of Q (whole points) and the same rows of U
/// (svd.u's rows there): worst[i] becomes the max of itself and these rows' largest point error
/// with i + 1 basis vectors (worst.size() = maxM). Training runs it block by block, then takes the
/// max over ranks.
void accumulateBasisErrors(const Eigen::Ref<const Eigen::MatrixXd>& qRows,
                           const Eigen::Ref<const Eigen::MatrixXd>& uRows, const TruncatedSvd& svd,
                           Index channels, std::vector<double>& worst);
/// Smallest M with worst[M - 1] <= maxError, or worst.size() + 1.
Index basisSizeFromErrors(const std::vector<double>& worst, double maxError);

}  // namespace pmsc
