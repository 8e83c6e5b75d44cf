// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Communicator.h"
#include "pmsc/FrameSet.h"

#include <Eigen/Core>

#include <vector>

namespace pmsc {

/// Options of Kaiser's varimax rotation (section 4; Kaiser 1958).
struct VarimaxOptions {
    /// Kaiser row normalisation (rows scaled to unit length before rotating, scaled back after).
    /// Decision: off by default. The rows here are point-channels of an orthonormal basis block;
    /// normalising would give the many nearly-still points the same say as the few moving ones and
    /// defeat the localisation the key selection wants.
    bool normalize = false;
    double tolerance = 1e-8;  ///< stop when the relative gain of the objective is below this
    int maxIterations = 200;  ///< iteration cap
};

/// Result of a varimax rotation: rotated = loadings * rotation.
struct VarimaxResult {
    Eigen::MatrixXd rotation;       ///< B x B orthogonal
    Eigen::MatrixXd rotated;        ///< rows x B, the rotated block
    int iterations = 0;             ///< SVD steps taken
    bool converged = false;         ///< false if the iteration cap stopped it
    std::vector<double> objective;  ///< varimax criterion after 0, 1, ... steps (instrumentation)
};

/// The varimax criterion of a block Z (rows p, columns j), on the rows as given:
/// sum_j [ (1/p) sum_i z_ij^4 - ((1/p) sum_i z_ij^2)^2 ], the variance of the squared loadings
/// ("ratio of the 4th moment to the 2nd moment", section 4).
double varimaxCriterion(const Eigen::Ref<const Eigen::MatrixXd>& z);

/// Kaiser's varimax (section 4) by the standard SVD iteration (as R's stats::varimax): with
/// Z = X T, G = X^T (Z.^3 - Z diag(colsum(Z.^2)) / p), T <- U V^T from the SVD G = U S V^T.
/// Each step maximises a linear minorant of the (convex) criterion, so the criterion never
/// decreases. Stops when the relative gain of the criterion is below options.tolerance.
/// A block of one column is returned unrotated.
VarimaxResult varimax(const Eigen::Ref<const Eigen::MatrixXd>& loadings, const VarimaxOptions& options = {});

/// The same rotation of a block whose rows are split across ranks: `loadings` holds
/// this rank's rows, the criterion's column moments and the gradient G are summed over ranks (one
/// B x B + 2B reduction per step), so every rank takes the same steps and gets the same rotation;
/// `rotated` holds this rank's rows. The single-process varimax above is this with one rank.
VarimaxResult varimax(const Eigen::Ref<const Eigen::MatrixXd>& loadings, const VarimaxOptions& options,
                      Communicator& comm);
/// The same, rotating `loadings` where they lie (no copy of the N*C x k block): key selection
/// hands each round's block over.
VarimaxResult varimax(Eigen::MatrixXd&& loadings, const VarimaxOptions& options, Communicator& comm);

}  // namespace pmsc
