// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <Eigen/Core>

#include <vector>

namespace pmsc {

/// A mean-centred truncated SVD that can absorb new frames without the old ones (paper section 5:
/// "poses identified as cache misses can be tagged and used as additional training ... training
/// could be done each night").
///
/// Holds the running mean mu of every frame absorbed so far and a rank-r factorisation
/// U diag(sigma) of the mean-removed matrix of all of them (the right singular vectors V are not
/// kept: nothing at run time needs them). `totalEnergy` is the exact squared Frobenius norm of
/// that mean-removed matrix, so totalEnergy - ||sigma||^2 is the energy the rank-r state does not
/// hold (its tail), whatever truncations happened on the way.
struct IncrementalSubspace {
    Index frames = 0;        ///< n: frames absorbed (training frames plus every update)
    Eigen::VectorXd mean;    ///< N*C, exact mean of the n frames
    Eigen::MatrixXd u;       ///< (N*C) x r, orthonormal columns
    Eigen::VectorXd sigma;   ///< r, descending, > 0
    double totalEnergy = 0;  ///< exact ||Q - mu 1^T||_F^2 of all n frames
    /// Sum of sigma^2 dropped by the updates' truncations to `maxRank` (the training's own tail,
    /// beyond the rank it stored, is totalEnergy - ||sigma||^2 - discardedEnergy).
    double discardedEnergy = 0;

    Index rank() const { return sigma.size(); }
    /// sqrt(totalEnergy - ||sigma||^2): the Frobenius norm of everything the state does not
    /// represent. By Weyl's inequality every singular value of the state is within this of the
    /// corresponding singular value of the exact mean-removed matrix (see updateSubspace).
    double tailNorm() const;
    /// Checks sizes and invariants; throws std::invalid_argument naming the first problem.
    void validate() const;
};

/// Options of updateSubspace.
struct IncrementalSvdOptions {
    /// Largest rank r kept after the update (the leading triplets). 0 = keep everything the
    /// update produces (old rank + new frames + 1).
    Index maxRank = 0;
    /// Singular values at or below this fraction of the largest are dropped as numerical zero
    /// (their directions carry no data; keeping them would add noise vectors to U).
    double dropRelative = 1e-12;
};

/// Absorbs `newFrames` ((N*C) x m, raw frames as columns, not mean-removed) into `state`:
/// Brand's block update of a thin SVD (M. Brand, "Fast low-rank modifications of the thin
/// singular value decomposition", Linear Algebra Appl. 415, 2006; libROM's IncrementalSVDBrand
/// does it one column at a time) with the mean update of Ross, Lim, Lin & Yang ("Incremental
/// learning for robust visual tracking", IJCV 77, 2008):
///
///   B^ = [B - mu_B 1^T,  sqrt(n m / (n + m)) (mu_B - mu_A)]          (centred new data)
///   L  = U^T B^,  H = B^ - U L   (projected twice: classical Gram-Schmidt loses orthogonality)
///   H  = J K                     (rank-revealing QR, J orthonormal and orthogonal to U)
///   [diag(sigma) L; 0 K] = U~ S~ V~^T   (an (r + k) x (r + m + 1) SVD)
///   U' = [U J] U~,  sigma' = S~,  truncated to options.maxRank.
///
/// The scatter of the union about its new mean is exactly the old scatter plus B^ B^^T, so:
/// - exact: the mean, the frame count and totalEnergy, always; and U', sigma' are the exact SVD
///   of [U diag(sigma), B^] (to rounding), so when the old state held every direction of the old
///   frames (their rank <= r) and nothing is truncated, the result is the SVD of all frames,
///   the same as training from scratch up to rounding and the signs of U's columns;
/// - approximate otherwise: the old frames are represented by their rank-r part only. With E the
///   part left out (||E||_F = tailNorm() after the update), |sigma'_i - sigma_i(exact)| <=
///   ||E||_2 <= tailNorm() (Weyl), and the leading M directions are off by at most
///   sin(theta) <= tailNorm() / (sigma_M - sigma_{M+1}) (Wedin).
/// Cost: one (N*C) x (r + m + 1) x (r + m + 1) product for U' and two for L; the (N*C) data of the
/// old frames is never touched.
/// @pre newFrames.rows() == state.mean.size(), m >= 1, all values finite.
/// @throws std::invalid_argument for a size mismatch or an empty update.
void updateSubspace(IncrementalSubspace& state, const Eigen::Ref<const Eigen::MatrixXd>& newFrames,
                    const IncrementalSvdOptions& options = {});

/// The span of an update: every new frame about the state's mean, b_i - mu, lies in
/// span W = [U J], U the state's r vectors and J = h * toJ k orthonormal directions outside span(U)
/// (directions whose singular value is under 1e-7 of the data's scale dropped, as updateSubspace
/// does), and `coords` holds W^T (b_i - mu). An update of the state with any subset of the frames
/// is then an (r + k)-dimensional problem (updateInSpan): cross-fitting folds need no pass over the
/// (N*C) rows beyond forming their basis.
struct UpdateSpan {
    Eigen::MatrixXd h;       ///< (N*C) x m: the new frames about the old mean, with span(U) projected out
    Eigen::MatrixXd toJ;     ///< m x k: J = h * toJ
    Eigen::MatrixXd coords;  ///< (r + k) x m: W^T (b_i - mu)
};

/// W and the coordinates of `newFrames` ((N*C) x m raw frames) for updates of `state`.
/// Cost: two (N*C) x r x m products (span(U) projected out twice) and one (N*C) x m x m Gram
/// product. @throws std::invalid_argument as updateSubspace.
UpdateSpan spanOfUpdate(const IncrementalSubspace& state, const Eigen::Ref<const Eigen::MatrixXd>& newFrames,
                        const IncrementalSvdOptions& options = {});

/// `state` updated with the columns `columns` of `newFrames` (the frames spanOfUpdate(state, ...)
/// was given), computed in span W: equal to updateSubspace(state, those columns) to rounding (the
/// same core SVD, rotated into W's coordinates; tested), at the cost of the small core SVD, one
/// (N*C) x (r + m) x r' product for U' (r' the rank kept) and a pass over the chosen frames for the
/// exact mean and energy.
/// @throws std::invalid_argument for an empty or out-of-range column list.
IncrementalSubspace updateInSpan(const IncrementalSubspace& state, const UpdateSpan& span,
                                 const Eigen::Ref<const Eigen::MatrixXd>& newFrames,
                                 const std::vector<Index>& columns,
                                 const IncrementalSvdOptions& options = {});

/// The largest principal angle (radians) between the column spaces of two matrices with
/// orthonormal columns: theta_max with sin(theta_max) = ||(I - A A^T) B||_2 when A has at least as
/// many columns as B (the two spaces' dimensions are taken as they are; equal in practice).
double largestPrincipalAngle(const Eigen::Ref<const Eigen::MatrixXd>& a,
                             const Eigen::Ref<const Eigen::MatrixXd>& b);

}  // namespace pmsc
