// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/BulkAllocator.h"

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace pmsc {

/// Signed index type used throughout (matches Eigen::Index).
using Index = Eigen::Index;

/// F frames of N points with C channels (3 for positions or RGB, 1 allowed).
///
/// Storage is exactly the C-order layout of a NumPy array of shape (F, N, C):
/// value(f, p, c) = values[(f * N + p) * C + c]. Seen as a column-major
/// (N*C) x F matrix this is the paper's training matrix Q (section 3), rows
/// indexed by x = p*C + c ("space"), columns by t = f ("time").
struct FrameSet {
    Index frames = 0;
    Index points = 0;
    Index channels = 0;
    /// Aligned as an Eigen matrix's own storage (EIGEN_MAX_ALIGN_BYTES), so the training matrix can
    /// be centred and trained where the frames lie (MatrixBlocks(FrameSet&&)) and computes to the
    /// bit what it computes on a copy.
    std::vector<double, BulkAllocator<double>> values;

    /// Tag of the constructor whose values are left for the caller to fill.
    struct Uninitialised {};

    FrameSet() = default;
    /// Allocates F*N*C zeros. @throws std::invalid_argument on a non-positive size.
    FrameSet(Index frameCount, Index pointCount, Index channelCount);
    /// Allocates F*N*C values the caller must write, every one, before reading any (a file
    /// reader, a calculation of every point). @throws std::invalid_argument on a non-positive size.
    FrameSet(Index frameCount, Index pointCount, Index channelCount, Uninitialised);

    Index rows() const { return points * channels; }

    /// The (N*C) x F training matrix, a view on `values`.
    Eigen::Map<const Eigen::MatrixXd> matrix() const { return {values.data(), rows(), frames}; }
    Eigen::Map<Eigen::MatrixXd> matrix() { return {values.data(), rows(), frames}; }

    /// One frame's N*C values (point-major, channel-minor).
    const double* frame(Index f) const { return values.data() + f * rows(); }
    double* frame(Index f) { return values.data() + f * rows(); }
};

}  // namespace pmsc
