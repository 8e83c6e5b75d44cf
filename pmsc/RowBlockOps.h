// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/Communicator.h"
#include "pmsc/RowBlocks.h"

#include <Eigen/Core>

#include <vector>

namespace pmsc {

// The passes over the rows of Q that training makes. Each visits the owned blocks once
// and reduces over ranks through the Communicator; "local" matrices hold the owned rows only
// (ownedRows() x k), replicated ones are the same on every rank.

/// Q^T Q (F x F, replicated): the sum over blocks and ranks of symmetric rank-k updates.
Eigen::MatrixXd gramOf(RowBlocks& q, Communicator& comm);

/// Q_local * w (ownedRows x w.cols(), local).
Eigen::MatrixXd timesRight(RowBlocks& q, const Eigen::MatrixXd& w);

/// B^T Q (B.cols() x F, replicated) for a local B.
Eigen::MatrixXd transposeTimes(RowBlocks& q, Communicator& comm, const Eigen::MatrixXd& localB);

/// The largest point residual of Q - B C over all points and frames (maxPointResidual of
/// KeyPointSelector.h, block by block and over ranks). B local, C replicated (M x F).
double maxPointResidualOf(RowBlocks& q, Communicator& comm, const Eigen::MatrixXd& localB,
                          const Eigen::MatrixXd& coords);

/// The key points' rows (K*C x F, replicated) of the mean-removed Q, in key order.
Eigen::MatrixXd keyRowsOfQ(RowBlocks& q, Communicator& comm, const std::vector<Index>& keys);

/// The key points' rows (K*C x k, replicated) of a local matrix laid out like q's owned rows.
Eigen::MatrixXd keyRowsOf(const RowBlocks& layout, Communicator& comm, const Eigen::MatrixXd& local,
                          const std::vector<Index>& keys);

/// A local matrix's rows from every rank, stacked in rank order (the (N*C) x k matrix), on
/// `root`; an empty matrix elsewhere. Column by column, so the root holds one column extra.
Eigen::MatrixXd gatherRowsTo(Communicator& comm, const Eigen::MatrixXd& local, Index totalRows, int root = 0);

/// pinv(B_K) from the key rows B_K themselves (makeProjector without the gather).
Eigen::MatrixXd projectorFromKeyRows(const Eigen::MatrixXd& keyRows, Index channels);

}  // namespace pmsc
