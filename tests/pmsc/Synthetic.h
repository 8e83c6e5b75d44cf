// Synthetic training data with known structure, shared by the pmsc unit tests.
#pragma once

#include "pmsc/FrameSet.h"

#include <Eigen/Core>
#include <Eigen/QR>

#include <cmath>
#include <random>
#include <vector>

namespace pmsc::test {

/// A deterministic Gaussian matrix.
inline Eigen::MatrixXd gaussian(Index rows, Index cols, unsigned seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> normal(0.0, 1.0);
    Eigen::MatrixXd m(rows, cols);
    for (Index j = 0; j < cols; ++j)
        for (Index i = 0; i < rows; ++i) m(i, j) = normal(rng);
    return m;
}

/// An exactly rank-r matrix rows x cols with prescribed singular values sigma_i = scale * decay^i.
inline Eigen::MatrixXd lowRank(Index rows, Index cols, Index rank, unsigned seed, double decay = 0.7,
                               Eigen::VectorXd* sigmaOut = nullptr) {
    Eigen::MatrixXd a = gaussian(rows, rank, seed);
    Eigen::MatrixXd b = gaussian(cols, rank, seed + 1);
    Eigen::HouseholderQR<Eigen::MatrixXd> qa(a), qb(b);
    Eigen::MatrixXd u = qa.householderQ() * Eigen::MatrixXd::Identity(rows, rank);
    Eigen::MatrixXd v = qb.householderQ() * Eigen::MatrixXd::Identity(cols, rank);
    Eigen::VectorXd sigma(rank);
    for (Index i = 0; i < rank; ++i) sigma[i] = 10.0 * std::pow(decay, static_cast<double>(i));
    if (sigmaOut) *sigmaOut = sigma;
    return u * sigma.asDiagonal() * v.transpose();
}

/// Frames whose matrix is `m` plus an offset per row (so mean removal matters).
inline FrameSet framesFromMatrix(const Eigen::MatrixXd& m, Index channels, double offset = 5.0) {
    FrameSet set(m.cols(), m.rows() / channels, channels);
    auto q = set.matrix();
    for (Index i = 0; i < m.rows(); ++i)
        q.row(i) = m.row(i).array() + offset * std::sin(0.37 * static_cast<double>(i));
    return set;
}

/// Disjoint patches of points, each driven by its own signal: point p of patch k moves as
/// shape_k(p) * s_k(t) (per channel a fixed direction), and nothing else moves the patch.
/// `patchOf[p]` receives the patch of each point.
inline FrameSet patchFrames(Index patches, Index pointsPerPatch, Index channels, Index frames, unsigned seed,
                            std::vector<Index>* patchOf = nullptr) {
    const Index n = patches * pointsPerPatch;
    FrameSet set(frames, n, channels);
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> normal(0.0, 1.0);
    Eigen::MatrixXd signals(patches, frames);
    for (Index k = 0; k < patches; ++k)
        for (Index t = 0; t < frames; ++t)
            signals(k, t) = std::sin(0.05 * static_cast<double>((k + 1) * t) + static_cast<double>(k)) +
                            0.3 * normal(rng);
    Eigen::MatrixXd shape(n, channels);
    for (Index p = 0; p < n; ++p) {
        const double local = static_cast<double>(p % pointsPerPatch) / static_cast<double>(pointsPerPatch);
        for (Index c = 0; c < channels; ++c)
            shape(p, c) = (1.0 + 0.5 * c) * std::sin(3.14159 * local) + 0.1 * normal(rng);
    }
    if (patchOf) patchOf->resize(static_cast<size_t>(n));
    for (Index p = 0; p < n; ++p) {
        const Index k = p / pointsPerPatch;
        if (patchOf) (*patchOf)[static_cast<size_t>(p)] = k;
        for (Index t = 0; t < frames; ++t)
            for (Index c = 0; c < channels; ++c)
                set.frame(t)[p * channels + c] = 2.0 + shape(p, c) * signals(k, t);
    }
    return set;
}

}  // namespace pmsc::test
