// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/FrameSet.h"

#include <Eigen/Core>

#include <vector>

namespace pmsc {

/// A sparse spatial grid of points (section 4: "for rendering applications we may also add a
/// sparse grid of points to ensure that no large regions are devoid of key points").
///
/// The bounding box of `positions` (N x 3, one point per row) is cut into cellsPerAxis^3 equal
/// cells (the box's longest side sets the cell size, so cells are cubes). Each occupied cell
/// contributes the point nearest to its centre (ties to the lower index). The result is sorted
/// by cell (x fastest, then y, then z): deterministic, independent of point order except for ties.
/// @throws std::invalid_argument if cellsPerAxis < 1, positions has not 3 columns, or a
///         position is not finite.
std::vector<Index> sparseGridPoints(const Eigen::Ref<const Eigen::MatrixXd>& positions, Index cellsPerAxis);

/// At most `count` grid points: sparseGridPoints with the cellsPerAxis whose occupied-cell count is
/// the largest not above `count`. Found by doubling then bisection on cellsPerAxis; the occupied
/// count grows with cellsPerAxis only roughly (cell boundaries move), so the search keeps the best
/// grid it has seen rather than trusting monotonicity.
/// @throws std::invalid_argument if count < 1.
std::vector<Index> sparseGridPointsByCount(const Eigen::Ref<const Eigen::MatrixXd>& positions, Index count);

}  // namespace pmsc
