// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Communicator.h"
#include "pmsc/FrameSet.h"
#include "pmsc/RowBlocks.h"
#include "pmsc/Subspace.h"
#include "pmsc/Varimax.h"

#include <Eigen/Core>

#include <functional>
#include <vector>

namespace pmsc {

/// The growing set of key points: selection order kept, membership in O(1), never a duplicate.
/// A point is a key with all its channels (section 4).
class KeySet {
public:
    explicit KeySet(Index points) : isKey_(static_cast<size_t>(points), 0) {}
    /// Only points [0, candidates) may become keys (cross point multiplication: the keys
    /// of a joint (control, target) model are control points); 0 or >= points: all of them.
    KeySet(Index points, Index candidates) : KeySet(points) {
        if (candidates > 0)
            for (Index p = candidates; p < points; ++p) isKey_[static_cast<size_t>(p)] = 2;
    }
    /// Whether p is a key or may not become one (so it is never a candidate).
    bool contains(Index p) const { return isKey_[static_cast<size_t>(p)] != 0; }
    /// Adds p unless it is already a key; returns whether it was added.
    bool add(Index p) {
        if (contains(p)) return false;
        isKey_[static_cast<size_t>(p)] = 1;
        keys_.push_back(p);
        return true;
    }
    Index size() const { return static_cast<Index>(keys_.size()); }
    Index points() const { return static_cast<Index>(isKey_.size()); }
    const std::vector<Index>& keys() const { return keys_; }

private:
    std::vector<char> isKey_;
    std::vector<Index> keys_;
};

/// Seeds designer fiducials, then grid points, into `keys` (section 4: "seeded into the first
/// batch"). @throws std::invalid_argument naming the first index that is out of [0, N) or
/// repeated (a fiducial listed twice, or a grid point that is also a fiducial), since a silently
/// dropped designer point would surprise its designer.
void seedKeys(KeySet& keys, const std::vector<Index>& fiducials, const std::vector<Index>& gridPoints);

/// The teleconnection pair of one rotated basis vector v (section 4), added to `keys` while
/// keys.size() < budget. A point's loading is its C-vector v_p = v[p*C .. p*C+C).
/// First: the non-key point with the largest ||v_p||. Second: the non-key point q minimising
/// v_p1 . v_q, the most negative inner product of loadings; if no point has a negative one, the
/// next largest magnitude. Ties go to the lower index. Returns the number of keys added (0 when
/// no candidate is left or the budget is spent).
///
/// Why the inner product of loadings: the residual excited by this localized vector alone is
/// v (v^T R), so the time series of points p and q under that excitation have inner product
/// (v_p . v_q) ||v^T R||^2. Ranking by v_p . v_q is ranking by the inner product of the points'
/// motion under this basis function (the paper's "most negatively correlated point"), at O(N*C).
Index addTeleconnectionPair(const Eigen::Ref<const Eigen::VectorXd>& v, Index channels, KeySet& keys,
                            Index budget);

/// The same pair for a vector whose rows are split across ranks: `v` holds the rows of
/// the points [firstPoint, firstPoint + v.size() / C); `keys` is replicated. The arg-max and
/// arg-min go through argMaxOverRanks (same tie rule: the lower index), and the first point's
/// loading is sent from its owner, so every rank adds the same keys.
Index addTeleconnectionPair(const Eigen::Ref<const Eigen::VectorXd>& v, Index channels, KeySet& keys,
                            Index budget, Communicator& comm, Index firstPoint);

/// The point-multiplication approximation of every column of q with the given keys and basis
/// (coordinates pinv(B_K) Q_K: minimum norm while the key system is underdetermined) and its
/// residual: residual = q - basis * coords. Returns the largest point residual (max over points
/// and frames of the Euclidean norm over channels).
/// @param coords if not null, receives the coordinates (M x F).
double pmResidual(const Eigen::Ref<const Eigen::MatrixXd>& q, const Eigen::MatrixXd& basis, Index channels,
                  const std::vector<Index>& keys, Eigen::MatrixXd& residual,
                  Eigen::MatrixXd* coords = nullptr);

/// The largest leading basis size M' <= basis.cols() that the keys determine well: K*C >= M' and
/// cond(B_K[:, :M']) = sigma_max / sigma_min <= maxCondition. (The condition number of leading
/// columns never decreases as columns are added, by singular value interlacing, so a bisection
/// finds it.) Returns 0 if not even one vector is determined.
Index determinedBasisSize(const Eigen::MatrixXd& basis, Index channels, const std::vector<Index>& keys,
                          double maxCondition = 1e8);

/// The largest point residual of q - basis * coords (max over points and frames of the Euclidean
/// norm over channels) without materialising the residual: rows are processed in cache-sized
/// blocks, so the training matrix is read once and nothing of its size is written.
double maxPointResidual(const Eigen::Ref<const Eigen::MatrixXd>& q,
                        const Eigen::Ref<const Eigen::MatrixXd>& basis, const Eigen::MatrixXd& coords,
                        Index channels);

/// Options of the teleconnection key selection (section 4).
struct TeleconnectionOptions {
    Index maxKeys = 200;  ///< key budget K
    double maxError = 0;  ///< stop when the largest point residual <= this; 0 = off
    Index block = 16;     ///< basis vectors per Varimax block
    std::vector<Index> fiducials;
    std::vector<Index> gridPoints;
    /// Only points [0, candidates) may be keys (cross point multiplication); 0 = every point.
    Index candidates = 0;
    VarimaxOptions varimax;
    SvdOptions svd;  ///< for the residual's leading vectors in rounds 2, 3, ...
    /// Called after each round with (round, keys so far, largest point residual); may throw to
    /// cancel.
    std::function<void(Index round, Index keys, double residual)> onRound;
};

/// Result of a key selection.
struct KeySelection {
    std::vector<Index> keys;               ///< in selection order, no duplicates
    std::vector<double> residualPerRound;  ///< largest point residual after each round
    Index rounds = 0;
    Eigen::MatrixXd keyRows;  ///< Q's rows at the keys (K*C x F), key order
};

/// The paper's iterative key selection (section 4).
///
/// Round 1 block: the top-B left singular vectors of Q (`firstBlock`, with `firstSigma`, which
/// are the first B basis vectors). Later rounds: the top-B left singular vectors of the current
/// residual (randomized SVD, rank B). Each block is varimax-rotated; its rotated vectors are
/// visited in decreasing variance (||diag(sigma) t_j||^2 for rotation column t_j) and each adds
/// its teleconnection pair. Fiducials then grid points are seeded first. After each round the
/// training set is approximated by PM with the current keys and the basis of the INITIAL Q
/// (`basis`), and the round's largest point residual recorded. Stops when it is <= maxError (if
/// set), the budget is met, or no candidate is left.
///
/// Speed decision: with `gram` = Q^T Q (available when the subspace came from the Gram route),
/// the residual's leading vectors are found in frame space: with W = B^T Q (once) and the round's
/// coordinates C, R^T R = G - W^T C - C^T W + C^T C (B orthonormal), an F x F eigenproblem, and
/// U_R = R V_R S_R^-1 = Q (V_R S_R^-1) - B (C V_R S_R^-1) is two skinny products: the residual
/// is never formed (its largest point error comes from maxPointResidual, block by block). That replaces the
/// six (N*C) x F x (B+10) products and three tall QRs of the randomized SVD per round (a third of the
/// key-selection time at the face scale). It is always used (see the RowBlocks overload below
/// for why and for what replaces it when the residual is too small for the subtraction, sigma_R <= 1e-6
/// sigma_1(Q)). This overload wraps q in MatrixBlocks on one process and computes Q^T Q when `gram` is null.
/// @param q the mean-removed training matrix, (N*C) x F
/// @param basis the runtime basis (N*C) x M computed from q, orthonormal columns
/// @param gram Q^T Q or null
KeySelection selectKeysTeleconnection(const Eigen::Ref<const Eigen::MatrixXd>& q,
                                      const Eigen::MatrixXd& basis,
                                      const Eigen::Ref<const Eigen::MatrixXd>& firstBlock,
                                      const Eigen::VectorXd& firstSigma, Index channels,
                                      const TeleconnectionOptions& options,
                                      const Eigen::MatrixXd* gram = nullptr);

/// The selection above over the rows of Q this process owns (the one implementation:
/// the in-memory overload wraps q in MatrixBlocks). `basis` and `firstBlock` hold the owned rows;
/// `gram` = Q^T Q is required. Every product with Q is one pass over q's blocks, reduced over
/// ranks; the residual's leading vectors always come from frame space (see above), because out of
/// core every product is a read of the data and the randomized route needs 2q + 2 of them per
/// round plus a distributed tall QR. Decision: when the frame-space subtraction cancels
/// (sigma_R <= 1e-6 sigma_1(Q)), the Gram of the explicitly formed residual (block by block) is
/// used instead (vectors down to 1e-7 of its own largest singular value, as the randomized SVD it
/// replaces kept them); only an exactly zero residual ends the selection.
KeySelection selectKeysTeleconnection(RowBlocks& q, Communicator& comm, const Eigen::MatrixXd& basis,
                                      const Eigen::Ref<const Eigen::MatrixXd>& firstBlock,
                                      const Eigen::VectorXd& firstSigma, const TeleconnectionOptions& options,
                                      const Eigen::MatrixXd& gram);

}  // namespace pmsc
