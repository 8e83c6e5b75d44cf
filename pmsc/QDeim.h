// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <Eigen/Core>

#include <vector>

namespace pmsc {

/// Result of the Q-DEIM key selection.
struct QDeimSelection {
    std::vector<Index> keys;  ///< seeds first, then points in pivot order, no duplicates
    Index passes = 0;         ///< pivoted-QR passes run
};

/// Q-DEIM key points (Drmac & Gugercin 2016, "A new selection operator for the discrete empirical
/// interpolation method"): the pivots of a column-pivoted QR of B^T (M x N*C) are rows of B, i.e.
/// point-channels; each pivot row selects its whole point (section 4: a point is a key with all
/// its channels), duplicates are skipped.
///
/// Seeds (fiducials, then grid points) come first and are FORCED as the first pivots: their
/// columns of B^T are factored first and the remaining columns are projected onto the orthogonal
/// complement of their span before pivoting, which is exactly column-pivoted QR with those
/// columns forced to the front.
///
/// Decision, extending to a budget K beyond one pass: one pass yields at most M pivot rows (the
/// rank of B), so at most M points. To reach K we repeat the pivoted QR on the rows of the points
/// not yet chosen (each pass is the Q-DEIM selection of the remaining rows) until the budget is
/// met or no rows are left. Why this and not, e.g., leverage-score oversampling (Peherstorfer,
/// Drmac & Gugercin 2020): adding rows to B_K can only raise its smallest singular value, so the
/// conditioning guarantee of the first pass (||pinv(B_K)|| bounded as in Drmac & Gugercin) is
/// kept, every pass is deterministic and uses the same well-understood operator, and later
/// passes spread the extra keys over the points whose rows are next most independent instead of
/// concentrating them where leverage is already high.
/// @param basis (N*C) x M with orthonormal columns
/// @param seeds validated key points to force first (see seedKeys)
/// @param maxKeys the budget K (>= seeds.size())
/// @param candidates only points [0, candidates) may be keys (cross point multiplication); 0 = all
QDeimSelection selectKeysQDeim(const Eigen::MatrixXd& basis, Index channels, Index maxKeys,
                               const std::vector<Index>& seeds, Index candidates = 0);

}  // namespace pmsc
